"""The server's rate control: its levels, the frames each makes, calibration, the level on the wire."""
import numpy as np
import pytest

from pibr.protocol.errors import MalformedMessage
from pibr.protocol.messages import Frame, Hello, OutputConfig, PayloadKind, decode_frame_level, encode_frame_level
from pibr.protocol.pose import Pose
from pibr.scenes.registry import load_scene
from pibr.server.config import ServerConfig
from pibr.server.pipeline import SessionPipeline
from pibr.server.producer import FULL, FrameLevel
from pibr.server.rate_control import RateControl, server_levels


def test_levels_go_from_everything_to_less():
    for extra in (True, False):
        levels = server_levels(extra)
        assert levels[0].name == "full" and levels[0].scale == 1.0 and not levels[0].options
        assert [lv.scale for lv in levels] == sorted((lv.scale for lv in levels), reverse=True)
        edges = [lv.options.get("edge_deg", 6.0) for lv in levels]
        assert edges == sorted(edges)
        assert all(lv.method == "server" for lv in levels)
    assert not any("extra_every" in lv.options for lv in server_levels(False))
    assert len({lv.name for lv in server_levels(True)}) == len(server_levels(True))


def test_the_extra_view_is_rendered_on_its_frames_only():
    rc = RateControl(server_levels(True), 10.0)
    every_4th = next(k for k, lv in enumerate(rc.levels) if lv.options.get("extra_every") == 4)
    made = [rc.frame_level(every_4th, n) for n in range(8)]
    assert [m.extra for m in made] == [True, False, False, False] * 2
    assert made[0] == FrameLevel(True, 12.0, 1.0)
    assert rc.frame_level(0, 3) == FULL


def test_a_fast_machine_keeps_the_top_level_and_a_slow_one_moves_down():
    fast = RateControl(server_levels(True), 10.0)
    slow = RateControl(server_levels(True), 10.0)
    for k in range(len(fast.levels)):
        fast.controller.calibrate("frame", k, 20.0 - k)
        slow.controller.calibrate("frame", k, 300.0 - 30 * k)
    assert {fast.choose()[0] for _ in range(50)} == {0}
    assert slow.choose()[:2] == (len(slow.levels) - 1, 4)     # nothing fits: the cheapest (reason 4)


def test_a_frame_level_travels_as_one_byte():
    assert encode_frame_level(6) == b"\x06" and decode_frame_level(b"\x06") == 6
    for bad in (b"", b"\x01\x02"):
        with pytest.raises(MalformedMessage, match="frame-level payload is one byte"):
            decode_frame_level(bad)
    with pytest.raises(ValueError):
        encode_frame_level(256)


@pytest.mark.gl
def test_levels_make_frames_that_keep_the_extra_view_and_calibrate():
    from pibr.common.gl import create_context

    ctx = create_context()
    scene = load_scene("room")
    hello = Hello(clock="real", output=OutputConfig(160, 90, 90.0, 30.0))
    config = ServerConfig(view_size=(128, 128), extra_view="on")
    pipeline = SessionPipeline(config, scene, hello, deterministic=True).open(ctx)
    try:
        assert pipeline.session.options["server_levels"] == [lv.name for lv in server_levels(True)]
        pose = scene.viewer_origin
        moved = pose.compose(Pose.make([0.3, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]))
        first = pipeline.produce(pose, 0.0, FrameLevel(extra=True))
        extra_rect = pipeline.spec.layout.rect("extra.color")
        kept = pipeline.produce(moved, 0.1, FrameLevel(extra=False, edge_deg=12.0, scale=0.5))
        assert kept.extra_pose == first.extra_pose != moved.compose(pipeline.spec.extra_offset)
        x, y, w, h = extra_rect
        assert np.array_equal(first.yuv[y:y + h, x:x + w], kept.yuv[y:y + h, x:x + w])   # the atlas kept it
        whole = pipeline.produce(moved, 0.1, FULL)
        assert whole.extra_pose == moved.compose(pipeline.spec.extra_offset)
        half = pipeline.produce(moved, 0.1, FrameLevel(extra=True, scale=0.5))
        px, py, pw, ph = pipeline.spec.layout.rect("primary.color")
        a = whole.yuv[py:py + ph, px:px + pw].astype(float)
        b = half.yuv[py:py + ph, px:px + pw].astype(float)
        assert 0 < np.mean(np.abs(a - b)) < 12      # the same view, blurred by the upsampling
        assert half.moving is not None and half.moving.shape == (128, 128)   # motion upsampled too
        # a frame that keeps the extra view reads the small view back and brings it to size on the
        # CPU (view_upsample.py); one that peels a new extra view upsamples in GL: the same atlas
        on_cpu = pipeline.produce(moved, 0.1, FrameLevel(extra=False, scale=0.5))
        assert pipeline.producer._small_primary is not None
        turned = pose.compose(Pose.make([0.3, 0.0, 0.0], [0.7071, 0.0, 0.7071, 0.0]))  # the pendulum in view
        moving_gl = pipeline.produce(turned, 0.1, FrameLevel(extra=True, scale=0.5))
        moving_cpu = pipeline.produce(turned, 0.1, FrameLevel(extra=False, scale=0.5))
        c = on_cpu.yuv[py:py + ph, px:px + pw].astype(float)
        assert np.max(np.abs(b - c)) <= 1 and np.mean(b != c) < 0.3    # llvmpipe filters in 8-bit steps
        dx, dy, dw, dh = pipeline.spec.layout.rect("primary.depth")
        assert np.array_equal(half.yuv[dy:dy + dh, dx:dx + dw], on_cpu.yuv[dy:dy + dh, dx:dx + dw])
        assert np.array_equal(moving_gl.moving, moving_cpu.moving) and moving_gl.moving.any()
        assert np.allclose(moving_gl.motion, moving_cpu.motion, atol=0.05)      # half floats on the GPU
        assert np.abs(moving_cpu.motion).max() > 0.1
        rc = RateControl(server_levels(True), 10.0)
        costs = rc.calibrate(pipeline, pose, 0.0)
        assert len(costs) == len(rc.levels) and all(ms > 0 for ms in costs)
        encoded = pipeline.encode(whole, level=3)
        frame = Frame.parse(pipeline.frame(0, 0, 0, 0, whole, encoded).serialize())
        assert decode_frame_level(frame.payload(PayloadKind.FRAME_LEVEL)) == 3
        assert pipeline.frame(0, 0, 0, 0, whole, pipeline.encode(whole)).payload(PayloadKind.FRAME_LEVEL) is None
    finally:
        pipeline.release()
        ctx.release()


def test_the_virtual_clock_and_rate_control_off_announce_no_levels():
    scene = load_scene("sphere")
    for clock, mode in (("virtual", "on"), ("real", "off")):
        config = ServerConfig(view_size=(64, 64), rate_control=mode)
        pipeline = SessionPipeline(config, scene, Hello(clock=clock))
        assert "server_levels" not in pipeline.session.options
        pipeline.close_encoders()


def test_calibration_does_not_time_the_first_frame_of_either_kind():
    """A level's first frame of each kind (rendering the extra view, keeping it) pays one-off
    costs (its tessellation, the CPU upsampling's kernels loading): calibration makes both kinds
    once untimed, so a level that keeps the extra view is not calibrated at its first frame's cost."""
    import time as _time

    seen = set()

    class SlowFirstPipeline:
        def new_video_encoder(self):
            class Encoder:
                def encode(self, yuv):
                    return b"", False

                def close(self):
                    pass
            return Encoder()

        def produce(self, pose, t, level):
            first = level not in seen
            seen.add(level)
            _time.sleep(0.15 if first else 0.005)

            class Produced:
                yuv = None
            return Produced()

    rc = RateControl(server_levels(True), 10.0)
    costs = rc.calibrate(SlowFirstPipeline(), Pose.identity(), 0.0)
    assert len(costs) == len(rc.levels)
    assert max(costs) < 60.0, costs      # 5 ms frames; a first frame timed would add 150 / every
