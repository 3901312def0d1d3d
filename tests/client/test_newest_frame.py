"""Issue 13, deliverable 3: a slow reader gets the newest frame, never a backlog of stale ones.

Client side: frames that arrived while the decoder was busy are decoded together (each H.264
frame refers to the one before) but only the newest is converted and shown, and the server is
told they were all taken at once."""
import asyncio

import numpy as np
import pytest

from pibr.client.app import Client, WARMUP_SEQ
from pibr.client.config import ClientConfig
from pibr.client.connection import ServerClosed
from pibr.protocol.messages import FRAMES_DECODED, Bye, Frame, Hello, PayloadKind, PoseMsg, Stats, Welcome
from pibr.protocol.pose import Pose

from ..loopback import scripted_server

pytestmark = pytest.mark.gl


def _session_config() -> dict:
    from pibr.scenes.registry import load_scene
    from pibr.server.config import ServerConfig
    from pibr.server.session_plan import plan_session

    config, _ = plan_session(ServerConfig(scene="sphere", view_size=(64, 64), extra_view="off"), load_scene("sphere"),
                             Hello(scene="sphere", clock="real"))
    return config.to_json()


def _frames(config: dict, count: int) -> list:
    """``count`` real H.264 frames of the session's atlas, a grey ramp that changes every frame.

    Stamped as rendered from a pose sent a minute into the session: the client starts its clock
    only on a frame of a pose sent after its warm-up, and this script sends no other frames."""
    from pibr.server.video import H264Encoder

    w, h = config["atlas"]["width"], config["atlas"]["height"]
    encoder = H264Encoder(w, h, 10.0, 1000.0, 30, "ultrafast", deterministic=True)
    pose = Pose.make((0, 1.6, 0))
    frames = []
    for i in range(count):
        yuv = np.full((h * 3 // 2, w), 128, np.uint8)
        yuv[:h] = (np.arange(w)[None, :] + 20 * i) % 200 + 20
        data, key = encoder.encode(yuv)
        frames.append(Frame(frame_id=i, render_t_us=i * 100_000, pose_t_us=60_000_000, pose_seq=0, scene_t_us=i * 100_000,
                            primary_pose=pose, extra_pose=None, near=0.1, far=100.0,
                            payloads=((PayloadKind.H264_ATLAS, data),), keyframe=key))
    encoder.close()
    return frames


async def test_frames_that_arrive_together_are_taken_together_and_the_newest_is_shown(tmp_path):
    config = _session_config()
    frames = _frames(config, 5)
    reports = []

    async def server(peer):
        assert isinstance(await peer.recv(), Hello)
        await peer.send(Welcome(server="burst", session=1, config=config))
        while not isinstance(await peer.recv(), PoseMsg):   # the client warming up asks for a frame
            pass
        peer.conn.send(frames[0])
        for frame in frames[1:]:           # five frames in one write: all there when the client reads
            peer.conn.send(frame)
        peer.writer.write(peer.conn.data_to_send())
        while True:     # until the client has shown a frame: its clock started, tick poses come
            msg = await peer.recv()
            if isinstance(msg, Stats) and FRAMES_DECODED in msg.values:
                reports.append(msg.values[FRAMES_DECODED])
            if isinstance(msg, PoseMsg) and msg.seq != WARMUP_SEQ:
                break
        await peer.send(Bye("seen enough"))
        while await peer.recv() is not None:
            pass

    async with scripted_server(server) as (host, port):
        client = Client(ClientConfig(host=host, port=port, clock="real", trace="pred6dof-1", start_s=12.0,
                                     duration_s=1.0, rate_hz=10.0, methods=("none",), out_dir=str(tmp_path),
                                     width=64, height=48, progress="none", video=False, receive_timeout_s=10.0))
        with pytest.raises(ServerClosed, match="seen enough"):
            await asyncio.wait_for(client.run(), 60)
    assert reports == [5]                                   # one report for all five, not 1, 2, 3, ...
    assert client._decoder.frames == 5 and client._decoder.converted == 1
    assert client._newest.frame.frame_id == 4 and client.frames_received == 5
    # The newest frame decoded through the chain of the four before it is the picture encoded.
    y = client._newest.image.y.astype(int)
    expected = (np.arange(y.shape[1]) + 80) % 200 + 20
    assert np.abs(y - expected[None, :]).mean() < 2.0


async def test_the_inbox_is_bounded_in_bytes():
    from pibr.client.app import FrameInbox

    inbox = FrameInbox(max_bytes=100)
    await inbox.put("a", 0, 60)
    waiting = asyncio.create_task(inbox.put("b", 1, 60))    # would hold 120 bytes: waits
    await asyncio.sleep(0.01)
    assert not waiting.done()
    assert await inbox.take_all() == [("a", 0)]
    await asyncio.wait_for(waiting, 1)
    assert await inbox.take_all() == [("b", 1)]
    await inbox.put("big", 2, 500)                          # alone it may exceed the bound
    assert await inbox.take_all() == [("big", 2)]
