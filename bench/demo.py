"""``pibr demo``: server, relay and client as separate processes on loopback, then metrics.

With the defaults: the built-in ``room`` scene, 6 s from 30 s into the real HoloLens trace
``pred6dof-1``, 128 ms round trip (64 ms each way), 10 server frames per second, 30 output
frames per second, the virtual clock, methods ``none``, ``rotation`` and ``proxy``. Writes to ``out/``:
each method's recording, ``side_by_side.mp4``, ``metrics.json``, ``metrics_frames.csv``,
``quality.png`` and ``logs/``; prints a summary table.
"""
from __future__ import annotations

import os
import sys
import time

from .evaluate import evaluate_run, summary_table
from .processes import run_pipeline
from .results import write_result

DEFAULT_METHODS = ("none", "rotation", "proxy")


def check_inputs(scene: str, trace: str, start_s: float, duration_s: float) -> None:
    """Fail in one line, before any process starts, on what the children would refuse: an unknown
    scene or trace, a window outside the trace, no OpenGL on this machine."""
    from pibr.common.gl import create_context
    from pibr.common.traces.loading import load_trace
    from pibr.scenes.registry import check_scene_spec

    check_scene_spec(scene)
    load_trace(trace).window(start_s, duration_s)
    create_context().release()


def stream(out_dir: str, scene: str, trace: str, start_s: float, duration_s: float, rate_hz: float, size,
           latency_ms: float, methods, clock: str, server_args=(), anchor: str = "start", client_args=(),
           on_progress=None) -> dict:
    """The demo's streaming: server, relay (half the round trip each way) and client as processes
    on loopback, the client recording into ``out_dir``. -> run_pipeline's timings."""
    half = latency_ms / 2.0
    return run_pipeline(
        out_dir,
        server_args=["--scene", scene, *server_args],
        relay_args=["--up-ms", str(half), "--down-ms", str(half)],
        client_args=["--trace", trace, "--start", str(start_s), "--duration", str(duration_s),
                     "--rate", str(rate_hz), "--size", f"{size[0]}x{size[1]}", "--clock", clock,
                     "--anchor", anchor, "--method", ",".join(methods), *client_args],
        on_progress=on_progress)


def run_demo(out_dir: str = "out", scene: str = "room", trace: str = "pred6dof-1", start_s: float = 30.0,
             duration_s: float = 6.0, rate_hz: float = 30.0, size=(960, 540), latency_ms: float = 128.0,
             methods=DEFAULT_METHODS, clock: str = "virtual", flip_every: int = 4, server_args=(),
             progress: bool = True, anchor: str = "start", client_args=()) -> dict:
    from tqdm import tqdm

    check_inputs(scene, trace, start_s, duration_s)
    os.makedirs(out_dir, exist_ok=True)
    t0 = time.perf_counter()
    bar = tqdm(total=None, unit="tick", desc="streaming (server -> relay -> client)", file=sys.stderr,
               disable=None if progress else True, leave=False)

    def on_progress(done, total):
        if bar.total != total:
            bar.total = total
        bar.n = done
        bar.refresh()

    try:
        timings = stream(out_dir, scene, trace, start_s, duration_s, rate_hz, size, latency_ms, methods, clock,
                         server_args, anchor, client_args, on_progress)
    finally:
        bar.close()
    t_stream = time.perf_counter()
    metrics = evaluate_run(out_dir, scene_spec=scene, flip_every=flip_every, progress=progress)
    t_end = time.perf_counter()
    metrics["timings_s"] = {"server_start": timings["server_start_s"], "streaming": t_stream - t0,
                            "evaluation": t_end - t_stream, "total": t_end - t0}
    metrics["latency_ms"] = latency_ms
    if clock == "real":
        metrics["real_clock"] = real_clock_summary(out_dir, metrics, duration_s)
    write_result(out_dir, "metrics.json", metrics)
    return metrics


def real_clock_summary(out_dir: str, metrics: dict, duration_s: float) -> dict:
    """What the wall clock allowed: server frames received per second of the client's clock, and
    per method the ticks shown afresh per second and the share of missed deadlines (a missed
    tick repeats the previous image)."""
    from pibr.client.recorder import read_records

    from .evaluate import read_session

    session = read_session(out_dir)
    arrivals = session["result"].get("frame_arrivals_s", [])
    received = sum(1 for a in arrivals if 0.0 <= a <= duration_s)
    deadline = session.get("deadline") or {}
    methods = {}
    recordings = session.get("recordings") or {name: {"method": name} for name in metrics["methods"]}
    first = {}   # method -> its first recording (two eyes: the left eye's; both eyes share each tick)
    for recording, r in recordings.items():
        first.setdefault(r["method"], recording)
    for name, recording in first.items():
        m = metrics["methods"][recording]
        ticks, missed = m["frames"], m.get("missed_deadlines") or 0
        methods[name] = {"output_hz": (ticks - missed) / duration_s, "missed_fraction": missed / ticks if ticks else None}
        chosen = (deadline.get("methods") or {}).get(name)
        if chosen:   # the client's quality levels (client/deadline.py) and why
            methods[name]["levels"] = {k: v for k, v in chosen["share_at_level"].items() if v > 0}
            methods[name]["reasons"] = chosen["reasons"]
    out = {"server_fps": received / duration_s, "frames_received": received, "methods": methods,
           "budget_ms": deadline.get("budget_ms"), "tick_overhead_ms": deadline.get("overhead_ms")}
    names = session["session"].get("options", {}).get("server_levels")
    if names:   # the server's levels (server/rate_control.py), each frame shown counted once
        rows = read_records(os.path.join(out_dir, f"{next(iter(metrics['methods']))}.records.csv"))
        made = {r["frame_id"]: r["server_level"] for r in rows if r["frame_id"] >= 0 and r["server_level"] >= 0}
        out["server_levels"] = {names[k]: sum(1 for v in made.values() if v == k) / len(made)
                                for k in sorted(set(made.values()))} if made else {}
    return out


def print_report(metrics: dict, out_dir: str) -> None:
    t = metrics.get("timings_s", {})
    print(f"\npibr demo: scene {metrics['scene']}, trace {metrics['trace']['name']} "
          f"({metrics['trace']['duration_s']:.1f} s), {metrics.get('latency_ms', 0):.0f} ms round trip, "
          f"{metrics['clock']} clock, output {metrics['output']['width']}x{metrics['output']['height']} at "
          f"{metrics['output']['rate_hz']:g} Hz")
    print(summary_table(metrics))
    real = metrics.get("real_clock")
    if real:
        name, m = next(iter(real["methods"].items()))
        several = len(real["methods"]) > 1
        print(f"\nReal clock: the server delivered {real['server_fps']:.1f} frames/s; the client showed "
              f"{m['output_hz']:.1f} fresh images/s of {metrics['output']['rate_hz']:g} "
              f"({100 * m['missed_fraction']:.0f} % of ticks missed" + (
                  f": the {len(real['methods'])} methods render on every tick"
                  + (", each for both eyes" if metrics.get("stereo") else "")
                  + ", so their costs add up; time one at a time with --method proxy)." if several else ")."))
        if real.get("server_levels"):
            shares = ", ".join(f"{k} {100 * v:.0f} %" for k, v in real["server_levels"].items())
            print(f"The server's rate control made the frames shown at: {shares} (the best level predicted "
                  f"to fit its frame interval; --rate-control off makes every frame whole).")
        for name, mm in real["methods"].items():
            if mm.get("levels"):
                shares = ", ".join(f"{k} {100 * v:.0f} %" for k, v in mm["levels"].items())
                why = max(mm["reasons"].items(), key=lambda kv: kv[1])[0]
                print(f"The client drew {name} at: {shares}; mostly {why} (budget {real['budget_ms']:.1f} ms a "
                      f"tick after {real['tick_overhead_ms'] or 0:.1f} ms of other work; --deadline off to always "
                      f"draw the best level).")
    print(f"\nFLIP on every {metrics['flip_every']} frame(s). Finished in {t.get('total', 0):.0f} s "
          f"(streaming {t.get('streaming', 0):.0f} s, evaluation {t.get('evaluation', 0):.0f} s).")
    print(f"Outputs in {out_dir}/: report.html (open it in a browser), side_by_side.mp4, metrics.json, "
          f"metrics_frames.csv, quality.png, <method>.mp4, logs/")
