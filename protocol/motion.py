"""Rigid motions of moving objects over time.

Both ends need them: the server animates the scene it renders, and the client places the
proxies of moving objects at its own display time, so the motion model travels with the
proxies and is evaluated by this one function on both sides.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .pose import quat_from_axis_angle, quat_to_matrix

MOTION_KINDS = ("spin", "orbit", "swing", "slide")
#: Largest magnitude of any motion value (metres, rad/s, rad): a motion evaluated at any
#: time a session reaches stays finite (a proxy bundle's motion comes from the wire).
MAX_MOTION_VALUE = 1e9


@dataclass
class RigidMotion:
    """Motion applied in the object's parent frame before its rest transform.

    kind:
      ``"spin"``   rotation about ``axis`` through ``pivot`` at ``speed`` rad/s;
      ``"orbit"``  translation on a circle of ``radius`` about ``axis`` at ``speed`` rad/s;
      ``"swing"``  rotation about ``axis`` through ``pivot`` by ``amplitude`` rad * sin(speed * t);
      ``"slide"``  translation along ``axis`` by ``amplitude`` metres * sin(speed * t).
    """

    kind: str
    axis: tuple = (0.0, 1.0, 0.0)
    speed: float = 1.0
    pivot: tuple = (0.0, 0.0, 0.0)
    radius: float = 0.0
    amplitude: float = 0.0
    phase: float = 0.0

    KINDS = MOTION_KINDS

    def __post_init__(self):
        if self.kind not in MOTION_KINDS:
            raise ValueError(f"unknown animation kind {self.kind!r}; choose from {', '.join(MOTION_KINDS)}")
        axis = np.asarray(self.axis, dtype=np.float64)
        if axis.shape != (3,) or not np.all(np.abs(axis) <= MAX_MOTION_VALUE) or np.linalg.norm(axis) < 1e-12:
            raise ValueError(f"animation axis must be a non-zero 3-vector of finite numbers within "
                             f"±{MAX_MOTION_VALUE:g}")
        self.axis = tuple(float(x) for x in axis / np.linalg.norm(axis))
        pivot = np.asarray(self.pivot, dtype=np.float64)
        if pivot.shape != (3,) or not np.all(np.abs(pivot) <= MAX_MOTION_VALUE):
            raise ValueError(f"animation pivot must be a 3-vector of finite numbers within ±{MAX_MOTION_VALUE:g}")
        self.pivot = tuple(float(x) for x in pivot)
        for name in ("speed", "radius", "amplitude", "phase"):
            if not abs(float(getattr(self, name))) <= MAX_MOTION_VALUE:   # NaN fails too
                raise ValueError(f"animation {name} must be a finite number within ±{MAX_MOTION_VALUE:g}")

    def matrix(self, t: float) -> np.ndarray:
        """(4, 4) motion at time t seconds."""
        m = np.eye(4)
        axis = np.array(self.axis)
        pivot = np.array(self.pivot, dtype=np.float64)
        if self.kind in ("spin", "swing"):
            angle = self.speed * t + self.phase if self.kind == "spin" else \
                self.amplitude * math.sin(self.speed * t + self.phase)
            r = quat_to_matrix(quat_from_axis_angle(axis, angle))
            m[:3, :3] = r
            m[:3, 3] = pivot - r @ pivot
        elif self.kind == "orbit":
            angle = self.speed * t + self.phase
            ref = np.cross(axis, [1.0, 0, 0] if abs(axis[0]) < 0.9 else [0, 0, 1.0])
            ref /= np.linalg.norm(ref)
            r = quat_to_matrix(quat_from_axis_angle(axis, angle))
            m[:3, 3] = self.radius * (r @ ref)
        else:  # slide
            m[:3, 3] = axis * self.amplitude * math.sin(self.speed * t + self.phase)
        return m

    def to_array(self) -> np.ndarray:
        """(11,) float64: kind index, axis (3), speed, pivot (3), radius, amplitude, phase."""
        return np.array([MOTION_KINDS.index(self.kind), *self.axis, self.speed, *self.pivot,
                         self.radius, self.amplitude, self.phase], dtype=np.float64)

    @classmethod
    def from_array(cls, a) -> "RigidMotion":
        a = np.asarray(a, dtype=np.float64)
        if a.shape != (11,) or not np.all(np.isfinite(a)):
            raise ValueError("a motion needs 11 finite numbers")
        k = int(a[0])
        if k != a[0] or not 0 <= k < len(MOTION_KINDS):
            raise ValueError(f"unknown motion kind index {a[0]}")
        return cls(MOTION_KINDS[k], tuple(a[1:4]), float(a[4]), tuple(a[5:8]), float(a[8]), float(a[9]),
                    float(a[10]))
