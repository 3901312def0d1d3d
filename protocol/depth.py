"""Depth on the wire: radial distance <-> quantized disparity (numpy and GLSL from one source).

Disparity is ``near / r`` in (0, 1] for geometry between the near and far spheres. A code of
``bits`` bits stores it linearly in ``[min_code, 2**bits - 1]``; codes below ``min_code / 2``
mean *sky* (nothing hit). Inside pibr a distance of 0 means sky, because no surface can be
closer than the near sphere.

``min_code`` leaves a guard band between sky and the farthest geometry for lossy transports:
in the H.264 atlas (8 bits) sky is 0 and geometry starts at 16, so coding noise of a few
levels never turns sky into a wall or a wall into sky. The lossless edge codec uses
``min_code = 1``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .formula import GLSL_PRELUDE, Formula

QUANTIZE = Formula(
    "depth_quantize",
    inputs=("r", "near", "far", "min_code", "max_code"),
    steps=(
        ("d", "near / max(r, near)"),
        ("code", "min_code + floor(d * (max_code - min_code) + 0.5)"),
        ("code", "select(r > far, 0.0, select(r <= 0.0, 0.0, code))"),
    ),
    outputs=("code",),
)

DEQUANTIZE = Formula(
    "depth_dequantize",
    inputs=("code", "near", "far", "min_code", "max_code"),
    steps=(
        ("d", "max((code - min_code) / (max_code - min_code), 0.5 / (max_code - min_code))"),
        ("r", "min(near / d, far)"),
        ("r", "select(code < 0.5 * min_code, 0.0, r)"),
    ),
    outputs=("r",),
)

GLSL = (
    GLSL_PRELUDE
    + QUANTIZE.glsl("float", "code")
    + DEQUANTIZE.glsl("float", "r")
)


@dataclass(frozen=True)
class DepthQuantizer:
    """Quantization of radial distance for one transport. ``bits`` in 1..16."""

    near: float
    far: float
    bits: int = 8
    min_code: int = 16

    def __post_init__(self):
        if not (0 < self.near < self.far < float("inf")):
            raise ValueError(f"need 0 < near < far < inf, got near={self.near}, far={self.far}")
        if not (1 <= self.bits <= 16):
            raise ValueError(f"bits must be in 1..16, got {self.bits}")
        if not (1 <= self.min_code < self.max_code):
            raise ValueError(f"min_code must be in 1..{self.max_code - 1}, got {self.min_code}")

    @property
    def max_code(self) -> int:
        return (1 << self.bits) - 1

    def quantize(self, r) -> np.ndarray:
        """Distances (any shape; 0, inf, NaN or beyond far = sky) -> codes, uint8 or uint16."""
        r = np.asarray(r, dtype=np.float64)
        r = np.where(np.isfinite(r), r, 0.0)
        code = QUANTIZE.numpy(r=r, near=self.near, far=self.far, min_code=self.min_code, max_code=self.max_code)
        return code.astype(np.uint8 if self.bits <= 8 else np.uint16)

    def dequantize(self, code) -> np.ndarray:
        """Codes -> distances (float32), 0 for sky."""
        r = DEQUANTIZE.numpy(code=np.asarray(code, dtype=np.float64), near=self.near, far=self.far,
                             min_code=self.min_code, max_code=self.max_code)
        return r.astype(np.float32)

    def step_at(self, r) -> np.ndarray:
        """Size in metres of one code step at distance r: the quantization's resolution there."""
        r = np.asarray(r, dtype=np.float64)
        return r * r / (self.near * (self.max_code - self.min_code))


def h264_quantizer(near: float, far: float) -> DepthQuantizer:
    """The 8-bit disparity carried in the luma of the H.264 atlas."""
    return DepthQuantizer(near, far, bits=8, min_code=16)
