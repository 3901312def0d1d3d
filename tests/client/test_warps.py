"""The forward and plane warps (homography, splat, meshwarp, coarse-meshwarp) against ground
truth at a tiny size (512x512 views, 160x90 output: the paper's 1.6x angular density), in one
process, and their geometry at the extremes. Margins are the measured values plus a little."""
from __future__ import annotations

import numpy as np
import pytest

from pibr.bench.simulation import Simulation, bench_server_config
from pibr.bench.metrics import dssim, psnr, ssim
from pibr.protocol.errors import ConfigError
from pibr.protocol.pose import Pose, quat_from_axis_angle, quat_multiply
from pibr.scenes.registry import load_scene

pytestmark = pytest.mark.gl

WARPS = (("homography", {}), ("splat", {}), ("meshwarp", {}), ("coarse-meshwarp", {"step": 4}))


@pytest.fixture(scope="module", params=["room", "sphere"])
def sim(request):
    s = Simulation(load_scene(request.param), bench_server_config((512, 512)), (160, 90))
    yield s
    s.close()
    s.ctx.release()


def _show(sim, name, options, pose, frame):
    m = sim.make_method(name, **options)
    try:
        rgb, holes, _ = sim.display(m, pose, frame, 0.0)
        return rgb, holes, m.last_primitives
    finally:
        m.release()


def _translated(pose: Pose, metres: float) -> Pose:
    return Pose.make(pose.p + metres * pose.rotation()[:, 0], pose.q)


def _turned(pose: Pose, radians: float) -> Pose:
    return Pose.make(pose.p, quat_multiply(pose.q, quat_from_axis_angle([0.0, 1.0, 0.0], radians)))


# Measured PSNR loss against showing the frame as it is (none) at zero displacement, room /
# sphere: homography 0 / 0 (the plane is exact along the camera's own rays), meshwarp 1.4 / 0,
# coarse-meshwarp s=4 5.3 / 8.7 (one vertex per 16 pixels blurs), splat 10.6 / 11.0 (a point
# per pixel, unfiltered: aliasing where several land in one output pixel).
ZERO_MARGIN_DB = {"homography": 0.01, "meshwarp": 2.0, "coarse-meshwarp": 9.5, "splat": 11.5}


@pytest.mark.parametrize("name, options", WARPS)
def test_zero_displacement_against_the_frame_itself(sim, name, options):
    pose = sim.scene.viewer_origin
    frame = sim.frame_at(0.0, pose)
    gt = sim.ground_truth(pose, 0.0)
    reference, _, _ = _show(sim, "none", {}, pose, frame)
    rgb, holes, _ = _show(sim, name, options, pose, frame)
    assert holes < 0.001
    assert psnr(gt, rgb) >= psnr(gt, reference) - ZERO_MARGIN_DB[name]


def test_error_ordering_under_a_translation(sim):
    """30 cm to the right of the rendered pose. Measured DSSIM, room: rotation 0.378,
    homography 0.357, splat 0.327, meshwarp 0.254, coarse-meshwarp s=4 0.173 (its rubber sheets
    fill what the others leave as holes); sphere: rotation 0.039, splat 0.034, meshwarp 0.025,
    homography 0.024, coarse 0.023."""
    pose = sim.scene.viewer_origin
    frame = sim.frame_at(0.0, pose)
    moved = _translated(pose, 0.3)
    gt = sim.ground_truth(moved, 0.0)
    score = {}
    for name, options in (("rotation", {}),) + WARPS:
        rgb, _, _ = _show(sim, name, options, moved, frame)
        score[name] = dssim(ssim(gt, rgb))
    assert all(score[n] < score["rotation"] for n, _ in WARPS), score
    assert score["meshwarp"] < 0.9 * score["splat"], score
    assert score["coarse-meshwarp"] < score["splat"], score
    if sim.scene.name == "room":
        assert score["meshwarp"] < 0.75 * score["homography"], score


@pytest.mark.parametrize("name, options", WARPS)
def test_nothing_behind_the_output_camera_wraps_around(sim, name, options):
    """Turned 180 degrees, every transmitted point is behind the output camera: nothing may be
    drawn (a point behind the camera projected without clipping would land mirrored in view)."""
    pose = sim.scene.viewer_origin
    frame = sim.frame_at(0.0, pose)
    _, holes, _ = _show(sim, name, options, _turned(pose, np.pi), frame)
    assert holes == 1.0


@pytest.mark.parametrize("name, options", WARPS)
def test_at_the_hemisphere_rim(sim, name, options):
    """Turned 90 degrees left: the left half of the output looks beyond the primary view's
    hemisphere (all holes), the right half into it (measured 0-7.5 % holes at its rim)."""
    pose = sim.scene.viewer_origin
    frame = sim.frame_at(0.0, pose)
    sim.target.begin()
    m = sim.make_method(name, **options)
    try:
        m.render(_turned(pose, np.pi / 2), frame, sim.textures, 0.0)
    finally:
        m.release()
    holes = sim.target.read()[:, :, 3] == 0
    assert holes[:, :75].mean() > 0.99
    assert holes[:, 85:].mean() < 0.1


def test_coarse_grid_step_beyond_the_view():
    """A step larger than the view is clamped to it: one quad between the corner pixels (the
    projection's poles), two triangles, the same image as a step of exactly the view's size."""
    s = Simulation(load_scene("sphere"), bench_server_config((64, 64)), (32, 18))
    try:
        pose = s.scene.viewer_origin
        frame = s.frame_at(0.0, pose)
        rgb, _, prims = _show(s, "coarse-meshwarp", {"step": 4096}, pose, frame)
        same, _, _ = _show(s, "coarse-meshwarp", {"step": 63}, pose, frame)
        assert prims == 2 and np.array_equal(rgb, same)
        with pytest.raises(ConfigError, match="step"):
            s.make_method("coarse-meshwarp", step=0)
        with pytest.raises(ConfigError, match="split"):
            s.make_method("meshwarp", split=float("nan"))
        with pytest.raises(ConfigError, match="plane distance"):
            s.make_method("homography", plane_distance=-1.0)
        with pytest.raises(ConfigError, match="point size"):
            s.make_method("splat", point_size=0.0)
    finally:
        s.close()
        s.ctx.release()


def test_own_holes_count_what_the_method_did_not_accept_whatever_it_shows(sim):
    """One definition of own holes (README, Reading the metrics): alpha 0 where the method
    accepted no transmitted sample, whatever colour it then shows. ``homography`` past its plane
    falls back to the ray's direction, shown but counted; ``gridwarp`` fills its holes but counts
    the same ones as without filling; ``none`` never leaves one."""
    frame = sim.frame_at(0.0, sim.scene.viewer_origin)
    past = Pose.make(sim.scene.viewer_origin.p + 1.5 * -sim.scene.viewer_origin.rotation()[:, 2],
                     sim.scene.viewer_origin.q)            # 1.5 m forward: beyond a 1 m plane
    rgb, holes, _ = _show(sim, "homography", {"plane_distance": 1.0}, past, frame)
    assert holes > 0.9 and rgb.mean() > 20                  # shown, not black, yet every pixel counted
    rgb, holes, _ = _show(sim, "homography", {"plane_distance": 4.0}, past, frame)
    assert holes < 0.01
    moved = _translated(sim.scene.viewer_origin, 0.5)
    filled, filled_holes, _ = _show(sim, "gridwarp", {}, moved, frame)
    bare, bare_holes, _ = _show(sim, "gridwarp", {"fill": False}, moved, frame)
    assert bare_holes > 0.001 and filled_holes == bare_holes
    black = (bare == 0).all(axis=-1)
    assert black.mean() >= bare_holes and (filled[black] > 0).any()
    assert _show(sim, "none", {}, moved, frame)[1] == 0.0
