"""Regular samples: one sample code per 2^k x 2^k cell (32 x 32 by default), coded with Paeth.

The samples form a low-resolution image of shape (rh, rw) = ``grid_shape(w, h, k)`` =
(ceil(h / s), ceil(w / s)), s = 2^k, spread evenly from the first to the last row and column
(row i at round(i * (h - 1) / (rh - 1)); the middle row when rh = 1), so the image borders are
sampled too: diffusion extrapolates badly. They anchor the diffusion far from edges and serve
as the fallback predictor of edge values (the nearest one).

Each sample is predicted by the Paeth predictor (PNG) of its decoded left, upper and upper-left
neighbours (the left one in the first row, the upper one in the first column, 0 for the first),
and the residual — quantized by q like the edge values, closed loop — is an adaptive integer
whose context is the local gradient |left - upper-left| + |upper - upper-left|.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .arith import (INT_SLOT, RATE_SHIFT, as_data, dec_sint, dec_start, decoder_ok, enc_finish, enc_sint, enc_start,
                    encoder_bytes, new_model)
from .bitstream import grid_shape
from .values import quantize_residual, reconstruct

_N_BUCKETS = 6
N_CONTEXTS = _N_BUCKETS * INT_SLOT


def _spread(n: int, size: int) -> np.ndarray:
    if n == 1:
        return np.array([(size - 1) // 2], dtype=np.int64)
    i = np.arange(n, dtype=np.int64)
    return (2 * i * (size - 1) + (n - 1)) // (2 * (n - 1))


def sample_positions(width: int, height: int, spacing_log2: int) -> tuple[np.ndarray, np.ndarray]:
    """(rows (rh,), cols (rw,)) int64: pixel coordinates of the regular samples."""
    rh, rw = grid_shape(width, height, spacing_log2)
    return _spread(rh, height), _spread(rw, width)


def nearest_index(positions: np.ndarray, size: int) -> np.ndarray:
    """(size,) int64: for every pixel coordinate, the index of the nearest of ``positions`` (lower on ties)."""
    mid = (positions[:-1] + positions[1:]) // 2 + 1
    return np.searchsorted(mid, np.arange(size), side="right").astype(np.int64)


@njit(cache=True, nogil=True)
def _paeth(G, i, j):
    if i == 0 and j == 0:
        return 0, 0
    if i == 0:
        return int(G[i, j - 1]), 0
    if j == 0:
        return int(G[i - 1, j]), 0
    a = int(G[i, j - 1])
    b = int(G[i - 1, j])
    c = int(G[i - 1, j - 1])
    p = a + b - c
    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    g = abs(a - c) + abs(b - c)
    if pa <= pb and pa <= pc:
        return a, g
    if pb <= pc:
        return b, g
    return c, g


@njit(cache=True, nogil=True)
def _bucket(g):
    if g == 0:
        return 0
    if g <= 2:
        return 1
    if g <= 8:
        return 2
    if g <= 32:
        return 3
    if g <= 128:
        return 4
    return 5


@njit(cache=True, nogil=True)
def _encode_kernel(values, q, max_code, buf, m, rate, G):
    es = enc_start()
    rh, rw = values.shape
    for i in range(rh):
        for j in range(rw):
            pred, g = _paeth(G, i, j)
            rq, rec = quantize_residual(int(values[i, j]), pred, q, max_code)
            es = enc_sint(es, buf, m, rate, _bucket(g) * INT_SLOT, rq)
            G[i, j] = rec
    return enc_finish(es, buf)


@njit(cache=True, nogil=True)
def _decode_kernel(data, q, max_code, m, rate, G):
    ds = dec_start(data)
    rh, rw = G.shape
    for i in range(rh):
        for j in range(rw):
            pred, g = _paeth(G, i, j)
            ds, rq = dec_sint(ds, data, m, rate, _bucket(g) * INT_SLOT)
            G[i, j] = reconstruct(pred, rq, q, max_code)
    return ds


def encode_regular(values, q: int, max_code: int) -> tuple[bytes, np.ndarray]:
    """values (rh, rw) int true codes -> (bytes, decoded grid (rh, rw) int32)."""
    values = np.ascontiguousarray(values, dtype=np.int32)
    capacity = 8 * values.size + 64
    while True:
        G = np.zeros(values.shape, dtype=np.int32)
        buf = np.zeros(capacity, dtype=np.uint8)
        es = _encode_kernel(values, q, max_code, buf, new_model(N_CONTEXTS), RATE_SHIFT, G)
        out = encoder_bytes(es, buf)
        if out is not None:
            return out, G
        capacity = int(es[4]) + 16


def decode_regular(data, shape: tuple[int, int], q: int, max_code: int) -> tuple[np.ndarray, bool]:
    """bytes -> (grid (rh, rw) int32, stream decoded cleanly)."""
    G = np.zeros(shape, dtype=np.int32)
    arr = as_data(data)
    ds = _decode_kernel(arr, q, max_code, new_model(N_CONTEXTS), RATE_SHIFT, G)
    return G, decoder_ok(ds, arr)
