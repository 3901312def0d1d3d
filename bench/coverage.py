"""How much of each displayed view the transmitted views cover (Reinert et al., Fig. 4).

The coverage test itself (a displayed pixel is covered when some transmitted view shows the
same surface point within a relative distance tolerance, or sky where the view shows sky) is
:mod:`pibr.server.coverage`, which the server also uses to plan sessions. An uncovered pixel is
a hole an ideal, depth-exact warp of the transmitted views could not fill.

Variants (``VARIANTS``): the primary view alone; plus an extra view at zero offset with
peeling (a second depth layer); at the offset without peeling; at the offset with peeling.
``floor`` is the primary view rendered at the displayed pose itself (no latency): what the
test misses with nothing to disocclude (grazing surfaces, sub-texel leaves), the noise floor
the other numbers sit on.

Frames follow the system's virtual-clock schedule (protocol/session.py): at display time t
the client shows the newest server frame usable by then, rendered from the newest pose
that had reached the server.
"""
from __future__ import annotations

import os

import numpy as np

from pibr.protocol.pose import Pose
# The coverage test itself lives with the server, which uses it to plan sessions (scene_plan.py);
# it is re-exported here for the benchmarks.
from pibr.server.coverage import (COVERAGE_TOLERANCE, CoverageProbe, LatencyModel, camera_rays,  # noqa: F401
                                  display_samples, displayed_points, matches_view, project_to_view,
                                  sky_in_view, trace_samples, trace_ticks, uncovered)
from .results import write_result

VARIANTS = ("primary", "peel_no_offset", "offset_no_peel", "offset_peel")
VARIANT_LABELS = {"primary": "primary only", "peel_no_offset": "extra: peeling, no offset",
                  "offset_no_peel": "extra: offset, no peeling", "offset_peel": "extra: offset + peeling",
                  "floor": "primary, no latency (floor)"}


def trace_poses(scene, trace_spec: str, start_s: float, duration_s: float | None, rate_hz: float,
                anchor: str = "start"):
    """:func:`pibr.server.coverage.trace_ticks` of a trace given by name or file."""
    from pibr.protocol.trace import load_trace

    return trace_ticks(scene, load_trace(trace_spec), start_s, duration_s, rate_hz, anchor)



class LinkSchedule:
    """The schedule of one session through a modelled network, frame by frame.

    Each direction is a :class:`~pibr.protocol.link.LinkModel`, the relay's own model: a delay,
    a jitter drawn from a seeded generator, and a bandwidth cap under which messages queue
    behind each other (a frame of B bits holds the link B / cap seconds). The client sends its
    pose every display tick; the server renders every ``1 / server_fps`` from the newest pose
    that has reached it and sends the frame ``server_delay_ms`` later, unless ``max_in_flight``
    frames it sent are not known to be received (the real clock's rule, server/session.py: the
    client reports what it decoded, the report travelling the uplink); the client shows the
    newest frame that has arrived. Without jitter, cap or skipped frames this is
    :class:`LatencyModel`'s arithmetic. Sizes of frames come from the stream as it is made, so
    the schedule advances with it: :meth:`due`, then :meth:`sent` for each frame made.
    """

    POSE_BYTES = 80   # a Pose message on the wire (framing header included)

    def __init__(self, rate_hz: float, server_fps: float, up, down, server_delay_ms: float = 20.0,
                 seed: int = 0, max_in_flight: int | None = 3):
        """up, down: ``protocol.link.LinkParams``; max_in_flight None: never skip a frame."""
        from pibr.protocol.link import LinkModel

        self.tick_us = int(round(1e6 / rate_hz))
        self.interval_us = int(round(1e6 / server_fps))
        self.delay_us = int(round(server_delay_ms * 1000))
        self.up, self.down = LinkModel(up, seed=2 * seed), LinkModel(down, seed=2 * seed + 1)
        self.max_in_flight = max_in_flight
        self._pose_arrivals: list[int] = []    # per display tick, in order
        self._sent: list[tuple[int, int]] = []  # (render us, arrival us) of every frame sent
        # Pre-roll: the first frames are rendered before the window starts (from its first pose),
        # so that the first display tick has a frame whatever the latency.
        lead = self.delay_us + self.down._delay_us + self.down._jitter_us + 2 * self.interval_us
        self._next_render = -(-lead // self.interval_us) * -self.interval_us
        self._pose_i = 0
        self.skipped = 0

    def _pose_arrival(self, i: int) -> int:
        while len(self._pose_arrivals) <= i:
            k = len(self._pose_arrivals)
            self._pose_arrivals.append(self.up.arrival_us(k * self.tick_us, self.POSE_BYTES))
        return self._pose_arrivals[i]

    def _pose_tick(self, render_us: int) -> int:
        """Client time of the newest pose that reached the server by ``render_us`` (0 if none);
        render times only grow, and so do arrivals (the link is FIFO)."""
        while self._pose_arrival(self._pose_i + 1) <= render_us:
            self._pose_i += 1
        return self._pose_i * self.tick_us

    def next_due(self, t_us: int):
        """The next server frame to render whose send time is at or before display time ``t_us``:
        (render us, client us of its pose), or None; frames skipped on the way are counted in
        ``skipped``. Report each with :meth:`sent` before asking for the next."""
        while self._next_render + self.delay_us <= t_us:
            r = self._next_render
            self._next_render += self.interval_us
            if self.max_in_flight is not None:
                known = sum(1 for _, a in self._sent if a + self.up.min_delay_us <= r)
                if len(self._sent) - known >= self.max_in_flight:
                    self.skipped += 1
                    continue
            return r, self._pose_tick(r)
        return None

    def sent(self, render_us: int, nbytes: int) -> int:
        """Record the frame rendered at ``render_us`` of ``nbytes`` on the wire -> its arrival us."""
        arrival = self.down.arrival_us(render_us + self.delay_us, nbytes)
        self._sent.append((render_us, arrival))
        return arrival


def measure_coverage(probe: CoverageProbe, samples, offset: Pose, variants=VARIANTS + ("floor",)) -> dict:
    """Per variant, the missing fraction of every sample -> {variant: [fraction, ...]}, and
    under ``variant + ":geometry"`` the same over pixels that show geometry (no sky)."""
    zero = Pose.identity()
    out = {v: [] for v in variants}
    out.update({v + ":geometry": [] for v in variants})
    out["sky_share"] = []
    for t_disp, display, t_render, rendered in samples:
        points, sky, dirs = probe.display_points(display, t_disp)
        out["sky_share"].append(float(sky.mean()))
        if "floor" in variants:
            here = probe.render_primary(display, t_disp)
            everything, geometry = probe.missing(points, sky, dirs, [(display, here, False)])
            out["floor"].append(everything)
            out["floor:geometry"].append(geometry)
        primary = probe.render_primary(rendered, t_render)
        base = [(rendered, primary, False)]
        for v in variants:
            if v == "floor":
                continue
            if v == "primary":
                views = base
            else:
                off = zero if v == "peel_no_offset" else offset
                peel = v != "offset_no_peel"
                extra = probe.render_extra(rendered, off, t_render, peel)
                views = base + [(rendered.compose(off), extra, peel)]
            everything, geometry = probe.missing(points, sky, dirs, views)
            out[v].append(everything)
            out[v + ":geometry"].append(geometry)
    return out


def run_coverage_bench(scene_spec="room", windows=None, latency_ms=128.0, rate_hz=30.0, view_size=(1024, 1024),
                       out_size=(320, 180), offset=None, stride=2, out_dir="out/bench", progress=True) -> dict:
    """``pibr bench coverage``: JSON and plot of the four variants' missing-pixel fractions,
    per window (default: the evaluation windows of bench/windows.py)."""
    from pibr.scenes.registry import load_scene
    from pibr.server.config import PAPER_EXTRA_OFFSET, extra_offset_pose

    from .windows import EVALUATION_WINDOWS, windows_json

    windows = tuple(windows or EVALUATION_WINDOWS)
    scene = load_scene(scene_spec)
    if offset is None:
        offset_pose = scene.extra_view_offset or extra_offset_pose(*PAPER_EXTRA_OFFSET)
    else:
        offset_pose = extra_offset_pose(*offset)
    latency = LatencyModel(rate_hz=rate_hz, up_ms=latency_ms / 2, down_ms=latency_ms / 2)
    all_samples = {w.label: display_samples(scene, w.trace, w.start_s, w.duration_s, rate_hz, latency)[::stride]
                   for w in windows}
    probe = CoverageProbe(scene, view_size, out_size)
    per_window = {}
    bar = None
    try:
        if progress:
            import sys

            from tqdm import tqdm

            bar = tqdm(total=sum(len(s) for s in all_samples.values()), unit="frame", desc="coverage",
                       file=sys.stderr, leave=False,
                       disable=None)  # None: no bar when stderr is not a terminal
        for label, samples in all_samples.items():
            series = {}
            for s in samples:
                for k, vals in measure_coverage(probe, [s], offset_pose).items():
                    series.setdefault(k, []).extend(vals)
                if bar is not None:
                    bar.update(1)
            sky_share = series.pop("sky_share")
            per_window[label] = {"times": [s[0] for s in samples], "missing": series,
                                 "means": {k: float(np.mean(v)) for k, v in series.items()},
                                 "nearly_all_sky_frames": int(sum(x > 0.95 for x in sky_share))}
    finally:
        if bar is not None:
            bar.close()
        probe.close()
    labels = list(per_window)
    overall = {k: float(np.mean(np.concatenate([per_window[w]["missing"][k] for w in labels])))
               for k in per_window[labels[0]]["missing"]}
    result = {"scene": scene.name, "windows": windows_json(windows, "reporting"), "latency_ms": latency_ms,
              "rate_hz": rate_hz, "stride": stride, "view_size": list(view_size), "output_size": list(out_size),
              "offset": list(offset_pose.as_array()), "tolerance": COVERAGE_TOLERANCE, "means": overall,
              "per_window": per_window}
    write_result(out_dir, "coverage.json", result)
    from .plots import plot_coverage

    plot_coverage(result, os.path.join(out_dir, "coverage.png"))
    return result


def print_coverage_table(result: dict) -> None:
    print(f"pibr bench coverage: scene {result['scene']}, {result['latency_ms']:g} ms round trip, "
          f"missing-pixel fraction % (lower is better)")
    w = result["windows"]
    if not w["disjoint_from_tuning"]:
        print("note: some windows overlap the tuning windows (bench/windows.py)")
    variants = VARIANTS + ("floor",)
    short = {"primary": "primary", "peel_no_offset": "peel, no off", "offset_no_peel": "offset, no peel",
             "offset_peel": "offset+peel", "floor": "floor"}
    head = f"{'window':<26}" + "".join(f"{short[v]:>16}" for v in variants)
    print(head)
    print("-" * len(head))
    sky = sum(d["nearly_all_sky_frames"] for d in result["per_window"].values())
    for label, d in result["per_window"].items():
        print(f"{label:<26}" + "".join(f"{100 * d['means'][v]:>16.2f}" for v in variants))
    print(f"{'all':<26}" + "".join(f"{100 * result['means'][v]:>16.2f}" for v in variants))
    print(f"{'all, geometry only':<26}" + "".join(f"{100 * result['means'][v + ':geometry']:>16.2f}" for v in variants))
    print("'geometry only' leaves out pixels showing sky.")
    if sky:
        print(f"warning: {sky} displayed frames are more than 95 % sky; there is little to cover on them")
