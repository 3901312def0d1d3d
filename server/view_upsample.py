"""A primary view rendered at a fraction of its size, brought to its whole size on the CPU after
the readback (server/producer.py; the rate control's smaller views, server/rate_control.py).

Colour is filtered bilinearly, as GL's LINEAR filter samples a texture at the whole view's pixel
centres (edges clamped); distance (and a moving scene's motion and moving flags) takes the
nearest low pixel: a distance between two surfaces, or a flag between an object and what is
behind it, would be neither. On llvmpipe the GL pass that did this into the whole-size target,
and the whole-size readback after it, cost more than half the frame's render at 1/3 of the side
(18 + 3 ms against 33 on one core, room, 1088^2): reading the small view back and filling the
readback buffers here costs a few ms and the GL thread nothing.
"""
from __future__ import annotations

import numpy as np
from numba import njit


def _taps(low: int, high: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per output pixel of ``high``: the two low pixels bilinear filtering reads, the weight of the
    second (int32, int32, float32), and the nearest low pixel (int32)."""
    centre = (np.arange(high, dtype=np.float64) + 0.5) * (low / high)
    u = centre - 0.5
    first = np.floor(u)
    weight = (u - first).astype(np.float32)
    a = np.clip(first, 0, low - 1).astype(np.int32)
    b = np.clip(first + 1, 0, low - 1).astype(np.int32)
    nearest = np.clip(np.floor(centre), 0, low - 1).astype(np.int32)
    return a, b, weight, nearest


@njit(cache=True, nogil=True, error_model="numpy")
def _upsample_colour(low, out, rows, xa, xb, wx, ya, yb, wy):
    """low (h, w, 4) uint8 -> out (H, W, 4) uint8, bilinear with the taps of :func:`_taps`, alpha
    255. Separable: each low row once across to W into ``rows`` (h, W * 4) float32, then each output
    row a blend of two of them (contiguous inner loops, which LLVM vectorises)."""
    h = low.shape[0]
    height, width = out.shape[0], out.shape[1]
    for y in range(h):
        src, dst = low[y], rows[y]
        for i in range(width):
            fx, a, b = wx[i], xa[i], xb[i]
            for c in range(3):
                first = np.float32(src[a, c])
                dst[4 * i + c] = first + fx * (np.float32(src[b, c]) - first)
            dst[4 * i + 3] = np.float32(255.0)
    flat = out.reshape(height, width * 4)
    for j in range(height):
        top, bottom, fy = rows[ya[j]], rows[yb[j]], wy[j]
        dst = flat[j]
        for k in range(width * 4):
            dst[k] = np.uint8(top[k] + fy * (bottom[k] - top[k]) + np.float32(0.5))


@njit(cache=True, nogil=True, error_model="numpy")
def _upsample_nearest(low, out, xn, yn):
    """low (h, w, c) -> out (H, W, c) of its dtype, each pixel its nearest low pixel's values."""
    height, width, channels = out.shape
    for j in range(height):
        src = low[yn[j]]
        row = out[j]
        for i in range(width):
            for c in range(channels):
                row[i, c] = src[xn[i], c]


class ViewUpsampler:
    """Fills whole-size readback buffers from a smaller view's; the taps are made once per size."""

    def __init__(self):
        self._taps: dict = {}
        self._rows: dict = {}     # (h, W) -> the colour's horizontal pass, (h, W * 4) float32

    def _for(self, low_shape: tuple, shape: tuple) -> tuple:
        key = (low_shape, shape)
        taps = self._taps.get(key)
        if taps is None:
            (h, w), (H, W) = low_shape, shape
            taps = self._taps[key] = (_taps(w, W), _taps(h, H))
        return taps

    def colour(self, low: np.ndarray, out: np.ndarray) -> np.ndarray:
        """low (h, w, 4) uint8 RGBA -> out (H, W, 4) uint8, bilinear; returns ``out``."""
        (xa, xb, wx, _), (ya, yb, wy, _) = self._for(low.shape[:2], out.shape[:2])
        key = (low.shape[0], out.shape[1])
        if key not in self._rows:
            self._rows[key] = np.empty((low.shape[0], out.shape[1] * 4), np.float32)
        _upsample_colour(low, out, self._rows[key], xa, xb, wx, ya, yb, wy)
        return out

    def distance(self, low: np.ndarray, out: np.ndarray) -> np.ndarray:
        """low (h, w) float32 -> out (H, W) float32, nearest; returns ``out``."""
        (_, _, _, xn), (_, _, _, yn) = self._for(low.shape, out.shape)
        _upsample_nearest(low[:, :, None], out[:, :, None], xn, yn)
        return out

    def nearest(self, low: np.ndarray, size: tuple) -> np.ndarray:
        """low (h, w) or (h, w, c) -> a new (H, W) or (H, W, c) array of its dtype, each pixel its
        nearest low pixel's values; ``size`` = (W, H)."""
        (_, _, _, xn), (_, _, _, yn) = self._for(low.shape[:2], (size[1], size[0]))
        out = np.empty((size[1], size[0]) + low.shape[2:], low.dtype)
        _upsample_nearest(low.reshape(low.shape[:2] + (-1,)), out.reshape(out.shape[:2] + (-1,)), xn, yn)
        return out
