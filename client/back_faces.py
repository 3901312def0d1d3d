"""When a mesh may skip its back faces.

From a point outside a closed mesh wound outward (its winding number never negative, see
protocol.proxy.winds_outward) every ray meets a front face of the mesh before any back face,
so back-facing fragments can only lose the depth test: culling them leaves the image as it
was. Two things can break that for a camera: being inside the mesh (winding number not 0 at the
eye) and the near plane cutting the mesh open (a triangle within the near plane's reach of the
eye). :class:`BackFaceTest` checks both per frame, cheaply: a box test first, and only for a
mesh whose box holds the eye a compiled pass over its triangles (the solid angle each
subtends, Van Oosterom and Strackee's formula, summed to the winding number).

Open meshes (a cylinder without caps shows its inside through its ends) are never culled.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from pibr.protocol.proxy import winds_outward


@njit(cache=True, nogil=True)
def _eye_clear(vertices, faces, eye, reach, max_edge):
    """Whether ``eye`` (3,) is outside the closed mesh (vertices (n, 3) f64, faces (m, 3) i64;
    winding number 0) and no triangle comes within ``reach`` of it (conservatively: no vertex
    within reach + the longest edge)."""
    limit = (reach + max_edge) ** 2
    for i in range(vertices.shape[0]):
        d = 0.0
        for k in range(3):
            d += (vertices[i, k] - eye[k]) ** 2
        if d <= limit:
            return False
    total = 0.0
    ex, ey, ez = eye[0], eye[1], eye[2]
    for j in range(faces.shape[0]):
        i0, i1, i2 = faces[j, 0], faces[j, 1], faces[j, 2]
        ax, ay, az = vertices[i0, 0] - ex, vertices[i0, 1] - ey, vertices[i0, 2] - ez
        bx, by, bz = vertices[i1, 0] - ex, vertices[i1, 1] - ey, vertices[i1, 2] - ez
        cx, cy, cz = vertices[i2, 0] - ex, vertices[i2, 1] - ey, vertices[i2, 2] - ez
        la = np.sqrt(ax * ax + ay * ay + az * az)
        lb = np.sqrt(bx * bx + by * by + bz * bz)
        lc = np.sqrt(cx * cx + cy * cy + cz * cz)
        det = ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
        den = (la * lb * lc + (ax * bx + ay * by + az * bz) * lc + (bx * cx + by * cy + bz * cz) * la
               + (cx * ax + cy * ay + cz * az) * lb)
        total += 2.0 * np.arctan2(det, den)
    return abs(total) < 2.0 * np.pi   # the winding number total / 4 pi rounds to 0


class BackFaceTest:
    """Whether one mesh (vertices (n, 3), faces (m, 3) in object space) may be drawn without its
    back faces from a given eye. ``enabled=False``: never."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, enabled: bool = True):
        self.closed = bool(enabled) and winds_outward(vertices, faces)
        self.vertices = np.ascontiguousarray(vertices, np.float64).reshape(-1, 3)
        self.faces = np.ascontiguousarray(faces, np.int64).reshape(-1, 3)
        self.lo, self.hi = (self.vertices.min(axis=0), self.vertices.max(axis=0)) if len(self.vertices) else (0, 0)
        self._placement_key = None
        if self.closed:
            tri = self.vertices[self.faces]
            self.max_edge = float(np.sqrt(np.max(np.sum((tri - np.roll(tri, 1, axis=1)) ** 2, axis=2))))

    def allows(self, eye: np.ndarray, model: np.ndarray, reach: float) -> bool:
        """Whether the mesh, placed by ``model`` (4, 4 object to world), may skip its back faces
        seen from ``eye`` (3,) in world space, whose near plane reaches ``reach`` from it."""
        if not self.closed:
            return False
        key = model.tobytes()
        if key != self._placement_key:   # a static object's placement is worked out once
            linear = np.asarray(model, np.float64)[:3, :3]
            mirrors = np.linalg.det(linear) <= 0.0   # a mirroring placement swaps front and back
            self._inverse = None if mirrors else np.linalg.inv(linear)
            # the near plane's reach in object space is divided by the placement's least stretch
            self._least_stretch = float(np.linalg.svd(linear, compute_uv=False)[-1])
            self._offset = np.array(model[:3, 3], np.float64)
            self._placement_key = key
        if self._inverse is None:
            return False
        local = self._inverse @ (np.asarray(eye, np.float64) - self._offset)
        local_reach = reach / self._least_stretch
        if np.any(local < self.lo - local_reach) or np.any(local > self.hi + local_reach):
            return True
        return bool(_eye_clear(self.vertices, self.faces, local, local_reach, self.max_edge))
