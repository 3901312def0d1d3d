"""Fingerprints of the LoD proxies of the room and of Spot at the default parameters, pinned in
``golden/lod_proxies.json``: the kernels of :mod:`pibr.scenes.mesh_queries` and
:mod:`pibr.scenes.voxelize` must leave every proxy bit for bit as the numpy code made it.

The file was written by this module run against main at 2aab3c5 (before the kernels), with the
library versions it records. Regenerate only when the generator's output changes on purpose
(then bump ``lod_cache.FORMAT_VERSION`` too): ``python -m tests.scenes.golden_lod``.
"""
from __future__ import annotations

import hashlib
import json
import os
from importlib.metadata import version
from pathlib import Path

GOLDEN_PATH = Path(__file__).resolve().parent / "golden" / "lod_proxies.json"
SPOT = Path(__file__).resolve().parents[2] / "scenes" / "data" / "assets" / "spot_triangulated.obj"
#: Libraries whose floating-point output the proxies depend on (marching cubes, decimation, numpy's
#: SIMD loops): the pinned hashes hold for these versions.
LIBRARIES = ("numpy", "scipy", "scikit-image", "fast-simplification")


def library_versions() -> dict:
    return {name: version(name) for name in LIBRARIES}


def scenes():
    """(label, scene) pairs fingerprinted: the room and the Spot asset."""
    from pibr.scenes.registry import load_scene

    return [("room", load_scene("room")), ("spot", load_scene(str(SPOT)))]


def fingerprint(result) -> dict:
    """What must not change of a LodResult: sha256 of the proxy's vertex and face bytes, its kind,
    size, encaging iterations, enclosure measures and note."""
    digest = hashlib.sha256(result.proxy.vertices.tobytes() + result.proxy.faces.tobytes()).hexdigest()
    return {"sha256": digest, "kind": result.kind, "triangles": result.triangles_proxy,
            "iterations": result.iterations, "enclosed_fraction": result.enclosed_fraction,
            "max_outside_distance": result.max_outside_distance, "note": result.note}


def generate() -> dict:
    from pibr.scenes.lod import simplify_encaging

    objects = {f"{label}/{obj.name}": fingerprint(simplify_encaging(obj.mesh))
               for label, scene in scenes() for obj in scene.objects}
    return {"parameters": "simplify_encaging defaults (resolution 128, target_fraction 0.005)",
            "libraries": library_versions(), "objects": objects}


if __name__ == "__main__":
    GOLDEN_PATH.parent.mkdir(exist_ok=True)
    with open(GOLDEN_PATH, "w") as f:
        json.dump(generate(), f, indent=1, sort_keys=True)
        f.write("\n")
    print(f"wrote {GOLDEN_PATH} ({os.path.getsize(GOLDEN_PATH)} bytes)")
