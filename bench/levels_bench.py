"""``pibr bench levels``: what each quality level of the deadline controller costs and keeps.

The client keeps its output rate by drawing each method at the best level whose predicted cost
fits the tick (client/deadline.py). This measures the trade those levels make, in one process
on the virtual clock's schedule (as ``pibr bench ibr``): per method and level, on the same
display ticks, the wall and CPU ms of the display pass (median, the first draw of each level
not counted: it compiles shaders) and DSSIM / PSNR against ground truth and the own holes.

The quality figures are the same on every machine; the times are this machine's, taken
interleaved (every level drawn on each tick in turn), so compare them within one run. The
result's ``costs_ms`` is a cost table (method -> level -> median wall ms) that ``pibr client
--cost-table`` takes, so the virtual clock can replay the choices this machine would make.
"""
from __future__ import annotations

import sys
import time

import numpy as np

from pibr.common.link import SessionSchedule
from pibr.common.replay import display_samples

from .metrics import dssim, psnr, ssim
from .results import write_result
from .simulation import BENCH_VIEW_SIZE, Simulation, bench_server_config, load_proxies
from .windows import EVALUATION_WINDOWS, windows_json


def run_levels_bench(scene_spec="room", methods=("proxy", "rotation"), windows=None, latency_ms=128.0,
                     rate_hz=30.0, stride=10, view_size=BENCH_VIEW_SIZE, out_size=(960, 540), out_dir="out/bench",
                     progress=True) -> dict:
    """Every level of every method on every ``stride``-th tick of the windows (default: the evaluation windows)."""
    from pibr.client.deadline import levels_for
    from pibr.client.render_scale import make_level
    from pibr.scenes.registry import load_scene

    windows = tuple(windows or EVALUATION_WINDOWS)
    scene = load_scene(scene_spec)
    proxies, _ = load_proxies(scene, progress=False)
    schedule = SessionSchedule.round_trip(rate_hz, latency_ms)
    samples = [s for w in windows
               for s in display_samples(scene, w.trace, w.start_s, w.duration_s, schedule)[::stride]]
    levels = {m: levels_for(m) for m in methods}
    sim = Simulation(scene, bench_server_config(view_size), out_size, proxies=proxies)
    options = {"poses": sim.poses, "oracle_pose": sim.oracle_pose}
    drawn = {m: [make_level(sim.ctx, lv, sim.output, sim.session, proxies, **options) for lv in ls]
             for m, ls in levels.items()}
    series = {m: [{"ms": [], "cpu_ms": [], "dssim": [], "psnr": [], "holes": []} for _ in ls]
              for m, ls in levels.items()}
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(samples), unit="tick", desc="bench levels", file=sys.stderr, leave=False, disable=None)
    try:
        for i, (t_disp, display, t_render, rendered) in enumerate(samples):
            frame = sim.frame_at(t_render, rendered)
            gt = sim.ground_truth(display, t_disp)
            for m, instances in drawn.items():
                for k, method in enumerate(instances):
                    c0 = time.process_time()
                    rgb, holes, ms = sim.display(method, display, frame, t_disp)
                    cpu = (time.process_time() - c0) * 1e3
                    s = series[m][k]
                    if i > 0:   # the first draw compiles the level's shaders
                        s["ms"].append(ms)
                        s["cpu_ms"].append(cpu)
                    q = ssim(gt, rgb)
                    s["dssim"].append(dssim(q))
                    s["psnr"].append(psnr(gt, rgb))
                    s["holes"].append(holes)
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
        for instances in drawn.values():
            for method in instances:
                method.release()
        sim.close()
        sim.ctx.release()
    result = {"benchmark": "levels", "scene": scene.name, "windows": windows_json(windows, "reporting"),
              "latency_ms": latency_ms, "rate_hz": rate_hz, "stride": stride, "ticks": len(samples),
              "output": list(out_size), "view_size": list(view_size), "methods": {}, "costs_ms": {}}
    for m, ls in levels.items():
        rows = []
        top = None
        for lv, s in zip(ls, series[m]):
            row = {**lv.to_json(), "ms_median": float(np.median(s["ms"])) if s["ms"] else None,
                   "cpu_ms_median": float(np.median(s["cpu_ms"])) if s["cpu_ms"] else None,
                   "dssim_mean": float(np.mean(s["dssim"])), "psnr_mean": float(np.mean(s["psnr"])),
                   "own_holes_mean": float(np.mean(s["holes"]))}
            top = top or row
            if top["ms_median"] and row["ms_median"] is not None:
                row["ms_of_top"] = row["ms_median"] / top["ms_median"]
            rows.append(row)
        result["methods"][m] = rows
        result["costs_ms"][m] = {r["name"]: round(r["ms_median"], 3) for r in rows if r["ms_median"] is not None}
    write_result(out_dir, "levels.json", result)
    return result


def print_levels_table(r: dict) -> None:
    print(f"pibr bench levels: scene {r['scene']}, output {r['output'][0]}x{r['output'][1]}, {r['ticks']} ticks, "
          f"{r['latency_ms']:g} ms round trip (times: this machine, this run)")
    for m, rows in r["methods"].items():
        print(f"\n{m}:{'':<20}{'ms':>8}{'CPU ms':>8}{'x top':>7}{'DSSIM':>8}{'PSNR':>7}{'holes %':>8}")
        for row in rows:
            ms = "-" if row["ms_median"] is None else f"{row['ms_median']:.1f}"
            cpu = "-" if row["cpu_ms_median"] is None else f"{row['cpu_ms_median']:.1f}"
            rel = f"{row['ms_of_top']:.2f}" if "ms_of_top" in row else "-"
            print(f"  {row['name']:<22}{ms:>8}{cpu:>8}{rel:>7}{row['dssim_mean']:>8.4f}{row['psnr_mean']:>7.2f}"
                  f"{100 * row['own_holes_mean']:>8.2f}")
