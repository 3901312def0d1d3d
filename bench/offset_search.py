"""``pibr bench optimize-offset``: the extra view's offset that leaves the fewest holes.

Reinert et al. search exhaustively over the offset's forward/back distance, its height and
its tilt (no sideways offset, no yaw: head motion is symmetric left-right) for the lowest
mean missing-pixel fraction over recorded traces. The objective here is exactly
``bench/coverage.py``'s "offset + peeling" variant on a fixed set of displayed frames.

Each frame's ground truth and primary view are rendered once and reused for every
candidate offset; a candidate costs one peeled extra-view render per frame.

``method="coarse-to-fine"`` evaluates every other grid value per axis, then refines the
full-resolution neighbourhood of the best few candidates until the best stops moving; it
returns the exhaustive grid's optimum whenever the surface is smooth at the coarse scale
(a test checks one such case).
"""
from __future__ import annotations

import itertools
import os
import sys

import numpy as np

from pibr.common.link import SessionSchedule
from pibr.common.replay import display_samples
from pibr.server.coverage import CoverageProbe

from .results import write_result


def parse_range(text: str) -> list[float]:
    """``"a:b:step"`` (inclusive) or ``"x,y,z"`` -> values."""
    text = text.strip()
    if ":" in text:
        parts = [float(x) for x in text.split(":")]
        if len(parts) != 3 or parts[2] <= 0 or parts[1] < parts[0]:
            raise ValueError(f"expected START:STOP:STEP with STEP > 0 and STOP >= START, got {text!r}")
        n = int(np.floor((parts[1] - parts[0]) / parts[2] + 1e-9)) + 1
        return [round(parts[0] + i * parts[2], 9) for i in range(n)]
    values = [float(x) for x in text.split(",") if x.strip()]
    if not values:
        raise ValueError(f"no values in {text!r}")
    return sorted(set(values))


class OffsetObjective:
    """Mean missing fraction of the peeled extra view at a candidate offset over fixed frames."""

    def __init__(self, probe: CoverageProbe, samples, objective: str = "all"):
        if objective not in ("all", "geometry"):
            raise ValueError("objective must be 'all' or 'geometry'")
        self.probe, self.objective = probe, objective
        self.frames = []
        for t_disp, display, t_render, rendered in samples:
            points, sky, dirs = probe.display_points(display, t_disp)
            primary = probe.render_primary(rendered, t_render)
            self.frames.append((points, sky, dirs, rendered, primary, t_render))
        self.evaluations = 0

    def __call__(self, forward: float, up: float, tilt_deg: float) -> float:
        from pibr.server.config import extra_offset_pose

        offset = extra_offset_pose(forward, up, tilt_deg)
        values = []
        for points, sky, dirs, rendered, primary, t in self.frames:
            self.probe.load_primary(primary)
            extra = self.probe.render_extra(rendered, offset, t, peel=True)
            everything, geometry = self.probe.missing(
                points, sky, dirs, [(rendered, primary, False), (rendered.compose(offset), extra, True)])
            values.append(everything if self.objective == "all" else geometry)
        self.evaluations += 1
        return float(np.mean(values))


def exhaustive(objective, axes, progress=None) -> dict:
    """Evaluate every grid point. -> {(i, j, k): value}."""
    out = {}
    for idx in itertools.product(*(range(len(a)) for a in axes)):
        out[idx] = objective(*(a[i] for a, i in zip(axes, idx)))
        if progress:
            progress()
    return out


def coarse_to_fine(objective, axes, keep: int = 3, progress=None) -> dict:
    """Every other value per axis first, then full resolution around the best ``keep`` points."""
    out = {}

    def evaluate(idx):
        if idx not in out:
            out[idx] = objective(*(a[i] for a, i in zip(axes, idx)))
            if progress:
                progress()

    coarse = [sorted(set(range(0, len(a), 2)) | {len(a) - 1}) for a in axes]
    for idx in itertools.product(*coarse):
        evaluate(idx)
    centres: set = set()
    while True:
        best = sorted(out, key=out.get)[:keep]
        new = [c for c in best if c not in centres]
        if not new:
            return out
        for c in new:
            centres.add(c)
            ranges = [range(max(0, i - 2), min(len(a), i + 3)) for a, i in zip(axes, c)]
            for idx in itertools.product(*ranges):
                evaluate(idx)


def search_offset(scene_spec="room", windows=None, latency_ms=128.0, rate_hz=30.0, frames_per_window=12,
                  forward=(-1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0), up=(0.0, 0.3, 0.6, 0.9, 1.2, 1.5, 1.8),
                  tilt=(-30.0, -15.0, 0.0, 15.0, 30.0, 45.0), method="exhaustive", view_size=(512, 512),
                  out_size=(192, 108), objective="all", out_dir="out/bench", progress=True) -> dict:
    from pibr.scenes.registry import load_scene

    if method not in ("exhaustive", "coarse-to-fine"):
        raise ValueError("method must be 'exhaustive' or 'coarse-to-fine'")
    scene = load_scene(scene_spec)
    schedule = SessionSchedule.round_trip(rate_hz, latency_ms)
    from .windows import TUNING_WINDOWS, windows_json

    windows = tuple(windows or TUNING_WINDOWS)     # a search fits a default: tuning windows only
    samples = []
    for w in windows:
        s = display_samples(scene, w.trace, w.start_s, w.duration_s, schedule)
        stride = max(1, len(s) // frames_per_window)
        samples += s[::stride][:frames_per_window]
    axes = [list(forward), list(up), list(tilt)]
    probe = CoverageProbe(scene, view_size, out_size)
    bar = None
    try:
        f = OffsetObjective(probe, samples, objective)
        total = int(np.prod([len(a) for a in axes]))
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=total, unit="offset", desc=f"offset search ({method})", file=sys.stderr, leave=False,
                       disable=None)
        step = bar.update if bar is not None else None
        values = exhaustive(f, axes, step) if method == "exhaustive" else coarse_to_fine(f, axes, progress=step)
    finally:
        if bar is not None:
            bar.close()
        probe.close()
    surface = np.full([len(a) for a in axes], np.nan)
    for idx, v in values.items():
        surface[idx] = v
    best_idx = min(values, key=values.get)
    best = {"forward": axes[0][best_idx[0]], "up": axes[1][best_idx[1]], "tilt": axes[2][best_idx[2]],
            "missing": values[best_idx]}
    result = {"scene": scene.name, "windows": windows_json(windows, "tuning"), "latency_ms": latency_ms,
              "method": method,
              "objective": objective, "frames": len(samples), "evaluations": len(values),
              "grid": {"forward": axes[0], "up": axes[1], "tilt": axes[2]},
              "surface": np.where(np.isfinite(surface), surface, None).tolist(), "best": best,
              "view_size": list(view_size), "output_size": list(out_size)}
    if out_dir:
        write_result(out_dir, "offset_search.json", result)
        from .plots import plot_offset_search

        plot_offset_search({**result, "surface": surface.tolist()}, os.path.join(out_dir, "offset_search.png"))
    return result
