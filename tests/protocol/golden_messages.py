"""The messages pinned as golden bytes in ``golden/``. Regenerate only when the wire format
changes on purpose: ``python -m tests.protocol.golden_messages`` (then review the diff)."""
from __future__ import annotations

from pibr.protocol.framing import encode_frame
from pibr.protocol.messages import (Bye, Clock, Error, Frame, Hello, OutputConfig, PayloadKind, PoseMsg, ProxyChunk,
                                    Stats, Welcome)
from pibr.protocol.pose import Pose

from .golden_files import GOLDEN_DIR, write_goldens  # noqa: F401 (GOLDEN_DIR: the tests import it from here)


POSE = Pose.make((0.5, 1.6, -2.0), (0.9238795325112867, 0.0, 0.3826834323650898, 0.0))
EXTRA = Pose.make((0.5, 3.4, -3.5), (0.9914448613738104, -0.13052619222005157, 0.0, 0.0))

MESSAGES = {
    "hello": (Hello(client="golden", scene="room", clock="virtual", output=OutputConfig(960, 540, 90.0, 60.0),
                    want_proxies=True, depth_codec="h264"), 0),
    "welcome": (Welcome(server="pibr-server/0.1", session=7, config={"server_fps": 10.0, "scene": {"name": "room"}},
                        setup_us=123), 0),
    "pose": (PoseMsg(seq=42, t_us=700_000, pose=POSE), 700_000),
    "frame": (Frame(frame_id=3, render_t_us=300_000, pose_t_us=216_667, pose_seq=13, scene_t_us=300_000,
                    primary_pose=POSE, extra_pose=EXTRA, near=0.1, far=1000.0,
                    timings_ms=(12.5, 1.25, 3.0, 6.5),
                    payloads=((PayloadKind.H264_ATLAS, b"\x00\x00\x00\x01\x67fake-h264"),
                              (PayloadKind.EDGE_DEPTH, b"edge")), keyframe=True), 320_000),
    "clock": (Clock(), 420_000),
    "proxy_chunk": (ProxyChunk(index=1, count=3, total_size=10, data=b"zstd"), 0),
    "stats": (Stats({"frames_received": 12.0, "missed_deadlines": 0.0}), 0),
    "bye": (Bye("done"), 0),
    "error": (Error(6, "Pose: invalid pose: quaternion norm below 1e-06"), 0),
}


def golden_bytes(name: str) -> bytes:
    msg, vt = MESSAGES[name]
    return encode_frame(msg.TYPE, msg.serialize(), vt)


if __name__ == "__main__":
    write_goldens(MESSAGES, golden_bytes)
