"""Binocular consistency: do the two shown images agree about the surfaces both eyes see?

Single-eye scores cannot see a mismatch between the eyes, and a colour or disparity mismatch is
what makes stereo uncomfortable. So, from the ground truth of both eyes:

1. **Binocular points.** Every pixel of the left eye's ground truth is a surface point (its
   radial distance along its ray); the point is *binocular* when the right eye's ground truth
   shows it too: it projects inside the right image, in front, where the right ground truth's
   distance agrees with the point's distance from the right eye within the coverage test's
   tolerance (server/coverage.py, 3 %). This pairs a left pixel with a right pixel.
2. **Mismatch.** At each pair, the two shown images' colours differ by d_shown (the largest of
   the three channels' absolute differences, 0-255) and the two ground truths' by d_true
   (view-dependent shading and pixel sampling make even a perfect pair differ). A pair is
   *inconsistent* when d_shown - d_true exceeds :data:`MISMATCH_LEVELS`: a surface drawn with
   the wrong colour in one eye, or at the wrong disparity (shifted, so the pair lands on
   another surface), or a hole filled differently in each eye.

Reported: the inconsistent share of binocular pairs, and the mean excess max(0, d_shown - d_true).
The ground truth's own pair scores 0 by construction; the same image shown to both eyes (no
disparity at all) scores high wherever there is texture or a depth edge.
"""
from __future__ import annotations

import math

import numpy as np

from pibr.protocol.frustum import to_pixels
from pibr.protocol.pose import Pose
from pibr.server.coverage import COVERAGE_TOLERANCE, displayed_points

#: Colour levels (of 255, largest channel) by which a shown pair may differ more than the
#: ground truth's before it counts as inconsistent: about 10 %, well above H.264's colour noise
#: at pibr's bitrates (a few levels) and below what a displaced edge or a wrong surface gives.
MISMATCH_LEVELS = 24


def binocular_pairs(rays: np.ndarray, size: tuple[int, int], fov_deg: float, left: Pose, right: Pose,
                    left_distance: np.ndarray, right_distance: np.ndarray,
                    tolerance: float = COVERAGE_TOLERANCE, right_frustum=None) -> tuple[np.ndarray, np.ndarray]:
    """Flat pixel indices (m,), (m,) of the left and right ground truths that show one surface point.

    rays : (w * h, 3) camera rays of the left eye's output (server.coverage.camera_rays); size :
    (w, h); left, right : the eyes' poses; *_distance : (h, w) ground-truth radial distances, 0 =
    sky; ``right_frustum``: the right eye's (left, right, down, up) tangents when its frustum is
    not the symmetric one of ``fov_deg`` (protocol/frustum.py)."""
    w, h = size
    if left_distance.shape != (h, w) or right_distance.shape != (h, w):
        raise ValueError(f"need two ({h}, {w}) distance maps, got {left_distance.shape} and {right_distance.shape}")
    points, sky, _ = displayed_points(rays, left, left_distance)
    idx = np.flatnonzero(~sky)
    local = (points[idx] - right.p) @ right.rotation()
    depth = -local[:, 2]
    front = depth > 1e-6
    if right_frustum is None:
        tan_x = math.tan(math.radians(fov_deg) / 2)
        tan_y = tan_x * h / w
        safe = np.where(front, depth, 1.0)
        col = np.floor((local[:, 0] / (safe * tan_x) + 1.0) * 0.5 * w).astype(np.int64)
        row = np.floor((1.0 - local[:, 1] / (safe * tan_y)) * 0.5 * h).astype(np.int64)
    else:
        col, row = (np.floor(c).astype(np.int64) for c in to_pixels(local, right_frustum, w, h))
    inside = front & (col >= 0) & (col < w) & (row >= 0) & (row < h)
    col, row = np.clip(col, 0, w - 1), np.clip(row, 0, h - 1)
    shown = right_distance[row, col]
    r = np.linalg.norm(local, axis=1)
    visible = inside & (shown > 0) & (np.abs(shown - r) < tolerance * r)
    return idx[visible], (row * w + col)[visible]


def stereo_consistency(shown_left: np.ndarray, shown_right: np.ndarray, true_left: np.ndarray,
                       true_right: np.ndarray, pairs: tuple[np.ndarray, np.ndarray],
                       levels: int = MISMATCH_LEVELS) -> dict:
    """The shown pair's mismatch beyond the ground truth's at the binocular ``pairs``.

    Images : (h, w, 3) uint8. -> {"inconsistent": share of pairs whose excess is above ``levels``,
    "excess_mean": mean excess in levels, "pairs": how many pairs}; None values without pairs."""
    il, ir = pairs
    if not len(il):
        return {"inconsistent": None, "excess_mean": None, "pairs": 0}

    def difference(a, b):
        a = a.reshape(-1, 3)[il].astype(np.int16)
        b = b.reshape(-1, 3)[ir].astype(np.int16)
        return np.abs(a - b).max(axis=1)

    excess = np.maximum(difference(shown_left, shown_right) - difference(true_left, true_right), 0)
    return {"inconsistent": float(np.mean(excess > levels)), "excess_mean": float(excess.mean()),
            "pairs": int(len(il))}
