"""Procedural textures: deterministic, tileable, uint8 sRGB images (h, w, 3).

Each generator is vectorised numpy and takes a ``seed``; the same arguments always give the
same bytes. Row 0 is the image's top (see :class:`~pibr.scenes.scene.Material`). All
patterns except the leaf and the rug (mapped once) wrap around both edges, so they tile
seamlessly when UVs exceed [0, 1].
Results are cached per arguments; every call returns a fresh copy.
"""
from __future__ import annotations

from functools import lru_cache
from typing import Callable

import numpy as np

from pibr.protocol.errors import SceneError


# ----------------------------------------------------------------------------- noise

def periodic_noise(height: int, width: int, cells_y: int, cells_x: int, rng: np.random.Generator) -> np.ndarray:
    """Smooth value noise (height, width) float32 in [0, 1] that wraps at both edges.

    Random values on a (cells_y, cells_x) lattice, interpolated with a smoothstep, separably
    (columns first on the small lattice, then rows), so it costs a few passes over the image.
    """
    lattice = rng.random((cells_y, cells_x), dtype=np.float32)

    def weights(n: int, cells: int):
        x = np.arange(n, dtype=np.float32) * (cells / n)
        i0 = np.floor(x).astype(np.int64)
        f = x - i0
        return i0 % cells, (i0 + 1) % cells, (f * f * (3 - 2 * f)).astype(np.float32)

    x0, x1, wx = weights(width, cells_x)
    rows = lattice[:, x0] * (1 - wx) + lattice[:, x1] * wx                  # (cells_y, width)
    y0, y1, wy = weights(height, cells_y)
    return rows[y0] * (1 - wy)[:, None] + rows[y1] * wy[:, None]


def fractal_noise(height: int, width: int, base_cells: int, octaves: int, rng: np.random.Generator,
                  persistence: float = 0.5, aspect: float = 1.0) -> np.ndarray:
    """Sum of ``octaves`` :func:`periodic_noise` layers (height, width) float32, normalised to [0, 1].

    ``aspect`` stretches the lattice: > 1 gives more cells across x than y (streaks along y).
    """
    out = np.zeros((height, width), dtype=np.float32)
    amp, total = 1.0, 0.0
    for o in range(octaves):
        cy = max(1, int(round(base_cells * 2 ** o)))
        cx = max(1, int(round(base_cells * aspect * 2 ** o)))
        out += amp * periodic_noise(height, width, min(cy, height), min(cx, width), rng)
        total += amp
        amp *= persistence
    out /= total
    lo, hi = out.min(), out.max()
    return (out - lo) / max(hi - lo, 1e-6)


def _to_uint8(rgb: np.ndarray) -> np.ndarray:
    """(h, w, 3) floats in [0, 1] (sRGB) -> uint8."""
    out = np.asarray(rgb, dtype=np.float32) * np.float32(255.0) + np.float32(0.5)
    np.clip(out, 0, 255, out=out)
    return out.astype(np.uint8)


def _grid(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel-centre coordinates y (h, 1), x (1, w) in [0, 1)."""
    return ((np.arange(height, dtype=np.float32) + 0.5) / height)[:, None], \
        ((np.arange(width, dtype=np.float32) + 0.5) / width)[None, :]


def _check_size(size: int) -> None:
    if int(size) != size or not 16 <= size <= 4096:
        raise SceneError(f"texture size must be an integer in [16, 4096], got {size}")


# ----------------------------------------------------------------------------- textures

@lru_cache(maxsize=32)
def _parquet(size: int, rows: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    h = w = size
    y, x = _grid(h, w)
    row = np.minimum((y[:, 0] * rows).astype(np.int64), rows - 1)          # (h,)
    in_row = y[:, 0] * rows - row                                           # 0..1 across the plank
    planks_per_row = rng.choice([2, 3], size=rows)
    offsets = rng.random(rows, dtype=np.float32)
    count = planks_per_row[row].astype(np.float32)[:, None]                 # (h, 1)
    pos = (x + offsets[row][:, None]) * count                               # (h, w) plank units
    start = np.floor(pos)
    along = pos - start                                                     # 0..1 along the plank
    plank_id = row[:, None] * 4 + (start.astype(np.int32) % count.astype(np.int32))
    n_ids = rows * 4
    tone = rng.normal(0.0, 1.0, n_ids).astype(np.float32)
    hue = rng.normal(0.0, 1.0, n_ids).astype(np.float32)
    # grain: noise stretched along the planks (x), plus growth rings bent by the noise
    streak = fractal_noise(h, w, 8, 4, rng, 0.55, aspect=0.125)
    wobble = fractal_noise(h, w, 4, 3, rng, 0.5)
    ring_phase = rng.random(n_ids, dtype=np.float32) * 20
    rings = np.sin((in_row[:, None] * 9.0 + wobble * 6.0 + ring_phase[plank_id]) * np.float32(2 * np.pi))
    lum = 1.0 + 0.11 * tone[plank_id] + 0.16 * (0.55 * (streak - 0.5) + 0.25 * rings)
    # seams: dark lines along the rows and at plank ends, with slightly bevelled edges
    row_px = h / rows
    edge_y = (np.minimum(in_row, 1 - in_row) * row_px)[:, None]            # pixels to the long edge
    edge_x = np.minimum(along, 1 - along) * (w / count)                    # pixels to the plank end
    shade = np.clip(np.minimum(edge_y, edge_x) / np.float32(2.5), 0.0, 1.0)
    lum *= 0.35 + 0.65 * shade
    h_shift = hue[plank_id] * lum
    rgb = np.empty((h, w, 3), dtype=np.float32)
    rgb[..., 0] = 0.62 * lum + 0.025 * h_shift
    rgb[..., 1] = 0.42 * lum
    rgb[..., 2] = 0.24 * lum - 0.02 * h_shift
    return _to_uint8(rgb)


def parquet(size: int = 1024, rows: int = 8, seed: int = 1) -> np.ndarray:
    """Wooden plank floor (size, size, 3) uint8: ``rows`` rows of 2-3 staggered planks along x,
    with grain, growth rings, per-plank tone and dark seams. Map it to ~1.6 m for 20 cm planks."""
    _check_size(size)
    return _parquet(size, rows, seed).copy()


@lru_cache(maxsize=32)
def _wood(size: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y, x = _grid(size, size)
    streak = fractal_noise(size, size, 6, 5, rng, 0.55, aspect=0.125)
    wobble = fractal_noise(size, size, 3, 3, rng, 0.5)
    rings = np.sin((y * 14.0 + wobble * 5.0) * np.float32(2 * np.pi))   # 14 rings across: periodic
    lum = 1.0 + 0.2 * (streak - 0.5) + 0.1 * rings
    rgb = np.empty((size, size, 3), dtype=np.float32)
    rgb[..., 0] = 0.6 * lum
    rgb[..., 1] = 0.4 * lum
    rgb[..., 2] = 0.24 * lum
    return _to_uint8(rgb)


def wood(size: int = 512, seed: int = 10) -> np.ndarray:
    """Plain wood grain along x (size, size, 3) uint8, no seams: furniture, handrails."""
    _check_size(size)
    return _wood(size, seed).copy()


@lru_cache(maxsize=32)
def _plaster(size: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    mottle = fractal_noise(size, size, 4, 5, rng, 0.55)
    fine = rng.random((size, size), dtype=np.float32)
    lum = 0.88 + 0.06 * (mottle - 0.5) + 0.035 * (fine - 0.5)
    rgb = lum[..., None] * np.array([1.0, 0.985, 0.955], dtype=np.float32)
    return _to_uint8(rgb)


def plaster(size: int = 512, seed: int = 2) -> np.ndarray:
    """Painted plaster wall (size, size, 3) uint8: near-white with subtle mottling and grain;
    tint it with the material's base colour."""
    _check_size(size)
    return _plaster(size, seed).copy()


@lru_cache(maxsize=32)
def _brick(size: int, bricks_across: int, courses: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y, x = _grid(size, size)
    course = np.minimum((y[:, 0] * courses).astype(np.int64), courses - 1)
    in_course = y[:, 0] * courses - course
    shift = np.where(course % 2 == 1, 0.5, 0.0)[:, None]
    pos = x * bricks_across + shift
    brick_idx = np.floor(pos).astype(np.int64) % bricks_across
    along = pos - np.floor(pos)
    ids = course[:, None] * bricks_across + brick_idx
    n_ids = courses * bricks_across
    tone = rng.normal(0.0, 1.0, n_ids).astype(np.float32)
    redness = rng.normal(0.0, 1.0, n_ids).astype(np.float32)
    grit = fractal_noise(size, size, 16, 4, rng, 0.6)
    blotch = fractal_noise(size, size, 6, 3, rng, 0.5)
    base = np.array([0.58, 0.27, 0.18], dtype=np.float32)
    lum = 1.0 + 0.12 * tone[ids] + 0.22 * (grit - 0.5) + 0.12 * (blotch - 0.5)
    rgb = base * lum[..., None]
    rgb[..., 0] += 0.05 * redness[ids]
    rgb[..., 1] += 0.015 * redness[ids]
    # mortar: 10 mm joints on 225 x 75 mm bricks -> fractions of a brick / a course
    joint_x = 0.5 * 10.0 / 225.0
    joint_y = 0.5 * 10.0 / 75.0
    mortar = (np.minimum(along, 1 - along) < joint_x) | (np.minimum(in_course, 1 - in_course) < joint_y)[:, None]
    mortar_rgb = (0.62 + 0.12 * (grit - 0.5))[..., None] * np.array([1.0, 0.97, 0.9], dtype=np.float32)
    rgb = np.where(mortar[..., None], mortar_rgb, rgb)
    return _to_uint8(rgb)


def brick(size: int = 1024, bricks_across: int = 4, courses: int = 12, seed: int = 3) -> np.ndarray:
    """Running-bond brick wall (size, size, 3) uint8: ``bricks_across`` x ``courses`` bricks
    (225 x 75 mm with mortar: map the texture to 0.9 m) with per-brick colour and grit."""
    _check_size(size)
    if courses % 2:
        raise SceneError("brick courses must be even so the running bond tiles")
    return _brick(size, bricks_across, courses, seed).copy()


@lru_cache(maxsize=32)
def _marble(size: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y, x = _grid(size, size)
    turb = fractal_noise(size, size, 4, 6, rng, 0.55)
    turb2 = fractal_noise(size, size, 8, 4, rng, 0.5)
    # integer frequencies keep the veins periodic across the tile
    phase = (x + 2 * y) * np.float32(2 * np.pi) + turb * 10.0
    vein = np.abs(np.sin(phase)) ** 0.2                    # thin dark lines where sin ~ 0
    fine = np.abs(np.sin((3 * x - y) * np.float32(2 * np.pi) + turb2 * 14.0)) ** 0.08
    lum = 0.94 - 0.38 * (1 - vein) - 0.1 * (1 - fine) + 0.06 * (turb2 - 0.5)
    rgb = lum[..., None] * np.array([1.0, 0.985, 0.97], dtype=np.float32)
    rgb[..., 2] += 0.04 * (1 - vein)                       # veins slightly blue-grey
    return _to_uint8(rgb)


def marble(size: int = 1024, seed: int = 4) -> np.ndarray:
    """White marble (size, size, 3) uint8 with turbulent grey veins."""
    _check_size(size)
    return _marble(size, seed).copy()


@lru_cache(maxsize=32)
def _leaf(size: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y, x = _grid(size, size)
    v = 1.0 - y                                             # along the leaf (v = 0 at the stalk)
    across = x - 0.5
    mottle = fractal_noise(size, size, 6, 4, rng, 0.5)
    base = np.array([0.18, 0.42, 0.12], dtype=np.float32)
    lum = 0.85 + 0.3 * v + 0.25 * (mottle - 0.5) - 0.25 * np.abs(across)
    rgb = base * lum[..., None]
    midrib = np.exp(-(across / 0.012) ** 2)
    # side veins: lines leaving the midrib towards the tip, 7 per half
    side = np.abs(np.sin((v - 0.9 * np.abs(across)) * 7 * np.pi)) ** 8 * (np.abs(across) > 0.01)
    vein = np.maximum(midrib, 0.6 * side)
    rgb = rgb * (1 - 0.5 * vein[..., None]) + 0.5 * vein[..., None] * np.array([0.5, 0.7, 0.3], dtype=np.float32)
    return _to_uint8(rgb)


def leaf_green(size: int = 512, seed: int = 5) -> np.ndarray:
    """Leaf blade (size, size, 3) uint8 for :func:`~pibr.scenes.primitives.leaf` UVs: green with a
    pale midrib down the middle column and side veins."""
    _check_size(size)
    return _leaf(size, seed).copy()


@lru_cache(maxsize=32)
def _grass(size: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    patches = fractal_noise(size, size, 3, 4, rng, 0.55)
    blades = fractal_noise(size, size, 64, 2, rng, 0.6, aspect=0.25)
    speck = rng.random((size, size), dtype=np.float32)
    green = np.array([0.30, 0.48, 0.16], dtype=np.float32)
    dry = np.array([0.52, 0.50, 0.26], dtype=np.float32)
    mix = np.clip((patches - 0.35) * 1.5, 0, 1)[..., None] * 0.6
    rgb = green * (1 - mix) + dry * mix
    rgb *= (0.75 + 0.35 * blades + 0.12 * (speck - 0.5))[..., None]
    return _to_uint8(rgb)


def grass(size: int = 512, seed: int = 6) -> np.ndarray:
    """Meadow (size, size, 3) uint8: green with dry patches and blade-scale speckle."""
    _check_size(size)
    return _grass(size, seed).copy()


@lru_cache(maxsize=32)
def _fabric(size: int, threads: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y, x = _grid(size, size)
    warp = np.sin(x * threads * 2 * np.pi)                  # threads running along y
    weft = np.sin(y * threads * 2 * np.pi)
    over = np.sin(x * threads * np.pi) * np.sin(y * threads * np.pi) > 0   # plain weave checker
    weave = np.where(over, 0.5 + 0.5 * np.abs(warp), 0.5 + 0.5 * np.abs(weft))
    slub = fractal_noise(size, size, 32, 2, rng, 0.5, aspect=0.25)
    lum = 0.72 + 0.22 * weave + 0.1 * (slub - 0.5)
    return _to_uint8(np.repeat(lum[..., None], 3, axis=2))


def fabric(size: int = 512, threads: int = 96, seed: int = 7) -> np.ndarray:
    """Plain-weave cloth (size, size, 3) uint8, grey: tint with the base colour (sofa, curtains)."""
    _check_size(size)
    return _fabric(size, threads, seed).copy()


@lru_cache(maxsize=32)
def _carpet(size: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y, x = _grid(size, size)
    cx, cy = x - 0.5, y - 0.5
    border = np.maximum(np.abs(cx), np.abs(cy))             # 0 centre .. 0.5 edge (square rings)
    diamond = np.abs(cx) + np.abs(cy)
    red = np.array([0.50, 0.10, 0.10], dtype=np.float32)
    navy = np.array([0.10, 0.14, 0.32], dtype=np.float32)
    cream = np.array([0.85, 0.78, 0.60], dtype=np.float32)
    gold = np.array([0.78, 0.58, 0.20], dtype=np.float32)
    rgb = np.broadcast_to(red, (size, size, 3)).copy()
    band = (border > 0.40) & (border < 0.46)
    rgb[band] = navy
    rgb[(border > 0.465) & (border < 0.48)] = cream
    rgb[border >= 0.48] = navy
    # a repeating motif inside the border band
    motif = np.sin(cx * 40 * np.pi) * np.sin(cy * 40 * np.pi) > 0.5
    rgb[band & motif] = gold
    med = diamond < 0.22
    rgb[med] = navy
    rgb[(diamond < 0.16) & (diamond > 0.13)] = cream
    rgb[diamond < 0.07] = gold
    ring = np.abs(np.sin(diamond * 60 * np.pi)) > 0.92
    rgb[ring & (border < 0.38) & ~med] *= 0.7
    pile = fractal_noise(size, size, 64, 2, rng, 0.6)
    tuft = rng.random((size, size), dtype=np.float32)
    rgb *= (0.85 + 0.2 * pile + 0.1 * (tuft - 0.5))[..., None]
    return _to_uint8(rgb)


def carpet(size: int = 1024, seed: int = 8) -> np.ndarray:
    """Patterned rug (size, size, 3) uint8: red field, navy border with a gold motif, central
    medallion, pile noise. Map it once onto a rug (UVs 0..1)."""
    _check_size(size)
    return _carpet(size, seed).copy()


@lru_cache(maxsize=32)
def _test_pattern(size: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y, x = _grid(size, size)
    cells = 8
    cell_id = (np.floor(y * cells) * cells + np.floor(x * cells)).astype(np.int64)
    hues = rng.random((cells * cells, 3)).astype(np.float32) * 0.6 + 0.3
    checker = ((np.floor(x * cells * 4) + np.floor(y * cells * 4)) % 2).astype(np.float32)
    rgb = hues[cell_id] * (0.55 + 0.45 * checker)[..., None]
    # zone plate in every cell: frequency rising towards the cell edge (up to ~pixel rate)
    fx, fy = (x * cells) % 1.0 - 0.5, (y * cells) % 1.0 - 0.5
    r2 = fx * fx + fy * fy
    zone = 0.5 + 0.5 * np.cos(np.pi * r2 * (size / cells) * 0.9)
    rgb = rgb * (0.6 + 0.4 * zone[..., None])
    # thin grid lines (1 px) every 1/32 and bold ones every cell
    px = 1.0 / size
    fine = (np.abs((x * 32) % 1.0) < 32 * px) | (np.abs((y * 32) % 1.0) < 32 * px)
    bold = (np.abs((x * cells) % 1.0) < 3 * cells * px) | (np.abs((y * cells) % 1.0) < 3 * cells * px)
    rgb = np.where(fine[..., None], 0.05, rgb)
    rgb = np.where(bold[..., None], 1.0, rgb)
    return _to_uint8(rgb)


def test_pattern(size: int = 1024, seed: int = 9) -> np.ndarray:
    """Calibration texture (size, size, 3) uint8: 8 x 8 coloured cells with checkers, a zone
    plate each (frequencies up to near the pixel rate) and 1 px grid lines: detail everywhere."""
    _check_size(size)
    return _test_pattern(size, seed).copy()


test_pattern.__test__ = False  # not a pytest test, despite the name


def clear_cache() -> None:
    """Forget every cached texture (tests that time or compare fresh generation)."""
    for fn in (_parquet, _wood, _plaster, _brick, _marble, _leaf, _grass, _fabric, _carpet, _test_pattern):
        fn.cache_clear()


#: name -> generator with default arguments.
TEXTURES: dict[str, Callable[[], np.ndarray]] = {
    "parquet": parquet,
    "wood": wood,
    "plaster": plaster,
    "brick": brick,
    "marble": marble,
    "leaf_green": leaf_green,
    "grass": grass,
    "fabric": fabric,
    "carpet": carpet,
    "test_pattern": test_pattern,
}
