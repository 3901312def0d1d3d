"""``pibr bench trade``: what each knob buys, with the others at their defaults.

One sweep per knob, every point on the same display ticks of the same head-trace windows:

* **stream knobs** (a new server stream per point): colour bitrate, x264 preset, keyframe
  interval, primary view size, the extra view's size, server frame rate, and the network:
  round-trip latency, jitter, a bandwidth cap. Every server frame is rendered, encoded and
  decoded in order, on the schedule of :class:`~pibr.common.link.SessionSchedule` (the relay's
  link model per direction: jitter from a seeded generator, frames queueing behind each other
  under a cap, the real clock's limit of frames in flight);
* **client knobs** (the default stream, shown again): the proxy's tau and depth slack, and the
  proxies' LoD voxel resolution and decimation fraction (a bundle built with those settings).

Per point and method: DSSIM, PSNR, FLIP (every ``flip_every``-th scored tick), geometric holes
(pareto's definition: ``coverage.uncovered`` over the views the method draws from), the CPU ms
of the client's display pass (median), the server's CPU ms per frame (render, pack and every
encoder; median), total bits per frame (colour + depth + motion), and the age of the frame
shown (display time minus render time). Ground truth does not depend on any knob: it is
rendered once per scored tick and reused by every point.
"""
from __future__ import annotations

import collections
import dataclasses
import os
import sys
import time
from dataclasses import dataclass

import numpy as np

from pibr.common.link import LinkParams, SessionSchedule
from pibr.common.replay import trace_poses
from pibr.protocol.errors import ConfigError
from pibr.server.config import DEFAULT_MAX_IN_FLIGHT
from pibr.server.coverage import camera_rays

from .metrics import frame_metrics, nearly_uniform, pixels_per_degree
from .results import write_result
from .simulation import BENCH_VIEW_SIZE, geometric_holes
from .variants import Variant, sweep_labels
from .windows import EVALUATION_WINDOWS, describe_windows, windows_json

#: rotation, proxy, and the best competitors of ``pibr bench pareto`` (README: gridwarp, and
#: coarse-meshwarp with a vertex every 4th pixel, the fastest of the warps within 45 % of proxy).
DEFAULT_METHODS = (Variant("rotation", "rotation"), Variant("proxy", "proxy"), Variant("gridwarp", "gridwarp"),
                   Variant("coarse-meshwarp s=4", "coarse-meshwarp", {"step": 4}))


@dataclass(frozen=True)
class StreamPoint:
    """What the server sends and how the network carries it (defaults: the server's and pareto's)."""

    bitrate_kbps: float = 16000.0
    preset: str = "ultrafast"
    keyint: int = 30
    view_size: tuple = BENCH_VIEW_SIZE
    extra_scale: float = 0.5          # 0: no extra view
    fps: float = 10.0
    latency_ms: float = 128.0         # round trip, half each way
    jitter_ms: float = 0.0            # each direction, uniform +-
    cap_kbps: float = 0.0             # downlink cap, 0: none

    def to_json(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(self).items()}

    def server_config(self):
        """The server's settings of this point (the network's are the schedule's)."""
        from .simulation import bench_server_config

        extra = {"extra_view": "off"} if self.extra_scale == 0 else {"extra_scale": self.extra_scale}
        return bench_server_config(self.view_size, fps=self.fps, bitrate_kbps=self.bitrate_kbps, keyint=self.keyint,
                                   preset=self.preset, **extra)


def default_stream(out_size=(960, 540), fov_deg: float = 90.0) -> StreamPoint:
    """The server's own defaults (server/config.py; the primary view as its plan sizes it for an
    ``out_size`` output), 128 ms round trip as pareto's."""
    from pibr.server.config import ServerConfig
    from pibr.server.scene_plan import view_side_for

    c = ServerConfig()
    if c.view_size is not None:
        view = tuple(c.view_size)
    else:
        view = (view_side_for(out_size[0], fov_deg),) * 2
    return StreamPoint(c.bitrate_kbps, c.preset, c.keyint, view, c.extra_scale, c.fps)


def default_client() -> dict:
    """The client knobs' defaults: proxy tau and depth slack (h264), LoD settings."""
    from pibr.client.frame_textures import DEPTH_SLACK_CODES
    from pibr.client.methods.proxy import DEFAULT_TAU
    from pibr.server.proxies import ProxySettings

    p = ProxySettings()
    return {"tau": DEFAULT_TAU, "slack": DEPTH_SLACK_CODES["h264"], "lod_resolution": p.resolution,
            "lod_fraction": p.target_fraction}


@dataclass(frozen=True)
class Knob:
    name: str
    values: tuple
    unit: str
    client: bool = False      # only the client's proxy changes: shown on the default stream


def _square(n):
    return (n, n)


#: The knobs and the values each is swept over (the default is always added).
KNOBS = {
    "bitrate": Knob("bitrate", (1000.0, 2000.0, 4000.0, 8000.0, 16000.0), "kbit/s"),
    "preset": Knob("preset", ("ultrafast", "veryfast", "medium"), ""),
    "keyint": Knob("keyint", (10, 30, 100), "frames"),
    "view": Knob("view", (512, 768, 1024, 1536, 2048), "px"),
    "extra": Knob("extra", (0.0, 0.5, 0.71, 1.0), "x primary"),
    "fps": Knob("fps", (5.0, 10.0, 20.0), "fps"),
    "latency": Knob("latency", (0.0, 32.0, 64.0, 128.0, 256.0), "ms"),
    "jitter": Knob("jitter", (0.0, 10.0, 30.0), "ms"),
    "cap": Knob("cap", (0.0, 2000.0, 4000.0, 8000.0, 32000.0), "kbit/s"),
    "tau": Knob("tau", (0.025, 0.05, 0.1, 0.2, 0.4), "", client=True),
    "slack": Knob("slack", (0.0, 1.0, 2.5, 5.0, 10.0), "codes", client=True),
    "lod_resolution": Knob("lod_resolution", (64, 128, 256), "voxels", client=True),
    "lod_fraction": Knob("lod_fraction", (0.002, 0.005, 0.02), "", client=True),
}

_STREAM_FIELD = {"bitrate": "bitrate_kbps", "preset": "preset", "keyint": "keyint", "view": "view_size",
                 "extra": "extra_scale", "fps": "fps", "latency": "latency_ms", "jitter": "jitter_ms",
                 "cap": "cap_kbps"}


def parse_knobs(text: str) -> tuple:
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    unknown = [n for n in names if n not in KNOBS]
    if unknown or not names:
        raise ConfigError(f"unknown knob(s) {', '.join(unknown) or '(none)'}; choose from {', '.join(KNOBS)}")
    return names


def _stream_value(knob: str, value):
    return _square(int(value)) if knob == "view" else value


def _knob_value(point: StreamPoint, knob: str):
    v = getattr(point, _STREAM_FIELD[knob])
    return v[0] if knob == "view" else v


def _ground_truth(worker, sim, scene_spec, out_size, window, rate_hz, i, pose, t):
    """Ground truth of a scored tick (rgb (h, w, 3) uint8, radial distance (h, w) float32, nearly
    uniform), rendered once per worker: it depends on the display pose and time only."""
    cache = worker.cache("trade-ground-truth")
    key = (scene_spec, tuple(out_size), window, rate_hz, i)
    if key not in cache:
        rgb = sim.ground_truth(pose, t)
        cache[key] = (rgb, sim.ground_truth_distance(), bool(nearly_uniform(rgb)))
    return cache[key]


def _proxies(worker, scene, lod) -> tuple:
    """(proxy objects, bundle) of a LoD setting (resolution, fraction), built (or read from the LoD
    cache) once per worker."""
    from pibr.server.proxies import ProxySettings

    from .simulation import load_proxies

    cache = worker.cache("trade-proxies")
    key = (scene.name, int(lod[0]), float(lod[1]))
    if key not in cache:
        cache[key] = load_proxies(scene, settings=ProxySettings(*key[1:]))
    return cache[key]


class _Series:
    """Per-label lists of per-tick values; ``summary`` gives the point's figures."""

    def __init__(self):
        self.values: dict = collections.defaultdict(lambda: collections.defaultdict(list))

    def extend(self, label, window, values: dict):
        for k, v in values.items():
            self.values[label][k].extend(v)
            self.values[label][f"{window}|{k}"].extend(v)

    def summary(self, label, windows) -> dict:
        s = self.values[label]

        def mean(key):
            vals = [v for v in s.get(key, []) if v is not None and not np.isnan(v)]
            return float(np.mean(vals)) if vals else None

        return {"dssim": mean("dssim"), "psnr": mean("psnr"), "flip": mean("flip"),
                "geometric_holes": mean("geometric_holes"), "own_holes": mean("own_holes"),
                "client_cpu_ms": float(np.median(s["cpu_ms"])) if s.get("cpu_ms") else None,
                "frames": len(s.get("dssim", [])),
                "flip_frames": sum(1 for v in s.get("flip", []) if v is not None and not np.isnan(v)),
                "per_window_dssim": {w: mean(f"{w}|dssim") for w in windows}}


def _client_variants(knobs, methods, defaults, values_of) -> list[tuple[str, str, str, dict, tuple]]:
    """(label, knob, value, proxy options, LoD key) of the client knobs' non-default points."""
    out = []
    if not any(v.method == "proxy" for v in methods):
        return out
    lod_default = (defaults["lod_resolution"], defaults["lod_fraction"])
    for name in knobs:
        knob = KNOBS[name]
        if not knob.client:
            continue
        for value in values_of[name]:
            if value == defaults[name]:
                continue
            label = f"proxy {name}={value:g}"
            if name == "tau":
                out.append((label, name, value, {"tau": value}, lod_default))
            elif name == "slack":
                out.append((label, name, value, {"slack_codes": value}, lod_default))
            elif name == "lod_resolution":
                out.append((label, name, value, {}, (value, defaults["lod_fraction"])))
            else:
                out.append((label, name, value, {}, (defaults["lod_resolution"], value)))
    return out


def measure_window(worker, scene_spec, point: StreamPoint, window, methods, client_variants, lod_default, rate_hz,
                   stride, out_size, flip_every, seed) -> dict:
    """One stream point on one window, a session of its own that starts with the window: per method
    label the scored ticks' values (lists), the stream's per-frame figures, the scored ticks whose
    ground truth is nearly uniform, and the proxy bundles' sizes. A :class:`~.cluster.Point`."""
    from .simulation import Simulation

    scene = worker.scene(scene_spec)
    bundles = {lod: _proxies(worker, scene, lod) for lod in {lod_default} | {v[4] for v in client_variants}}
    proxies = bundles[lod_default][0]
    sim = Simulation(scene, point.server_config(), out_size, proxies=proxies, ctx=worker.ctx, keep_distances=True)
    ppd = pixels_per_degree(out_size[0], sim.output.fov_deg)
    rays = camera_rays(*out_size, sim.output.fov_deg)
    peeled_marked = bool(sim.session.options.get("peel_marker"))
    stream = {"bits": [], "server_cpu_ms": [], "age_ms": [], "skipped": 0, "unserved_ticks": 0, "span_us": 0,
              "delivered_bits": 0, "atlas": [sim.spec.layout.width, sim.spec.layout.height]}
    values = collections.defaultdict(lambda: collections.defaultdict(list))
    uniform = []
    made = {}
    pending = []

    def settle(item):
        label, job, extra = item
        m = job.result()
        for k, v in dict(psnr=m["psnr"], dssim=m["dssim"], flip=m["flip"], **extra).items():
            values[label][k].append(v)

    try:
        for v in methods:
            made[v.label] = sim.make_method(v.method, **v.options)
        for label, _, _, options, lod in client_variants:
            sim.proxies = bundles[lod][0]
            made[label] = sim.make_method("proxy", **options)
        sim.proxies = proxies
        uses_extra = {label: bool(m.uses_extra_view) for label, m in made.items()}
        ticks, pose_at = trace_poses(scene, window.trace, window.start_s, window.duration_s, rate_hz)
        half = point.latency_ms / 2
        schedule = SessionSchedule(rate_hz, point.fps, LinkParams(half, point.jitter_ms),
                                   LinkParams(half, point.jitter_ms, point.cap_kbps), seed=seed,
                                   max_in_flight=DEFAULT_MAX_IN_FLIGHT)
        in_flight = collections.deque()
        shown = shown_distances = None
        first_render = None
        for i, t_us in enumerate(ticks):
            while (due := schedule.next_due(t_us)) is not None:
                render_us, pose_us = due
                first_render = render_us if first_render is None else first_render
                frame, distances = sim.serve(render_us / 1e6, pose_at(pose_us))
                bits = sim.frame_bits()
                stream["bits"].append(bits)
                stream["server_cpu_ms"].append(sim.server_cpu_ms[-1])
                in_flight.append((schedule.sent(render_us, bits // 8), frame, distances, bits))
            while in_flight and in_flight[0][0] <= t_us:
                _, frame, distances, bits = in_flight.popleft()
                stream["delivered_bits"] += bits
                sim.receive(frame, distances)
                shown, shown_distances = frame, distances
            if i % stride:
                continue
            if shown is None:
                stream["unserved_ticks"] += 1
                continue
            t = t_us / 1e6
            display = pose_at(t_us)
            stream["age_ms"].append((t_us - shown.render_t_us) / 1e3)
            gt_rgb, gt_distance, flat = _ground_truth(worker, sim, scene_spec, out_size, window, rate_hz, i,
                                                      display, t)
            if flat:
                uniform.append(i)
            geo = geometric_holes(rays, display, gt_distance, shown, shown_distances, peeled_marked)
            with_flip = flip_every > 0 and (i // stride) % flip_every == 0
            for label, m in made.items():
                rgb, own, _, cpu = sim.display_timed(m, display, shown, t)
                pending.append((label, worker.submit(frame_metrics, gt_rgb, rgb, ppd, with_flip),
                                dict(cpu_ms=cpu, own_holes=own,
                                     geometric_holes=geo["both" if uses_extra[label] else "primary"])))
            while len(pending) > 4 * len(made):
                settle(pending.pop(0))
        while pending:
            settle(pending.pop(0))
        stream["skipped"] = schedule.skipped
        # from the first frame served (the pre-roll's, before the window) to the window's end
        stream["span_us"] = ticks[-1] + schedule.tick_us - (first_render if first_render is not None else 0)
    finally:
        for m in made.values():
            m.release()
        sim.close()
    return {"labels": {label: dict(v) for label, v in values.items()}, "stream": stream, "uniform": uniform,
            "proxy_bundles": {f"{r}/{f:g}": {"bytes": len(b.compressed), "triangles": b.triangles}
                              for (r, f), (_, b) in bundles.items()}}


def _point_figures(parts: list, windows) -> dict:
    """A stream point's figures from its windows' :func:`measure_window` results (in window order)."""
    series = _Series()
    stream = {"bits": [], "server_cpu_ms": [], "age_ms": []}
    counts = collections.Counter()
    for w, part in zip(windows, parts):
        for label, values in part["labels"].items():
            series.extend(label, w.label, values)
        for k in stream:
            stream[k].extend(part["stream"][k])
        for k in ("skipped", "unserved_ticks", "span_us", "delivered_bits"):
            counts[k] += part["stream"][k]
    labels = [w.label for w in windows]
    span = max(counts["span_us"], 1)
    return {"stream": {"bits_per_frame": float(np.mean(stream["bits"])),
                       # what was sent (frames skipped under a cap or the in-flight limit send nothing)
                       "kbps": float(np.sum(stream["bits"]) / span * 1e3),
                       # ... and what reached the client by the window's end
                       "delivered_kbps": float(counts["delivered_bits"] / span * 1e3),
                       "server_cpu_ms": float(np.median(stream["server_cpu_ms"])),
                       "age_ms_mean": float(np.mean(stream["age_ms"])) if stream["age_ms"] else None,
                       "frames_served": len(stream["bits"]), "frames_skipped": counts["skipped"],
                       "ticks_without_frame": counts["unserved_ticks"], "atlas": parts[0]["stream"]["atlas"]},
            "methods": {label: series.summary(label, labels) for label in series.values}}


def _point_cost(point: StreamPoint, scored_ticks: int, labels: int, window_s: float) -> float:
    """A rough CPU-s estimate of one window of a point: server frames (~0.5 s per 1024^2 primary,
    the extra view by its area) and ~0.25 s per method and scored tick (display and scoring)."""
    area = point.view_size[0] * point.view_size[1] / 1024 ** 2 * (1 + point.extra_scale ** 2)
    return 0.5 * area * point.fps * (window_s + point.latency_ms / 1e3) + 0.25 * scored_ticks * labels


def run_trade_bench(scenes=("room",), knobs=tuple(KNOBS), windows=EVALUATION_WINDOWS, purpose=None,
                    methods=DEFAULT_METHODS, rate_hz=30.0, stride=16, out_size=(960, 540), flip_every=4,
                    window_s=None, stream=None, values=None, seed=0, placement=None, out_dir="out/bench",
                    progress=True) -> dict:
    """Sweep ``knobs`` (names of :data:`KNOBS`) one at a time; write trade.json and one plot per
    knob. ``window_s``: keep only the first seconds of each window (every server frame is made,
    about 0.5 CPU-s each at 1024² on this machine); ``stream``: the default StreamPoint (None: the
    server's defaults); ``values``: knob name -> values swept instead of :data:`KNOBS`' (the
    default is always added); ``placement``: where the points run (:class:`~.cluster.Placement`,
    default this process). Each (stream point, window) is one point of the sweep, a session of its
    own, so the numbers are the same wherever and in whatever order the points run."""
    from .cluster import Placement, Point, run_points
    from .windows import overlapping_tuning

    placement = placement or Placement()
    for name in knobs:
        if name not in KNOBS:
            raise ConfigError(f"unknown knob {name!r}; choose from {', '.join(KNOBS)}")
    if window_s is not None:
        windows = tuple(dataclasses.replace(w, duration_s=min(w.duration_s, window_s)) for w in windows)
    windows = tuple(windows)
    base = stream or default_stream(out_size)
    values_of = {name: knob.values for name, knob in KNOBS.items()} | dict(values or {})
    defaults = default_client()
    lod_default = (defaults["lod_resolution"], defaults["lod_fraction"])
    purpose = purpose or ("tuning" if overlapping_tuning(windows) else "reporting")
    # stream points: the default, then every knob's other values
    points = {"default": base}
    sweeps = {}
    for name in knobs:
        knob = KNOBS[name]
        if knob.client:
            continue
        values = values_of[name]
        default_value = _knob_value(base, name)
        values = tuple(sorted(set(values) | {default_value}, key=lambda v: (isinstance(v, str), v)))
        if name == "preset":   # fastest first
            order = ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow", "slower", "veryslow")
            values = tuple(sorted(values, key=lambda v: order.index(v) if v in order else len(order)))
        sweeps[name] = []
        for value in values:
            key = "default" if value == default_value else f"{name}={value}"
            if key != "default":
                points[key] = dataclasses.replace(base, **{_STREAM_FIELD[name]: _stream_value(name, value)})
            sweeps[name].append((value, key))
    client_variants = _client_variants(knobs, methods, defaults, values_of)
    for name in knobs:
        if KNOBS[name].client:
            sweeps[name] = [(defaults[name], "proxy")] + [(value, label) for label, k, value, _, _ in client_variants
                                                         if k == name]
            sweeps[name].sort(key=lambda x: x[0])
    from pibr.scenes.registry import load_scene

    loaded = {spec: load_scene(spec) for spec in scenes}
    scored = {}
    for spec, scene in loaded.items():
        for w in windows:
            scored[spec, w] = len(trace_poses(scene, w.trace, w.start_s, w.duration_s, rate_hz)[0][::stride])
    per_tick = sum(scored[scenes[0], w] for w in windows)
    work = []     # (scene spec, point key, window) of each sweep point, in the order results are merged
    sweep_points = []
    for spec in scenes:
        for key, point in points.items():
            extra = client_variants if key == "default" else []
            for w in windows:
                work.append((spec, key, w))
                sweep_points.append(Point(
                    measure_window, dict(scene_spec=spec, point=point, window=w, methods=tuple(methods),
                                         client_variants=tuple(extra), lod_default=lod_default, rate_hz=rate_hz,
                                         stride=stride, out_size=tuple(out_size), flip_every=flip_every, seed=seed),
                    cost=_point_cost(point, scored[spec, w], len(methods) + len(extra), w.duration_s),
                    ticks=scored[spec, w], name=f"{spec} {key} {w.label}"))
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=per_tick * len(points) * len(scenes), unit="tick", desc="bench trade", file=sys.stderr,
                   leave=False, disable=None)
    t0 = time.perf_counter()
    result = {"knobs": list(knobs), "defaults": {"stream": base.to_json(), "client": defaults},
              "methods": {v.label: v.to_json() for v in methods}, "rate_hz": rate_hz, "stride": stride,
              "output": list(out_size), "flip_every": flip_every, "seed": seed,
              "windows": windows_json(windows, purpose), "placement": placement.to_json(),
              "points": len(sweep_points), "scenes": {}}
    parts: dict = {}

    def gather(final: bool) -> None:
        for spec, scene in loaded.items():
            measured, uniform, bundles = {}, set(), {}
            for key in points:
                got = [parts.get((spec, key, w)) for w in windows]
                if any(g is None for g in got):
                    continue
                measured[key] = _point_figures(got, windows)
                for w, g in zip(windows, got):
                    uniform |= {(w.label, i) for i in g["uniform"]}
                    bundles |= g["proxy_bundles"]
            if not measured and not final:
                continue
            result["scenes"][scene.name] = {
                "ticks_scored_per_point": per_tick, "nearly_uniform_ticks": len(uniform),
                "frames": {w.label: scored[spec, w] for w in windows},
                "proxy_bundles": bundles,
                "sweeps": {name: _sweep_json(name, sweep, measured, points) for name, sweep in sweeps.items()
                           if "default" in measured}}

    def on_result(i, r):
        parts[work[i]] = r
        gather(False)
        # what is measured so far, for a long run stopped early
        write_result(out_dir, "trade.json", result | {"complete": False, "seconds": time.perf_counter() - t0})

    ran = {}
    try:
        run_points(sweep_points, placement, bar, on_result, ran)
    finally:
        if bar is not None:
            bar.close()
    gather(True)
    result["placement"] = placement.to_json(ran)
    result["seconds"] = time.perf_counter() - t0
    result["complete"] = True
    write_result(out_dir, "trade.json", result)
    from .plots import plot_trade

    for name in result["knobs"]:
        plot_trade(result, name, os.path.join(out_dir, f"trade_{name}.png"), KNOBS[name].client,
                   KNOBS[name].unit)
    return result


def _sweep_json(name, sweep, measured, points) -> list[dict]:
    """The knob's curve: per value, the stream's figures and each method's (the values measured so far)."""
    out = []
    default = measured["default"]
    for value, key in sweep:
        if not KNOBS[name].client and key not in measured:
            continue
        if KNOBS[name].client:
            row = {"value": value, "stream": default["stream"], "methods": {"proxy": default["methods"][key]}}
        else:
            m = measured[key]
            row = {"value": value, "point": points[key].to_json(), "stream": m["stream"], "methods": m["methods"]}
        row["default"] = key in ("default", "proxy")
        out.append(row)
    return out


def print_trade_tables(r: dict) -> None:
    print(f"pibr bench trade: {describe_windows(r['windows'])}, every {r['stride']}th tick at "
          f"{r['rate_hz']:g} Hz, output {r['output'][0]}x{r['output'][1]}, {r['seconds']:.0f} s")
    for scene, s in r["scenes"].items():
        print(f"\n{scene}: {s['ticks_scored_per_point']} ticks scored per point")
        for name, rows in s["sweeps"].items():
            labels = sweep_labels(rows)
            unit = KNOBS[name].unit
            print(f"\n  {name} ({unit})" if unit else f"\n  {name}")
            ref_label = labels[min(1, len(labels) - 1)]
            head = (f"    {'value':>9}{'Mbit/s':>8}{'kbit/fr':>9}{'srv ms':>8}{'age ms':>8}"
                    + "".join(f"{'DSSIM ' + lab[:12]:>20}" for lab in labels)
                    + f"{'PSNR':>7}{'FLIP':>7}{'holes%':>7}{'cli ms':>8}   (last four: {ref_label})")
            print(head)
            for row in rows:
                st = row["stream"]
                ref = row["methods"][ref_label]
                value = row["value"]
                value = f"{value:g}" if isinstance(value, float) else str(value)
                age = "-" if st["age_ms_mean"] is None else f"{st['age_ms_mean']:.0f}"
                flip = "-" if ref["flip"] is None else f"{ref['flip']:.3f}"
                print(f"    {value + ('*' if row['default'] else ''):>9}{st['kbps'] / 1e3:>8.2f}"
                      f"{st['bits_per_frame'] / 1e3:>9.0f}{st['server_cpu_ms']:>8.0f}{age:>8}"
                      + "".join(f"{row['methods'][lab]['dssim']:>20.4f}" for lab in labels)
                      + f"{ref['psnr']:>7.2f}{flip:>7}{100 * ref['geometric_holes']:>7.2f}"
                        f"{ref['client_cpu_ms']:>8.0f}")
        print("\n  * the default; Mbit/s and kbit/fr: colour + depth + motion of every frame served")
