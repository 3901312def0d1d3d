"""The coverage test's compiled kernels equal the numpy formulation they replaced, to the bit."""
import numpy as np
import pytest

from pibr.protocol.pose import Pose
from pibr.protocol.projection import FORWARD
from pibr.server import coverage


def _numpy_matches(points, view_pose, distance, tolerance):
    """The array formulation (FORWARD.numpy and fancy indexing) the kernel replaced."""
    h, w = distance.shape
    t, r, front = coverage.project_to_view(points, view_pose)
    tx = (t[:, 0] + 1.0) * 0.5 * w - 0.5
    ty = (1.0 - t[:, 1]) * 0.5 * h - 0.5
    x0, y0 = np.floor(tx).astype(np.int64), np.floor(ty).astype(np.int64)
    hit = np.zeros(len(points), bool)
    for dx, dy in ((0, 0), (1, 0), (0, 1), (1, 1)):
        d = distance[np.clip(y0 + dy, 0, h - 1), np.clip(x0 + dx, 0, w - 1)]
        hit |= (d > 0) & (np.abs(d - r) < tolerance * r)
    return hit & front


def _numpy_sky(directions, view_pose, distance):
    h, w = distance.shape
    local = directions @ view_pose.rotation()
    tx, ty, _ = FORWARD.numpy(px=local[:, 0], py=local[:, 1], pz=local[:, 2])
    x = np.clip(((tx + 1.0) * 0.5 * w).astype(np.int64), 0, w - 1)
    y = np.clip(((1.0 - ty) * 0.5 * h).astype(np.int64), 0, h - 1)
    return (local[:, 2] <= 0.0) & (distance[y, x] == 0)


def _awkward_points(rng, n):
    """Camera-space points with the projection's hard cases: poles, the image edges, the plane
    z = 0, zero, tiny and huge magnitudes."""
    p = rng.normal(size=(n, 3)) * rng.choice([1e-300, 1e-3, 1.0, 50.0, 1e150], size=(n, 1))
    p[: n // 8, :2] = 0.0                           # on the axis
    p[n // 8: n // 4, 0] = 0.0                      # the pole's row (x = 0)
    p[n // 4: n // 4 + 10] = 0.0                     # the origin
    p[n // 4 + 10: n // 3, 2] = 0.0                  # the plane z = 0
    p[n // 3: n // 2, 2] = -np.abs(p[n // 3: n // 2, 0])   # 45 degrees: the square's edge
    return p


@pytest.mark.parametrize("seed", range(4))
def test_projection_kernel_is_formula_to_the_bit(seed):
    rng = np.random.default_rng(seed)
    p = _awkward_points(rng, 4000)
    want = FORWARD.numpy(px=p[:, 0], py=p[:, 1], pz=p[:, 2])
    got = np.array([coverage._project(*row) for row in p]).T
    for g, w in zip(got, want):
        assert np.array_equal(g, w)


@pytest.mark.parametrize("seed", range(4))
def test_matches_and_sky_are_the_array_formulation(seed):
    rng = np.random.default_rng(100 + seed)
    view = Pose.make(rng.normal(size=3), rng.normal(size=4))
    h, w = rng.integers(5, 90, size=2)
    distance = rng.uniform(0.5, 8.0, (h, w)).astype(np.float32)
    distance[rng.random((h, w)) < 0.3] = 0.0       # sky
    distance[rng.random((h, w)) < 0.1] = -1.0      # peeled
    # points on what the view stores (hits), near it (within and beyond the tolerance), anywhere
    dirs = rng.normal(size=(3000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    local = dirs * rng.uniform(0.3, 9.0, (3000, 1))
    points = view.p + local @ view.rotation().T
    for tolerance in (0.0, 0.03, 0.5):
        got = coverage.matches_view(points, view, distance, tolerance)
        want = _numpy_matches(points, view, distance, tolerance)
        assert np.array_equal(got, want)
    assert 0 < coverage.matches_view(points, view, distance, 0.5).sum() < len(points)
    world_dirs = dirs @ view.rotation().T
    assert np.array_equal(coverage.sky_in_view(world_dirs, view, distance), _numpy_sky(world_dirs, view, distance))
    assert 0 < coverage.sky_in_view(world_dirs, view, distance).sum() < len(world_dirs)


@pytest.mark.gl
@pytest.mark.parametrize("scene_name", ["room", "courtyard", "dynamic"])
def test_a_probe_draws_the_distances_of_a_shading_renderer(scene_name):
    """Coverage probes draw distances only (no lighting, no textures): the same bits as the
    renderer that shades, for perspective views, wide views and peeled extra views."""
    from pibr.common.gl import create_context
    from pibr.scenes.registry import load_scene
    from pibr.server.render_target import RenderTarget
    from pibr.server.renderer import PEEL_TOLERANCE, Renderer

    scene = load_scene(scene_name)
    ctx = create_context()
    try:
        with ctx:
            shading, unshaded = Renderer(ctx, scene), Renderer(ctx, scene, shade=False)
            primary, extra, persp = RenderTarget(ctx, 192, 192), RenderTarget(ctx, 96, 96), RenderTarget(ctx, 160, 90)
            lo, hi = scene.viewing_region()
            rng = np.random.default_rng(7)
            drawn = 0
            for k in range(3):
                pose = Pose.make(lo + (hi - lo) * rng.random(3), rng.normal(size=4))
                offset = Pose.make([0.25, 0.1, -0.2], [1.0, 0.0, 0.0, 0.0])
                maps, colours = [], []
                for renderer in (shading, unshaded):
                    renderer.render_perspective(persp, pose, 0.4 * k, 90.0)
                    colours.append(persp.read_color().copy())
                    renderer.render_wide(primary, pose, 0.4 * k)
                    wide = primary.read_distance().copy()
                    renderer.render_wide(extra, pose.compose(offset), 0.4 * k, peel=(primary, pose, PEEL_TOLERANCE))
                    maps.append((persp.read_distance().copy(), wide, extra.read_distance().copy()))
                for a, b in zip(*maps):
                    assert np.array_equal(a.view(np.uint32), b.view(np.uint32))
                drawn += int((maps[0][1] > 0).sum())
                geometry = maps[0][0] > 0   # the unshaded renderer drew its surfaces black
                assert geometry.any() and not colours[1][geometry].any() and colours[0][geometry].any()
            assert drawn > 0
            shading.release()
            unshaded.release()
            for t in (primary, extra, persp):
                t.release()
    finally:
        ctx.release()


def test_uncovered_by_views_is_uncovered_of_each_prefix():
    """Each view's mask equals uncovered() of the views up to it (the primary's mask is where
    testing both starts), with and without marked peeling."""
    rng = np.random.default_rng(11)
    views = []
    for k in range(3):
        d = rng.uniform(0.5, 8.0, (40, 60)).astype(np.float32)
        d[rng.random(d.shape) < 0.3] = 0.0
        views.append((Pose.make(rng.normal(size=3) * 0.2, rng.normal(size=4)), d, k > 0))
    dirs = rng.normal(size=(2000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    r = rng.uniform(0.5, 8.0, 2000)
    sky = rng.random(2000) < 0.2
    points = dirs * r[:, None]
    for marked in (True, False):
        masks = coverage.uncovered_by_views(points, sky, dirs, views, peeled_marked=marked)
        for k in range(3):
            assert np.array_equal(masks[k], coverage.uncovered(points, sky, dirs, views[:k + 1], peeled_marked=marked))
        assert masks[0].sum() > masks[2].sum() > 0
