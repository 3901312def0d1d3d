"""A trace window replayed as a session shows it: the display ticks, the viewer's pose at each,
and the server frame each tick shows (rendered when, from the pose of which tick), on the
schedule of :class:`~pibr.common.link.SessionSchedule`, placed in the scene as the client places
it (:func:`~pibr.common.traces.placement.placement`).

``scene`` is anything with a ``viewer_origin`` pose (a loaded scene, or a session's scene info)."""
from __future__ import annotations

import math

from pibr.protocol.pose import Pose

from .link import SessionSchedule
from .traces.loading import load_trace
from .traces.placement import placement


def trace_ticks(scene, trace, start_s: float, duration_s: float | None, rate_hz: float, anchor: str = "start"):
    """-> (tick us [n], pose_at): the display ticks of a window of a loaded
    :class:`~pibr.protocol.trace.HeadTrace` and the viewer's pose at a client time (us from the
    window's start; earlier times clamp to its start)."""
    _, end = trace.window(start_s, duration_s)
    n = max(1, int(math.floor((end - start_s) * rate_hz + 1e-9)))
    tick_us = int(round(1e6 / rate_hz))
    origin = placement(trace, start_s, scene.viewer_origin, anchor)

    def pose_at(t_us: int) -> Pose:
        return origin.compose(trace.pose_at(start_s + max(t_us, 0) / 1e6))

    return [i * tick_us for i in range(n)], pose_at


def trace_poses(scene, trace_spec: str, start_s: float, duration_s: float | None, rate_hz: float,
                anchor: str = "start"):
    """:func:`trace_ticks` of a trace given by name or file."""
    return trace_ticks(scene, load_trace(trace_spec), start_s, duration_s, rate_hz, anchor)


def trace_samples(scene, trace, start_s: float, duration_s: float | None, schedule: SessionSchedule,
                  stride: int = 1, anchor: str = "start"):
    """[(display time s, display pose, render time s, render pose)] of every ``stride``-th display
    tick (at ``schedule.rate_hz``) of a window of a loaded trace, on an ideal link's schedule
    (``schedule.frame_for``)."""
    ticks, pose_at = trace_ticks(scene, trace, start_s, duration_s, schedule.rate_hz, anchor)
    out = []
    for t_us in ticks[::stride]:
        render_us, pose_us = schedule.frame_for(t_us)
        out.append((t_us / 1e6, pose_at(t_us), render_us / 1e6, pose_at(pose_us)))
    return out


def display_samples(scene, trace_spec: str, start_s: float, duration_s: float | None, schedule: SessionSchedule,
                    stride: int = 1, anchor: str = "start"):
    """:func:`trace_samples` of a trace given by name or file."""
    return trace_samples(scene, load_trace(trace_spec), start_s, duration_s, schedule, stride, anchor)
