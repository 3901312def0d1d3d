"""Moving objects under ``proxy``'s extrapolations: quality over the frame and over the moving
objects' pixels, against ground truth, in one process (``simulation.Simulation``).

Per displayed tick of each window, on the virtual clock's schedule (``pibr.common.link.SessionSchedule``):
the server's frame as the client has it, then ``proxy`` with each ``motion`` mode
(client/object_motion.py; ``oracle`` evaluates the scene's animation, which only a benchmark
has). The moving objects' pixels are those showing a moving object in the ground truth at the
display time *or* at the shown frame's scene time (both seen from the display pose): where
the objects are and where a client that does not extrapolate leaves them. DSSIM over them is
the mean of the SSIM map there, (1 - mean) / 2; PSNR over them likewise.

``measure_motion`` is the reusable piece (``pibr bench dynamic`` builds on it).
"""
from __future__ import annotations

import time

import numpy as np

from pibr.common.link import SessionSchedule
from pibr.common.replay import display_samples

from .metrics import masked_metrics

MODES = ("static", "velocity", "accel", "oracle")


def measure_motion(scene, windows, modes=MODES, latency_ms: float = 128.0, rate_hz: float = 30.0, stride: int = 3,
                   view_size=(512, 512), out_size=(480, 270), depth_codec: str = "h264", proxies=None,
                   bar=None) -> dict:
    """Quality of ``proxy`` per motion mode on ``scene`` (a Scene) over ``windows`` (bench.windows.Window).

    -> {"modes": {mode: {dssim_mean, psnr_mean, moving_dssim_mean, moving_psnr_mean,
    moving_frames, frames, ms_median, per_window: {label: {...}}}}, "series": {mode: [[t, dssim,
    moving dssim or None], ...] per window label}, ...}."""
    from pibr.server.render_target import RenderTarget

    from .simulation import Simulation, bench_server_config, load_proxies

    if proxies is None:
        proxies, _ = load_proxies(scene, progress=False)
    schedule = SessionSchedule.round_trip(rate_hz, latency_ms)
    sim = Simulation(scene, bench_server_config(view_size, depth_codec=depth_codec), out_size, proxies=proxies)
    truth = RenderTarget(sim.ctx, *out_size, motion=True)
    rows = {m: {} for m in modes}
    try:
        methods = {m: sim.make_method("proxy", motion=m) for m in modes}
        for window in windows:
            samples = display_samples(scene, window.trace, window.start_s, window.duration_s, schedule)[::stride]
            for t_disp, display, t_render, rendered in samples:
                frame = sim.frame_at(t_render, rendered)
                sim.renderer.render_perspective(truth, display, frame.scene_t_us / 1e6, sim.output.fov_deg)
                stale = truth.read_motion()[1].copy()
                sim.renderer.render_perspective(truth, display, t_disp, sim.output.fov_deg)
                gt = truth.read_color().copy()
                mask = truth.read_motion()[1] | stale
                for mode, m in methods.items():
                    rgb, _, ms = sim.display(m, display, frame, t_disp)
                    q = masked_metrics(gt, rgb, {"moving": mask}, min_pixels=1)   # one SSIM map for both
                    moving = (q["dssim_moving"], q["psnr_moving"]) if mask.any() else (None, None)
                    rows[mode].setdefault(window.label, []).append(
                        (t_disp, q["dssim"], q["psnr"], *moving, ms, int(mask.sum())))
                if bar is not None:
                    bar.update(1)
        for m in methods.values():
            m.release()
    finally:
        truth.release()
        sim.close()
        sim.ctx.release()
    return {"scene": scene.name, "latency_ms": latency_ms, "rate_hz": rate_hz, "stride": stride,
            "output": list(out_size), "view_size": list(view_size), "depth_codec": depth_codec,
            "windows": [w.label for w in windows], "modes": {m: _summary(r) for m, r in rows.items()},
            "series": {m: {w: [[t, d, md] for t, d, _, md, *_ in r] for w, r in per.items()} for m, per in rows.items()}}


def _summary(per_window: dict) -> dict:
    def stats(rows):
        a = lambda k: [r[k] for r in rows if r[k] is not None]
        mean = lambda v: float(np.mean(v)) if v else None
        return {"dssim_mean": mean(a(1)), "psnr_mean": mean(a(2)), "moving_dssim_mean": mean(a(3)),
                "moving_psnr_mean": mean(a(4)), "moving_frames": len(a(3)), "frames": len(rows),
                "moving_pixels_mean": mean(a(6)), "ms_median": float(np.median(a(5))) if rows else None}

    everything = [r for rows in per_window.values() for r in rows]
    return {**stats(everything), "per_window": {w: stats(rows) for w, rows in per_window.items()}}


def print_motion_table(result: dict) -> None:
    print(f"proxy's motion extrapolation: scene {result['scene']}, {result['latency_ms']:g} ms, "
          f"{result['output'][0]}x{result['output'][1]}, every {result['stride']} tick(s) of {result['rate_hz']:g} Hz")
    print(f"{'motion':>10}{'DSSIM':>9}{'PSNR':>8}{'moving DSSIM':>14}{'moving PSNR':>13}{'frames':>8}{'ms':>7}")
    for mode, s in result["modes"].items():
        md = "-" if s["moving_dssim_mean"] is None else f"{s['moving_dssim_mean']:.4f}"
        mp = "-" if s["moving_psnr_mean"] is None else f"{s['moving_psnr_mean']:.2f}"
        print(f"{mode:>10}{s['dssim_mean']:>9.4f}{s['psnr_mean']:>8.2f}{md:>14}{mp:>13}"
              f"{s['moving_frames']:>4}/{s['frames']:<3}{s['ms_median']:>7.1f}")


if __name__ == "__main__":   # python -m pibr.bench.motion_eval SCENE [WINDOWS] [LATENCY_MS] [STRIDE]
    import json
    import sys

    from pibr.scenes.registry import load_scene

    from .windows import parse_windows

    scene_name = sys.argv[1] if len(sys.argv) > 1 else "dynamic"
    wins = parse_windows(sys.argv[2] if len(sys.argv) > 2 else "evaluation")
    t0 = time.perf_counter()
    r = measure_motion(load_scene(scene_name), wins, latency_ms=float(sys.argv[3]) if len(sys.argv) > 3 else 128.0,
                       stride=int(sys.argv[4]) if len(sys.argv) > 4 else 3)
    print_motion_table(r)
    print(f"({time.perf_counter() - t0:.0f} s)")
    if len(sys.argv) > 5:
        with open(sys.argv[5], "w") as f:
            json.dump(r, f, indent=2)
