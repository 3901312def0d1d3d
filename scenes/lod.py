"""Encaging level-of-detail proxies (Reinert et al. 2016, "Proxy-guided IBR for mobile devices").

The client re-renders the current view by rasterising a drastically simplified *proxy* of
each object and gathering colour from transmitted views. Depth carving only ever removes
proxy surface, so a proxy must *encage* its object: every original vertex inside it or
within ``tolerance`` of its surface. Each object gets three levels of detail: the original
mesh, the encaging proxy made here, and its bounding box.

:func:`simplify_encaging` follows the paper:

1. voxelize the surface at ``resolution`` voxels along the longest bounding-box side;
2. close small gaps (morphological closing, one voxel) and fill the inside (flood the empty
   space from outside, invert), so internal cavities are solid;
3. marching cubes: a closed, watertight surface;
4. decimate (quadric edge collapse, ``fast_simplification``) to ``target_fraction`` of the
   *original* triangle count, never below ``min_triangles``; pinched (non-manifold) edges and
   vertices that decimating thin parts creates are split again (:func:`make_manifold`);
5. push proxy vertices outward until every original vertex is inside (generalised winding
   number >= 1/2) or within ``tolerance`` of the surface (:func:`encage`).

A drastic target can be out of reach at a fine resolution: decimating 100 000 marching-cubes
triangles of many small parts (leaves, books) to 30 collapses the hull, and pushing such a
wreck outward does not converge. Then the hull is rebuilt at half the resolution (whose
coarser voxels merge the parts), down to :data:`MIN_RESOLUTION`. When simplification cannot
beat the box -- the target is no more triangles than the box's 12, the encaged proxy holds at
least the box's volume, or no resolution gives a proxy that encages -- the proxy is the
bounding box, which encloses by construction. :attr:`LodResult.kind` and :attr:`LodResult.note`
say what happened and why; ``enclosed_fraction`` and ``max_outside_distance`` are always
measured on the proxy returned.

Everything is numpy/scipy (trimesh's ``contains`` needs rtree or embree, neither installed), but for
the point-mesh queries that encaging repeats and the surface voxelization: numba kernels in
:mod:`.mesh_queries` and :mod:`.voxelize`.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from pibr.protocol.errors import SceneError
from pibr.protocol.proxy import closed_box, is_closed, signed_volume

from .mesh_queries import closest_points_on_mesh, winding_numbers
from .scene import Mesh
from .voxelize import CLOSING_VOXELS, voxel_hull

#: Default encaging tolerance, in voxels: an original vertex at most this far outside the proxy
#: counts as enclosed. A tenth of a voxel is far below what the voxel hull resolves anyway.
DEFAULT_TOLERANCE_VOXELS = 0.1
#: Empty voxels around the object's grid: the closing's dilation must not reach the border,
#: and marching cubes needs an empty layer to close the surface.
PADDING_VOXELS = CLOSING_VOXELS + 1
#: Encaging pushes at most this many times before falling back to the box.
DEFAULT_MAX_ITERATIONS = 40
#: Encaging gives up after this many iterations without progress.
STALL_ITERATIONS = 8
#: Coarsest voxel resolution tried when finer hulls fail (see :func:`simplify_encaging`).
MIN_RESOLUTION = 16
#: Decimations tried (with targets 10 % apart) before a hull counts as unsimplifiable.
DECIMATION_RETRIES = 3
#: A decimated hull that keeps less than this fraction of the hull's volume has collapsed
#: (too few triangles for the voxel detail): a coarser hull is tried instead of encaging it.
MIN_VOLUME_KEPT = 0.5
#: Triangles of a bounding box: a proxy target at or below this cannot beat the box.
BOX_TRIANGLES = 12

# fast_simplification keeps the mesh being simplified in module-level C++ state.
_simplify_lock = threading.Lock()


@dataclass
class LodResult:
    """Levels of detail of one mesh (object space, like the mesh).

    proxy                : encaging proxy (the box when ``kind`` is ``"box"``; empty for ``"empty"``)
    box                  : the bounding box as 12 triangles (each side at least ``tolerance`` thick)
    enclosed_fraction    : fraction of the original (referenced) vertices inside the proxy or within
                           ``tolerance`` of it, measured on ``proxy``
    max_outside_distance : largest distance of an original vertex outside ``proxy`` (0: none outside)
    triangles_original, triangles_proxy : triangle counts
    iterations           : encaging push iterations run
    seconds              : wall time of the generation
    params               : the parameters, resolved: resolution, target_fraction, min_triangles,
                           max_iterations, voxel_size and tolerance (metres), tolerance_voxels,
                           target_triangles, closing_voxels, padding_voxels, resolution_used
                           (after coarsening) and, for "simplified", volume_ratio_to_box
    kind                 : ``"simplified"`` (voxel hull, decimated, encaged), ``"box"`` or ``"empty"``
    note                 : why the box was used, or what else is worth knowing
    """

    proxy: Mesh
    box: Mesh
    enclosed_fraction: float
    max_outside_distance: float
    triangles_original: int
    triangles_proxy: int
    iterations: int
    seconds: float
    params: dict = field(default_factory=dict)
    kind: str = "simplified"
    note: str = ""

    KINDS = ("simplified", "box", "empty")


# ----------------------------------------------------------------------------- geometry helpers

def box_mesh(lo, hi, min_extent: float = 0.0) -> Mesh:
    """The proxy's box level (protocol/proxy.py :func:`closed_box`, as the client builds it from
    the bounds) from corners (3,) ``lo`` to ``hi``: 8 vertices and 12 outward triangles.

    Sides shorter than ``min_extent`` are widened about their centre, so a flat object's box
    still has a (thin) inside.
    """
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    centre, half = (lo + hi) / 2, np.maximum((hi - lo) / 2, min_extent / 2)
    return Mesh(*closed_box(centre - half, centre + half))


def is_watertight(faces: np.ndarray) -> bool:
    """Whether (m, 3) faces form a closed, consistently oriented 2-manifold-edged surface:
    every directed edge occurs exactly once and its reverse exactly once."""
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return False
    e = f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    n = int(f.max()) + 1
    code = e[:, 0] * n + e[:, 1]
    if len(np.unique(code)) != len(code):
        return False
    return bool(np.all(np.isin(e[:, 1] * n + e[:, 0], code)))


# ----------------------------------------------------------------------------- pipeline stages

def hull_surface(solid: np.ndarray, lo: np.ndarray, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """Marching cubes of a padded solid grid: ((n, 3) float64 vertices, (m, 3) int64 faces), outward."""
    from skimage.measure import marching_cubes

    verts, faces, _normals, _values = marching_cubes(solid.astype(np.float32), level=0.5,
                                                     spacing=(voxel, voxel, voxel), allow_degenerate=False)
    verts = verts.astype(np.float64) + lo + 0.5 * voxel      # grid samples sit at voxel centres
    faces = faces.astype(np.int64)
    if signed_volume(verts, faces) < 0:
        faces = faces[:, ::-1].copy()
    return verts, faces


def decimate(vertices: np.ndarray, faces: np.ndarray, target: int) -> tuple[np.ndarray, np.ndarray]:
    """Quadric edge-collapse decimation to about ``target`` triangles; unreferenced vertices dropped.

    fast_simplification stops early when no collapse stays under its error threshold (thin
    sheets, e.g. a heightfield's hull); then the threshold is allowed to grow faster (``agg``).
    """
    import fast_simplification

    best = (vertices, faces)
    if target < len(faces):
        for agg in (7.0, 9.0, 11.0):
            with _simplify_lock:
                v, f = fast_simplification.simplify(vertices, faces, target_count=int(target), agg=agg)
            v, f = np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64).reshape(-1, 3)
            if len(f) < len(best[1]):
                best = (v, f)
            if len(f) <= 1.25 * target:
                break
    v, f = best
    keep = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0])
    f = f[keep]
    used = np.unique(f)
    remap = np.full(len(v), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return v[used], remap[f]


def make_manifold(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split a closed mesh's non-manifold edges and vertices: ((n', 3) vertices, (m, 3) faces).

    Decimating thin sheets pinches them: four (or more) faces meet at an edge, or two fans at a
    vertex. Each half-edge is paired with one reverse half-edge -- around an edge with more than
    two faces, each face with its neighbour in angular order on the side its normal faces, which
    separates the sheets as they lie -- the corners that the pairing connects around a vertex form
    its fans, and every fan gets its own copy of the vertex. Geometry (so every winding number)
    is unchanged; the result is watertight in the strict sense (:func:`is_watertight`) unless
    the sheets intersect at the edge. Needs :func:`is_closed` faces.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    m, n = len(f), len(v)
    # half-edge h = 3 * face + k runs from corner k to corner (k + 1) % 3
    start = f.reshape(-1)
    end = f[:, [1, 2, 0]].reshape(-1)
    opposite = f[:, [2, 0, 1]].reshape(-1)
    lo, hi = np.minimum(start, end), np.maximum(start, end)
    key = lo * n + hi
    forward = start < end
    h = np.arange(3 * m)
    fwd = h[forward][np.lexsort((h[forward], key[forward]))]
    bwd = h[~forward][np.lexsort((h[~forward], key[~forward]))]
    if len(fwd) != len(bwd) or not np.array_equal(key[fwd], key[bwd]):
        raise ValueError("make_manifold needs a closed mesh (every edge matched by its reverse)")
    keys, group_start, group_size = np.unique(key[fwd], return_index=True, return_counts=True)
    for g0, size in zip(group_start[group_size > 1], group_size[group_size > 1]):
        hs = np.concatenate([fwd[g0:g0 + size], bwd[g0:g0 + size]])
        a, b = v[lo[hs[0]]], v[hi[hs[0]]]
        axis = (b - a) / max(np.linalg.norm(b - a), 1e-300)
        ref = np.cross(axis, np.eye(3)[np.argmin(np.abs(axis))])
        ref /= max(np.linalg.norm(ref), 1e-300)
        side = v[opposite[hs]] - a
        angle = np.arctan2(side @ np.cross(axis, ref), side @ ref)
        ring = hs[np.lexsort((hs, angle))]
        # a face running lo -> hi faces counter-clockwise about the axis: its partner comes next
        at = np.flatnonzero(forward[ring])
        partner = ring[(at + 1) % len(ring)]
        if np.all(~forward[partner]) and len(np.unique(partner)) == size:
            fwd[g0:g0 + size], bwd[g0:g0 + size] = ring[at], partner
    # h = u -> w pairs with g = w -> u: corner (h's start) ~ corner after g, and vice versa
    nxt = (h // 3) * 3 + (h % 3 + 1) % 3
    rows = np.concatenate([fwd, nxt[fwd]])
    cols = np.concatenate([nxt[bwd], bwd])
    graph = coo_matrix((np.ones(len(rows), dtype=np.int8), (rows, cols)), shape=(3 * m, 3 * m))
    fan = connected_components(graph, directed=False)[1]
    # one new vertex per fan, numbered by the fan's first corner (deterministic)
    first = np.unique(fan, return_index=True)[1]
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    corner_vertex = rank[fan]
    new_vertices = np.zeros((len(first), 3))
    new_vertices[corner_vertex] = v[start]
    return new_vertices, corner_vertex.reshape(-1, 3)


def measure_enclosure(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray,
                      tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """For (n, 3) points: (outside distance (n,), 0 when inside; enclosed (n,) bool: inside or
    within ``tolerance``). Inside means a winding number of at least 1/2."""
    outside_d = np.zeros(len(points))
    if len(points) == 0:
        return outside_d, np.ones(0, dtype=bool)
    outside = winding_numbers(points, vertices, faces) < 0.5
    if np.any(outside):
        outside_d[outside] = closest_points_on_mesh(points[outside], vertices, faces)[0]
    return outside_d, outside_d <= tolerance


def barycentric(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(k, 3) barycentric coordinates of (k, 3) points in the plane of their (k, 3, 3) triangles
    (1/3 each for degenerate triangles)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    v0, v1, v2 = b - a, c - a, points - a
    d00, d01, d11 = (np.einsum("ij,ij->i", x, y) for x, y in ((v0, v0), (v0, v1), (v1, v1)))
    d20, d21 = np.einsum("ij,ij->i", v2, v0), np.einsum("ij,ij->i", v2, v1)
    den = d00 * d11 - d01 * d01
    ok = den > 1e-12 * np.maximum(d00 * d11, 1e-300)
    safe = np.where(ok, den, 1.0)
    w1 = np.where(ok, (d11 * d20 - d01 * d21) / safe, 1 / 3)
    w2 = np.where(ok, (d00 * d21 - d01 * d20) / safe, 1 / 3)
    return np.clip(np.stack([1 - w1 - w2, w1, w2], axis=1), 0.0, 1.0)


def encage(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, tolerance: float,
           max_iterations: int, progress: Callable[[str], None] | None = None) -> tuple[np.ndarray, int, bool]:
    """Push proxy vertices outward until every (n, 3) point is inside or within ``tolerance``.

    Each iteration takes the points outside by more than ``tolerance``; for each, the closest
    point q on the proxy (preferring triangles that face it), its barycentric coordinates b on
    that triangle, and the outward direction u from q to the point. The triangle's vertices move
    along u by the least-norm amounts that carry q past the point by ``tolerance``:
    need * b_k / sum(b^2) (need = distance + tolerance); a vertex asked by several points takes
    the largest demand. u is the surface normal where q lies inside a triangle and a direction
    of the normal cone at an edge or corner; pushing along *vertex* normals instead ran away
    wherever a vertex normal was nearly perpendicular to u (thin parts, sharp ridges). Moves
    that would flip a triangle are halved, up to four times, then dropped for this iteration;
    after :data:`STALL_ITERATIONS` iterations without fewer points outside than ever before, it
    gives up. Only the points outside at the last check are re-tested until none is; then all
    are, since a push can uncover another (in folds).

    Returns (vertices (n, 3), iterations run, converged).
    """
    v = np.array(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    everyone = np.arange(len(points))
    active, full_check = everyone, True
    fewest, stalled = len(points) + 1, 0
    for it in range(max_iterations + 1):
        outside = active[winding_numbers(points[active], v, f) < 0.5]
        d, q, t = closest_points_on_mesh(points[outside], v, f, facing_slack=tolerance)
        bad = d > tolerance
        if not np.any(bad) and not full_check:
            active, full_check = everyone, True                     # re-test everything once
            outside = everyone[winding_numbers(points, v, f) < 0.5]
            d, q, t = closest_points_on_mesh(points[outside], v, f, facing_slack=tolerance)
            bad = d > tolerance
        if not np.any(bad):
            return v, it, True
        # pushes that keep failing (their moves would flip triangles) will not start working
        fewest, stalled = (int(bad.sum()), 0) if bad.sum() < fewest else (fewest, stalled + 1)
        if it == max_iterations or stalled >= STALL_ITERATIONS:
            return v, it, False
        active, full_check = outside[bad], False
        if progress is not None:
            progress(f"encage {it + 1}: {len(active)} vertices outside")
        d, q, t = d[bad], q[bad], t[bad]
        u = (points[active] - q) / d[:, None]                       # outward direction at q
        b = barycentric(q, v[f[t]])
        amount = (d + tolerance)[:, None] * b / np.maximum(np.sum(b * b, axis=1), 1e-12)[:, None]
        # per proxy vertex the largest demand wins (ties: the first point, for determinism)
        vert, amount = f[t].reshape(-1), amount.reshape(-1)
        order = np.lexsort((-amount, vert))
        first = order[np.r_[True, vert[order][1:] != vert[order][:-1]]]
        move = np.zeros_like(v)
        move[vert[first]] = amount[first, None] * np.repeat(u, 3, axis=0)[first]
        v = v + _without_flips(v, f, move)
    return v, max_iterations, False


def _without_flips(v: np.ndarray, f: np.ndarray, move: np.ndarray, halvings: int = 4) -> np.ndarray:
    """``move`` (n, 3) with the moves of vertices of triangles it would flip halved (repeatedly),
    and finally dropped."""
    before = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    move = move.copy()
    for attempt in range(halvings + 1):
        w = v + move
        after = np.cross(w[f[:, 1]] - w[f[:, 0]], w[f[:, 2]] - w[f[:, 0]])
        flipped = np.einsum("ij,ij->i", before, after) <= 0
        flipped &= np.any(move[f].any(axis=2), axis=1)              # only triangles this move touches
        if not np.any(flipped):
            break
        affected = np.unique(f[flipped])
        move[affected] *= 0.0 if attempt == halvings else 0.5
    return move


# ----------------------------------------------------------------------------- the whole thing

def simplify_encaging(mesh: Mesh, resolution: int = 128, target_fraction: float = 0.005,
                      min_triangles: int = 12, tolerance: float | None = None,
                      progress: Callable[[str], None] | None = None,
                      max_iterations: int = DEFAULT_MAX_ITERATIONS) -> LodResult:
    """Encaging proxy and bounding box of ``mesh`` (see the module docstring).

    resolution      : voxels along the longest bounding-box side (>= 4)
    target_fraction : proxy triangles as a fraction of the mesh's triangles, in (0, 1]
    min_triangles   : never fewer proxy triangles than this (>= 4)
    tolerance       : metres an original vertex may lie outside the proxy; None:
                      :data:`DEFAULT_TOLERANCE_VOXELS` of a voxel
    progress        : called with a short stage description while working, or None
    max_iterations  : encaging pushes before giving up on the simplified proxy (then: the box)

    Only vertices that some face references are encaged (the others are never drawn).
    Deterministic: the same mesh and parameters give the same proxy.
    """
    t0 = time.perf_counter()
    if isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer)) or resolution < 4:
        raise SceneError(f"LoD resolution must be an integer >= 4, got {resolution!r}")
    if not (isinstance(target_fraction, (int, float)) and 0 < target_fraction <= 1):
        raise SceneError(f"LoD target_fraction must be in (0, 1], got {target_fraction!r}")
    if isinstance(min_triangles, bool) or not isinstance(min_triangles, (int, np.integer)) or min_triangles < 4:
        raise SceneError(f"LoD min_triangles must be an integer >= 4, got {min_triangles!r}")
    if tolerance is not None and not (math.isfinite(tolerance) and tolerance >= 0):
        raise SceneError(f"LoD tolerance must be a finite number of metres >= 0 or None, got {tolerance!r}")
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, (int, np.integer)) or max_iterations < 0:
        raise SceneError(f"LoD max_iterations must be an integer >= 0, got {max_iterations!r}")

    def report(stage: str) -> None:
        if progress is not None:
            progress(stage)

    n_tris = mesh.triangle_count
    params = {"resolution": int(resolution), "target_fraction": float(target_fraction),
              "min_triangles": int(min_triangles), "max_iterations": int(max_iterations)}
    if n_tris == 0:
        empty = Mesh(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint32))
        params.update(voxel_size=0.0, tolerance=0.0 if tolerance is None else float(tolerance),
                      target_triangles=0)
        return LodResult(empty, empty, 1.0, 0.0, 0, 0, 0, time.perf_counter() - t0, params, "empty",
                         "the mesh has no faces: nothing to draw, nothing to encage")

    faces = mesh.faces.astype(np.int64)
    used = np.unique(faces)
    points = mesh.vertices[used].astype(np.float64)
    lo, hi = points.min(0), points.max(0)
    longest = float(np.max(hi - lo))
    # a mesh collapsed to a point still gets a (tiny) voxel
    voxel = longest / resolution if longest > 0 else max(1e-6, 1e-6 * float(np.max(np.abs(lo))))
    tol = DEFAULT_TOLERANCE_VOXELS * voxel if tolerance is None else float(tolerance)
    target = max(int(min_triangles), int(math.ceil(target_fraction * n_tris)))
    params.update(voxel_size=voxel, tolerance=tol, tolerance_voxels=tol / voxel, target_triangles=target,
                  closing_voxels=CLOSING_VOXELS, padding_voxels=PADDING_VOXELS)
    box = box_mesh(lo, hi, min_extent=max(tol, 1e-9 * max(longest, 1.0)))
    unique_pts, inverse = np.unique(points, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)

    def finish(proxy: Mesh, kind: str, note: str, iterations: int) -> LodResult:
        report("measure")
        outside_d, enclosed = measure_enclosure(unique_pts, proxy.vertices.astype(np.float64),
                                                proxy.faces.astype(np.int64), tol)
        return LodResult(proxy, box, float(np.mean(enclosed[inverse])), float(outside_d.max(initial=0.0)),
                         n_tris, proxy.triangle_count, iterations, time.perf_counter() - t0, params, kind, note)

    if longest <= 0:
        return finish(box, "box", "degenerate mesh: all vertices coincide", 0)
    if target <= BOX_TRIANGLES:
        return finish(box, "box", f"target {target} triangles <= the box's {BOX_TRIANGLES}", 0)

    box_volume = signed_volume(box.vertices, box.faces)
    notes, iterations = [], 0
    res = int(resolution)
    while True:
        attempt = _attempt(mesh.vertices, faces, unique_pts, lo, hi, longest / res, target, tol,
                           int(max_iterations), report, progress)
        iterations += attempt.iterations
        if attempt.failure is None:
            volume = signed_volume(attempt.vertices, attempt.faces)
            if volume < box_volume:
                proxy = Mesh(attempt.vertices.astype(np.float32), attempt.faces.astype(np.uint32))
                params.update(resolution_used=res, volume_ratio_to_box=volume / box_volume)
                note = "; ".join(notes + [f"built at resolution {res}"]) if notes else ""
                return finish(proxy, "simplified", note, iterations)
            attempt.failure = (f"the encaged proxy ({len(attempt.faces)} triangles) holds "
                               f"{volume / box_volume:.2f}x the box's volume")
        notes.append(f"resolution {res}: {attempt.failure}")
        if res // 2 < MIN_RESOLUTION:
            break
        res //= 2        # a coarser hull merges the parts the triangle budget cannot keep apart
    params["resolution_used"] = res
    return finish(box, "box", "; ".join(notes) + ": using the box", iterations)


@dataclass
class _Attempt:
    vertices: np.ndarray | None = None
    faces: np.ndarray | None = None
    iterations: int = 0
    failure: str | None = None


def _attempt(vertices, faces, points, lo, hi, voxel, target, tol, max_iterations, report,
             progress) -> _Attempt:
    """One voxel hull -> marching cubes -> decimation -> encaging pass at one voxel size."""
    report(f"voxelize ({voxel:.3g} m voxels)")
    grid_lo = lo - PADDING_VOXELS * voxel
    dims = np.floor((hi - lo) / voxel).astype(np.int64) + 1 + 2 * PADDING_VOXELS
    solid = voxel_hull(vertices, faces, grid_lo, voxel, dims)
    report("marching cubes")
    hv, hf = hull_surface(solid, grid_lo, voxel)
    hull_volume = signed_volume(hv, hf)
    for k in range(DECIMATION_RETRIES):
        # the retries nudge the target: a different collapse order avoids a pinch that
        # make_manifold cannot split (an edge whose both ends are single fans)
        goal = int(round(target * 1.1 ** k))
        if len(hf) <= goal:
            dv, df = hv, hf
        else:
            report(f"decimate {len(hf)} -> {goal}")
            dv, df = decimate(hv, hf, goal)
        if len(df) < 4 or not is_closed(df):
            return _Attempt(failure=f"decimation to {len(df)} triangles left the hull open")
        if signed_volume(dv, df) < MIN_VOLUME_KEPT * hull_volume:
            return _Attempt(failure=f"decimation to {len(df)} triangles collapsed the hull "
                                    f"(kept {signed_volume(dv, df) / hull_volume:.0%} of its volume)")
        if not is_watertight(df):
            dv, df = make_manifold(dv, df)
        if is_watertight(df):
            break
    else:
        return _Attempt(failure=f"decimation pinched the hull into non-manifold edges "
                                f"{DECIMATION_RETRIES} times")
    report("encage")
    ev, iterations, converged = encage(points, dv, df, tol, max_iterations, progress)
    if not converged:
        outside_d, enclosed = measure_enclosure(points, ev, df, tol)
        return _Attempt(iterations=iterations,
                        failure=f"encaging did not converge in {iterations} iterations "
                                f"({100 * np.mean(enclosed):.2f} % of distinct vertices enclosed, "
                                f"max {outside_d.max():.3g} m outside)")
    return _Attempt(ev, df, iterations)
