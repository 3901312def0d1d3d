"""Moving objects on the wire: every frame of a scene that moves carries its objects' transforms
(with either depth codec, with or without proxies); a static scene's frames carry no motion of
any kind, and the session says so."""

import numpy as np
import pytest

from pibr.client.connection import ClientConnection
from pibr.client.depth_decoders import EdgeDepthDecoder
from pibr.protocol.messages import Hello, OutputConfig, PayloadKind, ProxyChunk
from pibr.protocol.object_poses import decode_object_poses
from pibr.protocol.proxy import BundleAssembler, BundleInfo, decode_bundle, decompress_bundle
from pibr.scenes.registry import load_scene
from pibr.server.config import ServerConfig

from ..loopback import exchange_virtual, running_server

pytestmark = pytest.mark.gl

MOTION_KINDS = (PayloadKind.OBJECT_POSES, PayloadKind.EDGE_MOTION, PayloadKind.MOTION_FLOW)


@pytest.fixture
async def server():
    config = ServerConfig(port=0, scene="sphere", view_size=(128, 128), fps=10.0, server_delay_ms=20.0,
                          bitrate_kbps=2000)
    async with running_server(config) as (_, host, port):
        yield host, port


async def _session(host, port, scene: str, depth_codec: str, want_proxies: bool = False, ticks: int = 8):
    """-> (SessionConfig, proxies or None, [Frame])."""
    c = await ClientConnection.open(host, port)
    cfg = await c.handshake(Hello(client="test", scene=scene, output=OutputConfig(160, 96, 90.0, 30.0),
                                  want_proxies=want_proxies, depth_codec=depth_codec))
    proxies = None
    if want_proxies:
        info = BundleInfo.from_json(cfg.proxies)
        assembler = BundleAssembler(info)
        while not assembler.complete:
            env = await c.recv(timeout=300)
            assert isinstance(env.message, ProxyChunk)
            assembler.add(env.message)
        proxies = decode_bundle(decompress_bundle(assembler.data(), info.raw_bytes, info.objects))
    interval = 33_333
    frames = await exchange_virtual(c, cfg.viewer_origin, [k * interval for k in range(ticks)], interval)
    await c.close()
    return cfg, proxies, [f for _, f in frames]


@pytest.mark.parametrize("depth_codec, want_proxies", [("h264", False), ("edge", False), ("h264", True)])
async def test_a_moving_scene_sends_its_objects_transforms_in_every_frame(server, depth_codec, want_proxies):
    scene = load_scene("dynamic")
    moving = [i for i, o in enumerate(scene.objects) if o.is_dynamic]
    cfg, proxies, frames = await _session(*server, "dynamic", depth_codec, want_proxies)
    assert cfg.motion is True and cfg.object_count == len(scene.objects)
    assert len(frames) >= 2
    if proxies is not None:
        assert [i for i, o in enumerate(proxies) if o.moving] == moving
    for f in frames:
        poses = decode_object_poses(f.payload(PayloadKind.OBJECT_POSES), cfg.object_count)
        assert poses.indices.tolist() == moving
        t = f.scene_t_us / 1e6
        truth = np.stack([scene.objects[i].animation.matrix(t) for i in moving])
        np.testing.assert_allclose(poses.matrices(), truth, atol=2e-6)   # float32 on the wire
        assert len(f.payload(PayloadKind.OBJECT_POSES)) == 4 + 32 * len(moving)
    assert frames[0].scene_t_us != frames[-1].scene_t_us


@pytest.mark.parametrize("depth_codec", ["h264", "edge"])
async def test_a_static_scene_sends_no_motion_of_any_kind(server, depth_codec):
    cfg, _, frames = await _session(*server, "sphere", depth_codec)
    assert cfg.motion is False and cfg.to_json()["motion"] is False
    assert frames
    for f in frames:
        assert not [k for k, _ in f.payloads if k in MOTION_KINDS], f.payloads
    if depth_codec == "edge":   # and the edge codec's depth carries no motion flow either
        decoder = EdgeDepthDecoder(cfg)
        try:
            for f in frames:
                decoder.decode(f)
                assert decoder.motion is None
        finally:
            decoder.close()


@pytest.mark.parametrize("depth_codec", ["h264", "edge"])
async def test_a_moving_scene_sends_its_motion_flow_with_either_depth_codec(server, depth_codec):
    """MOTION_FLOW in every frame, a flow of the primary view; the edge codec's depth carries none."""
    from pibr.client.motion_flow import MotionFlowDecoder

    cfg, _, frames = await _session(*server, "dynamic", depth_codec)
    assert frames
    decoder = MotionFlowDecoder(cfg.primary.width, cfg.primary.height)
    moving_frames = 0
    for f in frames:
        flow, moving = decoder.decode(f.payload(PayloadKind.MOTION_FLOW))
        assert flow.shape == (cfg.primary.height, cfg.primary.width, 2)
        assert np.all(flow[~moving] == 0)
        moving_frames += bool(moving.any())
    assert moving_frames >= 1     # the viewer origin looks at the spinning turnstile
    if depth_codec == "edge":
        depth = EdgeDepthDecoder(cfg)
        try:
            for f in frames:
                depth.decode(f)
                assert depth.motion is None
        finally:
            depth.close()


def test_the_flow_coder_is_checked():
    from pibr.protocol.errors import ConfigError

    with pytest.raises(ConfigError, match="flow coder must be one of blocks, edges, got 'dct'"):
        ServerConfig(flow_coder="dct")
