"""The client never has the scene's animation model: it cannot import it, and nothing it
parses from the wire (proxy bundle, frames' object poses) holds one (DESIGN.md)."""
import json
import subprocess
import sys

import numpy as np

from pibr.protocol.messages import Frame, PayloadKind
from pibr.protocol.object_poses import decode_object_poses
from pibr.protocol.pose import Pose
from pibr.protocol.proxy import decode_bundle, decompress_bundle
from pibr.scenes.animation import Animation
from pibr.scenes.registry import load_scene

_IMPORT_EVERY_CLIENT_MODULE = """
import importlib, inspect, json, pkgutil, sys
import pibr.client
names = [m.name for m in pkgutil.walk_packages(pibr.client.__path__, "pibr.client.")]
for name in names:
    importlib.import_module(name)
# any class anywhere in the process that looks like an animation: it evaluates a motion at a time
animated = sorted(f"{mod}.{cls}" for mod, module in list(sys.modules.items())
                  if mod.startswith("pibr") for cls, obj in vars(module).items()
                  if inspect.isclass(obj) and cls in ("Animation", "RigidMotion"))
print(json.dumps({"imported": names, "loaded": sorted(sys.modules), "animated": animated}))
"""


def test_no_client_module_imports_the_animation_model():
    out = subprocess.run([sys.executable, "-c", _IMPORT_EVERY_CLIENT_MODULE], capture_output=True, text=True,
                         check=True, timeout=300)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert "pibr.client.app" in result["imported"] and "pibr.client.methods.proxy" in result["imported"]
    leaked = [m for m in result["loaded"] if m.startswith(("pibr.scenes", "pibr.server", "pibr.bench"))]
    assert leaked == []
    assert "pibr.protocol.motion" not in result["loaded"]
    assert result["animated"] == []


def _objects_reachable(root, limit=100_000) -> list:
    """Every object reachable from ``root`` through attributes, containers and dataclass fields."""
    seen, stack, out = set(), [root], []
    while stack and len(out) < limit:
        o = stack.pop()
        if id(o) in seen or isinstance(o, (str, bytes, int, float, bool, type(None), np.ndarray, np.generic)):
            continue
        seen.add(id(o))
        out.append(o)
        if isinstance(o, dict):
            stack.extend(o.keys())
            stack.extend(o.values())
        elif isinstance(o, (list, tuple, set)):
            stack.extend(o)
        elif hasattr(o, "__dict__"):
            stack.extend(vars(o).values())
    return out


def test_what_the_client_parses_holds_no_animation_model():
    from pibr.server.object_poses import object_poses_payload
    from pibr.server.proxies import build_bundle

    scene = load_scene("dynamic")
    assert any(isinstance(o.animation, Animation) for o in scene.objects)
    bundle = build_bundle(scene)
    proxies = decode_bundle(decompress_bundle(bundle.compressed, bundle.raw_bytes, bundle.objects))
    payload = object_poses_payload(scene, 1.25)
    frame = Frame.parse(Frame(0, 1_250_000, 1_200_000, 0, 1_250_000, Pose.identity(), None, 0.1, 100.0,
                              payloads=((PayloadKind.OBJECT_POSES, payload),)).serialize())
    poses = decode_object_poses(frame.payload(PayloadKind.OBJECT_POSES), len(proxies))
    for root in (proxies, frame, poses):
        for o in _objects_reachable(root):
            assert not isinstance(o, Animation)
            assert not type(o).__module__.startswith(("pibr.scenes", "pibr.server")), type(o)
    assert sum(o.moving for o in proxies) == len(poses) == sum(o.is_dynamic for o in scene.objects)
