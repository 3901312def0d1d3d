"""Edge samples of a depth (and motion) frame, and rate control of the edge codec.

Pajak et al. 2011, Sec. 4.1: depth is sampled where its Laplacian is significant; diffusion on
the client recreates everything in between. Here:

* **Laplacian** of the quantized disparity codes (disparity is linear in image space on a plane,
  so planes cost nothing; near geometry weighs more than far), and of the non-linearly quantized
  motion components when objects move;
* **weighted significance** per pixel: ``w_depth * |L_depth| + w_motion * (|L_mx| + |L_my|)``,
  optionally multiplied by a perceptual importance from the low-resolution colour
  (:func:`perceptual_importance`);
* a **threshold** on it; edges are two pixels wide (both sides of a discontinuity get a sample
  with its own value) and every sky/surface boundary is sampled
  (:func:`pibr.protocol.edgecodec.codec.select_edges`); the sign of the Laplacian is kept per sample;
* one **regular sample** per 32 x 32 cell (added by the codec).

:class:`RateController` scales the threshold from frame to frame towards a bit budget.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pibr.protocol.depth import DepthQuantizer
from pibr.protocol.edgecodec.codec import DEFAULT_THRESHOLD, depth_edges, laplacian, select_edges
from pibr.protocol.edgecodec.motion import quantize_motion
from pibr.protocol.edgecodec.quantize import quantize_codes


@dataclass
class EdgeSamples:
    """edges (h, w) bool; signs (h, w) int8 (+1 / -1 at edges); significance (h, w) float32;
    codes (h, w) int32 quantized disparity; threshold used."""

    edges: np.ndarray
    signs: np.ndarray
    significance: np.ndarray
    codes: np.ndarray
    threshold: float

    @property
    def fraction(self) -> float:
        """Share of pixels that are edge samples."""
        return float(self.edges.mean())


def perceptual_importance(colour, shape: tuple[int, int], c50: float = 0.08, exponent: float = 2.0,
                          floor: float = 0.25) -> np.ndarray:
    """Weight (h, w) float32 in [floor, 1] of a depth edge's visibility from the low-resolution colour.

    A simple version of the paper's contrast transducer: depth errors show where the colour
    has contrast (a misplaced textured edge is visible, a misplaced edge in a flat region is
    not). Per low-resolution pixel: luminance Y (Rec. 709 weights), local RMS contrast
    C = (standard deviation of Y over 3x3) / (mean of Y over 3x3 + 0.05) (Weber-like; the
    offset keeps dark regions from dominating),
    response T = C^p / (C^p + c50^p) (Naka-Rushton: threshold near c50, saturating above),
    weight = floor + (1 - floor) * max(T over the 3x3 neighbourhood), nearest-upsampled to
    ``shape``. ``floor`` keeps depth edges in flat regions: their disocclusions still matter.

    colour : (hl, wl, 3) uint8 or float in [0, 1].
    """
    c = np.asarray(colour)
    if c.ndim != 3 or c.shape[2] < 3:
        raise ValueError(f"colour must have shape (h, w, 3), got {c.shape}")
    c = c[..., :3].astype(np.float64)
    if np.issubdtype(np.asarray(colour).dtype, np.integer):
        c /= 255.0
    y = 0.2126 * c[..., 0] + 0.7152 * c[..., 1] + 0.0722 * c[..., 2]
    p = np.pad(y, 1, mode="edge")
    windows = [p[dy:dy + y.shape[0], dx:dx + y.shape[1]] for dy in range(3) for dx in range(3)]
    mean = sum(windows) / 9.0
    var = np.maximum(sum(wi * wi for wi in windows) / 9.0 - mean * mean, 0.0)
    contrast = np.sqrt(var) / (mean + 0.05)
    t = contrast ** exponent / (contrast ** exponent + c50 ** exponent)
    tp = np.pad(t, 1, mode="edge")
    t = np.max([tp[dy:dy + y.shape[0], dx:dx + y.shape[1]] for dy in range(3) for dx in range(3)], axis=0)
    weight = floor + (1.0 - floor) * t
    h, w = shape
    rows = np.minimum((np.arange(h) * y.shape[0]) // h, y.shape[0] - 1)
    cols = np.minimum((np.arange(w) * y.shape[1]) // w, y.shape[1] - 1)
    return weight[np.ix_(rows, cols)].astype(np.float32)


def significance(codes, motion=None, depth_weight: float = 1.0, motion_weight: float = 1.0,
                 motion_scale: int = 8, importance=None) -> tuple[np.ndarray, np.ndarray]:
    """(significance (h, w) float32, depth Laplacian (h, w) int32) of codes (h, w).

    motion : (h, w, 2) float pixels or None, quantized as the codec does (sqrt, ``motion_scale``)
    before its Laplacian; importance : (h, w) weights from :func:`perceptual_importance` or None.
    """
    lap = laplacian(codes)
    sig = depth_weight * np.abs(lap).astype(np.float32)
    if motion is not None:
        m = quantize_motion(motion, motion_scale)
        sig += motion_weight * (np.abs(laplacian(m[..., 0])) + np.abs(laplacian(m[..., 1]))).astype(np.float32)
    if importance is not None:
        sig *= np.asarray(importance, dtype=np.float32)
    return sig, lap


def extract_edge_samples(distance, quantizer: DepthQuantizer, threshold: float = DEFAULT_THRESHOLD, motion=None,
                         colour=None, depth_weight: float = 1.0, motion_weight: float = 1.0,
                         motion_scale: int = 8) -> EdgeSamples:
    """Edge samples of one frame.

    distance : (h, w) float radial distance, 0 = sky; motion : (h, w, 2) or None;
    colour : low-resolution colour (hl, wl, 3) for :func:`perceptual_importance`, or None.
    Pass the result's ``edges``, ``signs`` and ``codes`` to ``EdgeEncoder.encode(..., edges=, signs=, codes=)``.
    """
    codes = quantize_codes(distance, quantizer)
    if motion is None and colour is None:  # depth alone: one compiled pass, same result
        edges, signs, sig = depth_edges(codes, threshold, depth_weight)
        return EdgeSamples(edges=edges, signs=signs, significance=sig, codes=codes, threshold=float(threshold))
    importance = None if colour is None else perceptual_importance(colour, codes.shape)
    sig, lap = significance(codes, motion, depth_weight, motion_weight, motion_scale, importance)
    edges, signs = select_edges(codes, threshold, sig, lap)
    return EdgeSamples(edges=edges, signs=signs, significance=sig, codes=codes, threshold=float(threshold))


class RateController:
    """Scales the significance threshold towards ``target_bits_per_frame``.

    After each frame, ``update(bits)`` sets threshold *= (bits / target) ^ gain, the factor
    limited to [1 / max_step, max_step]. Frame size falls with the threshold roughly as a power
    law, so in the log domain this is a proportional controller: the error shrinks by a
    constant factor per frame (exponential convergence) as long as gain * exponent < 2.
    """

    def __init__(self, target_bits_per_frame: float, threshold: float = DEFAULT_THRESHOLD, gain: float = 0.7,
                 min_threshold: float = 0.5, max_threshold: float = 65535.0, max_step: float = 2.0):
        if not (target_bits_per_frame > 0 and math.isfinite(target_bits_per_frame)):
            raise ValueError(f"target bits per frame must be positive, got {target_bits_per_frame}")
        if not (0 < min_threshold <= threshold <= max_threshold):
            raise ValueError(f"need 0 < min_threshold <= threshold <= max_threshold, got "
                             f"{min_threshold}, {threshold}, {max_threshold}")
        if not (0 < gain <= 2 and max_step > 1):
            raise ValueError(f"need 0 < gain <= 2 and max_step > 1, got {gain}, {max_step}")
        self.target = float(target_bits_per_frame)
        self.threshold = float(threshold)
        self.gain, self.min_threshold, self.max_threshold = gain, min_threshold, max_threshold
        self.max_step = max_step

    def update(self, bits: float) -> float:
        """Account for a frame of ``bits`` coded at the current threshold; returns the next threshold."""
        ratio = max(float(bits), 1.0) / self.target
        step = min(max(ratio ** self.gain, 1.0 / self.max_step), self.max_step)
        self.threshold = min(max(self.threshold * step, self.min_threshold), self.max_threshold)
        return self.threshold
