"""The wide-angle projection (Reinert et al. 2016, Eq. 1), in numpy and GLSL from one source.

For a camera-space point p with r = |p|: t = (p_x / r, p_y / r), t'_x = t_x / sqrt(1 - t_y^2),
t'_y = t_y. The front hemisphere (p_z <= 0) fills the square [-1, 1]^2; the inverse maps
(t'_x, t'_y) back to a unit direction, and the stored radial distance r gives the point.

Numerics. The row stretch 1 / sqrt(1 - t_y^2) blows up at the poles (t_y -> +-1), where t_x
also goes to 0. We never form that quotient: 1 - t_y^2 = (p_x^2 + p_z^2) / r^2, so
t'_x = p_x / sqrt(p_x^2 + p_z^2), which is bounded by 1 and only 0/0 exactly on the Y axis,
where it is guarded to 0 (any value is right there: the whole top row is one direction).
The point is first scaled by its largest component, so neither r -> 0 nor r -> inf
overflows or loses the direction.

Image convention (all of pibr): row 0 is the *top* of an image (t'_y = +1), column 0 the
left (t'_x = -1); pixel centres sit at half-integers. A texture uploaded from such an
array is sampled at ``uv = ((t'_x + 1) / 2, (1 - t'_y) / 2)``.
"""
from __future__ import annotations

import numpy as np

from .formula import GLSL_PRELUDE, Formula

#: Guards for divisions: the smallest normal number of each precision, so only an exact
#: zero is ever guarded (numpy evaluates in float64, shaders in float32).
EPS = float(np.finfo(np.float64).tiny)
EPS_GLSL = 1e-30

FORWARD = Formula(
    "wa_project_xyz",
    inputs=("px", "py", "pz"),
    steps=(
        ("m", "max(max(abs(px), abs(py)), max(abs(pz), EPS))"),
        ("qx", "px / m"),
        ("qy", "py / m"),
        ("qz", "pz / m"),
        ("qn", "sqrt(qx * qx + qy * qy + qz * qz)"),
        ("r", "m * qn"),
        ("ty", "clamp(qy / max(qn, EPS), -1.0, 1.0)"),
        ("tx", "clamp(qx / max(sqrt(qx * qx + qz * qz), EPS), -1.0, 1.0)"),
    ),
    outputs=("tx", "ty", "r"),
    constants={"EPS": EPS},
    glsl_constants={"EPS": EPS_GLSL},
)

# Rasterising a mesh in this projection needs vertices behind the camera (p_z > 0) to land
# *outside* the square, continuously across p_z = 0: x' continues from +-1 towards +-2 as the
# azimuth goes from +-90 to +-180 degrees. Straight behind, x' jumps from +2 to -2; a triangle
# there has every vertex behind the camera and is removed by the clip distance -p_z.
FORWARD_EXTENDED = Formula(
    "wa_project_extended_xyz",
    inputs=("px", "py", "pz"),
    steps=FORWARD.steps + (
        ("tx", "select(pz > 0.0, select(px >= 0.0, 2.0 - tx, -2.0 - tx), tx)"),
    ),
    outputs=("tx", "ty", "r"),
    constants={"EPS": EPS},
    glsl_constants={"EPS": EPS_GLSL},
)

INVERSE = Formula(
    "wa_unproject_xy",
    inputs=("vx", "vy"),
    steps=(
        ("ty", "clamp(vy, -1.0, 1.0)"),
        ("tx", "clamp(vx, -1.0, 1.0) * sqrt(max(1.0 - ty * ty, 0.0))"),
        ("dz", "-sqrt(max(1.0 - tx * tx - ty * ty, 0.0))"),
    ),
    outputs=("tx", "ty", "dz"),
)

GLSL = (
    GLSL_PRELUDE
    + FORWARD.glsl("vec3", "vec3(tx, ty, r)")
    + FORWARD_EXTENDED.glsl("vec3", "vec3(tx, ty, r)")
    + INVERSE.glsl("vec3", "vec3(tx, ty, dz)")
    + """
// camera-space point -> (t'_x, t'_y, r); meaningful for p.z <= 0 (front hemisphere)
vec3 wa_project(vec3 p) { return wa_project_xyz(p.x, p.y, p.z); }
// as wa_project, but points behind the camera land outside [-1, 1] in x (for rasterising)
vec3 wa_project_extended(vec3 p) { return wa_project_extended_xyz(p.x, p.y, p.z); }
// (t'_x, t'_y) in [-1, 1]^2 -> unit camera-space direction with z <= 0
vec3 wa_unproject(vec2 t) { return wa_unproject_xy(t.x, t.y); }
// (t'_x, t'_y) -> texture coordinates of a top-row-first image
vec2 wa_uv(vec2 t) { return vec2(0.5 * (t.x + 1.0), 0.5 * (1.0 - t.y)); }
vec2 wa_from_uv(vec2 uv) { return vec2(2.0 * uv.x - 1.0, 1.0 - 2.0 * uv.y); }
"""
)


def project(points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera-space points (n, 3) -> t' (n, 2), r (n,), valid (n,) bool.

    ``valid`` is False behind the camera (p_z > 0), at the camera centre (r == 0) and for
    non-finite input; t' is still finite there.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {p.shape}")
    finite = np.all(np.isfinite(p), axis=1)
    q = np.where(finite[:, None], p, 0.0)
    tx, ty, r = FORWARD.numpy(px=q[:, 0], py=q[:, 1], pz=q[:, 2])
    valid = finite & (q[:, 2] <= 0.0) & (r > 0.0) & np.isfinite(r)
    return np.stack([tx, ty], axis=1), r, valid


def unproject(t, r=None) -> np.ndarray:
    """t' (n, 2) -> unit camera-space directions (n, 3), or points (n, 3) when r (n,) is given."""
    t = np.asarray(t, dtype=np.float64)
    if t.ndim != 2 or t.shape[1] != 2:
        raise ValueError(f"t must have shape (n, 2), got {t.shape}")
    d = np.stack(INVERSE.numpy(vx=t[:, 0], vy=t[:, 1]), axis=1)
    if r is None:
        return d
    return d * np.asarray(r, dtype=np.float64)[:, None]


def pixel_centers(width: int, height: int) -> np.ndarray:
    """t' of every pixel centre of a ``width`` x ``height`` wide-angle image, (height, width, 2), row 0 on top."""
    if width < 1 or height < 1:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    x = (np.arange(width) + 0.5) / width * 2.0 - 1.0
    y = 1.0 - (np.arange(height) + 0.5) / height * 2.0
    return np.stack(np.meshgrid(x, y), axis=-1)


def to_pixels(t, width: int, height: int) -> np.ndarray:
    """t' (n, 2) -> continuous pixel coordinates (n, 2) as (column, row), row 0 on top."""
    t = np.asarray(t, dtype=np.float64)
    return np.stack([(t[:, 0] + 1.0) * 0.5 * width, (1.0 - t[:, 1]) * 0.5 * height], axis=1)
