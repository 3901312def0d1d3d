"""An output camera's frustum: the tangents of its four edges, symmetric or not.

A flat display's camera looks through the centre of its image: its frustum is symmetric, set
by the horizontal field of view and the image's aspect. A headset's eye does not: each eye's
lens sits off the centre of its panel, so its frustum reaches further outward (away from the
nose) than inward, and often further down than up (OpenXR reports it as four angles per eye,
``XrFovf``). pibr writes a frustum as the tangents ``(left, right, down, up)`` of the angles
from the camera's axis (-Z, x right, y up) to its edges, left and down negative for a frustum
around its axis. Pixels map linearly onto the image plane at distance 1 in between, so every
consumer (a method's rays and projection, ground truth, hole geometry, binocular pairs) uses
the same two numbers per axis: the half extent and the centre (0 for a symmetric frustum).

``--eye-fov-deg OUTER,INNER,UP,DOWN`` gives the left eye's four angles; the right eye mirrors
it (its outer edge is its right one).
"""
from __future__ import annotations

import math

import numpy as np

from .errors import ConfigError

#: (left, right, down, up) tangents of a frustum's edges.
Tangents = tuple[float, float, float, float]
#: The widest angle from an eye's axis to one edge of its frustum, in degrees.
MAX_EDGE_DEG = 80.0


def symmetric(fov_deg: float, width: int, height: int) -> Tangents:
    """The frustum of a camera through its image's centre: horizontal field of view ``fov_deg``,
    square pixels over ``width`` x ``height``."""
    tx = math.tan(math.radians(fov_deg) / 2.0)
    ty = tx * height / width
    return (-tx, tx, -ty, ty)


def check_eye_fov_deg(values) -> tuple[float, float, float, float]:
    """``values`` (OUTER, INNER, UP, DOWN: four numbers, or their comma-separated text) as floats,
    or a ConfigError naming the problem."""
    if isinstance(values, str):
        values = [v.strip() for v in values.split(",")]
    try:
        out = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise ConfigError(f"an eye's field of view is four angles in degrees OUTER,INNER,UP,DOWN, got {values!r}") from None
    if len(out) != 4:
        raise ConfigError(f"an eye's field of view is four angles in degrees OUTER,INNER,UP,DOWN, got {len(out)}")
    for name, v in zip(("outer", "inner", "up", "down"), out):
        if not (0.0 < v <= MAX_EDGE_DEG):
            raise ConfigError(f"an eye's {name} angle must be in (0, {MAX_EDGE_DEG:g}] degrees, got {v:g}")
    return out


def eye_tangents(eye: str, eye_fov_deg) -> Tangents:
    """The frustum of ``eye`` (left or right) whose left eye sees ``eye_fov_deg`` = (outer, inner,
    up, down) degrees from its axis; the right eye mirrors it."""
    outer, inner, up, down = (math.tan(math.radians(a)) for a in check_eye_fov_deg(eye_fov_deg))
    if eye == "left":
        return (-outer, inner, -down, up)
    if eye == "right":
        return (-inner, outer, -down, up)
    raise ConfigError(f"an asymmetric field of view belongs to an eye, left or right, not {eye!r}")


def equivalent_fov_deg(tangents: Tangents) -> float:
    """The horizontal field of view of the symmetric frustum with the same image-plane width:
    the same pixels per radian at the image's centre (what sizes the server's views and FLIP's
    pixels per degree)."""
    return 2.0 * math.degrees(math.atan(half_and_centre(tangents)[0][0]))


def eyes_tangents(eyes, eye_fov_deg) -> dict:
    """eye -> its frustum's tangents for ``eye_fov_deg`` (:func:`eye_tangents`), None for the
    head's centre or without ``eye_fov_deg`` (a symmetric frustum)."""
    return {eye: None if eye_fov_deg is None or eye not in ("left", "right") else eye_tangents(eye, eye_fov_deg)
            for eye in eyes}


def check_tangents(tangents) -> Tangents:
    """``tangents`` as four floats (left < right, down < up, each edge within MAX_EDGE_DEG of the
    axis), or a ConfigError."""
    try:
        t = tuple(float(v) for v in tangents)
    except (TypeError, ValueError):
        raise ConfigError(f"a frustum is four tangents (left, right, down, up), got {tangents!r}") from None
    limit = math.tan(math.radians(MAX_EDGE_DEG)) * (1.0 + 1e-9)
    if len(t) != 4 or not all(math.isfinite(v) and abs(v) <= limit for v in t) or not (t[0] < t[1] and t[2] < t[3]):
        raise ConfigError(f"a frustum is four tangents left < right, down < up, each within {MAX_EDGE_DEG:g} degrees "
                          f"of the axis, got {tangents!r}")
    return t


def half_and_centre(tangents: Tangents) -> tuple[tuple[float, float], tuple[float, float]]:
    """((half width, half height), (centre x, centre y)) of the image plane at distance 1: a pixel
    at ndc (x, y) in [-1, 1]^2 looks along (cx + x * hx, cy + y * hy, -1)."""
    left, right, down, up = tangents
    return (0.5 * (right - left), 0.5 * (up - down)), (0.5 * (right + left), 0.5 * (up + down))


def projection(tangents: Tangents, near: float, far: float) -> np.ndarray:
    """(4, 4) OpenGL perspective matrix of the frustum (glFrustum's, scaled to distance 1)."""
    (hx, hy), (cx, cy) = half_and_centre(tangents)
    m = np.zeros((4, 4))
    m[0, 0], m[1, 1] = 1 / hx, 1 / hy
    m[0, 2], m[1, 2] = cx / hx, cy / hy
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def rays(tangents: Tangents, width: int, height: int) -> np.ndarray:
    """Unit directions (width * height, 3) of the pixel centres, row 0 on top, in camera space."""
    (hx, hy), (cx, cy) = half_and_centre(tangents)
    xs = cx + ((np.arange(width) + 0.5) / width * 2 - 1) * hx
    ys = cy + (1 - (np.arange(height) + 0.5) / height * 2) * hy
    gx, gy = np.meshgrid(xs, ys)
    d = np.stack([gx, gy, -np.ones_like(gx)], axis=-1).reshape(-1, 3)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def to_pixels(local: np.ndarray, tangents: Tangents, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Continuous (column, row) (n,), (n,) where camera-space points ``local`` (n, 3) in front of
    the camera (z < 0) land, row 0 on top; points behind get garbage the caller masks."""
    (hx, hy), (cx, cy) = half_and_centre(tangents)
    depth = np.where(-local[:, 2] > 1e-6, -local[:, 2], 1.0)
    col = ((local[:, 0] / depth - cx) / hx + 1.0) * 0.5 * width
    row = (1.0 - (local[:, 1] / depth - cy) / hy) * 0.5 * height
    return col, row
