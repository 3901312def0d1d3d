"""Compiled kernels behind SSIM and PSNR that give scikit-image's and numpy's numbers to the bit.

Scoring a run computes SSIM for every method on every tick, and scikit-image's SSIM is many full
passes over float64 images (three box filters per channel, a dozen element-wise operations).
These kernels do the same arithmetic in one or two passes: each value is computed by the same
IEEE operations in the same order, so the results are the same bits
(tests/bench/test_metrics.py checks them against scikit-image and numpy).

- The box filter is scipy.ndimage's ``uniform_filter`` of size ``win`` with its default
  ``reflect`` border: along axis 0, then along axis 1, each a running sum over the extended line
  (the first window's sum from 0.0, then ``sum += (new - old)``) divided by the size.
- The SSIM map follows ``skimage.metrics.structural_similarity``'s expressions as numpy evaluates
  them, left to right. Its mean over the cropped map stays numpy's (pairwise summation).
- PSNR's squared errors of uint8 images are integers, so their sum is exact in any order, and
  so equal to numpy's float64 sum; numpy's mean divides that sum by the count.
"""
from __future__ import annotations

import numpy as np
from numba import njit

@njit(cache=True, nogil=True, inline="always")
def _reflect(i, n):
    """Index into a line of ``n`` (>= half the window) of position ``i`` on its reflect-extended line."""
    if i < 0:
        return -i - 1
    if i >= n:
        return 2 * n - i - 1
    return i


@njit(cache=True, nogil=True)
def _box_columns(sums, out, win):
    """out (h, w) float64 = the running window sums ``sums`` (h, w) float64 of integer-valued
    rows filtered along axis 0, divided by ``win`` (the sums are exact, so only the division rounds)."""
    h, w = out.shape
    half = win // 2
    acc = np.zeros(w, np.float64)
    for k in range(-half, half + 1):
        r = _reflect(k, h)
        for x in range(w):
            acc[x] += sums[r, x]
    for x in range(w):
        out[0, x] = acc[x] / win
    for y in range(1, h):
        add = _reflect(y + half, h)
        drop = _reflect(y - half - 1, h)
        for x in range(w):
            acc[x] += sums[add, x] - sums[drop, x]
            out[y, x] = acc[x] / win


@njit(cache=True, nogil=True)
def _box_rows(a, out, win):
    """out (h, w) = a (h, w) float64 filtered along axis 1 exactly as scipy's running sum does."""
    h, w = a.shape
    half = win // 2
    for y in range(h):
        tmp = 0.0
        for k in range(-half, half + 1):
            tmp += a[y, _reflect(k, w)]
        out[y, 0] = tmp / win
        for x in range(1, w):
            tmp += a[y, _reflect(x + half, w)] - a[y, _reflect(x - half - 1, w)]
            out[y, x] = tmp / win


@njit(cache=True, nogil=True)
def box_filter(a, win):
    """scipy.ndimage.uniform_filter(a, win) of integer-valued a (h, w) float64 (h, w >= win)."""
    tmp = np.empty_like(a)
    out = np.empty_like(a)
    _box_columns(a, tmp, win)
    _box_rows(tmp, out, win)
    return out


@njit(cache=True, nogil=True)
def reference_channel(ref, c, win, cov_norm):
    """One channel ``c`` of a ground truth (h, w, 3) uint8: its float64 values x, local mean ux,
    ux ** 2 and local variance (as scikit-image's SSIM computes them)."""
    h, w = ref.shape[:2]
    x = np.empty((h, w), np.float64)
    xx = np.empty((h, w), np.float64)
    for j in range(h):
        for i in range(w):
            v = np.float64(ref[j, i, c])
            x[j, i] = v
            xx[j, i] = v * v
    ux = box_filter(x, win)
    uxx = box_filter(xx, win)
    ux2 = np.empty((h, w), np.float64)
    vx = np.empty((h, w), np.float64)
    for j in range(h):
        for i in range(w):
            u = ux[j, i]
            ux2[j, i] = u * u
            vx[j, i] = cov_norm * (uxx[j, i] - u * u)
    return x, ux, ux2, vx


@njit(cache=True, nogil=True)
def ssim_map(test, c, x, ux, ux2, vx, win, cov_norm, c1, c2):
    """(h, w) float64: the SSIM map of channel ``c`` of test (h, w, 3) uint8 against a reference
    channel's x, ux, ux ** 2 and variance vx, before cropping."""
    h, w = x.shape
    y = np.empty((h, w), np.float64)
    yy = np.empty((h, w), np.float64)
    xy = np.empty((h, w), np.float64)
    for j in range(h):
        for i in range(w):
            v = np.float64(test[j, i, c])
            y[j, i] = v
            yy[j, i] = v * v
            xy[j, i] = x[j, i] * v
    uy = box_filter(y, win)
    uyy = box_filter(yy, win)
    uxy = box_filter(xy, win)
    s = np.empty((h, w), np.float64)
    for j in range(h):
        for i in range(w):
            a = ux[j, i]
            b = uy[j, i]
            vy = cov_norm * (uyy[j, i] - b * b)
            vxy = cov_norm * (uxy[j, i] - a * b)
            a1 = 2 * a * b + c1
            a2 = 2 * vxy + c2
            b1 = ux2[j, i] + b * b + c1
            b2 = vx[j, i] + vy + c2
            s[j, i] = (a1 * a2) / (b1 * b2)
    return s


@njit(cache=True, nogil=True)
def squared_error_sum(ref, test):
    """The exact sum of squared differences of two uint8 arrays of one shape, as a float64."""
    a = ref.ravel()
    b = test.ravel()
    total = 0
    for k in range(a.size):
        d = np.int64(a[k]) - np.int64(b[k])
        total += d * d
    return np.float64(total)


@njit(cache=True, nogil=True)
def colour_by_difference(ref, test, colours):
    """(h, w, 3) uint8: per pixel of two (h, w, 3) uint8 images (any strides) the row of
    ``colours`` (766, 3) uint8 at the sum of the three channels' absolute differences."""
    h, w = ref.shape[:2]
    out = np.empty((h, w, 3), np.uint8)
    for j in range(h):
        for i in range(w):
            total = 0
            for c in range(3):
                total += abs(np.int32(ref[j, i, c]) - np.int32(test[j, i, c]))
            for c in range(3):
                out[j, i, c] = colours[total, c]
    return out
