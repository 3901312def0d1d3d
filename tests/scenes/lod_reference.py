"""The numpy broadcasts that computed winding numbers and closest points before the numba kernels
of :mod:`pibr.scenes.mesh_queries` (main at 2aab3c5, ``scenes/lod.py``), kept verbatim as the
reference the kernels must reproduce bit for bit (``test_mesh_queries.py``)."""
from __future__ import annotations

import numpy as np


def winding_numbers(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray,
                    chunk_pairs: int = 500_000) -> np.ndarray:
    """Generalised winding number (n,) of (n, 3) points w.r.t. a triangle mesh (Jacobson et al. 2013).

    ~1 inside a closed outward-wound mesh, ~0 outside; robust to self-intersections and small
    cracks. Solid angle per triangle by Van Oosterom and Strackee; O(n m), chunked.
    """
    p = np.asarray(points, dtype=np.float64)
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]   # (m, 3, 3)
    out = np.zeros(len(p))
    if len(tri) == 0 or len(p) == 0:
        return out
    step = max(1, chunk_pairs // len(tri))
    for s in range(0, len(p), step):
        q = p[s:s + step, None, :]
        a, b, c = tri[None, :, 0] - q, tri[None, :, 1] - q, tri[None, :, 2] - q
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        det = np.einsum("ijk,ijk->ij", a, np.cross(b, c))
        denom = (la * lb * lc + np.einsum("ijk,ijk->ij", a, b) * lc
                 + np.einsum("ijk,ijk->ij", b, c) * la + np.einsum("ijk,ijk->ij", c, a) * lb)
        out[s:s + step] = np.arctan2(det, denom).sum(axis=1) / (2.0 * np.pi)
    return out


def closest_points_on_mesh(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray,
                           facing_slack: float | None = None,
                           chunk_pairs: int = 250_000) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For (n, 3) points: (distance (n,), closest point (n, 3), index of its triangle (n,)) on a mesh.

    Exact point-triangle distance (Ericson, *Real-Time Collision Detection* 5.1.5), vectorised
    over points x triangles in chunks. Degenerate triangles are handled (their edges still count).
    With ``facing_slack`` (metres), a triangle whose front faces the point wins over a closer one
    that shows it its back, unless that one is closer by more than the slack: on the coincident
    sheets of a squashed part, the sheet to push outward is the one facing the point.
    """
    p = np.asarray(points, dtype=np.float64)
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    n = len(p)
    best_d = np.full(n, np.inf)
    best_q = np.zeros((n, 3))
    best_t = np.zeros(n, dtype=np.int64)
    if n == 0 or len(tri) == 0:
        return best_d, best_q, best_t
    if facing_slack is not None:
        normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    step = max(1, chunk_pairs // len(tri))
    for s in range(0, n, step):
        ps = p[s:s + step]
        q = _closest_on_triangles(ps, tri)                              # (k, m, 3)
        dist = np.sqrt(np.sum((q - ps[:, None, :]) ** 2, axis=2))
        score = dist
        if facing_slack is not None:
            back = np.einsum("ijk,jk->ij", ps[:, None, :] - q, normals) < 0
            score = np.where(back, dist + facing_slack, dist)
        t = np.argmin(score, axis=1)
        rows = np.arange(len(t))
        best_d[s:s + step] = dist[rows, t]
        best_q[s:s + step] = q[rows, t]
        best_t[s:s + step] = t
    return best_d, best_q, best_t


def _closest_on_triangles(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """(k, m, 3) closest point on each of the (m, 3, 3) triangles to each of the (k, 3) points."""
    a, b, c = tri[None, :, 0], tri[None, :, 1], tri[None, :, 2]
    pp = p[:, None, :]
    ab, ac, ap = b - a, c - a, pp - a
    d1, d2 = np.einsum("ijk,ijk->ij", np.broadcast_to(ab, ap.shape), ap), \
        np.einsum("ijk,ijk->ij", np.broadcast_to(ac, ap.shape), ap)
    bp = pp - b
    d3, d4 = np.einsum("ijk,ijk->ij", np.broadcast_to(ab, bp.shape), bp), \
        np.einsum("ijk,ijk->ij", np.broadcast_to(ac, bp.shape), bp)
    cp = pp - c
    d5, d6 = np.einsum("ijk,ijk->ij", np.broadcast_to(ab, cp.shape), cp), \
        np.einsum("ijk,ijk->ij", np.broadcast_to(ac, cp.shape), cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    eps = 1e-300

    # Interior by default, then Ericson's Voronoi regions from the last tested to the first
    # (A, B, AB, C, AC, BC), so the first test that holds wins, as in his early-out version.
    denom = va + vb + vc
    safe = np.where(np.abs(denom) > eps, denom, 1.0)
    v = vb / safe
    w = vc / safe
    out = a + ab * v[..., None] + ac * w[..., None]

    def put(mask, value):
        nonlocal out
        out = np.where(mask[..., None], value, out)

    # edge BC
    e_bc = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
    den = (d4 - d3) + (d5 - d6)
    t_bc = np.clip((d4 - d3) / np.where(den > eps, den, 1.0), 0.0, 1.0)
    put(e_bc, b + (c - b) * t_bc[..., None])
    # edge AC
    e_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
    t_ac = np.clip(d2 / np.where((d2 - d6) > eps, d2 - d6, 1.0), 0.0, 1.0)
    put(e_ac, a + ac * t_ac[..., None])
    put((d6 >= 0) & (d5 <= d6), np.broadcast_to(c, out.shape))
    # edge AB
    e_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
    t_ab = np.clip(d1 / np.where((d1 - d3) > eps, d1 - d3, 1.0), 0.0, 1.0)
    put(e_ab, a + ab * t_ab[..., None])
    put((d3 >= 0) & (d4 <= d3), np.broadcast_to(b, out.shape))
    put((d1 <= 0) & (d2 <= 0), np.broadcast_to(a, out.shape))

    # Degenerate (collinear or collapsed) triangles: the Voronoi tests above can misfire, so
    # take the nearest point of their three edges instead.
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    scale2 = np.max(np.stack([np.sum((tri[:, i] - tri[:, j]) ** 2, axis=1)
                              for i, j in ((0, 1), (1, 2), (2, 0))]), axis=0)
    degenerate = area2 <= 1e-12 * np.maximum(scale2, 1e-300)
    if np.any(degenerate):
        dt = tri[degenerate]
        best, best_d2 = None, None
        for i, j in ((0, 1), (1, 2), (2, 0)):
            s0, s1 = dt[None, :, i], dt[None, :, j]
            seg = s1 - s0
            len2 = np.sum(seg ** 2, axis=2)
            t = np.clip(np.einsum("ijk,ijk->ij", pp - s0, np.broadcast_to(seg, (len(p),) + seg.shape[1:]))
                        / np.where(len2 > 0, len2, 1.0), 0.0, 1.0)
            q = s0 + seg * t[..., None]
            d2_ = np.sum((q - pp) ** 2, axis=2)
            if best is None:
                best, best_d2 = q, d2_
            else:
                closer = d2_ < best_d2
                best = np.where(closer[..., None], q, best)
                best_d2 = np.where(closer, d2_, best_d2)
        out[:, degenerate] = best
    return out
