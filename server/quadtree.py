"""Depth quadtrees of a frame's views, built on the server (Reinert et al. 2016, Section 6.2).

The paper's quadtree warping groups neighbouring pixels by their depth (the client's future
motion is unknown to the server, so Didyk et al.'s disparity criterion does not apply). Here a
node is a leaf when its pixels form one class:

* all sky (distance 0, or negative: the extra view's peeled-away pixels); or
* all geometry with a small relative range, ``max - min <= threshold * min``;

a node mixing sky and geometry, or spanning a larger range, splits, down to single pixels.
The root tiles are :data:`ROOT_TILE` pixels square; a view need not be a multiple of it (the
tiles of the last row and column are clipped to the image).

Both criteria only get easier to meet in a smaller node, so a node is a leaf exactly when it
passes and its parent does not: every level is decided at once from min / max pyramids,
vectorised in numpy. :func:`quadtree_payload` turns a produced frame's distance maps into
the ``PayloadKind.QUADTREE`` bytes (``pibr.protocol.quadtree``).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from pibr.protocol.quadtree import encode_quadtrees

#: Side of a root tile in pixels (a power of two): the largest quad the client draws.
ROOT_TILE = 64


def check_threshold(threshold: float) -> float:
    if not (isinstance(threshold, (int, float)) and math.isfinite(threshold) and threshold > 0):
        raise ValueError(f"quadtree threshold must be a positive relative distance range, got {threshold!r}")
    return float(threshold)


def _reduce(a: np.ndarray, op) -> np.ndarray:
    """2 x 2 blocks of ``a`` combined with the binary ufunc ``op``."""
    return op(op(a[0::2, 0::2], a[0::2, 1::2]), op(a[1::2, 0::2], a[1::2, 1::2]))


@njit(cache=True, nogil=True)
def _first_level(d, lo, hi, sky, inside):
    """Nodes of 2 x 2 pixels: geometry min / max (+-inf without geometry), any sky, any pixel
    inside the image. The node grid may reach past the image (clipped tiles)."""
    h, w = d.shape
    for j in range(lo.shape[0]):
        for i in range(lo.shape[1]):
            a, b, s, n = np.inf, -np.inf, False, False
            for y in range(2 * j, min(2 * j + 2, h)):
                for x in range(2 * i, min(2 * i + 2, w)):
                    n = True
                    v = d[y, x]
                    if v > 0:
                        a = min(a, v)
                        b = max(b, v)
                    else:
                        s = True
            lo[j, i], hi[j, i], sky[j, i], inside[j, i] = a, b, s, n


@njit(cache=True, nogil=True)
def _pixel_leaves(h, w, parent_leaf, out):
    """Every pixel inside the image whose 2 x 2 node is not a leaf, as (x, y, 1); -> count."""
    n = 0
    for y in range(h):
        for x in range(w):
            if not parent_leaf[y // 2, x // 2]:
                out[n, 0], out[n, 1], out[n, 2] = x, y, 1
                n += 1
    return n


def _uniform(lo, hi, sky, inside, threshold: float) -> np.ndarray:
    has_geo = lo < np.inf
    return inside & (~has_geo | (~sky & (hi - lo <= np.float32(threshold) * lo)))


def build_leaves(distance, threshold: float, tile: int = ROOT_TILE) -> np.ndarray:
    """Leaves (n, 3) int32 (x, y, size) of the quadtree over ``distance`` (h, w) float radial
    distances (0 = sky), largest levels first."""
    threshold = check_threshold(threshold)
    if not (isinstance(tile, int) and tile >= 1 and tile & (tile - 1) == 0):
        raise ValueError(f"root tile size must be a power of two, got {tile!r}")
    d = np.ascontiguousarray(distance, dtype=np.float32)
    if d.ndim != 2 or d.size == 0:
        raise ValueError(f"distance must be a non-empty (h, w) array, got shape {d.shape}")
    h, w = d.shape
    levels = tile.bit_length() - 1
    if levels == 0:
        ys, xs = np.indices((h, w)).reshape(2, -1)
        return np.stack([xs, ys, np.ones_like(xs)], axis=1).astype(np.int32)
    H, W = -(-h // tile) * tile, -(-w // tile) * tile
    shape = (H // 2, W // 2)
    lo, hi = np.empty(shape, np.float32), np.empty(shape, np.float32)
    sky, inside = np.empty(shape, bool), np.empty(shape, bool)
    _first_level(d, lo, hi, sky, inside)
    # uniform[k - 1]: the nodes of 2^k pixels that pass
    uniform = [_uniform(lo, hi, sky, inside, threshold)]
    for _ in range(levels - 1):
        lo, hi = _reduce(lo, np.minimum), _reduce(hi, np.maximum)
        sky, inside = _reduce(sky, np.logical_or), _reduce(inside, np.logical_or)
        uniform.append(_uniform(lo, hi, sky, inside, threshold))
    out = []
    for k in range(levels, 0, -1):
        leaf = uniform[k - 1]
        if k < levels:   # ... and the parent is not a leaf (then it split, and so did every ancestor)
            hk, wk = leaf.shape
            leaf = (leaf.reshape(hk // 2, 2, wk // 2, 2) & ~uniform[k][:, None, :, None]).reshape(hk, wk)
        ys, xs = np.nonzero(leaf)
        s = 1 << k
        out.append(np.stack([xs * s, ys * s, np.full(xs.shape, s)], axis=1).astype(np.int32))
    pixels = np.empty((h * w, 3), np.int32)
    n = _pixel_leaves(h, w, uniform[0], pixels)
    out.append(pixels[:n])
    return np.concatenate(out)


def quadtree_payload(distances: dict, threshold: float, tile: int = ROOT_TILE) -> bytes:
    """A frame's ``PayloadKind.QUADTREE`` bytes from its views' distance maps
    (``ProducedFrame.distances``: "primary" and, when the session has one, "extra")."""
    views = []
    for index, name in enumerate(("primary", "extra")):
        if name in distances:
            d = distances[name]
            views.append((index, d.shape[1], d.shape[0], tile, build_leaves(d, threshold, tile)))
    return encode_quadtrees(views)
