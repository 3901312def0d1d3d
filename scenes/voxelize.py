"""Solid voxel hull of a triangle surface, the first stage of the LoD generator (:mod:`.lod`).

Surface voxels are found by sampling every triangle on a barycentric grid at most half a voxel
apart (a numba kernel that marks voxels as it goes, no sample arrays); a one-voxel morphological
closing bridges small gaps; the empty space reachable from outside is flooded and inverted, so
internal cavities become solid. Booleans all the way: the grid is exactly the one the numpy /
``scipy.ndimage.binary_*`` version made (kept in ``tests/scenes/lod_reference.py``), each sample
point being formed by the same float operations.
"""
from __future__ import annotations

import numpy as np
from numba import njit

#: Morphological closing radius, voxels.
CLOSING_VOXELS = 1


def voxel_hull(vertices: np.ndarray, faces: np.ndarray, lo: np.ndarray, voxel: float,
               dims: np.ndarray) -> np.ndarray:
    """Solid (dims) bool grid of the surface's voxels, gaps closed, inside filled.

    vertices (n, 3), faces (m, 3); voxel (i, j, k) covers ``lo + [i, i + 1) * voxel`` (per axis),
    ``lo`` (3,) including any padding, which must keep the closing off the grid's border.
    """
    from scipy import ndimage

    occupied = surface_voxels(vertices, faces, lo, voxel, dims)
    # Closing, not a plain dilation: dilate-then-erode by one voxel bridges gaps up to two voxels
    # wide (cracks between samples of a coarse sampling, small holes of open meshes, seams between
    # touching parts) that would let the flood fill leak inside, yet leaves the outer surface where
    # it was. A dilation would also close them but would inflate the whole proxy by a voxel; the
    # encaging pass already guarantees enclosure, so the hull need not be conservative.
    # The cube's dilation and erosion are separable: one 3-wide max / min filter per axis, with
    # the erosion treating outside the grid as empty, as binary_closing does.
    grid = occupied.view(np.uint8)
    size = 2 * CLOSING_VOXELS + 1
    for axis in range(3):
        grid = ndimage.maximum_filter1d(grid, size, axis=axis, mode="constant", cval=0)
    for axis in range(3):
        grid = ndimage.minimum_filter1d(grid, size, axis=axis, mode="constant", cval=0)
    closed = grid.view(bool)
    # Flood the empty space from outside (6-connected, the complement of a 26-connected solid)
    # and invert, as binary_fill_holes does: empty components touching the border are outside.
    labels, _count = ndimage.label(~closed)
    border = np.unique(np.concatenate([labels[[0, -1]].ravel(), labels[:, [0, -1]].ravel(),
                                       labels[:, :, [0, -1]].ravel()]))
    outside = np.zeros(int(labels.max()) + 1, dtype=bool)
    outside[border] = True
    outside[0] = False                      # label 0: the closed surface itself
    return ~outside[labels]


def surface_voxels(vertices: np.ndarray, faces: np.ndarray, lo: np.ndarray, voxel: float,
                   dims: np.ndarray) -> np.ndarray:
    """(dims) bool grid of the voxels that samples of the (n, 3) / (m, 3) surface fall in: each
    triangle sampled on a barycentric grid with at most ``voxel / 2`` between neighbours
    (degenerate triangles give points on their edges); samples off the grid go to its border."""
    v = np.asarray(vertices, dtype=np.float64)
    tri = np.ascontiguousarray(v[np.asarray(faces, dtype=np.int64)])
    longest = np.sqrt(np.max(np.stack([np.sum((tri[:, i] - tri[:, j]) ** 2, axis=1)
                                       for i, j in ((0, 1), (1, 2), (2, 0))]), axis=0))
    divisions = np.maximum(1, np.ceil(longest / (0.5 * voxel))).astype(np.int64)
    occupied = np.zeros(tuple(int(d) for d in dims), dtype=bool)
    _mark_samples(tri, divisions, np.asarray(lo, dtype=np.float64), float(voxel),
                  np.asarray(dims, dtype=np.int64), occupied)
    return occupied


@njit(cache=True)
def _mark_samples(tri, divisions, lo, voxel, dims, occupied):
    """Mark the voxels of the points (1 - i/n - j/n) A + (i/n) B + (j/n) C, i + j <= n, of every
    triangle (A, B, C) of ``tri`` (m, 3, 3), n = ``divisions`` (m,)."""
    for t in range(tri.shape[0]):
        n = divisions[t]
        for i in range(n + 1):
            w1 = i / n
            for j in range(n + 1 - i):
                w2 = j / n
                w0 = 1.0 - w1 - w2
                x = (tri[t, 0, 0] * w0 + tri[t, 1, 0] * w1) + tri[t, 2, 0] * w2
                y = (tri[t, 0, 1] * w0 + tri[t, 1, 1] * w1) + tri[t, 2, 1] * w2
                z = (tri[t, 0, 2] * w0 + tri[t, 1, 2] * w1) + tri[t, 2, 2] * w2
                occupied[_cell(x, lo[0], voxel, dims[0]), _cell(y, lo[1], voxel, dims[1]),
                         _cell(z, lo[2], voxel, dims[2])] = True


@njit(cache=True)
def _cell(x, lo, voxel, size):
    """Voxel index of coordinate x, clipped to [0, size)."""
    k = np.int64(np.floor((x - lo) / voxel))
    if k < 0:
        return 0
    if k > size - 1:
        return size - 1
    return k
