"""Binocular consistency (bench/stereo_metrics.py) on an analytic scene: a checkered wall 2 m ahead
and a square 1 m ahead in front of it, seen by two eyes 64 mm apart."""
import numpy as np
import pytest

from pibr.bench.stereo_metrics import MISMATCH_LEVELS, binocular_pairs, stereo_consistency
from pibr.protocol.frustum import eye_tangents
from pibr.protocol.pose import Pose
from pibr.protocol.stereo import eye_poses
from pibr.server.coverage import camera_rays, displayed_points

W, H, FOV = 240, 136, 90.0
RAYS = camera_rays(W, H, FOV)


def _view(eye: Pose, rays=RAYS):
    """(distance (H, W), rgb (H, W, 3) uint8) of the analytic scene from ``eye`` (looking along -z)."""
    d = rays @ eye.rotation().T
    best = np.full(len(d), np.inf)
    colour = np.zeros((len(d), 3), np.uint8)
    for z, half, base in ((-2.0, np.inf, 40), (-1.0, 0.2, 150)):
        t = (z - eye.p[2]) / d[:, 2]
        hit = eye.p + d * t[:, None]
        ok = (t > 0) & (np.abs(hit[:, 0]) <= half) & (np.abs(hit[:, 1] - eye.p[1]) <= half) & (t < best)
        best[ok] = t[ok]
        checker = ((np.floor(hit[:, 0] / 0.05) + np.floor(hit[:, 1] / 0.05)) % 2).astype(np.uint8)
        colour[ok] = (base + 100 * checker[ok])[:, None]
    return best.reshape(H, W).astype(np.float32), colour.reshape(H, W, 3)


@pytest.fixture(scope="module")
def scene():
    left, right = eye_poses(Pose.make((0.0, 1.6, 0.0)), 64.0)
    (dl, cl), (dr, cr) = _view(left), _view(right)
    return left, right, dl, dr, cl, cr


def test_pairs_show_one_surface_point_and_skip_what_the_other_eye_cannot_see(scene):
    left, right, dl, dr, _, _ = scene
    il, ir = binocular_pairs(RAYS, (W, H), FOV, left, right, dl, dr)
    pl, _, _ = displayed_points(RAYS, left, dl)
    pr, _, _ = displayed_points(RAYS, right, dr)
    gap = np.linalg.norm(pl[il] - pr[ir], axis=1)
    assert np.percentile(gap, 99) < 0.01     # one point, to within a pixel's footprint at 2 m (~1.7 cm)
    # the wall just left of the square's shadow from the left eye is in its shadow from the right
    # eye: x in (-0.432, -0.368) m (the eyes at -+0.032, the square's edge at -0.2 m, 1 m ahead)
    hidden = (np.abs(pl[:, 2] + 2.0) < 1e-6) & (pl[:, 0] > -0.425) & (pl[:, 0] < -0.375) \
        & (np.abs(pl[:, 1] - 1.6) < 0.35)
    assert hidden.sum() > 20 and not np.isin(np.flatnonzero(hidden), il).any()
    # everything else the left eye sees, but a strip at the image's edge, is paired
    assert 0.9 < len(il) / (W * H) < 1.0
    assert np.median((il % W) - (ir % W)) > 0     # a point sits further left in the right eye's image


def test_the_true_pair_is_consistent_and_one_image_for_both_eyes_is_not(scene):
    left, right, dl, dr, cl, cr = scene
    pairs = binocular_pairs(RAYS, (W, H), FOV, left, right, dl, dr)
    assert stereo_consistency(cl, cr, cl, cr, pairs)["inconsistent"] == 0.0
    flat = stereo_consistency(cl, cl, cl, cr, pairs)       # no disparity: the checker's edges disagree
    assert flat["inconsistent"] > 0.3 and flat["excess_mean"] > 30
    # colour noise below the threshold in one eye is not a mismatch; a wrong surface colour is
    noisy = np.clip(cr.astype(np.int16) + np.random.default_rng(0).integers(-8, 9, cr.shape), 0, 255).astype(np.uint8)
    assert stereo_consistency(cl, noisy, cl, cr, pairs)["inconsistent"] == 0.0
    wrong = cr.copy()
    wrong[:, W // 2:] = 255 - wrong[:, W // 2:]
    share = stereo_consistency(cl, wrong, cl, cr, pairs)["inconsistent"]
    assert 0.3 < share < 0.7
    assert MISMATCH_LEVELS > 8


def test_no_binocular_points_no_score(scene):
    left, right, dl, dr, cl, cr = scene
    empty = (np.array([], np.int64), np.array([], np.int64))
    assert stereo_consistency(cl, cr, cl, cr, empty) == {"inconsistent": None, "excess_mean": None, "pairs": 0}
    with pytest.raises(ValueError, match="distance maps"):
        binocular_pairs(RAYS, (W, H), FOV, left, right, dl[:10], dr)


def test_pairs_through_asymmetric_frustums_show_one_surface_point():
    """Eyes with a headset's frustums (each reaching further outward): a pair is still one point,
    found through each eye's own projection (fewer pairs: the outer strips have no partner); read
    as symmetric, the right eye's pixels miss."""
    left, right = eye_poses(Pose.make((0.0, 1.6, 0.0)), 64.0)
    fl, fr = (eye_tangents(e, (52.0, 38.0, 40.0, 50.0)) for e in ("left", "right"))
    rays_l, rays_r = camera_rays(W, H, FOV, fl), camera_rays(W, H, FOV, fr)
    (dl, _), (dr, _) = _view(left, rays_l), _view(right, rays_r)
    il, ir = binocular_pairs(rays_l, (W, H), FOV, left, right, dl, dr, right_frustum=fr)
    pl, _, _ = displayed_points(rays_l, left, dl)
    pr, _, _ = displayed_points(rays_r, right, dr)
    gap = np.linalg.norm(pl[il] - pr[ir], axis=1)
    assert np.percentile(gap, 99) < 0.01 and len(il) > 0.6 * W * H
    sym = binocular_pairs(RAYS, (W, H), FOV, left, right, *(v[0] for v in (_view(left), _view(right))))[0]
    assert len(il) < len(sym)
    # the right eye read as symmetric: measured 2005 chance matches (against 24100), 0.62 m apart
    il_sym, ir_sym = binocular_pairs(rays_l, (W, H), FOV, left, right, dl, dr)
    assert len(il_sym) < 0.2 * len(il) and np.median(np.linalg.norm(pl[il_sym] - pr[ir_sym], axis=1)) > 0.1
