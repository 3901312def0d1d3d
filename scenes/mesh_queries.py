"""Point-versus-triangle-mesh queries of the LoD generator (:mod:`.lod`): winding numbers, closest points.

Both are O(points x triangles); encaging asks them dozens of times per object, so they are
numba kernels, one fused loop over points and triangles each. They give *the same bits* as the
numpy broadcasts they replace (kept as the reference in ``tests/scenes/lod_reference.py``): every
quantity is formed by the same IEEE operations in the same order (no FMA contraction, no
reassociation; three-term sums grouped as numpy's reductions and ``einsum`` group them). The
winding number's arctangents and their sum over triangles stay with numpy -- its ``arctan2`` (a
SIMD implementation on AVX-512 machines) differs from libm's in the last bit for a few per cent
of arguments, and its row sum is pairwise -- so the kernel fills the two arctangent arguments
and numpy finishes the rows, on chunks of the same shape as before.

The kernels run on one thread. Variants parallel over points (``prange``), bit-identical too,
were slower at every size measured on the 2-core machine shared with other jobs (the torus
knot's whole build 1.56 s instead of 0.92 s wall): a parallel launch waits for a busy core, and
the slowest thread sets the pace. The LoD cache already generates meshes in one process per
core (:func:`pibr.scenes.lod_cache.lods_for_scene`).
"""
from __future__ import annotations

import numpy as np
from numba import njit

#: Point-triangle pairs per winding-number chunk (the (k, m) argument arrays of one chunk).
WINDING_CHUNK_PAIRS = 500_000


def _triangles(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(m, 3, 3) float64 corner coordinates, C-contiguous."""
    return np.ascontiguousarray(np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)])


def winding_numbers(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray,
                    chunk_pairs: int = WINDING_CHUNK_PAIRS) -> np.ndarray:
    """Generalised winding number (n,) of (n, 3) points w.r.t. a triangle mesh (Jacobson et al. 2013).

    ~1 inside a closed outward-wound mesh, ~0 outside; robust to self-intersections and small
    cracks. Solid angle per triangle by Van Oosterom and Strackee: ``atan2(det, denom)`` summed
    over triangles, divided by 2 pi. O(n m), chunked.
    """
    p = np.ascontiguousarray(points, dtype=np.float64)
    tri = _triangles(vertices, faces)
    out = np.zeros(len(p))
    if len(tri) == 0 or len(p) == 0:
        return out
    step = max(1, chunk_pairs // len(tri))
    det = np.empty((min(step, len(p)), len(tri)))
    denom = np.empty_like(det)
    for s in range(0, len(p), step):
        k = min(step, len(p) - s)
        _solid_angle_arguments(p[s:s + k], tri, det[:k], denom[:k])
        out[s:s + k] = np.arctan2(det[:k], denom[:k]).sum(axis=1) / (2.0 * np.pi)
    return out


@njit(cache=True)
def _dot(x0, x1, x2, y0, y1, y2):
    """x . y summed as ``numpy.einsum`` sums three products on SIMD machines (one masked vector,
    reduced by halving: (x0 y0 + x2 y2) + x1 y1), added to its zeroed output."""
    return 0.0 + ((x0 * y0 + x2 * y2) + x1 * y1)


@njit(cache=True)
def _solid_angle_arguments(p, tri, det, denom):
    """Fill (k, m) ``det`` and ``denom``: the solid angle of triangle j of ``tri`` (m, 3, 3) seen
    from point i of p (k, 3) is 2 atan2(det, denom) (Van Oosterom and Strackee)."""
    for i in range(p.shape[0]):
        px, py, pz = p[i, 0], p[i, 1], p[i, 2]
        for j in range(tri.shape[0]):
            ax, ay, az = tri[j, 0, 0] - px, tri[j, 0, 1] - py, tri[j, 0, 2] - pz
            bx, by, bz = tri[j, 1, 0] - px, tri[j, 1, 1] - py, tri[j, 1, 2] - pz
            cx, cy, cz = tri[j, 2, 0] - px, tri[j, 2, 1] - py, tri[j, 2, 2] - pz
            la = np.sqrt(0.0 + ax * ax + ay * ay + az * az)
            lb = np.sqrt(0.0 + bx * bx + by * by + bz * bz)
            lc = np.sqrt(0.0 + cx * cx + cy * cy + cz * cz)
            # a . (b x c), the cross product's terms as numpy.cross forms them
            det[i, j] = _dot(ax, ay, az, by * cz - bz * cy, bz * cx - bx * cz, bx * cy - by * cx)
            ab = _dot(ax, ay, az, bx, by, bz)
            bc = _dot(bx, by, bz, cx, cy, cz)
            ca = _dot(cx, cy, cz, ax, ay, az)
            denom[i, j] = la * lb * lc + ab * lc + bc * la + ca * lb


def closest_points_on_mesh(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray,
                           facing_slack: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For (n, 3) points: (distance (n,), closest point (n, 3), index of its triangle (n,)) on a mesh.

    Exact point-triangle distance (Ericson, *Real-Time Collision Detection* 5.1.5) against every
    triangle. Degenerate triangles (collinear or collapsed) are handled: the nearest point of
    their three edges counts. With ``facing_slack`` (metres), a triangle whose front faces the
    point wins over a closer one that shows it its back, unless that one is closer by more than
    the slack: on the coincident sheets of a squashed part, the sheet to push outward is the one
    facing the point. Ties go to the lowest triangle index.
    """
    p = np.ascontiguousarray(points, dtype=np.float64)
    tri = _triangles(vertices, faces)
    n = len(p)
    best_d = np.full(n, np.inf)
    best_q = np.zeros((n, 3))
    best_t = np.zeros(n, dtype=np.int64)
    if n == 0 or len(tri) == 0:
        return best_d, best_q, best_t
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(normals, axis=1)
    scale2 = np.max(np.stack([np.sum((tri[:, i] - tri[:, j]) ** 2, axis=1)
                              for i, j in ((0, 1), (1, 2), (2, 0))]), axis=0)
    degenerate = area2 <= 1e-12 * np.maximum(scale2, 1e-300)
    _closest_points(p, tri, np.ascontiguousarray(normals), degenerate, facing_slack is not None,
                    0.0 if facing_slack is None else float(facing_slack), best_d, best_q, best_t)
    return best_d, best_q, best_t


@njit(cache=True)
def _clip01(t):
    # comparisons, not min/max: a NaN passes through as numpy.clip lets it
    if t < 0.0:
        return 0.0
    if t > 1.0:
        return 1.0
    return t


@njit(cache=True)
def _closest_on_triangle(px, py, pz, tri, j, degenerate):
    """Closest point (x, y, z) of triangle j of (m, 3, 3) ``tri`` to point p."""
    ax, ay, az = tri[j, 0, 0], tri[j, 0, 1], tri[j, 0, 2]
    bx, by, bz = tri[j, 1, 0], tri[j, 1, 1], tri[j, 1, 2]
    cx, cy, cz = tri[j, 2, 0], tri[j, 2, 1], tri[j, 2, 2]
    if degenerate:
        # the nearest point of the three edges; on a tie the earlier edge (AB, BC, CA) wins
        best_d2 = np.inf
        qx = qy = qz = 0.0
        for e in range(3):
            k = (e + 1) % 3
            sx, sy, sz = tri[j, e, 0], tri[j, e, 1], tri[j, e, 2]
            gx, gy, gz = tri[j, k, 0] - sx, tri[j, k, 1] - sy, tri[j, k, 2] - sz
            len2 = 0.0 + gx * gx + gy * gy + gz * gz
            dot = _dot(px - sx, py - sy, pz - sz, gx, gy, gz)
            t = _clip01(dot / (len2 if len2 > 0.0 else 1.0))
            ex, ey, ez = sx + gx * t, sy + gy * t, sz + gz * t
            d2 = 0.0 + (ex - px) * (ex - px) + (ey - py) * (ey - py) + (ez - pz) * (ez - pz)
            if e == 0 or d2 < best_d2:
                best_d2, qx, qy, qz = d2, ex, ey, ez
        return qx, qy, qz
    eps = 1e-300
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = _dot(abx, aby, abz, apx, apy, apz)
    d2 = _dot(acx, acy, acz, apx, apy, apz)
    if d1 <= 0.0 and d2 <= 0.0:
        return ax, ay, az                                            # vertex A
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3 = _dot(abx, aby, abz, bpx, bpy, bpz)
    d4 = _dot(acx, acy, acz, bpx, bpy, bpz)
    if d3 >= 0.0 and d4 <= d3:
        return bx, by, bz                                            # vertex B
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5 = _dot(abx, aby, abz, cpx, cpy, cpz)
    d6 = _dot(acx, acy, acz, cpx, cpy, cpz)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:                       # edge AB
        t = _clip01(d1 / ((d1 - d3) if (d1 - d3) > eps else 1.0))
        return ax + abx * t, ay + aby * t, az + abz * t
    if d6 >= 0.0 and d5 <= d6:
        return cx, cy, cz                                            # vertex C
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:                       # edge AC
        t = _clip01(d2 / ((d2 - d6) if (d2 - d6) > eps else 1.0))
        return ax + acx * t, ay + acy * t, az + acz * t
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:         # edge BC
        den = (d4 - d3) + (d5 - d6)
        t = _clip01((d4 - d3) / (den if den > eps else 1.0))
        return bx + (cx - bx) * t, by + (cy - by) * t, bz + (cz - bz) * t
    den = va + vb + vc                                               # interior
    safe = den if abs(den) > eps else 1.0
    v = vb / safe
    w = vc / safe
    return ax + abx * v + acx * w, ay + aby * v + acy * w, az + abz * v + acz * w


@njit(cache=True)
def _closest_points(p, tri, normals, degenerate, prefer_facing, facing_slack, best_d, best_q, best_t):
    """Fill best_d (n,), best_q (n, 3), best_t (n,) for the points p (n, 3) against tri (m, 3, 3)
    with normals (m, 3) and degenerate (m,) bool. The score is the distance, plus ``facing_slack``
    for a triangle showing the point its back when ``prefer_facing``; the lowest score wins, the
    first on a tie (a NaN score wins at once, as in numpy.argmin)."""
    for i in range(p.shape[0]):
        px, py, pz = p[i, 0], p[i, 1], p[i, 2]
        best_score = np.inf
        for j in range(tri.shape[0]):
            qx, qy, qz = _closest_on_triangle(px, py, pz, tri, j, degenerate[j])
            dist = np.sqrt(0.0 + (qx - px) * (qx - px) + (qy - py) * (qy - py) + (qz - pz) * (qz - pz))
            score = dist
            if prefer_facing:
                facing = _dot(px - qx, py - qy, pz - qz, normals[j, 0], normals[j, 1], normals[j, 2])
                if facing < 0.0:
                    score = dist + facing_slack
            if j == 0 or score < best_score or (np.isnan(score) and not np.isnan(best_score)):
                best_score = score
                best_d[i], best_t[i] = dist, j
                best_q[i, 0], best_q[i, 1], best_q[i, 2] = qx, qy, qz
            if np.isnan(best_score):
                break
