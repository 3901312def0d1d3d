"""Dual view: depth peeling, coverage variants, the offset search, and numerical extremes."""
import math

import numpy as np
import pytest

from pibr.bench.coverage import VARIANTS, measure_coverage
from pibr.common.link import SessionSchedule
from pibr.common.replay import display_samples
from pibr.server.coverage import CoverageProbe, matches_view
from pibr.bench.offset_search import OffsetObjective, coarse_to_fine, exhaustive, parse_range
from pibr.protocol.pose import Pose, quat_from_euler
from pibr.protocol.projection import unproject, pixel_centers
from pibr.scenes.registry import load_scene
from pibr.server.config import PAPER_EXTRA_OFFSET, extra_offset_pose
from pibr.protocol.depth import PEELED
from pibr.server.renderer import PEEL_TOLERANCE

pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def room_probe():
    probe = CoverageProbe(load_scene("room"), (256, 256), (96, 54))
    yield probe
    probe.close()


def _points_of(distance: np.ndarray, pose: Pose) -> np.ndarray:
    """World points (n, 3) of every texel of a wide-angle distance map that hit geometry."""
    h, w = distance.shape
    t = pixel_centers(w, h).reshape(-1, 2)
    d = distance.reshape(-1).astype(np.float64)
    hit = d > 0
    return pose.transform_points(unproject(t[hit], d[hit]))


def _random_poses(scene, n, seed):
    rng = np.random.default_rng(seed)
    lo, hi = scene.viewing_region()
    for _ in range(n):
        p = rng.uniform(lo, hi)
        q = quat_from_euler([rng.uniform(-np.pi, np.pi), rng.uniform(-0.6, 0.6), rng.uniform(-0.2, 0.2)], "yxz")
        yield Pose.make(p, q)


def test_peeling_keeps_no_point_the_primary_shows(room_probe):
    scene = room_probe.scene
    rng = np.random.default_rng(5)
    kept_total = seen_total = 0
    for pose in _random_poses(scene, 12, seed=1):
        offset = extra_offset_pose(rng.uniform(-1, 2), rng.uniform(0, 2), rng.uniform(-30, 45))
        primary = room_probe.render_primary(pose, 0.0)
        extra = room_probe.render_extra(pose, offset, 0.0, peel=True)
        unpeeled = room_probe.render_extra(pose, offset, 0.0, peel=False)
        pts = _points_of(extra, pose.compose(offset))
        kept_total += len(pts)
        # The same test the shader ran, in float64: a hair inside the tolerance absorbs float32 rounding.
        # The shader's own test, redone in float64 from the stored texels. A point rebuilt from a
        # texel centre differs from the fragment the shader tested by float32 rounding and by
        # interpolation across a fraction of a texel; that can shift the 2x2 neighbourhood by a
        # texel or flip the hemisphere test at the view's rim, so a few strays are allowed. The two
        # views may also draw an object from different pre-tessellated copies (chosen by each eye's
        # distance), whose chords differ by a fraction of a pixel: measured over these poses, the
        # worst pose went from 0.46 % to 0.51 % strays and all poses together from 0.21 % to 0.24 %.
        seen = matches_view(pts, pose, primary, PEEL_TOLERANCE)
        seen_total += seen.sum()
        assert seen.mean() < 6e-3, f"{seen.sum()} of {len(pts)} kept points are visible in the primary"
        assert (extra > 0).sum() <= (unpeeled > 0).sum()
        # Peeled pixels are marked apart from sky: the peeled view's sky is exactly the unpeeled one's.
        assert np.array_equal(extra == 0, unpeeled == 0)
        assert set(np.unique(extra[extra < 0]).tolist()) <= {PEELED}
    assert kept_total > 1000  # peeling kept real content, not nothing
    assert seen_total < 3e-3 * kept_total


def test_peeling_without_offset_is_a_second_depth_layer(room_probe):
    pose = next(_random_poses(room_probe.scene, 1, seed=3))
    primary = room_probe.render_primary(pose, 0.0)
    extra = room_probe.render_extra(pose, Pose.identity(), 0.0, peel=True)
    # Same camera: every kept texel lies behind what the primary shows in that direction.
    h, w = extra.shape
    nearest = primary.reshape(h, 2, w, 2).min(axis=(1, 3))   # the 2x2 primary texels under each extra texel
    both = (extra > 0) & (nearest > 0)
    assert both.sum() > 100
    assert np.mean(extra[both] > nearest[both] * (1 - PEEL_TOLERANCE)) > 0.99


def test_adding_a_view_never_adds_holes(room_probe):
    samples = display_samples(room_probe.scene, "pred6dof-2", 20.0, 1.0, SessionSchedule.round_trip(30.0))[::6]
    offset = extra_offset_pose(*PAPER_EXTRA_OFFSET)
    res = measure_coverage(room_probe, samples, offset)
    for v in VARIANTS[1:]:
        assert all(x <= p + 1e-12 for x, p in zip(res[v], res["primary"])), v
    for k, vals in res.items():
        assert all(0.0 <= x <= 1.0 and math.isfinite(x) for x in vals), k


@pytest.mark.parametrize("offset", [
    (0.0, 0.0, 0.0),          # primary and extra coincide
    (0.0, 0.0, 89.0),         # looking almost straight down
    (0.0, 0.0, -89.0),        # ... and up
    (-2000.0, 0.0, 0.0),      # far behind: beyond the far sphere
    (1.5, -0.6, 0.0),         # inside the exhibit's pedestal
])
def test_extreme_offsets_render_and_measure(room_probe, offset):
    pose = Pose.make((0.0, 1.6, 0.0))
    primary = room_probe.render_primary(pose, 0.0)
    off = extra_offset_pose(*offset)
    extra = room_probe.render_extra(pose, off, 0.0, peel=True)
    assert np.all(np.isfinite(extra)) and set(np.unique(extra[extra < 0]).tolist()) <= {PEELED}
    assert extra.max() <= room_probe.scene.far * 1.001
    points, sky, dirs = room_probe.display_points(pose, 0.0)
    m_all, m_geo = room_probe.missing(points, sky, dirs, [(pose, primary, False), (pose.compose(off), extra, True)])
    n_geo = int((~sky).sum())
    assert n_geo > 0 and 0 <= m_geo * n_geo <= m_all * sky.size + 1e-6   # geometry's holes are among all holes
    assert m_all < 0.05 and m_geo < 0.05        # the display pose is the primary's: little is missing (measured 1.9-2.5 %)
    assert room_probe.ctx.error == "GL_NO_ERROR"


def test_empty_scene_is_all_sky_and_all_covered():
    probe = CoverageProbe(load_scene("empty"), (64, 64), (48, 27))
    try:
        pose = Pose.identity()
        primary = probe.render_primary(pose, 0.0)
        extra = probe.render_extra(pose, extra_offset_pose(1.5, 1.8, 15), 0.0, peel=True)
        assert primary.max() == 0 and extra.max() == 0
        points, sky, dirs = probe.display_points(pose, 0.0)
        assert sky.all()
        assert probe.missing(points, sky, dirs, [(pose, primary, False)]) == (0.0, 0.0)
        # Turned around, the display looks where the primary has no image: all missing.
        back = Pose.make((0, 0, 0), quat_from_euler([np.pi, 0, 0], "yxz"))
        points, sky, dirs = probe.display_points(back, 0.0)
        assert probe.missing(points, sky, dirs, [(pose, primary, False)])[0] == 1.0
    finally:
        probe.close()


def test_a_peeled_view_vouches_for_sky_but_not_for_what_it_peeled(room_probe):
    # Looking out of the big window: sky in the displayed view.
    pose = Pose.make((0.5, 1.6, -1.0), quat_from_euler([0.0, 0.25, 0.0], "yxz"))
    primary = room_probe.render_primary(pose, 0.0)
    points, sky, dirs = room_probe.display_points(pose, 0.0)
    assert 0.05 < sky.mean() < 0.95
    assert room_probe.missing(points, sky, dirs, [(pose, primary, False)])[0] < 0.1  # 256 px: coarse
    # The extra view from the same camera, peeled: everything the primary shows is peeled away
    # (marked, not sky), so alone it covers the sky and little of the geometry.
    extra = room_probe.render_extra(pose, Pose.identity(), 0.0, peel=True)
    everything, geometry = room_probe.missing(points, sky, dirs, [(pose, extra, True)])
    assert everything <= (1 - sky.mean()) + 0.02      # the sky is covered ...
    assert geometry > 0.7                             # ... the peeled geometry is not


def test_latency_model_schedule():
    m = SessionSchedule.round_trip(30.0, 128.0, server_fps=10.0, server_delay_ms=20)
    render, pose_t = m.frame_for(300_000)
    assert render == 200_000                      # 200 + 20 + 64 <= 300 < 300 + 84
    assert pose_t == 133_332                      # newest 30 Hz tick with t + 64 ms <= 200 ms


def test_parse_range():
    assert parse_range("-1:1:0.5") == [-1.0, -0.5, 0.0, 0.5, 1.0]
    assert parse_range("3,1,2") == [1.0, 2.0, 3.0]
    with pytest.raises(ValueError):
        parse_range("1:0:0.5")


def test_coarse_to_fine_finds_the_exhaustive_optimum():
    scene = load_scene("room")
    probe = CoverageProbe(scene, (128, 128), (64, 36))
    try:
        samples = display_samples(scene, "pred6dof-1", 12.0, 2.0, SessionSchedule.round_trip(30.0))[::20]
        f = OffsetObjective(probe, samples)
        axes = [parse_range("-1:2:0.5"), parse_range("0:1.8:0.6"), [-20.0, 0.0, 20.0]]
        full = exhaustive(f, axes)
        fast = coarse_to_fine(f, axes)
        assert len(fast) < len(full)
        best_full = min(full, key=full.get)
        best_fast = min(fast, key=fast.get)
        assert full[best_fast] == full[best_full]
        assert all(full[k] == v for k, v in fast.items())  # the objective is deterministic
    finally:
        probe.close()


def test_without_the_marker_a_peeled_view_vouches_for_no_sky():
    """--no-peel-marker: peeled pixels stay 0 like sky, so the view cannot vouch for sky."""
    scene = load_scene("room")
    probe = CoverageProbe(scene, (256, 256), (96, 54), mark_peeled=False)
    try:
        pose = Pose.make((0.5, 1.6, -1.0), quat_from_euler([0.0, 0.25, 0.0], "yxz"))
        probe.render_primary(pose, 0.0)
        extra = probe.render_extra(pose, Pose.identity(), 0.0, peel=True)
        assert extra.min() == 0.0                       # no marker anywhere
        points, sky, dirs = probe.display_points(pose, 0.0)
        assert sky.any()
        everything, _ = probe.missing(points, sky, dirs, [(pose, extra, True)])
        assert everything >= sky.mean() - 1e-9          # not one sky pixel vouched for
    finally:
        probe.close()
