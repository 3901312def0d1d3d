"""``pibr bench predict``: how well each head-pose predictor sees ahead (server/pose_prediction.py).

The server receives the client's poses at the client's output rate; a predictor fed them in
order is asked, at every pose, for the pose ``look-ahead`` later, and compared with where the
trace really is then: position error (mm) and angular error (degrees), mean and 95th
percentile, per predictor and look-ahead (20-256 ms), per window and over all.

Windows: the evaluation windows of bench/windows.py (disjoint from tuning). ``fit=True`` runs
on the tuning windows instead and searches the Kalman filter's noise levels there (a grid, each
level's mean error over every look-ahead): the values it finds are what pose_prediction.py's
constants hold; the JSON says which windows it used and what it searched.
"""
from __future__ import annotations

import itertools
import math

import numpy as np

from pibr.protocol.pose import quat_angle

from .results import write_result
from .windows import windows_json

DEFAULT_LOOK_AHEADS_MS = (20.0, 50.0, 100.0, 128.0, 200.0, 256.0)
#: The Kalman noise levels searched with ``fit`` (process noise q, measurement noise r).
FIT_Q = (1.0, 4.0, 16.0, 64.0, 256.0, 1024.0, 4096.0)
FIT_R = (0.0005, 0.002, 0.008, 0.03, 0.1)


def prediction_errors(trace, start_s: float, duration_s: float, rate_hz: float, look_aheads_s, make) -> dict:
    """Feed a predictor (``make()``) the trace's poses at ``rate_hz`` over a window; -> {look-ahead
    s: (position errors m (n,), angular errors rad (n,))} for every pose from the third on whose
    look-ahead stays within the trace."""
    predictor = make()
    n = int(math.floor(duration_s * rate_hz + 1e-9))
    positions = {a: [] for a in look_aheads_s}
    angles = {a: [] for a in look_aheads_s}
    for k in range(n):
        t = start_s + k / rate_hz
        predictor.update(t, trace.pose_at(t))
        if k < 2:
            continue
        for a in look_aheads_s:
            if t + a > trace.duration:
                continue
            truth = trace.pose_at(t + a)
            guess = predictor.predict(a)
            positions[a].append(float(np.linalg.norm(guess.p - truth.p)))
            angles[a].append(float(quat_angle(guess.q, truth.q)))
    return {a: (np.asarray(positions[a]), np.asarray(angles[a])) for a in look_aheads_s}


#: The image-quality part: round trips, methods, windows (parts of evaluation windows), stride.
QUALITY_LATENCIES_MS = (64.0, 128.0, 256.0)
QUALITY_METHODS = ("rotation", "proxy")
QUALITY_SECONDS = 3.0
#: Its windows: the first QUALITY_SECONDS of these evaluation windows (real, walking, turning).
QUALITY_WINDOWS = (("pred6dof-1", 30.0), ("pred6dof-2", 50.0), ("synth-walk", 5.0), ("synth-turns", 5.0))
#: Its view and output sizes (as pibr bench dynamic: a few minutes on 2 cores).
QUALITY_VIEW_SIZE, QUALITY_OUT_SIZE = (512, 512), (480, 270)


def prediction_quality(windows, latencies_ms=QUALITY_LATENCIES_MS, methods=QUALITY_METHODS, rate_hz: float = 30.0,
                       stride: int = 4, view_size=None, out_size=(960, 540), scene_name: str = "room",
                       bar=None) -> dict:
    """The DSSIM of each method when the server renders every frame for the pose a predictor
    expects at the frame's display (server/pose_prediction.py display_look_ahead_s, the downlink
    taken as long as the uplink), on the virtual clock's ideal-link schedule. -> latency ms ->
    predictor -> method -> {dssim_mean, psnr_mean, frames}."""
    from pibr.common.link import SessionSchedule
    from pibr.common.replay import trace_ticks
    from pibr.common.traces.loading import load_trace
    from pibr.scenes.registry import load_scene
    from pibr.server.pose_prediction import PREDICTORS, display_look_ahead_s, make_predictor

    from .simulation import BENCH_VIEW_SIZE, Simulation, bench_server_config, evaluate_methods, load_proxies

    scene = load_scene(scene_name)
    proxies, _ = load_proxies(scene) if "proxy" in methods else (None, None)
    out = {}
    for latency in latencies_ms:
        schedule = SessionSchedule.round_trip(rate_hz, latency)
        up_us = schedule.up._delay_us
        per = out[f"{latency:g}"] = {}
        for name in PREDICTORS:
            scores = {m: {"dssim": [], "psnr": []} for m in methods}
            for w in windows:
                trace = load_trace(w.trace)
                ticks, pose_at = trace_ticks(scene, trace, w.start_s, w.duration_s, rate_hz)
                predictor, fed_us, frames, samples = make_predictor(name), None, {}, []
                for t_us in ticks[::stride]:
                    render_us, pose_us = schedule.frame_for(t_us)
                    if render_us not in frames:
                        # the client's poses up to the one this frame uses, as the server got them
                        k = (fed_us // schedule.tick_us + 1) if fed_us is not None else \
                            (pose_us // schedule.tick_us) - 3
                        for kk in range(k, pose_us // schedule.tick_us + 1):
                            predictor.update(kk * schedule.tick_us / 1e6, pose_at(kk * schedule.tick_us))
                        fed_us = pose_us
                        ahead = display_look_ahead_s(render_us, pose_us, schedule.delay_us, up_us,
                                                     schedule.interval_us)
                        frames[render_us] = predictor.predict(ahead)
                    samples.append((t_us / 1e6, pose_at(t_us), render_us / 1e6, frames[render_us]))
                sim = Simulation(scene, bench_server_config(tuple(view_size or BENCH_VIEW_SIZE)), out_size,
                                 proxies=proxies)
                try:
                    series = evaluate_methods(sim, samples, {m: (m, {}) for m in methods}, bar=bar)
                finally:
                    sim.close()
                    sim.ctx.release()
                for m in methods:
                    scores[m]["dssim"] += series[m]["dssim"]
                    scores[m]["psnr"] += series[m]["psnr"]
            per[name] = {m: {"dssim_mean": float(np.mean(v["dssim"])), "psnr_mean": float(np.mean(v["psnr"])),
                             "frames": len(v["dssim"])} for m, v in scores.items()}
    return out


def _summary(errors: list) -> dict:
    pos = np.concatenate([e[0] for e in errors]) if errors else np.zeros(0)
    ang = np.concatenate([e[1] for e in errors]) if errors else np.zeros(0)
    if not len(pos):
        return {"samples": 0}
    return {"position_mm_mean": 1e3 * float(pos.mean()), "position_mm_p95": 1e3 * float(np.percentile(pos, 95)),
            "angle_deg_mean": math.degrees(float(ang.mean())), "angle_deg_p95": math.degrees(float(np.percentile(ang, 95))),
            "samples": int(len(pos))}


def run_predict_bench(windows=None, rate_hz: float = 30.0, look_aheads_ms=DEFAULT_LOOK_AHEADS_MS, fit: bool = False,
                      out_dir: str = "out/bench", plot: bool = True, quality: bool = False, quality_windows=None,
                      quality_latencies_ms=QUALITY_LATENCIES_MS, stride: int = 4, out_size=QUALITY_OUT_SIZE,
                      view_size=QUALITY_VIEW_SIZE, progress: bool = True) -> dict:
    """Every predictor at every look-ahead on ``windows`` (default: evaluation; tuning with ``fit``);
    with ``quality`` also :func:`prediction_quality` on ``quality_windows`` (default: the first
    :data:`QUALITY_SECONDS` of :data:`QUALITY_WINDOWS`, parts of evaluation windows)."""
    from pibr.common.traces.loading import load_trace
    from pibr.server.pose_prediction import PREDICTORS, KalmanPredictor, make_predictor

    from .windows import EVALUATION_WINDOWS, TUNING_WINDOWS

    windows = tuple(windows or (TUNING_WINDOWS if fit else EVALUATION_WINDOWS))
    look = [a / 1e3 for a in look_aheads_ms]
    traces = {w.trace: load_trace(w.trace) for w in windows}
    result = {"windows": windows_json(windows, "tuning" if fit else "reporting"), "rate_hz": rate_hz,
              "look_aheads_ms": list(look_aheads_ms), "predictors": {}}

    def measure(make) -> tuple[dict, dict]:
        per_window, pooled = {}, {a: [] for a in look}
        for w in windows:
            errs = prediction_errors(traces[w.trace], w.start_s, w.duration_s, rate_hz, look, make)
            per_window[w.label] = {f"{1e3 * a:g}": _summary([errs[a]]) for a in look}
            for a in look:
                pooled[a].append(errs[a])
        return {f"{1e3 * a:g}": _summary(pooled[a]) for a in look}, per_window

    if fit:
        search = []
        for q, r in itertools.product(FIT_Q, FIT_R):
            overall, _ = measure(lambda: KalmanPredictor(q, r, q, r))
            search.append({"q": q, "r": r,
                           "position_mm_mean": float(np.mean([v["position_mm_mean"] for v in overall.values()])),
                           "angle_deg_mean": float(np.mean([v["angle_deg_mean"] for v in overall.values()]))})
        best_position = min(search, key=lambda s: s["position_mm_mean"])
        best_orientation = min(search, key=lambda s: s["angle_deg_mean"])
        result["fit"] = {"searched": search, "position": {"q": best_position["q"], "r": best_position["r"]},
                         "orientation": {"q": best_orientation["q"], "r": best_orientation["r"]},
                         "objective": "mean error over every look-ahead, position and orientation apart"}
    for name in PREDICTORS:
        overall, per_window = measure(lambda: make_predictor(name))
        result["predictors"][name] = {"overall": overall, "per_window": per_window}
    result["kalman_vs_none"] = {
        a: {"angle_deg_less": result["predictors"]["none"]["overall"][a]["angle_deg_mean"]
            - result["predictors"]["kalman"]["overall"][a]["angle_deg_mean"],
            "position_mm_less": result["predictors"]["none"]["overall"][a]["position_mm_mean"]
            - result["predictors"]["kalman"]["overall"][a]["position_mm_mean"]}
        for a in result["predictors"]["none"]["overall"]}
    result["kalman_beats_none_at_every_look_ahead"] = all(v["angle_deg_less"] > 0
                                                          for v in result["kalman_vs_none"].values())
    if quality and not fit:
        from .windows import Window

        qw = tuple(quality_windows or (Window(trace, start, QUALITY_SECONDS) for trace, start in QUALITY_WINDOWS))
        bar = None
        if progress:
            import sys

            from tqdm import tqdm

            per = sum(len(range(0, int(w.duration_s * rate_hz), stride)) for w in qw)
            bar = tqdm(total=per * len(quality_latencies_ms) * len(PREDICTORS), unit="tick", desc="bench predict",
                       file=sys.stderr, leave=False, disable=None)
        try:
            result["quality"] = {"windows": windows_json(qw, "reporting"), "stride": stride, "output": list(out_size),
                                 "view_size": list(view_size),
                                 "by_latency_ms": prediction_quality(qw, quality_latencies_ms, rate_hz=rate_hz,
                                                                     stride=stride, view_size=view_size,
                                                                     out_size=out_size, bar=bar)}
        finally:
            if bar is not None:
                bar.close()
    name = "predict-tuning.json" if fit else "predict.json"
    write_result(out_dir, name, result)
    if plot:
        from .plots import plot_predict

        plot_predict(result, f"{out_dir}/{name.replace('.json', '.png')}")
    return result


def print_predict(result: dict) -> None:
    look = [f"{a:g}" for a in result["look_aheads_ms"]]
    print(f"pose prediction at {result['rate_hz']:g} Hz ({result['windows']['purpose']} windows): mean angular error "
          f"deg / position mm by look-ahead")
    print(f"{'predictor':<10} " + " ".join(f"{a + ' ms':>14}" for a in look))
    for name, p in result["predictors"].items():
        cells = [f"{p['overall'][a]['angle_deg_mean']:.2f} / {p['overall'][a]['position_mm_mean']:.1f}" for a in look]
        print(f"{name:<10} " + " ".join(f"{c:>14}" for c in cells))
    if "fit" in result:
        print(f"fitted Kalman noise: position q={result['fit']['position']['q']:g} r={result['fit']['position']['r']:g}, "
              f"orientation q={result['fit']['orientation']['q']:g} r={result['fit']['orientation']['r']:g}")
    print("kalman below no prediction in angle at every look-ahead:", result["kalman_beats_none_at_every_look_ahead"])
    q = result.get("quality")
    if q:
        print("DSSIM of what the client shows when the server renders for the predicted pose (" +
              ", ".join(w["trace"] + "@" + f"{w['start_s']:g}" for w in q["windows"]["used"]) + "):")
        for latency, per in q["by_latency_ms"].items():
            for name, methods in per.items():
                print(f"  {latency:>4} ms {name:<9} " + "  ".join(f"{m} {v['dssim_mean']:.4f}" for m, v in methods.items()))
