"""The session pipeline: one place builds a session's frames, for the server and every benchmark."""
import numpy as np
import pytest

from pibr.protocol.messages import Frame, Hello, OutputConfig, PayloadKind
from pibr.protocol.pose import Pose
from pibr.scenes.registry import load_scene
from pibr.server.config import ServerConfig
from pibr.server.depth_encoders import AtlasDepthEncoder, EdgeDepthEncoder
from pibr.server.pipeline import SessionPipeline

pytestmark = pytest.mark.gl


@pytest.fixture
def gl_ctx():
    """A context of the test's own (current on this thread, no state shared with other tests)."""
    from pibr.common.gl import create_context

    ctx = create_context()
    yield ctx
    ctx.release()

HELLO = Hello(output=OutputConfig(160, 90, 90.0, 30.0))


def _frames(gl_ctx, config, scene, hello=HELLO, n=2):
    pipeline = SessionPipeline(config, scene, hello).open(gl_ctx)
    try:
        out = []
        for k in range(n):
            pose = scene.viewer_origin.compose(Pose.make([0.05 * k, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]))
            produced = pipeline.produce(pose, k * 0.1)
            frame = pipeline.frame(k, k * 100_000, k * 100_000 - 33_333, k, produced, pipeline.encode(produced))
            out.append(Frame.parse(frame.serialize()))   # what goes on the wire
        return pipeline, out
    finally:
        pipeline.release()


def test_payloads_follow_the_session_and_one_order(gl_ctx):
    still, moving = load_scene("courtyard"), load_scene("room")
    p, frames = _frames(gl_ctx, ServerConfig(view_size=(128, 128), extra_view="on", depth_codec="edge"), moving,
                        Hello(output=HELLO.output, quadtree_threshold=0.05))
    assert isinstance(p.depth, EdgeDepthEncoder) and p.session.depth_codec == "edge"
    assert [k for k, _ in frames[0].payloads] == [PayloadKind.H264_ATLAS, PayloadKind.EDGE_DEPTH,
                                                  PayloadKind.EDGE_DEPTH_EXTRA, PayloadKind.QUADTREE,
                                                  PayloadKind.OBJECT_POSES, PayloadKind.MOTION_FLOW]
    assert frames[0].keyframe and not frames[1].keyframe
    assert frames[1].pose_t_us == 66_667 and frames[1].scene_t_us == frames[1].render_t_us == 100_000
    p, frames = _frames(gl_ctx, ServerConfig(view_size=(128, 128), extra_view="off", depth_codec="h264"), still)
    assert isinstance(p.depth, AtlasDepthEncoder) and not p.session.motion
    assert [k for k, _ in frames[0].payloads] == [PayloadKind.H264_ATLAS]


def test_the_virtual_clock_makes_the_same_bytes_and_a_restart_starts_with_a_keyframe(gl_ctx):
    room = load_scene("room")   # it moves: object poses and motion flow too
    config = ServerConfig(view_size=(128, 128), extra_view="on", depth_codec="edge")
    _, a = _frames(gl_ctx, config, room, n=3)
    _, b = _frames(gl_ctx, config, room, n=3)
    assert [f.payloads for f in a] == [f.payloads for f in b]
    pipeline = SessionPipeline(config, room, HELLO).open(gl_ctx)
    try:
        pose = room.viewer_origin
        first = pipeline.encode(pipeline.produce(pose, 0.0))
        second = pipeline.encode(pipeline.produce(pose, 0.1))
        pipeline.restart_stream()
        again = pipeline.encode(pipeline.produce(pose, 0.0))
    finally:
        pipeline.release()
    assert first.keyframe and not second.keyframe and again.keyframe
    assert again.payloads == first.payloads   # a fresh stream: the edge codec's temporal context starts over too


def test_a_colour_scale_sends_a_quarter_of_the_colour_at_the_frames_jitter(gl_ctx):
    from pibr.protocol.atlas import colour_jitter
    from pibr.protocol.errors import ConfigError

    room = load_scene("room")
    config = ServerConfig(view_size=(128, 128), extra_view="on", depth_codec="edge", colour_scale=0.5)
    pipeline = SessionPipeline(config, room, HELLO).open(gl_ctx)
    try:
        assert pipeline.session.colour_scale == 0.5
        assert pipeline.session.atlas.rect("primary.color") == (0, 0, 64, 64)
        assert pipeline.session.atlas.rect("extra.color") == (64, 0, 32, 32)
        produced = pipeline.produce(room.viewer_origin, 0.0, frame_id=5, keep_colour=True)
        assert produced.frame_id == 5 and produced.colours["primary"].shape == (128, 128, 3)
        jx, jy = colour_jitter(5)
        y = produced.yuv[:64, :64].astype(int)
        rgb = produced.colours["primary"][jy::2, jx::2].astype(float)
        expected = np.floor(0.299 * rgb[..., 0] + 0.587 * rgb[..., 1] + 0.114 * rgb[..., 2] + 0.5)
        assert np.abs(y - expected).max() <= 1         # the luma of the jitter's pixels (float32 rounding)
        encoded = pipeline.encode(produced)
        assert pipeline.frame(5, 0, 0, 0, produced, encoded).frame_id == 5
        with pytest.raises(ValueError, match="produced for frame id 5"):
            pipeline.frame(6, 0, 0, 0, produced, encoded)
    finally:
        pipeline.release()
    with pytest.raises(ConfigError, match="colour scale must be one of 1, 0.5"):
        ServerConfig(colour_scale=0.25)
