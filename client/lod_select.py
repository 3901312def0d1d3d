"""Per object and output frame: cull against the view frustum, then pick the level of detail.

Levels: the original mesh, the encaging proxy, the bounding box. A level's mean edge length
L subtends about L / d radians at distance d. The finest level whose edges still subtend at
least the target angle is drawn, so the proxy's angular complexity stays roughly constant however
far objects are: each level has a distance threshold ``L / angle`` below which it is used.

The target is an angle, given as pixels of a reference output (``target_px`` pixels at
REFERENCE_FOCAL_PX pixels per radian: 960 pixels across 90 degrees), whatever the output's
size. It was pixels of the output until issue 26: a smaller output then picked coarser proxies,
while what a proxy's error costs is the reprojection's error, an angle (the proxy's geometric
error against the head's displacement), which the output's pixel count does not change.
Measured on the tuning windows (``pibr bench ibr --windows tuning --lod-targets
1.5,3,6,12,24``, docs/results/lod-target.json): on a close-up scene (a detailed object from
0.7 m) the quality first drops at 12 px of a 960-wide output and 6 px of a 480-wide one (both
0.025 rad) and at 24 px of a 1440-wide one (0.033 rad; 12 px there, 0.017 rad, cost nothing):
at about one angle. The default, 6 px of the reference (0.0125 rad), keeps below it; 3 px buys
the room about 1 % at 960x540 for more triangles.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pibr.protocol.messages import OutputConfig
from pibr.protocol.pose import Pose
from pibr.protocol.proxy import LEVELS, ProxyObject

DEFAULT_TARGET_PX = 6.0
#: Pixels per radian at the centre of the reference output the target is given for (960 px
#: across a 90-degree field of view): the default target is 6 / 480 = 0.0125 rad.
REFERENCE_FOCAL_PX = 480.0


def switch_distances(objects: list[ProxyObject], target_px: float = DEFAULT_TARGET_PX) -> np.ndarray:
    """(n, 2): per object the distance (metres) below which its original mesh, then its proxy
    level, is drawn; beyond both, its box. ``target_px``: pixels of the reference output."""
    out = []
    for o in objects:
        scale = float(np.cbrt(abs(np.linalg.det(o.transform[:3, :3])))) or 1.0
        lengths = [mean_edge_length(*o.level(level)) * scale for level in ("original", "proxy")]
        out.append([L * REFERENCE_FOCAL_PX / target_px for L in lengths])
    return np.array(out, dtype=np.float64).reshape(len(objects), 2)


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
        #: (n, 2): per object the distance below which its original mesh, then its proxy, is used
        self.thresholds = switch_distances(objects, target_px)
        #: (n, 8, 4) box corners of every object, object space and (at rest) world space, homogeneous
        self._corners = np.array([[[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
                                  for lo, hi in (o.bounds for o in objects)]).reshape(len(objects), 8, 4)
        self._rest_world = np.stack([c @ o.transform.T for c, o in zip(self._corners, objects)]) if objects else \
            np.zeros((0, 8, 4))

    def select(self, pose: Pose, near: float = 0.0, placed: dict | None = None,
               half_baseline: float = 0.0) -> list[Selection]:
        """What to draw at ``pose``; ``placed`` maps an object index to its (4, 4) object-to-world
        transform where it is not at rest (moving objects), the others use their rest transform.
        All objects at once: a frustum test of their box corners (conservative: culled only when
        all 8 lie outside one plane) and the distance from the eye to their world box.

        ``half_baseline`` (metres): for two eyes looking as ``pose`` does from ``half_baseline``
        either side of it along its x axis (a stereo pair), what either eye sees: their union
        frustum (its side planes those of the outer eyes), each object at the level of the nearer eye."""
        world = self._rest_world
        if placed:
            world = world.copy()
            for i, m in placed.items():
                world[i] = self._corners[i] @ m.T
        cam = world @ pose.view_matrix().T
        x, y, z = cam[:, :, 0], cam[:, :, 1], -cam[:, :, 2]
        visible = np.ones(len(world), dtype=bool)
        if self.cull:
            b = half_baseline
            left, right, down, up = self.output.tangents()
            visible = ~(np.all(z < near, axis=1)
                        | np.all(x > right * z + b, axis=1) | np.all(x < left * z - b, axis=1)
                        | np.all(y > up * z, axis=1) | np.all(y < down * z, axis=1))
        lo, hi = world[:, :, :3].min(axis=1), world[:, :, :3].max(axis=1)
        side = half_baseline * pose.rotation()[:, 0]
        eyes = (pose.p,) if half_baseline == 0.0 else (pose.p - side, pose.p + side)
        d = np.min([np.linalg.norm(np.maximum(0.0, np.maximum(lo - e, e - hi)), axis=1) for e in eyes], axis=0)
        out = []
        for i in np.flatnonzero(visible).tolist():
            if self.force_level is not None:
                level = self.force_level
            else:
                t_orig, t_proxy = self.thresholds[i]
                level = "original" if d[i] < t_orig else "proxy" if d[i] < t_proxy else "box"
            out.append(Selection(i, level, float(d[i])))
        return out
