"""Depth on the wire: radial distance <-> quantized disparity (numpy and GLSL from one source).

Disparity is ``near / r`` in (0, 1] for geometry between the near and far spheres. A code of
``bits`` bits stores it linearly in ``[min_code, 2**bits - 1]``. Inside pibr a distance of 0
means *sky* (nothing hit: no surface can be closer than the near sphere) and a negative
distance (:data:`PEELED`) a pixel of the depth-peeled extra view whose every surface the
primary view already shows: not sky, just nothing new (Reinert et al.'s dual view).

Below ``min_code`` lies a guard band: codes under a quarter of ``min_code`` mean sky, codes
from a quarter to three quarters of it *peeled*, the rest the farthest geometry (with
``min_code`` 1 there is no peeled band: sky below half a code). In the H.264
atlas (8 bits, ``min_code`` 16) sky is 0, peeled 8 and geometry starts at 16, so coding noise
of a few levels never turns sky, peeled pixels and walls into one another. The edge codec
uses ``min_code = 2``: sky 0, peeled 1.
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
        ("code", "select(r < 0.0, floor(0.5 * min_code), code)"),
    ),
    outputs=("code",),
)

DEQUANTIZE = Formula(
    "depth_dequantize",
    inputs=("code", "near", "far", "min_code", "max_code"),
    steps=(
        ("d", "max((code - min_code) / (max_code - min_code), 0.5 / (max_code - min_code))"),
        ("r", "min(near / d, far)"),
        # min_code 1 leaves no room for peeled: sky below half a code, as it always was
        ("sky_below", "select(min_code < 1.5, 0.5 * min_code, 0.25 * min_code)"),
        ("peeled_below", "select(min_code < 1.5, 0.0, 0.75 * min_code)"),
        ("r", "select(code < peeled_below, -1.0, r)"),
        ("r", "select(code < sky_below, 0.0, r)"),
    ),
    outputs=("r",),
)

GLSL = (
    GLSL_PRELUDE
    + QUANTIZE.glsl("float", "code")
    + DEQUANTIZE.glsl("float", "r")
)


#: The distance of a peeled-away pixel of the extra view (0 is sky).
PEELED = -1.0


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
        """Distances (any shape; 0, inf, NaN or beyond far = sky, negative = peeled) -> codes, uint8 or
        uint16. With ``min_code`` 1 there is no room for peeled: it is coded as sky."""
        r = np.asarray(r, dtype=np.float64)
        r = np.where(np.isfinite(r), r, 0.0)
        code = QUANTIZE.numpy(r=r, near=self.near, far=self.far, min_code=self.min_code, max_code=self.max_code)
        return code.astype(np.uint8 if self.bits <= 8 else np.uint16)

    def dequantize(self, code) -> np.ndarray:
        """Codes -> distances (float32), 0 for sky, :data:`PEELED` for peeled."""
        r = DEQUANTIZE.numpy(code=np.asarray(code, dtype=np.float64), near=self.near, far=self.far,
                             min_code=self.min_code, max_code=self.max_code)
        return r.astype(np.float32)

    def step_at(self, r) -> np.ndarray:
        """Size in metres of one code step at distance r: the quantization's resolution there."""
        r = np.asarray(r, dtype=np.float64)
        return r * r / (self.near * (self.max_code - self.min_code))
