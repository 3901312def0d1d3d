"""``pibr bench pareto``: every client method and knob on one speed/quality chart.

The trade Reinert et al. 2016 measured in Section 6.2 (Figure 9): client milliseconds per
output frame against DSSIM to ground truth, 128 ms of latency, a 10 fps server stream, every
method fed the same transmitted views. Here every registered method runs with each of its
knobs (:func:`default_variants`) on the built-in scenes and on the evaluation windows of
bench/windows.py (disjoint from every window a default was fitted on), beside:

* a **zero-latency oracle**: the server's frame rendered at the display pose itself and passed
  through the same colour codec, shown as it is: the loss due to coding and resampling alone;
* **geometric holes**, one definition for every method: the displayed pixels whose surface
  no transmitted view the method draws from saw (``coverage.uncovered``: the primary view for
  methods that use only it, both views otherwise), reported beside each method's own holes (alpha 0: pixels where
  it accepted no transmitted sample, whatever it shows there; README, "Reading the metrics").

Quality runs the real pipeline (``simulation.Simulation``) at the display rate divided by
``stride``, one point per (scene, window), each a session of its own: in this process with the
metrics computed in a worker process while the next frame renders, or spread over Ray workers
(:mod:`.cluster`) with the same numbers.
Speed is measured afterwards in a separate pass with nothing else running, every variant on
the same frames in turn, at each output size (960x540 and 1280x720 by default): median and
mean wall-clock ms of the display pass (GPU work finished) and the process's CPU ms.
"""
from __future__ import annotations

import os
import sys
import time

import numpy as np

from pibr.common.link import SessionSchedule
from pibr.common.replay import display_samples
from pibr.server.coverage import camera_rays

from .metrics import frame_metrics, nearly_uniform, pixels_per_degree
from .results import write_result
from .simulation import BENCH_VIEW_SIZE, geometric_holes
from .variants import ORACLE, Variant, pareto_front
from .windows import EVALUATION_WINDOWS, describe_windows, windows_json

def default_variants(methods=None) -> list[Variant]:
    """Every registered method with each of its knobs (the proxy's LoD target and tau, with and
    without the extra view included); ``methods`` restricts to those names."""
    from pibr.client.methods import method_names

    table = [
        Variant("none", "none"), Variant("rotation", "rotation"),
        *(Variant(f"homography {d:g} m", "homography", {"plane_distance": d}) for d in (1.0, 2.0, 4.0, 8.0)),
        Variant("splat", "splat"), Variant("splat 3 px", "splat", {"point_size": 3.0}),
        Variant("meshwarp", "meshwarp"),
        *(Variant(f"coarse-meshwarp s={s}", "coarse-meshwarp", {"step": s}) for s in (2, 4, 8, 16)),
        *(Variant(f"quadtree {t:g}", "quadtree", {"threshold": t}) for t in (0.01, 0.05)),
        Variant("iterative", "iterative"),
        Variant("gridwarp", "gridwarp"), Variant("gridwarp, no fill", "gridwarp", {"fill": False}),
        Variant("proxy", "proxy"),
        *(Variant(f"proxy lod {p:g}px", "proxy", {"lod_target_px": p}) for p in (2.0, 16.0)),
        *(Variant(f"proxy tau {t:g}", "proxy", {"tau": t}) for t in (0.05, 0.2)),
        Variant("proxy, no extra view", "proxy", {"extra_view": False}),
        Variant("proxy, no carving", "proxy", {"carve": False}),
        Variant("proxy, no inpainting", "proxy", {"inpaint": False}),
        Variant("proxy, no culling", "proxy", {"cull": False}),
    ]
    known = set(method_names())
    wanted = known if methods is None else set(methods)
    unknown = wanted - known
    if unknown:
        from pibr.protocol.errors import ConfigError

        raise ConfigError(f"unknown method(s) {', '.join(sorted(unknown))}; choose from {', '.join(sorted(known))}")
    return [v for v in table if v.method in wanted]


def motion_variants(variants, scene) -> list[Variant]:
    """In a scene that moves, each method also with its best way of showing moving objects, so
    the table compares methods, not motion models (issue 26):

    * ``proxy`` (which places moving objects' proxies) with the bounds of placing them
      (client/object_motion.py): ``static`` (where the newest frame saw them) and ``oracle``
      (the scene's animation, a benchmark's knowledge); the default proxy variant uses the
      client's default extrapolation between them;
    * every competitor that re-projects the primary view, at its default knobs, with ``flow``
      (the frame's moving pixels warped along their decoded motion flow, client/flow_warp.py;
      ``pibr bench dynamic`` measures it as the best mode without proxies). ``none`` is the
      baseline of no compensation and gets none; ``quadtree`` and ``iterative`` warp meshes
      built from the frame as decoded and take no motion mode.
    """
    if not scene.is_dynamic:
        return []
    out = []
    if any(v.method == "proxy" and not v.options for v in variants):
        out += [Variant(f"proxy, {mode} motion", "proxy", {"motion": mode}) for mode in ("static", "oracle")]
    seen = set()
    for v in variants:
        if v.method in ("proxy", "none") or v.method in seen or not _takes_flow(v.method) or not _at_defaults(v):
            continue
        seen.add(v.method)
        out.append(Variant(f"{v.label}, flow", v.method, {**v.options, "motion": "flow"}))
    return out


def _takes_flow(method: str) -> bool:
    from pibr.client.methods import method_options

    return "motion" in method_options(method)


def _at_defaults(v: Variant) -> bool:
    """Whether every knob of ``v`` is at its method's default."""
    import inspect

    from pibr.client.methods import METHODS

    params = inspect.signature(METHODS[v.method].__init__).parameters
    return all(k in params and params[k].default == value for k, value in v.options.items())


def window_winners(variants: dict, windows) -> dict:
    """Per window, every variant's DSSIM, the lowest of all, the best ``proxy`` variant and the
    best competitor; the zero-latency oracle and ``oracle`` motion (the scene's animation, which
    no client has) are bounds, recorded but never a winner. ``variants``: label -> the scene's
    variant record."""
    out = {}
    for w in windows:
        dssim = {label: v["quality"]["per_window"][w]["dssim_mean"] for label, v in variants.items()
                 if label != ORACLE and v["quality"]["per_window"][w]["dssim_mean"] is not None}
        if not dssim:
            continue
        runnable = {k: x for k, x in dssim.items() if variants[k]["options"].get("motion") != "oracle"}
        proxies = {k: x for k, x in runnable.items() if variants[k]["method"] == "proxy"}
        others = {k: x for k, x in runnable.items() if variants[k]["method"] != "proxy"}
        best = min(runnable, key=runnable.get)
        row = {"dssim": dssim, "winner": best, "winner_dssim": dssim[best]}
        if proxies:
            k = min(proxies, key=proxies.get)
            row.update(best_proxy=k, best_proxy_dssim=proxies[k])
        if others:
            k = min(others, key=others.get)
            row.update(best_competitor=k, best_competitor_dssim=others[k])
        out[w] = row
    return out


class _Quality:
    """Per-variant series of one scene."""

    KEYS = ("psnr", "ssim", "dssim", "flip", "geometric_holes", "own_holes", "primitives", "ms")

    def __init__(self):
        self.series: dict = {}

    def extend(self, label, window, values: dict):
        s = self.series.setdefault(label, {})
        for k, v in values.items():
            s.setdefault(k, []).extend(v)
            s.setdefault(f"{window}|{k}", []).extend(v)

    def summary(self, label, windows) -> dict:
        s = self.series[label]

        def mean(key):
            vals = [v for v in s.get(key, []) if v is not None and not np.isnan(v)]
            return float(np.mean(vals)) if vals else None

        out = {f"{k}_mean": mean(k) for k in self.KEYS if k != "ms"}
        out["frames"] = len(s.get("dssim", []))
        out["flip_frames"] = sum(1 for v in s.get("flip", []) if v is not None and not np.isnan(v))
        out["per_window"] = {w: {"dssim_mean": mean(f"{w}|dssim"), "psnr_mean": mean(f"{w}|psnr"),
                                 "geometric_holes_mean": mean(f"{w}|geometric_holes")} for w in windows}
        return out


def measure_window(worker, scene_spec, variants, window, latency_ms, rate_hz, stride, view_size, out_size,
                   flip_every, depth_codec) -> dict:
    """Every variant and the oracle on one window, a session of its own: per label the scored
    ticks' values (lists), which variants use the extra view, the nearly uniform ground truths.
    A :class:`~.cluster.Point`, so its numbers do not depend on where or after what it runs."""
    from .simulation import Simulation, bench_server_config, load_proxies

    scene = worker.scene(scene_spec)
    proxies = None
    if any(v.method == "proxy" for v in variants):
        cache = worker.cache("pareto-proxies")
        if scene_spec not in cache:
            cache[scene_spec] = load_proxies(scene)[0]
        proxies = cache[scene_spec]
    schedule = SessionSchedule.round_trip(rate_hz, latency_ms)
    samples = display_samples(scene, window.trace, window.start_s, window.duration_s, schedule)[::stride]
    oracle_rate = rate_hz / stride
    ppd = pixels_per_degree(out_size[0], 90.0)
    values: dict = {}
    uniform = 0
    pending = []

    def settle(item):
        label, job, extra = item
        m = job.result()
        for k, v in dict(psnr=m["psnr"], ssim=m["ssim"], dssim=m["dssim"], flip=m["flip"], **extra).items():
            values.setdefault(label, {}).setdefault(k, []).append(v)

    # frames carry and decode their motion flow, as a client's do, for the competitors' ``flow`` variants
    sim = Simulation(scene, bench_server_config(view_size, depth_codec=depth_codec), out_size, proxies=proxies,
                     ctx=worker.ctx, keep_distances=True, flow_frames=True)
    rays = camera_rays(*out_size, sim.output.fov_deg)
    methods = {}
    try:
        methods = {v.label: sim.make_method(v.method, **v.options) for v in variants}
        methods[ORACLE] = oracle_method = sim.make_method("none")
        uses_extra = {label: bool(m.uses_extra_view) for label, m in methods.items() if label != ORACLE}
        for i, (t_disp, display, t_render, rendered) in enumerate(samples):
            frame = sim.frame_at(t_render, rendered)
            gt = sim.ground_truth(display, t_disp)
            uniform += nearly_uniform(gt)
            geo = geometric_holes(rays, display, sim.ground_truth_distance(), frame, sim.distances,
                                  bool(sim.session.options.get("peel_marker")))
            with_flip = flip_every > 0 and i % flip_every == 0
            shown = []
            for v in variants:
                rgb, own, ms, _ = sim.display_timed(methods[v.label], display, frame, t_disp)
                shown.append((v.label, rgb, own, ms, methods[v.label].last_primitives,
                              geo["both" if uses_extra[v.label] else "primary"]))
            oframe, otextures = sim.oracle_frame(t_disp, display, oracle_rate)
            rgb, own, ms, _ = sim.display_timed(oracle_method, display, oframe, t_disp, otextures)
            shown.append((ORACLE, rgb, own, ms, 0, 0.0))
            for label, rgb, own, ms, prims, holes in shown:
                pending.append((label, worker.submit(frame_metrics, gt, rgb, ppd, with_flip),
                                dict(own_holes=own, ms=ms, primitives=prims, geometric_holes=holes)))
            while len(pending) > 8 * len(shown):
                settle(pending.pop(0))
        while pending:
            settle(pending.pop(0))
        flow_frames = sim.motion_decoder is not None
    finally:
        for m in methods.values():
            m.release()
        sim.close()
    return {"values": values, "uses_extra": uses_extra, "uniform": int(uniform), "frames": len(samples),
            "flow_frames": flow_frames}


def _scene_points(scene, scene_spec, variants, windows, latency_ms, rate_hz, stride, view_size, out_size,
                  flip_every, depth_codec):
    """(the variants with the scene's motion variants, display samples per window, one
    :func:`measure_window` point per window)."""
    from .cluster import Point

    variants = [*variants, *motion_variants(variants, scene)]
    schedule = SessionSchedule.round_trip(rate_hz, latency_ms)
    samples = {w.label: display_samples(scene, w.trace, w.start_s, w.duration_s, schedule)[::stride]
               for w in windows}
    points = [Point(measure_window, dict(scene_spec=scene_spec, variants=tuple(variants), window=w,
                                         latency_ms=latency_ms, rate_hz=rate_hz, stride=stride,
                                         view_size=tuple(view_size), out_size=tuple(out_size), flip_every=flip_every,
                                         depth_codec=depth_codec),
                    cost=len(samples[w.label]) * len(variants), ticks=len(samples[w.label]),
                    name=f"{scene.name} {w.label}")
              for w in windows]
    return variants, samples, points


def _scene_result(scene, variants, samples, parts, rate_hz, stride, view_size, out_size, speed_sizes, speed_frames,
                  depth_codec, bar) -> dict:
    """One scene's quality (its windows' :func:`measure_window` results, in window order) and the
    variants' speed, measured here and now with nothing else running."""
    from .simulation import load_proxies

    windows = list(samples)
    quality = _Quality()
    for window, part in zip(windows, parts):
        for label, vals in part["values"].items():
            quality.extend(label, window, vals)
    uses_extra = parts[0]["uses_extra"]
    proxies, bundle = load_proxies(scene) if any(v.method == "proxy" for v in variants) else (None, None)
    speed = _measure_speed(scene, variants, samples, proxies, view_size, speed_sizes, speed_frames, depth_codec, bar)
    views_px = view_size[0] * view_size[1]
    result = {"scene": scene.name, "view_size": list(view_size), "output": list(out_size), "stride": stride,
              "flow_frames": parts[0]["flow_frames"],   # frames decoded with their motion flow
              "oracle_rate_hz": rate_hz / stride, "frames": {w: len(s) for w, s in samples.items()},
              "nearly_uniform_frames": {w: part["uniform"] for w, part in zip(windows, parts)}, "variants": {}}
    if bundle is not None:
        result["proxies"] = bundle.info(1 << 20)
    for v in [*variants, Variant(ORACLE, "none")]:
        q = quality.summary(v.label, windows)
        q["primitives_per_view_pixel"] = (q["primitives_mean"] or 0.0) / views_px
        result["variants"][v.label] = {**v.to_json(), "uses_extra_view": uses_extra.get(v.label, False),
                                       "quality": q, "speed": speed.get(v.label, {})}
    result["per_window"] = window_winners(result["variants"], windows)
    return result


def _measure_speed(scene, variants, samples, proxies, view_size, sizes, frames, depth_codec, bar) -> dict:
    """label -> size -> {ms_median, ms_mean, cpu_ms_median}; every variant on the same frames in turn."""
    from .simulation import Simulation, bench_server_config

    per_window = max(1, -(-frames // len(samples)))
    chosen = [s for ws in samples.values() for s in ws[:per_window]][:frames]
    out: dict = {}
    for size in sizes:
        key = f"{size[0]}x{size[1]}"
        sim = Simulation(scene, bench_server_config(view_size, depth_codec=depth_codec), size, proxies=proxies,
                         keep_distances=True, flow_frames=True)
        try:
            methods = {v.label: sim.make_method(v.method, **v.options) for v in variants}
            methods[ORACLE] = sim.make_method("none")
            times = {label: ([], []) for label in methods}
            for t_disp, display, t_render, rendered in chosen:
                frame = sim.frame_at(t_render, rendered)
                for _ in range(2):      # the first display of a frame pays its per-frame work
                    for label, m in methods.items():
                        _, _, ms, cpu = sim.display_timed(m, display, frame, t_disp)
                        times[label][0].append(ms)
                        times[label][1].append(cpu)
                if bar is not None:
                    bar.update(1)
            for label, (ms, cpu) in times.items():
                out.setdefault(label, {})[key] = {"ms_median": float(np.median(ms)), "ms_mean": float(np.mean(ms)),
                                                  "cpu_ms_median": float(np.median(cpu)), "frames": len(ms)}
            for m in methods.values():
                m.release()
        finally:
            sim.close()
            sim.ctx.release()
    return out


def run_pareto_bench(scenes=("room",), methods=None, windows=EVALUATION_WINDOWS, latency_ms=128.0,
                     rate_hz=30.0, stride=8, view_size=BENCH_VIEW_SIZE, out_size=(960, 540),
                     speed_sizes=((960, 540), (1280, 720)), speed_frames=12, flip_every=4, depth_codec="h264",
                     placement=None, out_dir="out/bench", progress=True) -> dict:
    """Quality of every variant per (scene, window) point, run where ``placement`` says (default
    this process; :class:`~.cluster.Placement`), then each scene's speed in this process."""
    from pibr.scenes.registry import load_scene

    from .cluster import Placement, run_points

    placement = placement or Placement()
    variants = default_variants(methods)
    loaded = {spec: load_scene(spec) for spec in scenes}
    planned = {spec: _scene_points(scene, spec, variants, windows, latency_ms, rate_hz, stride, view_size, out_size,
                                   flip_every, depth_codec) for spec, scene in loaded.items()}
    bar = None
    if progress:
        from tqdm import tqdm

        total = sum(p.ticks for _, _, points in planned.values() for p in points)
        total += speed_frames * len(speed_sizes) * len(loaded)
        bar = tqdm(total=total, unit="frame", desc="bench pareto", file=sys.stderr, leave=False, disable=None)
    t0 = time.perf_counter()
    try:
        ran = {}
        parts = iter(run_points([p for _, _, points in planned.values() for p in points], placement, bar, ran=ran))
        per_scene = {}
        for spec, scene in loaded.items():
            scene_variants, samples, points = planned[spec]
            per_scene[scene.name] = _scene_result(scene, scene_variants, samples, [next(parts) for _ in points],
                                                  rate_hz, stride, view_size, out_size, speed_sizes, speed_frames,
                                                  depth_codec, bar)
    finally:
        if bar is not None:
            bar.close()
    result = {"latency_ms": latency_ms, "rate_hz": rate_hz, "server_fps": 10.0, "depth_codec": depth_codec,
              "windows": windows_json(windows, "reporting"), "placement": placement.to_json(ran), "scenes": per_scene,
              "seconds": time.perf_counter() - t0}
    write_result(out_dir, "pareto.json", result)
    from .plots import plot_pareto

    plot_pareto(result, os.path.join(out_dir, "pareto.png"))
    return result


def print_pareto_table(r: dict) -> None:
    print(f"pibr bench pareto: {r['latency_ms']:g} ms round trip, {r['depth_codec']} depth, "
          f"{describe_windows(r['windows'])}")
    for scene, s in r["scenes"].items():
        sizes = list(next(iter(s["variants"].values()))["speed"])
        uniform, frames = sum(s["nearly_uniform_frames"].values()), sum(s["frames"].values())
        if uniform:
            print(f"\nwarning: {uniform} of {frames} ground-truth frames of {scene} are nearly one colour (sky or a "
                  "wall filling the view); every method scores well on them")
        head = (f"\n{scene}: {'variant':<26}{'DSSIM':>8}{'PSNR':>7}{'FLIP':>7}{'geo holes %':>12}{'own %':>7}"
                + "".join(f"{'ms ' + z:>14}" for z in sizes) + f"{'prims/px':>9}")
        print(head)
        points = {}
        for label, v in s["variants"].items():
            q, sp = v["quality"], v["speed"]
            flip = "-" if q["flip_mean"] is None else f"{q['flip_mean']:.3f}"
            ms = "".join(f"{sp[z]['ms_median']:>14.1f}" if z in sp else f"{'-':>14}" for z in sizes)
            print(f"  {label:<32}{q['dssim_mean']:>8.4f}{q['psnr_mean']:>7.2f}{flip:>7}"
                  f"{100 * q['geometric_holes_mean']:>12.2f}{100 * q['own_holes_mean']:>7.2f}{ms}"
                  f"{q['primitives_per_view_pixel']:>9.3f}")
            if sizes and sizes[0] in sp and label != ORACLE:
                points[label] = (sp[sizes[0]]["ms_median"], q["dssim_mean"])
        if points:
            print(f"  Pareto front at {sizes[0]}: {' -> '.join(pareto_front(points))}")
        print(f"\n{scene}: per window, the lowest DSSIM (zero-latency oracle aside), the best proxy variant and the best "
              "competitor")
        for w, row in s.get("per_window", {}).items():
            print(f"  {w:<26} {row['winner']:<28}{row['winner_dssim']:.4f}   "
                  f"{row.get('best_proxy', '-'):<24}{row.get('best_proxy_dssim', float('nan')):.4f}   "
                  f"{row.get('best_competitor', '-'):<24}{row.get('best_competitor_dssim', float('nan')):.4f}")
