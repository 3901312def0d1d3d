"""The client process with a scene that moves: the frames' object transforms reach ``proxy``'s
extrapolation through the session's pose history; bad object poses close the session."""
import json

import numpy as np
import pytest

from pibr.client.app import Client, run_client
from pibr.client.config import ClientConfig
from pibr.protocol.errors import ConfigError, MalformedMessage
from pibr.protocol.messages import Frame, PayloadKind
from pibr.protocol.object_poses import ObjectPoses, encode_object_poses
from pibr.protocol.pose import Pose
from pibr.server.config import ServerConfig

from ..loopback import running_server

pytestmark = pytest.mark.gl


def _frames(path):
    import av

    with av.open(path) as c:
        return [f.to_ndarray(format="rgb24") for f in c.decode(video=0)]


@pytest.fixture
async def dynamic_server():
    config = ServerConfig(port=0, scene="dynamic", view_size=(192, 192), bitrate_kbps=3000)
    async with running_server(config) as (_, host, port):
        yield host, port


def _cfg(host, port, out, methods=("proxy",), **kw):
    return ClientConfig(host=host, port=port, trace="synth-turns", start_s=5.0, duration_s=1.0, rate_hz=30.0,
                        methods=methods, out_dir=str(out), width=160, height=96, progress="none", **kw)


async def test_proxy_extrapolates_from_the_transforms_on_the_wire(dynamic_server, tmp_path):
    host, port = dynamic_server
    shown = {}
    for motion in ("static", "velocity"):
        client = Client(_cfg(host, port, tmp_path / motion, options={"motion": motion}))
        await client.run()
        moving = [i for i, o in enumerate(client.proxies) if o.moving]
        assert len(moving) == 5 and sorted(client.poses.indices()) == moving   # every frame's transforms
        assert all(len(client.poses.track(i)) == 4 for i in moving)
        assert client.poses.newest_time == pytest.approx(0.9, abs=0.15)      # the last frames of the second
        shown[motion] = _frames(tmp_path / motion / "proxy.lossless.avi")
        info = json.load(open(tmp_path / motion / "session.json"))
        assert info["session"]["motion"] is True and info["session"]["scene"]["dynamic"] is True
        assert info["client"]["options"] == {"motion": motion}
    assert len(shown["static"]) == len(shown["velocity"]) == 30
    differ = [not np.array_equal(a, b) for a, b in zip(shown["static"], shown["velocity"])]
    assert sum(differ) >= 10            # the moving objects are placed by the transforms received


async def test_the_client_extrapolates_along_the_motion_flow_on_the_wire(dynamic_server, tmp_path):
    """--motion flow: the frames' MOTION_FLOW decoded in the decode pool, the primary view warped on
    the GL thread, for a method without proxies and for proxy alike."""
    host, port = dynamic_server
    shown = {}
    for motion in ("static", "flow"):
        client = Client(_cfg(host, port, tmp_path / motion, methods=("rotation", "proxy"),
                             options={"motion": motion}))
        result = await client.run()
        assert result.frames_received >= 8
        assert (client._motion_decoder is not None) == (motion == "flow")
        assert (client._newest.flow is not None) == (motion == "flow")
        shown[motion] = {m: _frames(tmp_path / motion / f"{m}.lossless.avi") for m in ("rotation", "proxy")}
    for m in ("rotation", "proxy"):
        assert len(shown["static"][m]) == len(shown["flow"][m]) == 30
        differ = [not np.array_equal(a, b) for a, b in zip(shown["static"][m], shown["flow"][m])]
        assert sum(differ) >= 10, m     # the moving pixels moved


async def test_the_oracle_is_not_a_client_option(dynamic_server, tmp_path):
    host, port = dynamic_server
    with pytest.raises(ConfigError, match="only the benchmarks have"):
        await run_client(_cfg(host, port, tmp_path, options={"motion": "oracle"}))


def test_bad_object_poses_are_a_protocol_error(tmp_path):
    """A frame's object poses are checked on arrival against the session: an index beyond the
    scene's objects, or poses in a session that said nothing moves."""
    from pibr.protocol.session import SessionConfig
    from pibr.scenes.registry import load_scene
    from pibr.server.session_plan import plan_session
    from pibr.protocol.messages import Hello

    def frame_with(poses):
        return Frame(0, 0, 0, 0, 0, Pose.identity(), None, 0.1, 100.0,
                     payloads=((PayloadKind.OBJECT_POSES, encode_object_poses(poses)),))

    client = Client(_cfg("127.0.0.1", 1, tmp_path))
    dynamic = load_scene("dynamic")
    config, _ = plan_session(ServerConfig(view_size=(64, 64)), dynamic, Hello())
    client.session = SessionConfig.from_json(config.to_json())
    n = len(dynamic.objects)
    ok = ObjectPoses.from_matrices([n - 1], [np.eye(4)])
    assert client._object_poses(frame_with(ok)).indices.tolist() == [n - 1]
    with pytest.raises(MalformedMessage, match=f"object index {n} is not below the object count {n}"):
        client._object_poses(frame_with(ObjectPoses.from_matrices([n], [np.eye(4)])))
    static, _ = plan_session(ServerConfig(view_size=(64, 64)), load_scene("sphere"), Hello())
    client.session = SessionConfig.from_json(static.to_json())
    with pytest.raises(MalformedMessage, match="the session has no moving objects"):
        client._object_poses(frame_with(ok))
    bad = dict(config.to_json(), scene=dict(config.to_json()["scene"], objects=-3))
    with pytest.raises(MalformedMessage, match="'objects' = -3 is outside"):
        SessionConfig.from_json(bad)
