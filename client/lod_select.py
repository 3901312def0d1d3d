"""Per object and output frame: cull against the view frustum, then pick the level of detail.

Levels: the original mesh, the encaging proxy, the bounding box. A level's mean edge length
L projects to about L * f / d pixels at distance d (f: focal length in pixels). The finest
level whose edges still cover at least ``target_px`` pixels is drawn, so the proxy's
screen-space complexity stays roughly constant however far objects are: each level has a
distance threshold ``L * f / target_px`` below which it is used.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pibr.protocol.messages import OutputConfig
from pibr.protocol.pose import Pose
from pibr.protocol.proxy import LEVELS, ProxyObject

DEFAULT_TARGET_PX = 6.0


def mean_edge_length(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Mean edge length of a mesh (object units); 0 without faces."""
    if len(faces) == 0:
        return 0.0
    v = vertices.astype(np.float64)[faces]
    e = np.linalg.norm(v - np.roll(v, 1, axis=1), axis=2)
    return float(e.mean())


@dataclass
class Selection:
    index: int
    level: str
    distance: float


class LodSelector:
    """Chooses what to draw of ``objects`` (ProxyObject) for an output camera."""

    def __init__(self, objects: list[ProxyObject], output: OutputConfig, target_px: float = DEFAULT_TARGET_PX,
                 cull: bool = True, force_level: str | None = None):
        if target_px <= 0:
            raise ValueError("the LoD target must be a positive number of pixels")
        if force_level is not None and force_level not in LEVELS:
            raise ValueError(f"level must be one of {', '.join(LEVELS)}")
        self.objects, self.output, self.target_px, self.cull = objects, output, target_px, cull
        self.force_level = force_level
        self.tan_x = math.tan(math.radians(output.fov_deg) / 2)
        self.tan_y = self.tan_x * output.height / output.width
        self.focal_px = output.width / 2 / self.tan_x
        thresholds = []
        for o in objects:
            scale = float(np.cbrt(abs(np.linalg.det(o.transform[:3, :3])))) or 1.0
            lengths = [mean_edge_length(*o.level(level)) * scale for level in ("original", "proxy")]
            thresholds.append([L * self.focal_px / target_px for L in lengths])
        #: (n, 2): per object the distance below which its original mesh, then its proxy, is used
        self.thresholds = np.array(thresholds, dtype=np.float64).reshape(len(objects), 2)
        #: (n, 8, 4) box corners of every object, object space and (at rest) world space, homogeneous
        self._corners = np.array([[[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
                                  for lo, hi in (o.bounds for o in objects)]).reshape(len(objects), 8, 4)
        self._rest_world = np.stack([c @ o.transform.T for c, o in zip(self._corners, objects)]) if objects else \
            np.zeros((0, 8, 4))

    def select(self, pose: Pose, near: float = 0.0, placed: dict | None = None) -> list[Selection]:
        """What to draw at ``pose``; ``placed`` maps an object index to its (4, 4) object-to-world
        transform where it is not at rest (moving objects), the others use their rest transform.
        All objects at once: a frustum test of their box corners (conservative: culled only when
        all 8 lie outside one plane) and the distance from the eye to their world box."""
        world = self._rest_world
        if placed:
            world = world.copy()
            for i, m in placed.items():
                world[i] = self._corners[i] @ m.T
        cam = world @ pose.view_matrix().T
        x, y, z = cam[:, :, 0], cam[:, :, 1], -cam[:, :, 2]
        visible = np.ones(len(world), dtype=bool)
        if self.cull:
            visible = ~(np.all(z < near, axis=1)
                        | np.all(x > self.tan_x * z, axis=1) | np.all(x < -self.tan_x * z, axis=1)
                        | np.all(y > self.tan_y * z, axis=1) | np.all(y < -self.tan_y * z, axis=1))
        lo, hi = world[:, :, :3].min(axis=1), world[:, :, :3].max(axis=1)
        d = np.linalg.norm(np.maximum(0.0, np.maximum(lo - pose.p, pose.p - hi)), axis=1)
        out = []
        for i in np.flatnonzero(visible).tolist():
            if self.force_level is not None:
                level = self.force_level
            else:
                t_orig, t_proxy = self.thresholds[i]
                level = "original" if d[i] < t_orig else "proxy" if d[i] < t_proxy else "box"
            out.append(Selection(i, level, float(d[i])))
        return out
