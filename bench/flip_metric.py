"""LDR-FLIP (Andersson et al. 2020) compiled, with one ground truth's half shared by every image
compared with it, giving NVIDIA flip-evaluator's numbers to the bit.

Scoring compares every method's image with the same ground truth, and flip-evaluator redoes the
ground truth's colour conversion, spatial filtering and edge/point detection for each of them.
:class:`FlipReference` does the ground truth's share once per tick and then, per image, only the
image's own share and the comparison.

Bit-exactness: flip-evaluator computes in float32 (C++, SSE, no fused multiply-add); every
operation here is the same float32 operation in the same order, the transcendental functions are
the C library's ``powf``/``expf`` (what numba's ``math.pow``/``math.exp`` on float32 call), the
sRGB decoding of 8-bit values is a 256-entry table of the same formula, and the mean is the same
serial float32 sum. tests/bench/test_flip_metric.py compares maps and means with flip-evaluator.
The steps follow FLIP.h (flip-evaluator 1.x): sRGB -> linear -> YCxCz; separable spatial
(contrast sensitivity) filters, back to linear RGB clamped, CIELab with the Hunt adjustment,
HyAB distance, compressed and re-mapped; separable edge and point detectors on the achromatic
channel; error = colour ** (1 - feature).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

F = np.float32

# FLIP's constants (FLIP.h: FLIPConstants, GaussianConstants, illuminants), as float32.
GQC, GPC, GPT, GW, GQF = F(0.7), F(0.4), F(0.95), F(0.082), F(0.5)
PI = F(3.14159265358979)
ILLUMINANT = (F(0.950428545), F(1.0), F(1.088900371))
INV_ILLUMINANT = (F(1.052156925), F(1.0), F(0.918357670))
_A1 = (F(1.0), F(1.0), F(34.1))
_B1 = (F(0.0047), F(0.0053), F(0.04))
_A2 = (F(0.0), F(0.0), F(13.5))
_B2 = (F(1.0e-5), F(1.0e-5), F(0.025))

# linear RGB -> XYZ (D65), each coefficient a float32 quotient as the C++ constant folds it
_RGB2XYZ = np.array([[F(10135552.0) / F(24577794.0), F(8788810.0) / F(24577794.0), F(4435075.0) / F(24577794.0)],
                     [F(2613072.0) / F(12288897.0), F(8788810.0) / F(12288897.0), F(887015.0) / F(12288897.0)],
                     [F(1425312.0) / F(73733382.0), F(8788810.0) / F(73733382.0), F(70074185.0) / F(73733382.0)]],
                    np.float32)
_XYZ2RGB = np.array([[3.241003275, -1.537398934, -0.498615861],
                     [-0.969224334, 1.875930071, 0.041554224],
                     [0.055639423, -0.204011202, 1.057148933]], np.float32)
_DELTA = F(6.0) / F(29.0)
_DELTA_CUBE = _DELTA * (_DELTA * _DELTA)
_LAB_FACTOR = F(1.0) / (F(3.0) * (_DELTA * _DELTA))
_LAB_TERM = F(4.0) / F(29.0)
_ONE_THIRD = F(1.0) / F(3.0)


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _clamp01(v):
    """FLIP's Min(Max(v, 0), 1) macros, signed zeros and all."""
    v = v if v > np.float32(0.0) else np.float32(0.0)
    return np.float32(1.0) if v > np.float32(1.0) else v


@njit(cache=True, nogil=True, error_model="numpy")
def _srgb_to_linear(s, gamma):
    if s <= np.float32(0.04045):
        return s / np.float32(12.92)
    return math.pow((s + np.float32(0.055)) / np.float32(1.055), gamma)


@njit(cache=True, nogil=True, error_model="numpy")
def srgb_table(gamma):
    """(256,) float32: the clamped linear value of each 8-bit sRGB level, as FLIP decodes v / 255
    (``gamma``: 2.4)."""
    out = np.empty(256, np.float32)
    for v in range(256):
        lin = _srgb_to_linear(np.float32(v) / np.float32(255.0), gamma)
        out[v] = _clamp01(lin)
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _lab(v, inv, third):
    v = v * inv
    if v > _DELTA_CUBE:
        return math.pow(v, third)
    return _LAB_FACTOR * v + _LAB_TERM


@njit(cache=True, nogil=True, error_model="numpy")
def to_ycxcz(img, table, m):
    """(h, w, 3) uint8 sRGB -> (3, h, w) float32 YCxCz planes (FLIP's linear RGB -> XYZ -> YCxCz)."""
    h, w = img.shape[:2]
    out = np.empty((3, h, w), np.float32)
    for j in range(h):
        for i in range(w):
            r = table[img[j, i, 0]]
            g = table[img[j, i, 1]]
            b = table[img[j, i, 2]]
            x = (m[0, 0] * r + m[0, 1] * g + m[0, 2] * b) * INV_ILLUMINANT[0]
            y = (m[1, 0] * r + m[1, 1] * g + m[1, 2] * b) * INV_ILLUMINANT[1]
            z = (m[2, 0] * r + m[2, 1] * g + m[2, 2] * b) * INV_ILLUMINANT[2]
            out[0, j, i] = np.float32(116.0) * y - np.float32(16.0)
            out[1, j, i] = np.float32(500.0) * (x - y)
            out[2, j, i] = np.float32(200.0) * (y - z)
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _filter_row(src, weights, out):
    """Into out (w,) float32: one row src (w,) float32 filtered with weights (2r+1,) float32,
    borders clamped, each pixel's products summed from 0 in tap order (as FLIP does).

    Tap by tap over the row rather than pixel by pixel over the taps: each pixel's sum takes the
    same operations in the same order, and the loop over pixels vectorises."""
    w = src.shape[0]
    r = weights.shape[0] // 2
    out[:] = np.float32(0.0)
    for t in range(2 * r + 1):
        k = t - r
        wk = weights[t]
        lo = min(max(0, -k), w)        # pixels whose tap i + k is inside the row
        hi = max(min(w, w - k), lo)
        for i in range(lo):
            out[i] += wk * src[min(max(0, i + k), w - 1)]
        inner = out[lo:hi]          # views, so that the indices are the loop's own (numba tests
        taps = src[lo + k:hi + k]   # a computed index for wrapping around, which stops vectorising)
        for i in range(hi - lo):
            inner[i] += wk * taps[i]
        for i in range(hi, w):
            out[i] += wk * src[min(max(0, i + k), w - 1)]


@njit(cache=True, nogil=True, error_model="numpy")
def _filter_column(planes, c, j, weights, out):
    """Into out (w,) float32: row j of planes[c] ((n, h, w) float32) filtered vertically with
    weights (2r+1,) float32, borders clamped, summed from 0 in tap order."""
    h = planes.shape[1]
    r = weights.shape[0] // 2
    out[:] = np.float32(0.0)
    for t in range(2 * r + 1):
        row = planes[c, min(max(0, j + t - r), h - 1)]
        wk = weights[t]
        for i in range(out.shape[0]):
            out[i] += wk * row[i]


@njit(cache=True, nogil=True, error_model="numpy")
def filtered_lab(ycc, ycx_w, cz_w, to_xyz, to_rgb, third):
    """(3, h, w) float32 YCxCz -> (3, h, w) float32 Hunt-adjusted CIELab of its spatially filtered
    image (FLIP's separable filters: x first, clamped borders; then back to clamped linear RGB;
    ``third``: 1/3 in float32)."""
    _, h, w = ycc.shape
    ycx_0, ycx_1 = np.ascontiguousarray(ycx_w[:, 0]), np.ascontiguousarray(ycx_w[:, 1])
    cz_0, cz_1 = np.ascontiguousarray(cz_w[:, 0]), np.ascontiguousarray(cz_w[:, 1])
    mid = np.empty((4, h, w), np.float32)   # x-filtered: Y, Cx (YCx filter), Cz (two Cz filters)
    for j in range(h):
        _filter_row(ycc[0, j], ycx_0, mid[0, j])
        _filter_row(ycc[1, j], ycx_1, mid[1, j])
        _filter_row(ycc[2, j], cz_0, mid[2, j])
        _filter_row(ycc[2, j], cz_1, mid[3, j])
    out = np.empty((3, h, w), np.float32)
    a0, a1, c0, c1 = np.empty(w, np.float32), np.empty(w, np.float32), np.empty(w, np.float32), np.empty(w, np.float32)
    for j in range(h):
        _filter_column(mid, 0, j, ycx_0, a0)
        _filter_column(mid, 1, j, ycx_1, a1)
        _filter_column(mid, 2, j, cz_0, c0)
        _filter_column(mid, 3, j, cz_1, c1)
        for i in range(w):   # YCxCz -> XYZ -> linear RGB, clamped to [0, 1]
            yy = (a0[i] + np.float32(16.0)) / np.float32(116.0)
            cx = a1[i] / np.float32(500.0)
            cz = (c0[i] + c1[i]) / np.float32(200.0)
            x = (yy + cx) * ILLUMINANT[0]
            y = yy * ILLUMINANT[1]
            z = (yy - cz) * ILLUMINANT[2]
            cr = _clamp01(to_rgb[0, 0] * x + to_rgb[0, 1] * y + to_rgb[0, 2] * z)
            cg = _clamp01(to_rgb[1, 0] * x + to_rgb[1, 1] * y + to_rgb[1, 2] * z)
            cb = _clamp01(to_rgb[2, 0] * x + to_rgb[2, 1] * y + to_rgb[2, 2] * z)
            # linear RGB -> XYZ -> CIELab, then the Hunt adjustment of a and b
            out[0, j, i], out[1, j, i], out[2, j, i] = _hunt_lab_of_linear(cr, cg, cb, to_xyz, third)
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def features(ycc, fw):
    """(2, h, w) float32: per pixel the edge and point detectors' magnitudes on the achromatic
    channel of YCxCz (3, h, w) float32, normalised to [0, 1] (FLIP's separable feature filters)."""
    _, h, w = ycc.shape
    one_over = np.float32(1.0) / np.float32(116.0)
    sixteen_over = np.float32(16.0) / np.float32(116.0)
    g_w, d_w, dd_w = np.ascontiguousarray(fw[:, 0]), np.ascontiguousarray(fw[:, 1]), np.ascontiguousarray(fw[:, 2])
    v = np.empty(w, np.float32)   # a row of the achromatic channel, as FLIP normalises it
    mid = np.empty((3, h, w), np.float32)
    for j in range(h):
        src = ycc[0, j]
        for i in range(w):
            v[i] = src[i] * one_over + sixteen_over
        _filter_row(v, d_w, mid[0, j])
        _filter_row(v, dd_w, mid[1, j])
        _filter_row(v, g_w, mid[2, j])
    out = np.empty((2, h, w), np.float32)
    dx, ddx, dy, ddy = np.empty(w, np.float32), np.empty(w, np.float32), np.empty(w, np.float32), np.empty(w, np.float32)
    for j in range(h):
        _filter_column(mid, 0, j, g_w, dx)
        _filter_column(mid, 1, j, g_w, ddx)
        _filter_column(mid, 2, j, d_w, dy)
        _filter_column(mid, 2, j, dd_w, ddy)
        edge, point = out[0, j], out[1, j]
        for i in range(w):
            edge[i] = math.sqrt(dx[i] * dx[i] + dy[i] * dy[i])
            point[i] = math.sqrt(ddx[i] * ddx[i] + ddy[i] * ddy[i])
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def error_map(ref_lab, ref_feat, test_lab, test_feat, cmax, pccmax, norm, qc, qf):
    """(h, w) float32 FLIP error of a test against its reference (Lab (3, h, w) and features
    (2, h, w) float32 each), and its mean (FLIP's serial float32 sum over rows, divided by the pixel
    count). The exponents ``qc`` and ``qf`` come as arguments: a constant 0.5 lets the compiler
    turn ``pow`` into ``sqrt``, which rounds otherwise."""
    _, h, w = ref_lab.shape
    out = np.empty((h, w), np.float32)
    below = GPT / pccmax
    for j in range(h):
        for i in range(w):
            dl = abs(ref_lab[0, j, i] - test_lab[0, j, i])
            da = ref_lab[1, j, i] - test_lab[1, j, i]
            db = ref_lab[2, j, i] - test_lab[2, j, i]
            colour = math.pow(dl + math.sqrt(da * da + db * db), qc)
            if colour < pccmax:
                colour *= below
            else:
                colour = GPT + ((colour - pccmax) / (cmax - pccmax)) * (np.float32(1.0) - GPT)
            edge = abs(ref_feat[0, j, i] - test_feat[0, j, i])
            point = abs(ref_feat[1, j, i] - test_feat[1, j, i])
            feature = math.pow(norm * (edge if edge > point else point), qf)
            out[j, i] = math.pow(colour, np.float32(1.0) - feature)
    total = np.float32(0.0)
    for j in range(h):
        for i in range(w):
            total += out[j, i]
    return out, total / np.float32(h * w)


@njit(cache=True, nogil=True, error_model="numpy")
def _gaussian(x2, a, b):
    return a * math.sqrt(PI / b) * math.exp(-(PI * PI) * x2 / b)


@njit(cache=True, nogil=True, error_model="numpy")
def _gaussian_sqrt(x2, a, b):
    return math.sqrt(a * math.sqrt(PI / b)) * math.exp(-(PI * PI) * x2 / b)


@njit(cache=True, nogil=True, error_model="numpy")
def spatial_filters(ppd):
    """((2r+1, 2) YCx weights (Y, Cx), (2r+1, 2) Cz weights (its two Gaussians)), normalised as FLIP does."""
    max_b = np.float32(0.04)   # the largest of the b constants
    r = int(math.ceil(np.float32(3.0) * math.sqrt(max_b / (np.float32(2.0) * (PI * PI))) * ppd))
    n = 2 * r + 1
    ycx = np.empty((n, 2), np.float32)
    cz = np.empty((n, 2), np.float32)
    dx = np.float32(1.0) / ppd
    s0 = np.float32(0.0)
    s1 = np.float32(0.0)
    t0 = np.float32(0.0)
    t1 = np.float32(0.0)
    for k in range(n):
        x = np.float32(k - r) * dx
        x2 = x * x
        ycx[k, 0] = _gaussian(x2, _A1[0], _B1[0])
        ycx[k, 1] = _gaussian(x2, _A1[1], _B1[1])
        cz[k, 0] = _gaussian_sqrt(x2, _A1[2], _B1[2])
        cz[k, 1] = _gaussian_sqrt(x2, _A2[2], _B2[2])
        s0 += ycx[k, 0]
        s1 += ycx[k, 1]
        t0 += cz[k, 0]
        t1 += cz[k, 1]
    n0 = np.float32(1.0) / s0
    n1 = np.float32(1.0) / s1
    nz = np.float32(1.0) / math.sqrt(t0 * t0 + t1 * t1)
    for k in range(n):
        ycx[k, 0] = ycx[k, 0] * n0
        ycx[k, 1] = ycx[k, 1] * n1
        cz[k, 0] = cz[k, 0] * nz
        cz[k, 1] = cz[k, 1] * nz
    return ycx, cz


@njit(cache=True, nogil=True, error_model="numpy")
def feature_filter(ppd):
    """(2r+1, 3) float32: Gaussian, its first and second derivatives, normalised as FLIP does."""
    sd = np.float32(0.5) * GW * ppd
    r = int(math.ceil(np.float32(3.0) * sd))
    n = 2 * r + 1
    out = np.empty((n, 3), np.float32)
    g_sum = np.float32(0.0)
    dg_neg = np.float32(0.0)
    dg_pos = np.float32(0.0)
    ddg_neg = np.float32(0.0)
    ddg_pos = np.float32(0.0)
    for k in range(n):
        x = np.float32(k - r)
        g = math.exp(-(x * x) / (np.float32(2.0) * sd * sd))
        g_sum += g
        dg = -x * g
        if dg > np.float32(0.0):
            dg_pos += dg
        else:
            dg_neg -= dg
        ddg = (x * x / (sd * sd) - np.float32(1.0)) * g
        if ddg > np.float32(0.0):
            ddg_pos += ddg
        else:
            ddg_neg -= ddg
        out[k, 0] = g
        out[k, 1] = dg
        out[k, 2] = ddg
    for k in range(n):
        out[k, 0] = out[k, 0] / g_sum
        out[k, 1] = out[k, 1] / (dg_pos if out[k, 1] > np.float32(0.0) else dg_neg)
        out[k, 2] = out[k, 2] / (ddg_pos if out[k, 2] > np.float32(0.0) else ddg_neg)
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _hunt_lab_of_linear(r, g, b, to_xyz, third):
    """Linear RGB -> XYZ -> CIELab, a and b Hunt-adjusted (FLIP's order of operations)."""
    fx = _lab(to_xyz[0, 0] * r + to_xyz[0, 1] * g + to_xyz[0, 2] * b, INV_ILLUMINANT[0], third)
    fy = _lab(to_xyz[1, 0] * r + to_xyz[1, 1] * g + to_xyz[1, 2] * b, INV_ILLUMINANT[1], third)
    fz = _lab(to_xyz[2, 0] * r + to_xyz[2, 1] * g + to_xyz[2, 2] * b, INV_ILLUMINANT[2], third)
    lum = np.float32(116.0) * fy - np.float32(16.0)
    return lum, np.float32(0.01) * lum * (np.float32(500.0) * (fx - fy)), \
        np.float32(0.01) * lum * (np.float32(200.0) * (fy - fz))


@njit(cache=True, nogil=True, error_model="numpy")
def max_distance(to_xyz, third, qc):
    """FLIP's cmax: the compressed HyAB distance of Hunt-adjusted green and blue."""
    gl, ga, gb = _hunt_lab_of_linear(np.float32(0.0), np.float32(1.0), np.float32(0.0), to_xyz, third)
    bl, ba, bb = _hunt_lab_of_linear(np.float32(0.0), np.float32(0.0), np.float32(1.0), to_xyz, third)
    return math.pow(abs(gl - bl) + math.sqrt((ga - ba) * (ga - ba) + (gb - bb) * (gb - bb)), qc)


class FlipReference:
    """One ground truth (H, W, 3) uint8 sRGB image prepared for LDR-FLIP at ``ppd`` pixels per
    degree: :meth:`mean` / :meth:`map_and_mean` of any test image against it equal
    ``flip_evaluator.evaluate(ref / 255, test / 255, "LDR", inputsRGB=True, parameters={"ppd": ppd})``."""

    def __init__(self, ref: np.ndarray, ppd: float):
        if ref.ndim != 3 or ref.shape[2] != 3 or ref.dtype != np.uint8:
            raise ValueError(f"need an (H, W, 3) uint8 image, got {ref.shape} {ref.dtype}")
        self.shape = ref.shape
        ppd = F(ppd)
        self._table = srgb_table(F(2.4))
        self._ycx, self._cz = spatial_filters(ppd)
        self._features = feature_filter(ppd)
        self._cmax = F(max_distance(_RGB2XYZ, _ONE_THIRD, GQC))   # a float32 computed, boxed as a Python float
        self._pccmax = GPC * self._cmax
        self._norm = F(1.0) / F(math.sqrt(2.0))   # 1 / sqrt(2) in float32 (sqrt is correctly rounded)
        self._ref_lab, self._ref_feat = self._prepare(ref)

    def _prepare(self, img: np.ndarray):
        ycc = to_ycxcz(np.ascontiguousarray(img), self._table, _RGB2XYZ)
        return filtered_lab(ycc, self._ycx, self._cz, _RGB2XYZ, _XYZ2RGB, _ONE_THIRD), features(ycc, self._features)

    def map_and_mean(self, test: np.ndarray):
        """((H, W) float32 per-pixel FLIP error, mean FLIP error in [0, 1]) of ``test`` (H, W, 3)
        uint8 against the reference."""
        if test.shape != self.shape or test.dtype != np.uint8:
            raise ValueError(f"need a {self.shape} uint8 image, got {test.shape} {test.dtype}")
        lab, feat = self._prepare(test)
        error, mean = error_map(self._ref_lab, self._ref_feat, lab, feat, self._cmax, self._pccmax, self._norm,
                                GQC, GQF)
        return error, float(mean)

    def mean(self, test: np.ndarray) -> float:
        """Mean FLIP error in [0, 1] of ``test`` (H, W, 3) uint8 against the reference."""
        return self.map_and_mean(test)[1]
