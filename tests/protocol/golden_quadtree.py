"""Quadtree payloads pinned as golden bytes in ``golden/quadtree_*.bin``, the synthetic distance
maps behind them, and a plain recursive quadtree builder the tests compare the server's
vectorised one with. Regenerate only when the bitstream changes on purpose:
``python -m tests.protocol.golden_quadtree`` (then review the diff)."""
from __future__ import annotations

import numpy as np

from pibr.protocol.quadtree import encode_quadtrees

from .golden_files import GOLDEN_DIR, write_goldens  # noqa: F401 (GOLDEN_DIR: the tests import it from here)


def scene_distances(height: int, width: int, seed: int = 0) -> np.ndarray:
    """(h, w) float32 radial distances: a slanted far wall, a floor, a box in front, a noisy
    patch, and sky in the top-left (0)."""
    rng = np.random.default_rng(seed)
    y, x = np.indices((height, width), dtype=np.float64)
    d = 8.0 + 0.01 * x                                              # far wall, gently slanted
    d = np.where(y > 0.6 * height, 3.0 + 6.0 * (height - y) / height, d)   # floor
    box = (np.abs(x - 0.55 * width) < 0.15 * width) & (np.abs(y - 0.45 * height) < 0.2 * height)
    d = np.where(box, 2.0, d)                                       # box in front (steps)
    noisy = (x > 0.8 * width) & (y > 0.7 * height)
    d = np.where(noisy, 4.0 + rng.random((height, width)), d)       # clutter
    d = np.where((x < 0.3 * width) & (y < 0.3 * height), 0.0, d)     # sky
    return d.astype(np.float32)


def reference_leaves(distance, threshold: float, tile: int) -> np.ndarray:
    """Leaves (n, 3) (x, y, size) in pre-order, top-down, one node at a time: the definition
    ``pibr.server.quadtree`` implements (sky its own class, relative range <= threshold)."""
    d = np.asarray(distance, dtype=np.float64)
    h, w = d.shape
    out = []

    def uniform(x, y, s):
        block = d[y:y + s, x:x + s]            # clipped to the image
        geo = block[block > 0]
        if geo.size == 0:
            return True                        # all sky
        if geo.size != block.size:
            return False                       # sky and geometry
        lo, hi = np.float32(geo.min()), np.float32(geo.max())
        return float(hi - lo) <= float(np.float32(threshold) * lo)

    def visit(x, y, s):
        if x >= w or y >= h:
            return
        if s == 1 or uniform(x, y, s):
            out.append((x, y, s))
            return
        h2 = s // 2
        for dy, dx in ((0, 0), (0, h2), (h2, 0), (h2, h2)):
            visit(x + dx, y + dy, h2)

    for ty in range(0, h, tile):
        for tx in range(0, w, tile):
            visit(tx, ty, tile)
    return np.array(out, dtype=np.int32).reshape(-1, 3)


def golden_views(name: str) -> list:
    """The (view index, width, height, tile, leaves) of golden payload ``name``."""
    if name == "quadtree_two_views":
        primary = scene_distances(24, 40, seed=1)
        extra = scene_distances(12, 20, seed=2)
        return [(0, 40, 24, 16, reference_leaves(primary, 0.05, 16)),
                (1, 20, 12, 16, reference_leaves(extra, 0.05, 16))]
    if name == "quadtree_clipped":   # a view that is no multiple of its 64-pixel tiles
        d = scene_distances(70, 100, seed=3)
        return [(0, 100, 70, 64, reference_leaves(d, 0.02, 64))]
    raise KeyError(name)


def golden_sizes(name: str) -> list:
    return [(w, h) for _, w, h, _, _ in sorted(golden_views(name), key=lambda v: v[0])]


def golden_payload(name: str) -> bytes:
    return encode_quadtrees(golden_views(name))


NAMES = ("quadtree_two_views", "quadtree_clipped")


if __name__ == "__main__":
    write_goldens(NAMES, golden_payload)
