"""Poses and quaternion maths.

Conventions (DESIGN.md, Contracts): metres, right-handed, +Y up, a camera looks along -Z.
A :class:`Pose` is camera-to-world: ``world = R(q) @ local + position``. Quaternions are
``(w, x, y, z)`` arrays; functions accept a single quaternion ``(4,)`` or a batch ``(n, 4)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import InvalidPose

#: A quaternion whose norm is below this is "zero": it names no rotation and is rejected.
MIN_QUAT_NORM = 1e-6


def _as_quats(q) -> np.ndarray:
    q = np.asarray(q, dtype=np.float64)
    if q.shape[-1] != 4:
        raise ValueError(f"quaternions must have shape (4,) or (n, 4), got {q.shape}")
    return q


def quat_normalize(q) -> np.ndarray:
    """Unit quaternion(s) with w >= 0. Raises :class:`InvalidPose` on NaN/inf or a zero quaternion.

    q : (4,) or (n, 4) float, (w, x, y, z)
    """
    q = _as_quats(q)
    if not np.all(np.isfinite(q)):
        raise InvalidPose("quaternion has a NaN or infinite component")
    with np.errstate(over="ignore"):
        n = np.linalg.norm(q, axis=-1, keepdims=True)
    if not np.all(np.isfinite(n)):   # components near the float limit overflow the squared norm
        big = np.max(np.abs(q), axis=-1, keepdims=True)
        q = np.where(np.isfinite(n), q, q / big)
        n = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(n < MIN_QUAT_NORM):
        raise InvalidPose(f"quaternion norm below {MIN_QUAT_NORM}: a zero quaternion names no rotation")
    q = q / n
    # Canonical sign: q and -q are the same rotation; make the first non-zero component
    # (w, then x, y, z) positive so equal rotations compare equal.
    sign = np.zeros(q.shape[:-1])
    for k in range(4):
        sign = np.where(sign == 0, np.sign(q[..., k]), sign)
    return q * sign[..., None]


def quat_multiply(a, b) -> np.ndarray:
    """Hamilton product a * b (apply b, then a). a, b : (4,) or (n, 4)."""
    a, b = _as_quats(a), _as_quats(b)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ], axis=-1)


def quat_conjugate(q) -> np.ndarray:
    """Inverse rotation of unit quaternion(s)."""
    q = _as_quats(q)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_to_matrix(q) -> np.ndarray:
    """Rotation matrices (3, 3) or (n, 3, 3) of unit quaternion(s) (4,) or (n, 4)."""
    q = _as_quats(q)
    w, x, y, z = np.moveaxis(q, -1, 0)
    m = np.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], axis=-1)
    return m.reshape(q.shape[:-1] + (3, 3))


def quat_from_matrix(m) -> np.ndarray:
    """Unit quaternion (w >= 0) of a rotation matrix (3, 3) (Shepperd's method, stable everywhere)."""
    m = np.asarray(m, dtype=np.float64)
    if m.shape != (3, 3):
        raise ValueError(f"rotation matrix must have shape (3, 3), got {m.shape}")
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    return quat_normalize(q)


def quat_from_axis_angle(axis, angle_rad: float) -> np.ndarray:
    """Unit quaternion rotating by ``angle_rad`` (right-hand rule) about ``axis`` (3,)."""
    axis = np.asarray(axis, dtype=np.float64)
    n = np.linalg.norm(axis)
    if not np.isfinite(n) or n < 1e-12:
        raise ValueError("rotation axis must be a finite non-zero vector")
    h = 0.5 * angle_rad
    return quat_normalize(np.concatenate([[math.cos(h)], axis / n * math.sin(h)]))


def quat_from_euler(angles_rad, order: str = "yxz") -> np.ndarray:
    """Quaternion(s) from Euler angles applied intrinsically in ``order``.

    angles_rad : (3,) or (n, 3), the angle about each axis named in ``order`` (same order).
    ``order="yxz"`` is yaw (about Y), then pitch (about the new X), then roll (about the new Z).
    """
    order = order.lower()
    if len(order) != 3 or any(c not in "xyz" for c in order):
        raise ValueError(f"Euler order must be three letters from 'xyz', got {order!r}")
    a = np.asarray(angles_rad, dtype=np.float64)
    if a.shape[-1] != 3:
        raise ValueError(f"Euler angles must have shape (3,) or (n, 3), got {a.shape}")
    axes = {"x": np.array([1.0, 0, 0]), "y": np.array([0, 1.0, 0]), "z": np.array([0, 0, 1.0])}
    q = None
    for i, c in enumerate(order):
        h = 0.5 * a[..., i]
        qi = np.concatenate([np.cos(h)[..., None], np.sin(h)[..., None] * axes[c]], axis=-1)
        q = qi if q is None else quat_multiply(q, qi)  # intrinsic: post-multiply
    return quat_normalize(q)


def quat_rotate(q, v) -> np.ndarray:
    """Rotate vector(s) v (3,) or (n, 3) by unit quaternion(s) q."""
    m = quat_to_matrix(q)
    v = np.asarray(v, dtype=np.float64)
    return np.einsum("...ij,...j->...i", m, v)


def quat_slerp(a, b, s) -> np.ndarray:
    """Spherical linear interpolation between unit quaternions a and b (4,) or (n, 4) at s in [0, 1].

    Takes the short way round; falls back to normalised lerp when a and b nearly coincide.
    """
    a, b = _as_quats(a), _as_quats(b)
    s = np.asarray(s, dtype=np.float64)[..., None]
    dot = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(dot < 0, -b, b)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_t = np.sin(theta)
    near = sin_t < 1e-6
    safe = np.where(near, 1.0, sin_t)
    wa = np.where(near, 1.0 - s, np.sin((1.0 - s) * theta) / safe)
    wb = np.where(near, s, np.sin(s * theta) / safe)
    out = wa * a + wb * b
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def quat_angle(a, b) -> np.ndarray:
    """Angle in radians of the rotation taking a to b (0..pi)."""
    dot = np.abs(np.sum(_as_quats(a) * _as_quats(b), axis=-1))
    return 2.0 * np.arccos(np.clip(dot, 0.0, 1.0))


@dataclass(frozen=True)
class Pose:
    """Camera-to-world rigid transform: ``position`` (3,) metres, ``orientation`` (4,) (w, x, y, z).

    Construct with :meth:`make`, which validates and normalises; the dataclass fields are
    then plain float tuples so a Pose is hashable and compares exactly.
    """

    position: tuple
    orientation: tuple

    @classmethod
    def make(cls, position, orientation=(1.0, 0.0, 0.0, 0.0)) -> "Pose":
        p = np.asarray(position, dtype=np.float64)
        if p.shape != (3,):
            raise InvalidPose(f"position must have shape (3,), got {p.shape}")
        if not np.all(np.isfinite(p)):
            raise InvalidPose("position has a NaN or infinite component")
        q = quat_normalize(orientation)
        if q.shape != (4,):
            raise InvalidPose(f"orientation must have shape (4,), got {q.shape}")
        return cls(tuple(float(x) for x in p), tuple(float(x) for x in q))

    @classmethod
    def identity(cls) -> "Pose":
        return cls((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))

    @classmethod
    def look_at(cls, eye, target, up=(0.0, 1.0, 0.0)) -> "Pose":
        """Camera at ``eye`` looking at ``target`` (its -Z axis points there)."""
        eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
        back = eye - target
        if np.linalg.norm(back) < 1e-12:
            raise InvalidPose("look_at: eye and target coincide")
        back /= np.linalg.norm(back)
        right = np.cross(up, back)
        if np.linalg.norm(right) < 1e-9:  # looking straight along up: pick any right axis
            right = np.cross([1.0, 0.0, 0.0] if abs(back[0]) < 0.9 else [0.0, 0.0, 1.0], back)
        right /= np.linalg.norm(right)
        true_up = np.cross(back, right)
        return cls.make(eye, quat_from_matrix(np.stack([right, true_up, back], axis=1)))

    @property
    def p(self) -> np.ndarray:
        return np.array(self.position)

    @property
    def q(self) -> np.ndarray:
        return np.array(self.orientation)

    def rotation(self) -> np.ndarray:
        """(3, 3) camera-to-world rotation."""
        return quat_to_matrix(self.q)

    def matrix(self) -> np.ndarray:
        """(4, 4) camera-to-world matrix."""
        m = np.eye(4)
        m[:3, :3] = self.rotation()
        m[:3, 3] = self.position
        return m

    def view_matrix(self) -> np.ndarray:
        """(4, 4) world-to-camera matrix (the inverse of :meth:`matrix`)."""
        r = self.rotation()
        m = np.eye(4)
        m[:3, :3] = r.T
        m[:3, 3] = -r.T @ self.p
        return m

    def inverse(self) -> "Pose":
        qi = quat_conjugate(self.q)
        return Pose.make(-quat_rotate(qi, self.p), qi)

    def compose(self, other: "Pose") -> "Pose":
        """``self ∘ other``: ``other`` expressed in ``self``'s frame, e.g. pose ∘ offset."""
        return Pose.make(self.p + quat_rotate(self.q, other.p), quat_multiply(self.q, other.q))

    def transform_points(self, pts) -> np.ndarray:
        """Map local points (n, 3) to world."""
        return np.asarray(pts, dtype=np.float64) @ self.rotation().T + self.p

    def forward(self) -> np.ndarray:
        """World direction the camera looks along (its -Z axis)."""
        return -self.rotation()[:, 2]

    def as_array(self) -> np.ndarray:
        """(7,) position then orientation (w, x, y, z)."""
        return np.array(self.position + self.orientation)

    @classmethod
    def from_array(cls, a) -> "Pose":
        a = np.asarray(a, dtype=np.float64)
        if a.shape != (7,):
            raise InvalidPose(f"a pose array must have shape (7,), got {a.shape}")
        return cls.make(a[:3], a[3:])


def dual_view_offset(forward: float, up: float, tilt_deg: float) -> Pose:
    """The dual view's extra camera relative to the primary: ``forward`` metres along the
    primary's view direction (-Z), ``up`` metres along its +Y, pitched ``tilt_deg`` down."""
    # Rotating about +X by a negative angle turns the view direction (-Z) downwards.
    return Pose.make((0.0, up, -forward), quat_from_axis_angle((1.0, 0.0, 0.0), -math.radians(tilt_deg)))
