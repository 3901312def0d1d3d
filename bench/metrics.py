"""Image-quality metrics against ground truth.

PSNR (dB, capped at PSNR_CAP so identical images give a finite, comparable number),
SSIM and DSSIM = (1 - SSIM) / 2 (scikit-image's, on all three channels), FLIP (NVIDIA
flip-evaluator's LDR-FLIP with the display's pixels per degree) and the fraction of pixels no
transmitted view covered (reported by the client).
"""
from __future__ import annotations

import functools
import math

import numpy as np

PSNR_CAP = 100.0


def _check_pair(ref: np.ndarray, test: np.ndarray) -> None:
    if ref.shape != test.shape or ref.ndim != 3 or ref.shape[2] != 3:
        raise ValueError(f"need two (H, W, 3) images of one shape, got {ref.shape} and {test.shape}")


def psnr(ref: np.ndarray, test: np.ndarray) -> float:
    """PSNR in dB of uint8 (H, W, 3) images; PSNR_CAP when they are identical."""
    from .metric_kernels import squared_error_sum

    _check_pair(ref, test)
    if ref.dtype == np.uint8 and test.dtype == np.uint8:
        # np.mean((ref - test) ** 2) in float64, to the bit: a sum of integer squares is exact
        mse = squared_error_sum(np.ascontiguousarray(ref), np.ascontiguousarray(test)) / ref.size
    else:
        mse = np.mean((ref.astype(np.float64) - test.astype(np.float64)) ** 2)
    if mse <= 0:
        return PSNR_CAP
    return min(PSNR_CAP, 10.0 * math.log10(255.0 ** 2 / mse))


def ssim(ref: np.ndarray, test: np.ndarray) -> float:
    """scikit-image's SSIM of (H, W, 3) images (uint8 ones of at least 7x7 by the compiled
    :class:`SsimReference`, the same bits)."""
    _check_pair(ref, test)
    if ref.dtype == np.uint8 and test.dtype == np.uint8 and min(ref.shape[:2]) >= SSIM_WIN:
        return SsimReference(ref).ssim(test)
    from skimage.metrics import structural_similarity

    return float(structural_similarity(ref, test, channel_axis=2, data_range=255))


#: SSIM's window (scikit-image's default for uniform weights) and its constants at data range 255.
SSIM_WIN = 7
_SSIM_COV_NORM = SSIM_WIN ** 2 / (SSIM_WIN ** 2 - 1)
_SSIM_C1 = (0.01 * 255) ** 2
_SSIM_C2 = (0.03 * 255) ** 2


class SsimReference:
    """One ground-truth (H, W, 3) uint8 image's share of SSIM, computed once for every image
    compared with it: per channel the local mean, its square and the local variance.

    The arithmetic is scikit-image's ``structural_similarity(ref, test, channel_axis=2,
    data_range=255)`` (uniform 7x7 window, sample covariance, the border of 3 pixels cropped,
    the channels' mean) operation for operation, so it gives the same bits
    (tests/bench/test_metrics.py); a tick's methods share the reference's filters instead of each
    recomputing them."""

    def __init__(self, ref: np.ndarray):
        from .metric_kernels import reference_channel

        if ref.ndim != 3 or ref.shape[2] != 3 or min(ref.shape[:2]) < SSIM_WIN or ref.dtype != np.uint8:
            raise ValueError(f"need an (H, W, 3) uint8 image of at least {SSIM_WIN}x{SSIM_WIN}, got {ref.shape} "
                             f"{ref.dtype}")
        self.ref = ref
        ref = np.ascontiguousarray(ref)
        self._channels = [reference_channel(ref, c, SSIM_WIN, _SSIM_COV_NORM) for c in range(3)]

    def ssim(self, test: np.ndarray) -> float:
        from .metric_kernels import ssim_map

        _check_pair(self.ref, test)
        if test.dtype != np.uint8:
            raise ValueError(f"need a uint8 image, got {test.dtype}")
        test = np.ascontiguousarray(test)
        pad = (SSIM_WIN - 1) // 2
        values = np.empty(3, np.float64)
        for c, (x, ux, ux2, vx) in enumerate(self._channels):
            s = ssim_map(test, c, x, ux, ux2, vx, SSIM_WIN, _SSIM_COV_NORM, _SSIM_C1, _SSIM_C2)
            values[c] = s[pad:s.shape[0] - pad, pad:s.shape[1] - pad].mean(dtype=np.float64)
        return float(values.mean())


def tick_metrics(ref: np.ndarray, images: list, ppd: float, with_flip: bool = True) -> list[dict]:
    """:func:`frame_metrics` of each of ``images`` against one ``ref`` (the same numbers), the
    reference's shares of SSIM and FLIP computed once."""
    from .flip_metric import FlipReference

    reference = SsimReference(ref)
    flip_reference = FlipReference(ref, ppd) if with_flip and images else None
    out = []
    for test in images:
        s = reference.ssim(test)
        out.append({"psnr": psnr(ref, test), "ssim": s, "dssim": dssim(s),
                    "flip": flip_reference.mean(test) if flip_reference is not None else float("nan")})
    return out


def dssim(ssim_value: float) -> float:
    return (1.0 - ssim_value) / 2.0


def flip(ref: np.ndarray, test: np.ndarray, pixels_per_degree: float = 67.0) -> float:
    """Mean LDR-FLIP error in [0, 1] (lower is better) of (H, W, 3) uint8 sRGB images: NVIDIA
    flip-evaluator's number, computed by bench/flip_metric.py (its maps too: FlipReference)."""
    from .flip_metric import FlipReference

    _check_pair(ref, test)
    return FlipReference(ref, pixels_per_degree).mean(test)


def pixels_per_degree(width: int, fov_deg: float) -> float:
    """Display resolution at the centre of a perspective view, pixels per degree."""
    return width / 2.0 / math.tan(math.radians(fov_deg) / 2.0) * math.pi / 180.0


def frame_metrics(ref: np.ndarray, test: np.ndarray, ppd: float, with_flip: bool = True) -> dict:
    """All per-frame metrics of one displayed image (FLIP is NaN when skipped)."""
    return tick_metrics(ref, [test], ppd, with_flip)[0]


@functools.lru_cache(maxsize=4)
def _error_colours(gain: float) -> np.ndarray:
    """(766, 3) uint8: the magma colour of each sum of the three channels' absolute differences
    (0..765), as (sum / 3 / 255 * gain * 255) clipped to 0..255 picks it."""
    from matplotlib import colormaps

    lut = (colormaps["magma"](np.linspace(0, 1, 256))[:, :3] * 255).astype(np.uint8)
    mean = np.arange(766, dtype=np.float64) / 3.0 / 255.0
    return lut[np.clip(mean * gain * 255, 0, 255).astype(np.uint8)]


def error_image(ref: np.ndarray, test: np.ndarray, gain: float = 4.0) -> np.ndarray:
    """(H, W, 3) uint8 heat map of the per-pixel colour difference (magma), for videos."""
    total = np.abs(ref.astype(np.int16) - test.astype(np.int16)).sum(axis=2, dtype=np.int16)
    return _error_colours(float(gain))[total]


def nearly_uniform(image: np.ndarray, fraction: float = 0.95, tolerance: int = 2) -> bool:
    """True when more than ``fraction`` of an (H, W, 3) uint8 image is one colour (within
    ``tolerance`` levels per channel): all sky, or a wall filling the view. Every method scores
    near-perfectly on such a frame, so a score over many of them says little."""
    flat = image.reshape(-1, 3)
    mode = np.median(flat[:: max(1, len(flat) // 4096)].astype(np.int16), axis=0)
    if flat.dtype == np.uint8:
        from .metric_kernels import count_near

        return bool(count_near(flat, mode, float(tolerance)) / len(flat) > fraction)
    same = np.all(np.abs(flat.astype(np.int16) - mode) <= tolerance, axis=1)
    return bool(same.mean() > fraction)


#: Pixels of a mask needed for :func:`masked_metrics` to score them.
MIN_PIXELS = 30


def masked_metrics(gt: np.ndarray, rgb: np.ndarray, masks: dict, min_pixels: int = MIN_PIXELS) -> dict:
    """Whole-frame PSNR / DSSIM of (H, W, 3) uint8 images and, per mask (H, W) bool, the PSNR and
    DSSIM of its pixels (the SSIM map averaged there); NaN where a mask has fewer than ``min_pixels``."""
    from skimage.metrics import structural_similarity

    _check_pair(gt, rgb)
    mean, smap = structural_similarity(gt, rgb, channel_axis=2, data_range=255, full=True)
    out = {"psnr": psnr(gt, rgb), "dssim": dssim(float(mean))}
    err = (gt.astype(np.float64) - rgb.astype(np.float64)) ** 2
    for name, mask in masks.items():
        if mask.sum() < max(1, min_pixels):
            out[f"psnr_{name}"] = out[f"dssim_{name}"] = float("nan")
            continue
        mse = float(err[mask].mean())
        out[f"psnr_{name}"] = PSNR_CAP if mse <= 0 else min(PSNR_CAP, 10 * math.log10(255.0 ** 2 / mse))
        out[f"dssim_{name}"] = dssim(float(smap[mask].mean()))
    return out
