"""Motion of moving objects: a lossless moving-pixel mask plus one quantized vector per block.

Only dynamic objects move on screen by themselves (camera motion is known from the poses),
so the motion field is zero almost everywhere and piecewise smooth where it is not: a rigid
object's flow is affine across its silhouette. What must not blur is the silhouette, where a
moving object meets the static background. So, instead of running the full edge/value/diffusion
machinery on the flow (Pajak et al. do), this codec sends

* the **moving mask** (h, w) bool, losslessly, with the four-pass context coder of
  :mod:`.edges` (a filled silhouette costs about as much as its outline);
* per ``2^block_log2`` block (8 x 8 by default) with at least one moving pixel, the mean motion
  of its moving pixels, **quantized non-linearly**: ``v_q = sign(v) * round(s * sqrt(|v|))``
  (slow motion, where errors are visible, gets fine steps: with s = 8 a 1-pixel motion has
  steps of 0.03 pixel, 64 pixels steps of 2 pixels); each component predicted by the median of
  the W, N and NE moving blocks and coded as an adaptive integer.

The decoder gives every moving pixel its block's vector, and 0 to every other pixel: the error
inside an object is that of a piecewise-constant fit on 8 x 8 blocks, and nothing leaks
across its outline. No moving pixel at all: no section (0 bytes; the frame header says so).

Section layout: u8 scale s (1..255), u8 block_log2 (3..6), u32 length of the mask stream,
the mask stream, the vector stream.
"""
from __future__ import annotations

import struct

import numpy as np
from numba import njit

from ..errors import CodecError
from .arith import (INT_SLOT, RATE_SHIFT, as_data, dec_sint, dec_start, decoder_ok, enc_finish, enc_sint, enc_start,
                    encoder_bytes, new_model)
from .edges import decode_edge_image, encode_edge_image

_HEAD = struct.Struct("<BBI")
MIN_BLOCK_LOG2, MAX_BLOCK_LOG2 = 3, 6
#: Motion beyond this many pixels per frame is clamped (it is meaningless for a warp anyway).
MAX_MOTION = 4096.0
N_CONTEXTS = 2 * 3 * INT_SLOT
#: Largest code magnitude: MAX_MOTION at the largest scale.
MAX_CODE = int(np.ceil(255 * np.sqrt(MAX_MOTION)))


def quantize_motion(v, scale: float) -> np.ndarray:
    """Motion components (any shape, pixels) -> int32 codes sign(v) * round(scale * sqrt(|v|)).

    Dequantized, a component with |v| <= MAX_MOTION comes back within sqrt(|v|) / scale +
    1 / (4 scale^2) pixels (half a step in sqrt(|v|)); a larger one is clamped to +-MAX_MOTION."""
    v = np.clip(np.nan_to_num(np.asarray(v, dtype=np.float64)), -MAX_MOTION, MAX_MOTION)
    return (np.sign(v) * np.floor(scale * np.sqrt(np.abs(v)) + 0.5)).astype(np.int32)


def dequantize_motion(vq, scale: float) -> np.ndarray:
    """Codes -> motion components (float32, pixels)."""
    vq = np.asarray(vq, dtype=np.float64)
    return (np.sign(vq) * (vq / scale) ** 2).astype(np.float32)


@njit(cache=True, nogil=True)
def _median_pred(G, M, i, j):
    """Median predictor of block (i, j) from the moving W, N, NE (or NW) blocks; (pred x, pred y, count)."""
    bw = G.shape[1]
    xs = np.zeros(3, dtype=np.int64)
    ys = np.zeros(3, dtype=np.int64)
    n = 0
    if j > 0 and M[i, j - 1]:
        xs[n] = G[i, j - 1, 0]
        ys[n] = G[i, j - 1, 1]
        n += 1
    if i > 0 and M[i - 1, j]:
        xs[n] = G[i - 1, j, 0]
        ys[n] = G[i - 1, j, 1]
        n += 1
    if i > 0 and j + 1 < bw and M[i - 1, j + 1]:
        xs[n] = G[i - 1, j + 1, 0]
        ys[n] = G[i - 1, j + 1, 1]
        n += 1
    elif i > 0 and j > 0 and M[i - 1, j - 1]:
        xs[n] = G[i - 1, j - 1, 0]
        ys[n] = G[i - 1, j - 1, 1]
        n += 1
    if n == 0:
        return 0, 0, 0
    if n == 1:
        return xs[0], ys[0], 1
    if n == 2:
        return (xs[0] + xs[1]) // 2, (ys[0] + ys[1]) // 2, 2
    mx = max(min(xs[0], xs[1]), min(max(xs[0], xs[1]), xs[2]))
    my = max(min(ys[0], ys[1]), min(max(ys[0], ys[1]), ys[2]))
    return mx, my, 3


@njit(cache=True, nogil=True)
def _ctx(comp, n):
    return (comp * 3 + (0 if n == 0 else (1 if n < 3 else 2))) * INT_SLOT


@njit(cache=True, nogil=True)
def _encode_vectors(M, V, buf, m, rate):
    es = enc_start()
    bh, bw = M.shape
    for i in range(bh):
        for j in range(bw):
            if not M[i, j]:
                continue
            px, py, n = _median_pred(V, M, i, j)
            es = enc_sint(es, buf, m, rate, _ctx(0, n), int(V[i, j, 0]) - px)
            es = enc_sint(es, buf, m, rate, _ctx(1, n), int(V[i, j, 1]) - py)
    return enc_finish(es, buf)


@njit(cache=True, nogil=True)
def _decode_vectors(data, M, m, rate, V):
    ds = dec_start(data)
    bh, bw = M.shape
    for i in range(bh):
        for j in range(bw):
            if not M[i, j]:
                continue
            px, py, n = _median_pred(V, M, i, j)
            ds, rx = dec_sint(ds, data, m, rate, _ctx(0, n))
            ds, ry = dec_sint(ds, data, m, rate, _ctx(1, n))
            # clamped so that corrupt data cannot overflow the int32 grid
            V[i, j, 0] = min(max(px + rx, -MAX_CODE), MAX_CODE)
            V[i, j, 1] = min(max(py + ry, -MAX_CODE), MAX_CODE)
        if ds[3] != 0:
            return ds
    return ds


def _block_any(mask, block_log2):
    h, w = mask.shape
    s = 1 << block_log2
    bh, bw = (h + s - 1) // s, (w + s - 1) // s
    p = np.zeros((bh * s, bw * s), dtype=bool)
    p[:h, :w] = mask
    return p.reshape(bh, s, bw, s).any(axis=(1, 3))


@njit(cache=True, nogil=True)
def _block_sums(motion, moving, block_log2, total, count):
    """Per block, the float64 sum of its moving pixels' motion (NaN as 0, +-inf as +-the largest
    float64, as numpy.nan_to_num) into total (bh, bw, 2), and how many there are into count (bh, bw).

    A pass over the mask that touches the motion of moving pixels only: the frame's motion is
    zero almost everywhere, and whole-frame float64 copies cost ~100 ms a 1088² frame."""
    h, w = moving.shape
    big = np.finfo(np.float64).max
    for y in range(h):
        i = y >> block_log2
        for x in range(w):
            if not moving[y, x]:
                continue
            j = x >> block_log2
            for c in range(2):
                v = np.float64(motion[y, x, c])
                if np.isnan(v):
                    v = 0.0
                elif np.isinf(v):
                    v = big if v > 0 else -big
                total[i, j, c] += v
            count[i, j] += 1


def encode_motion(motion, moving, scale: int = 8, block_log2: int = 3,
                  decoded: bool = True) -> tuple[bytes, np.ndarray | None, np.ndarray]:
    """Motion section of one frame.

    motion : (h, w, 2) float pixels (x right, y down); moving : (h, w) bool.
    Returns (section bytes, b"" when nothing moves; decoded motion (h, w, 2) float32, None
    unless ``decoded``; moving mask (h, w) bool).
    """
    moving = np.ascontiguousarray(moving, dtype=bool)
    h, w = moving.shape
    if not (1 <= scale <= 255 and MIN_BLOCK_LOG2 <= block_log2 <= MAX_BLOCK_LOG2):
        raise ValueError(f"motion scale must be 1..255 and block_log2 {MIN_BLOCK_LOG2}..{MAX_BLOCK_LOG2}")
    if not moving.any():
        return b"", np.zeros((h, w, 2), np.float32) if decoded else None, moving
    motion = np.asarray(motion)
    if motion.dtype not in (np.float32, np.float64):
        motion = motion.astype(np.float64)
    if motion.shape != (h, w, 2):
        raise ValueError(f"motion must have shape ({h}, {w}, 2), got {motion.shape}")
    s = 1 << block_log2
    bh, bw = (h + s - 1) // s, (w + s - 1) // s
    total = np.zeros((bh, bw, 2), dtype=np.float64)
    n = np.zeros((bh, bw), dtype=np.int64)
    _block_sums(np.ascontiguousarray(motion), moving, block_log2, total, n)
    blocks = n > 0
    mean = total / np.maximum(n, 1)[..., None]
    vq = np.ascontiguousarray(np.where(blocks[..., None], quantize_motion(mean, scale), 0), dtype=np.int32)
    mask_bytes = encode_edge_image(moving, None, True)
    capacity = 16 * int(blocks.sum()) + 64
    while True:
        buf = np.zeros(capacity, dtype=np.uint8)
        es = _encode_vectors(blocks, vq, buf, new_model(N_CONTEXTS), RATE_SHIFT)
        vec_bytes = encoder_bytes(es, buf)
        if vec_bytes is not None:
            break
        capacity = int(es[4]) + 16
    section = _HEAD.pack(scale, block_log2, len(mask_bytes)) + mask_bytes + vec_bytes
    return section, _expand(vq, moving, scale, block_log2) if decoded else None, moving


def _expand(vq, moving, scale, block_log2):
    h, w = moving.shape
    s = 1 << block_log2
    full = np.repeat(np.repeat(dequantize_motion(vq, scale), s, axis=0), s, axis=1)[:h, :w]
    return np.where(moving[..., None], full, 0.0).astype(np.float32)


def decode_motion(section, height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Section bytes -> (motion (h, w, 2) float32, moving (h, w) bool). Raises CodecError."""
    view = memoryview(section).cast("B")
    if len(view) < _HEAD.size:
        raise CodecError(f"edge codec: motion section of {len(view)} bytes is shorter than its {_HEAD.size}-byte head")
    scale, block_log2, mask_len = _HEAD.unpack_from(view, 0)
    if scale < 1:
        raise CodecError("edge codec: motion scale 0")
    if not (MIN_BLOCK_LOG2 <= block_log2 <= MAX_BLOCK_LOG2):
        raise CodecError(f"edge codec: motion block 2^{block_log2} outside 2^{MIN_BLOCK_LOG2}..2^{MAX_BLOCK_LOG2}")
    if mask_len > len(view) - _HEAD.size:
        raise CodecError(f"edge codec: motion mask of {mask_len} bytes exceeds its section")
    mask_data = view[_HEAD.size:_HEAD.size + mask_len]
    vec_data = view[_HEAD.size + mask_len:]
    moving, ok = decode_edge_image(mask_data, height, width, None, True)
    if not ok:
        raise CodecError("edge codec: motion mask stream is corrupt")
    if not moving.any():
        raise CodecError("edge codec: motion section with an empty moving mask")
    blocks = np.ascontiguousarray(_block_any(moving, block_log2))
    V = np.zeros(blocks.shape + (2,), dtype=np.int32)
    arr = as_data(vec_data)
    ds = _decode_vectors(arr, blocks, new_model(N_CONTEXTS), RATE_SHIFT, V)
    if not decoder_ok(ds, arr):
        raise CodecError("edge codec: motion vector stream is corrupt")
    return _expand(V, moving, scale, block_log2), moving
