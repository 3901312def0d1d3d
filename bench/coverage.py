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

Frames follow the virtual clock's schedule (pibr.common.link.SessionSchedule): at display
time t the client shows the newest server frame usable by then, rendered from the newest pose
that had reached the server.
"""
from __future__ import annotations

import os

import numpy as np

from pibr.common.link import SessionSchedule
from pibr.common.replay import display_samples
from pibr.protocol.pose import Pose
from pibr.server.coverage import COVERAGE_TOLERANCE, CoverageProbe

from .results import write_result
from .simulation import BENCH_VIEW_SIZE

VARIANTS = ("primary", "peel_no_offset", "offset_no_peel", "offset_peel")
VARIANT_LABELS = {"primary": "primary only", "peel_no_offset": "extra: peeling, no offset",
                  "offset_no_peel": "extra: offset, no peeling", "offset_peel": "extra: offset + peeling",
                  "floor": "primary, no latency (floor)"}


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


def measure_window(worker, scene_spec, window, latency_ms, rate_hz, view_size, out_size, offset: Pose,
                   stride) -> dict:
    """One window's missing fractions per variant and sample (:func:`measure_coverage`), the
    samples' display times and how many were nearly all sky. A :class:`~.cluster.Point`; the
    probe (its GL targets and renderer) is kept by the worker between windows."""
    scene = worker.scene(scene_spec)
    probes = worker.cache("coverage-probes")
    key = (scene_spec, tuple(view_size), tuple(out_size))
    if key not in probes:
        probes[key] = CoverageProbe(scene, view_size, out_size, ctx=worker.ctx)
    schedule = SessionSchedule.round_trip(rate_hz, latency_ms)
    samples = display_samples(scene, window.trace, window.start_s, window.duration_s, schedule)[::stride]
    series = measure_coverage(probes[key], samples, offset)
    sky_share = series.pop("sky_share")
    return {"times": [s[0] for s in samples], "missing": series,
            "means": {k: float(np.mean(v)) for k, v in series.items()},
            "nearly_all_sky_frames": int(sum(x > 0.95 for x in sky_share))}


def run_coverage_bench(scene_spec="room", windows=None, latency_ms=128.0, rate_hz=30.0, view_size=BENCH_VIEW_SIZE,
                       out_size=(320, 180), offset=None, stride=2, placement=None, out_dir="out/bench",
                       progress=True) -> dict:
    """``pibr bench coverage``: JSON and plot of the four variants' missing-pixel fractions,
    per window (default: the evaluation windows of bench/windows.py), one point per window run
    where ``placement`` says (default this process; :class:`~.cluster.Placement`)."""
    from pibr.scenes.registry import load_scene
    from pibr.server.config import PAPER_EXTRA_OFFSET, extra_offset_pose

    from .cluster import Placement, Point, run_points
    from .windows import EVALUATION_WINDOWS, windows_json

    placement = placement or Placement()
    windows = tuple(windows or EVALUATION_WINDOWS)
    scene = load_scene(scene_spec)
    if offset is None:
        offset_pose = scene.extra_view_offset or extra_offset_pose(*PAPER_EXTRA_OFFSET)
    else:
        offset_pose = extra_offset_pose(*offset)
    schedule = SessionSchedule.round_trip(rate_hz, latency_ms)
    counts = {w.label: len(display_samples(scene, w.trace, w.start_s, w.duration_s, schedule)[::stride])
              for w in windows}
    points = [Point(measure_window, dict(scene_spec=scene_spec, window=w, latency_ms=latency_ms, rate_hz=rate_hz,
                                         view_size=tuple(view_size), out_size=tuple(out_size), offset=offset_pose,
                                         stride=stride), cost=counts[w.label], ticks=counts[w.label], name=w.label)
              for w in windows]
    bar = None
    try:
        if progress:
            import sys

            from tqdm import tqdm

            bar = tqdm(total=sum(counts.values()), unit="frame", desc="coverage", file=sys.stderr, leave=False,
                       disable=None)  # None: no bar when stderr is not a terminal
        ran = {}
        per_window = dict(zip(counts, run_points(points, placement, bar, ran=ran)))
    finally:
        if bar is not None:
            bar.close()
    labels = list(per_window)
    overall = {k: float(np.mean(np.concatenate([per_window[w]["missing"][k] for w in labels])))
               for k in per_window[labels[0]]["missing"]}
    result = {"scene": scene.name, "windows": windows_json(windows, "reporting"), "latency_ms": latency_ms,
              "rate_hz": rate_hz, "stride": stride, "view_size": list(view_size), "output_size": list(out_size),
              "offset": list(offset_pose.as_array()), "tolerance": COVERAGE_TOLERANCE, "means": overall,
              "placement": placement.to_json(ran), "per_window": per_window}
    write_result(out_dir, "coverage.json", result)
    from .plots import plot_coverage

    plot_coverage(result, os.path.join(out_dir, "coverage.png"), VARIANTS, VARIANT_LABELS)
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
