"""Where a trace window goes in a scene (its anchor), the same for the client and the benchmarks."""
from __future__ import annotations

import math

import numpy as np

from pibr.protocol.errors import TraceError
from pibr.protocol.pose import Pose, quat_to_matrix
from pibr.protocol.trace import HeadTrace


#: How a trace window is placed in a scene (:func:`placement`).
ANCHORS = ("start", "origin", "none")


def heading(q) -> float:
    """Yaw in radians of a camera orientation (w, x, y, z): the angle about +Y from -Z to the
    direction it looks, projected on the floor (0 looking along -Z, +pi/2 along -X)."""
    f = quat_to_matrix(q) @ np.array([0.0, 0.0, -1.0])
    return math.atan2(-f[0], -f[2])


def placement(trace: HeadTrace, start_s: float, origin: Pose, anchor: str = "start") -> Pose:
    """Where a trace window goes in a scene: the world pose at trace time t is
    ``placement(...).compose(trace.pose_at(t))``.

    anchor 'start' : the window's first pose (at ``start_s``) is put at the scene's viewer
        ``origin``: its position there, its heading turned to the origin's (about +Y, so the
        trace's up stays up), its pitch and roll kept. Any window of any trace then starts
        where the scene's author put the viewer, facing where they meant.
    anchor 'origin' : the trace's own origin at the viewer origin (its coordinates taken as
        relative to it), as recorded around a point of interest.
    anchor 'none' : the trace is already in the scene's coordinates.
    """
    if anchor == "none":
        return Pose.identity()
    if anchor == "origin":
        return origin
    if anchor != "start":
        raise TraceError(f"unknown anchor {anchor!r}; expected one of {', '.join(ANCHORS)}")
    first = trace.pose_at(start_s)

    def on_floor(p, q) -> Pose:   # position and heading only
        h = heading(q)
        return Pose.make(p, [math.cos(h / 2), 0.0, math.sin(h / 2), 0.0])
    return on_floor(origin.p, origin.q).compose(on_floor(first.p, first.q).inverse())
