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
        self.thresholds = []  # per object: distance below which each of original, proxy is used
        for o in objects:
            scale = float(np.cbrt(abs(np.linalg.det(o.transform[:3, :3])))) or 1.0
            lengths = [mean_edge_length(*o.level(level)) * scale for level in ("original", "proxy")]
            self.thresholds.append([L * self.focal_px / target_px for L in lengths])
        self._corners = []
        for o in objects:
            lo, hi = o.bounds
            self._corners.append(np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                                           for z in (lo[2], hi[2])]))

    def _visible(self, cam: np.ndarray, near: float) -> bool:
        """Conservative: False only when all 8 box corners are outside one frustum plane."""
        x, y, z = cam[:, 0], cam[:, 1], -cam[:, 2]
        if np.all(z < near):
            return False
        if np.all(x > self.tan_x * z) or np.all(x < -self.tan_x * z):
            return False
        if np.all(y > self.tan_y * z) or np.all(y < -self.tan_y * z):
            return False
        return True

    def select(self, pose: Pose, near: float = 0.0, placed: dict | None = None) -> list[Selection]:
        """What to draw at ``pose``; ``placed`` maps an object index to its (4, 4) object-to-world
        transform where it is not at rest (moving objects), the others use their rest transform."""
        view = pose.view_matrix()
        placed = placed or {}
        out = []
        for i, o in enumerate(self.objects):
            world = self._corners[i] @ placed.get(i, o.transform).T
            cam = world @ view.T
            if self.cull and not self._visible(cam[:, :3], near):
                continue
            lo, hi = world[:, :3].min(0), world[:, :3].max(0)
            d = float(np.linalg.norm(np.maximum(0.0, np.maximum(lo - pose.p, pose.p - hi))))
            if self.force_level is not None:
                level = self.force_level
            else:
                t_orig, t_proxy = self.thresholds[i]
                level = "original" if d < t_orig else "proxy" if d < t_proxy else "box"
            out.append(Selection(i, level, d))
        return out
