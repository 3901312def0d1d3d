"""Compiled kernels behind SSIM and PSNR that give scikit-image's and numpy's numbers to the bit.

Scoring a run computes SSIM for every method on every tick, and scikit-image's SSIM is many full
passes over float64 images (three box filters per channel, a dozen element-wise operations).
These kernels do the same arithmetic row by row in one pass: each value is computed by the same
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

@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _reflect(i, n):
    """Index into a line of ``n`` (>= half the window) of position ``i`` on its reflect-extended line."""
    if i < 0:
        return -i - 1
    if i >= n:
        return 2 * n - i - 1
    return i


@njit(cache=True, nogil=True, error_model="numpy")
def channel_plane(img, c):
    """(h, w) int32: channel ``c`` of img (h, w, 3) uint8."""
    h, w = img.shape[:2]
    out = np.empty((h, w), np.int32)
    for j in range(h):
        for i in range(w):
            out[j, i] = img[j, i, c]
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _filtered_rows(y, x, win, sums, ext, means, row, products=True):
    """Row ``row`` (taken in order from 0) of scipy's ``uniform_filter(., win)`` of y, y * y and
    (if ``products``) y * x, integer planes (h, w) int32, into means (3, w) float64. ``sums``
    (3, w) int32 carries the column window sums from row to row, ``ext`` (3, w + win - 1) float64
    is scratch.

    scipy filters along axis 0, then axis 1, each line a running sum over its reflect-extended
    line (the first window summed from 0.0, then ``sum += new - old``) divided by ``win``. Along
    axis 0 the sums of integers are exact, so a window sum of integers divided by ``win`` is
    bit for bit scipy's; along axis 1 the running float64 sum is replayed in its order.

    Only the running sums are serial: the divisions and the column sums are loops of their own,
    which the compiler vectorises (1.7x faster than one loop doing all of it per pixel)."""
    h, w = y.shape
    half = win // 2
    if row == 0:
        sums[:] = 0
        for d in range(-half, half + 1):
            r = _reflect(d, h)
            yr = y[r]
            xr = x[r]
            for i in range(w):
                a = yr[i]
                sums[0, i] += a
                sums[1, i] += a * a
                sums[2, i] += a * xr[i]
    else:
        add = _reflect(row + half, h)
        drop = _reflect(row - half - 1, h)
        ya, yd, xa, xd = y[add], y[drop], x[add], x[drop]
        s0, s1, s2 = sums[0], sums[1], sums[2]
        for i in range(w):
            a = ya[i]
            d = yd[i]
            s0[i] += a - d
            s1[i] += a * a - d * d
            s2[i] += a * xa[i] - d * xd[i]
    for k in range(3 if products else 2):
        sk = sums[k]
        ek = ext[k]
        inner = ext[k, half:half + w]   # a view: numba tests a computed index for wrapping around,
        for i in range(w):              # which stops the loop vectorising
            inner[i] = sk[i] / win
        for j in range(half):   # the reflected ends
            ek[j] = ek[2 * half - 1 - j]
            ek[w + half + j] = ek[w + half - 1 - j]
    e0, e1, e2 = ext[0], ext[1], ext[2]
    m0, m1, m2 = means[0], means[1], means[2]
    t0 = 0.0
    t1 = 0.0
    t2 = 0.0
    for e in range(win):
        t0 += e0[e]
        t1 += e1[e]
        t2 += e2[e]
    m0[0], m1[0], m2[0] = t0, t1, t2
    # pixel i + 1 adds ext[i + win] and drops ext[i]: views, for the same reason
    n0, n1, n2, o0, o1, o2 = e0[win:], e1[win:], e2[win:], m0[1:], m1[1:], m2[1:]
    if products:   # three independent chains, each in scipy's order
        for i in range(w - 1):
            t0 += n0[i] - e0[i]
            t1 += n1[i] - e1[i]
            t2 += n2[i] - e2[i]
            o0[i] = t0
            o1[i] = t1
            o2[i] = t2
    else:
        for i in range(w - 1):
            t0 += n0[i] - e0[i]
            t1 += n1[i] - e1[i]
            o0[i] = t0
            o1[i] = t1
    for k in range(3 if products else 2):
        mk = means[k]
        for i in range(w):
            mk[i] = mk[i] / win


@njit(cache=True, nogil=True, error_model="numpy")
def reference_channel(ref, c, win, cov_norm):
    """One channel ``c`` of a ground truth (h, w, 3) uint8: its (h, w) int32 plane, and as (h, w)
    float64 its local mean ux, ux ** 2 and local variance (as scikit-image's SSIM computes them)."""
    h, w = ref.shape[:2]
    x = channel_plane(ref, c)
    ux = np.empty((h, w), np.float64)
    ux2 = np.empty((h, w), np.float64)
    vx = np.empty((h, w), np.float64)
    sums = np.empty((3, w), np.int32)
    ext = np.zeros((3, w + win - 1), np.float64)   # its third row stays unused: no products
    means = np.empty((3, w), np.float64)
    m0, m1 = means[0], means[1]
    for row in range(h):
        _filtered_rows(x, x, win, sums, ext, means, row, False)
        uxr, ux2r, vxr = ux[row], ux2[row], vx[row]
        for i in range(w):
            u = m0[i]
            uxr[i] = u
            ux2r[i] = u * u
            vxr[i] = cov_norm * (m1[i] - u * u)
    return x, ux, ux2, vx


@njit(cache=True, nogil=True, error_model="numpy")
def ssim_map(test, c, x, ux, ux2, vx, win, cov_norm, c1, c2):
    """(h, w) float64: the SSIM map of channel ``c`` of test (h, w, 3) uint8 against a reference
    channel's int32 plane x, ux, ux ** 2 and variance vx, before cropping."""
    h, w = x.shape
    y = channel_plane(test, c)
    s = np.empty((h, w), np.float64)
    sums = np.empty((3, w), np.int32)
    ext = np.empty((3, w + win - 1), np.float64)
    means = np.empty((3, w), np.float64)
    m0, m1, m2 = means[0], means[1], means[2]
    for row in range(h):
        _filtered_rows(y, x, win, sums, ext, means, row)
        uxr, ux2r, vxr, sr = ux[row], ux2[row], vx[row], s[row]
        for i in range(w):
            a = uxr[i]
            b = m0[i]
            vy = cov_norm * (m1[i] - b * b)
            vxy = cov_norm * (m2[i] - a * b)
            a1 = 2 * a * b + c1
            a2 = 2 * vxy + c2
            b1 = ux2r[i] + b * b + c1
            b2 = vxr[i] + vy + c2
            sr[i] = (a1 * a2) / (b1 * b2)
    return s


@njit(cache=True, nogil=True, error_model="numpy")
def squared_error_sum(ref, test):
    """The exact sum of squared differences of two uint8 arrays of one shape, as a float64."""
    a = ref.ravel()
    b = test.ravel()
    total = 0
    for k in range(a.size):
        d = np.int64(a[k]) - np.int64(b[k])
        total += d * d
    return np.float64(total)


@njit(cache=True, nogil=True, error_model="numpy")
def count_near(pixels, centre, tolerance):
    """How many of pixels (n, 3) uint8 lie within ``tolerance`` of centre (3,) float64 in every
    channel (numpy's ``all(abs(pixels - centre) <= tolerance)`` counted)."""
    count = 0
    for k in range(pixels.shape[0]):
        near = True
        for c in range(3):
            if not abs(np.float64(pixels[k, c]) - centre[c]) <= tolerance:
                near = False
                break
        count += near
    return count


@njit(cache=True, nogil=True, error_model="numpy")
def mosaic_rows(out, top, shown, ref, scale, colours):
    """Into out (H', W', 3) uint8, the kept pixels (every ``scale``-th of every ``scale``-th row) of
    one mosaic row starting at mosaic row ``top``: shown | ref | the ``colours`` (766, 3) of their
    summed absolute channel differences (the error image), each (h, w, 3) uint8."""
    h, w = ref.shape[:2]
    width = out.shape[1]
    first = -(-top // scale)
    for oy in range(first, out.shape[0]):
        my = oy * scale - top
        if my >= h:
            break
        for tile in range(3):
            start = -(-(tile * w) // scale)            # the first kept column in this tile
            stop = min(width, -(-((tile + 1) * w) // scale))
            for ox in range(start, stop):
                x = ox * scale - tile * w
                if tile == 0:
                    for c in range(3):
                        out[oy, ox, c] = shown[my, x, c]
                elif tile == 1:
                    for c in range(3):
                        out[oy, ox, c] = ref[my, x, c]
                else:
                    total = 0
                    for c in range(3):
                        total += abs(np.int32(ref[my, x, c]) - np.int32(shown[my, x, c]))
                    for c in range(3):
                        out[oy, ox, c] = colours[total, c]
