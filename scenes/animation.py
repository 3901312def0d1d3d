"""The analytic animation of a scene's moving objects: a rigid motion as a function of time.

It is the scene's script, known to the server (which renders the scene at each frame's time
and sends the moving objects' transforms with every frame) and to the benchmarks' ground
truth and their ``oracle`` extrapolation. It never travels to the client: a real
remote-rendering client does not know where a game's objects will be next (DESIGN.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pibr.protocol.errors import SceneError
from pibr.protocol.pose import quat_from_axis_angle, quat_to_matrix

ANIMATION_KINDS = ("spin", "orbit", "swing", "slide", "travel")
#: Largest magnitude of any animation value (metres, rad/s, rad, seconds): an animation
#: evaluated at any time a session reaches stays finite (1e308 axes once normalised to zero,
#: a speed of 1e300 made cos(inf) raise).
MAX_ANIMATION_VALUE = 1e9


@dataclass
class Animation:
    """Rigid motion applied in the object's parent frame before its rest transform.

    kind:
      ``"spin"``   rotation about ``axis`` through ``pivot`` at ``speed`` rad/s;
      ``"orbit"``  translation on a circle of ``radius`` about ``axis`` at ``speed`` rad/s;
      ``"swing"``  rotation about ``axis`` through ``pivot`` by ``amplitude`` rad * sin(speed * t);
      ``"slide"``  translation along ``axis`` by ``amplitude`` metres * sin(speed * t);
      ``"travel"`` starts and stops: rests ``rest`` seconds, travels ``amplitude`` metres along
                   ``axis`` at a constant ``speed`` m/s, rests, travels back, and so on. The
                   position is continuous, the velocity jumps at every start and stop.

    ``phase`` shifts the motion: radians for the periodic kinds, seconds into the cycle for
    ``travel``. Bad values raise :class:`SceneError`.
    """

    kind: str
    axis: tuple = (0.0, 1.0, 0.0)
    speed: float = 1.0
    pivot: tuple = (0.0, 0.0, 0.0)
    radius: float = 0.0
    amplitude: float = 0.0
    phase: float = 0.0
    rest: float = 0.0

    KINDS = ANIMATION_KINDS

    def __post_init__(self):
        if self.kind not in ANIMATION_KINDS:
            raise SceneError(f"unknown animation kind {self.kind!r}; choose from {', '.join(ANIMATION_KINDS)}")
        bound = MAX_ANIMATION_VALUE
        axis = np.asarray(self.axis, dtype=np.float64)
        if axis.shape != (3,) or not np.all(np.abs(axis) <= bound) or np.linalg.norm(axis) < 1e-12:
            raise SceneError(f"animation axis must be a non-zero 3-vector of finite numbers within ±{bound:g}")
        self.axis = tuple(float(x) for x in axis / np.linalg.norm(axis))
        pivot = np.asarray(self.pivot, dtype=np.float64)
        if pivot.shape != (3,) or not np.all(np.abs(pivot) <= bound):
            raise SceneError(f"animation pivot must be a 3-vector of finite numbers within ±{bound:g}")
        self.pivot = tuple(float(x) for x in pivot)
        for name in ("speed", "radius", "amplitude", "phase", "rest"):
            value = float(getattr(self, name))
            if not abs(value) <= bound:   # NaN fails too
                raise SceneError(f"animation {name} must be a finite number within ±{bound:g}")
            setattr(self, name, value)
        if self.rest < 0:
            raise SceneError(f"animation rest must be >= 0 seconds, got {self.rest}")
        if self.kind == "travel" and not (self.speed > 0 and self.amplitude > 0):
            raise SceneError("a travel animation needs a positive speed (m/s) and amplitude (m), got "
                             f"speed {self.speed} and amplitude {self.amplitude}")

    def travel_offset(self, t: float) -> float:
        """``travel``: metres along the axis at time t (0 at the start, ``amplitude`` at the far end)."""
        leg = self.amplitude / self.speed
        u = (t + self.phase) % (2.0 * (leg + self.rest))
        if u < self.rest:
            return 0.0
        u -= self.rest
        if u < leg:
            return u * self.speed
        u -= leg
        if u < self.rest:
            return self.amplitude
        return self.amplitude - (u - self.rest) * self.speed

    def matrix(self, t: float) -> np.ndarray:
        """(4, 4) rigid motion at time t seconds."""
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
        elif self.kind == "slide":
            m[:3, 3] = axis * self.amplitude * math.sin(self.speed * t + self.phase)
        else:  # travel
            m[:3, 3] = axis * self.travel_offset(t)
        return m
