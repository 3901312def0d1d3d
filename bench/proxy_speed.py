"""CPU cost of ``proxy``'s passes in one run: the default carving, ``carve_all`` (the passes it
replaced, the same image), both without inpainting (``inpaint=False``, no second carving pass),
``carve=False``, the default and carve=False also without culling back faces (``cull=False``),
and the floor of ``pibr bench ibr`` (a full-screen pass with the proxy pass's
lookups), interleaved frame by frame on room frames along the evaluation windows' head traces,
at each output size; and how far the default's images are from carve_all's and from those
drawn without culling, and the two without inpainting from each other.

    pibr bench proxy-speed [--sizes 960x540,1280x720] [--frames 12] [--repeats 3]

CPU ms of this process (``time.process_time``: the rasteriser's threads included) per display,
median over frames and repeats; the first display of every variant is not counted (shader
compilation). Other processes on the machine change the numbers: compare within one run.
"""
from __future__ import annotations

import time

import numpy as np

VARIANTS = {"proxy": {}, "proxy no cull": {"cull": False}, "proxy carve_all": {"carve_all": True},
            "proxy no inpaint": {"inpaint": False}, "carve_all no inpaint": {"carve_all": True, "inpaint": False},
            "proxy no carve": {"carve": False}, "no carve, no cull": {"carve": False, "cull": False}}


def _samples(scene, frames: int, rate_hz: float = 30.0, latency_ms: float = 128.0) -> list:
    """``frames`` display samples spread evenly over the evaluation windows."""
    from pibr.common.link import SessionSchedule
    from pibr.common.replay import display_samples

    from .windows import EVALUATION_WINDOWS

    schedule = SessionSchedule.round_trip(rate_hz, latency_ms)
    per = -(-frames // len(EVALUATION_WINDOWS))
    out = []
    for w in EVALUATION_WINDOWS:
        s = display_samples(scene, w.trace, w.start_s, w.duration_s, schedule)
        out += s[:: max(1, len(s) // per)][:per]
    return out[:frames]


def run(sizes=((960, 540), (1280, 720)), frames: int = 12, repeats: int = 3, scene_spec: str = "room") -> dict:
    """-> size -> {variant: median CPU ms, "ratio to floor": {...}, "image": {...}}."""
    from pibr.scenes.registry import load_scene

    from .simulation import Simulation, bench_server_config, load_proxies

    scene = load_scene(scene_spec)
    proxies, _ = load_proxies(scene)
    samples = _samples(scene, frames)
    result = {}
    for size in sizes:
        sim = Simulation(scene, bench_server_config(), size, proxies=proxies)
        methods = {label: sim.make_method("proxy", **options) for label, options in VARIANTS.items()}
        methods["floor"] = sim.make_method("floor")
        cpu = {label: [] for label in methods}
        diff_max, diff_pixels, fallback, cull_pixels = 0, [], [], []
        no_inpaint_max, no_inpaint_pixels = 0, []   # against carve_all without inpainting
        try:
            for i, (t_disp, display, t_render, rendered) in enumerate(samples):
                frame = sim.frame_at(t_render, rendered)
                images = {}
                for rep in range(repeats + (i == 0)):
                    for label, m in methods.items():
                        sim.target.begin()
                        sim.ctx.finish()
                        c0 = time.process_time()
                        m.render(display, frame, sim.textures, t_disp)
                        sim.ctx.finish()
                        ms = (time.process_time() - c0) * 1e3
                        if not (i == 0 and rep == 0):
                            cpu[label].append(ms)
                        images[label] = sim.target.read()
                d = np.abs(images["proxy"].astype(np.int16) - images["proxy carve_all"].astype(np.int16)).max(axis=2)
                diff_max = max(diff_max, int(d.max()))
                diff_pixels.append(float(np.mean(d > 0)))
                d = np.abs(images["proxy"].astype(np.int16) - images["proxy no cull"].astype(np.int16)).max(axis=2)
                cull_pixels.append(float(np.mean(d > 0)))
                d = np.abs(images["proxy no inpaint"].astype(np.int16)
                           - images["carve_all no inpaint"].astype(np.int16)).max(axis=2)
                no_inpaint_max = max(no_inpaint_max, int(d.max()))
                no_inpaint_pixels.append(float(np.mean(d > 0)))
                fallback.append(methods["proxy"].last_fallback_pixels / (size[0] * size[1]))
        finally:
            for m in methods.values():
                m.release()
            sim.close()
            sim.ctx.release()
        med = {label: float(np.median(v)) for label, v in cpu.items()}
        result[f"{size[0]}x{size[1]}"] = {
            "cpu_ms": med, "ratio_to_floor": {label: v / med["floor"] for label, v in med.items()},
            "image_vs_carve_all": {"max_abs_diff": diff_max, "pixels_differing_max": max(diff_pixels)},
            "no_inpaint_vs_carve_all_no_inpaint": {"max_abs_diff": no_inpaint_max,
                                                   "pixels_differing_max": max(no_inpaint_pixels)},
            "image_vs_no_cull": {"pixels_differing_mean": float(np.mean(cull_pixels)),
                                 "pixels_differing_max": max(cull_pixels)},
            "pass2_pixels_mean": float(np.mean(fallback)), "frames": len(samples), "repeats": repeats}
    return result


def print_table(result: dict) -> None:
    for size, r in result.items():
        print(f"{size} ({r['frames']} frames x {r['repeats']}; pass 2 on {100 * r['pass2_pixels_mean']:.2f} % of "
              f"pixels on average)")
        for label, ms in r["cpu_ms"].items():
            print(f"  {label:>20}: {ms:6.1f} CPU-ms  {r['ratio_to_floor'][label]:5.2f}x floor")
        im = r["image_vs_carve_all"]
        print(f"  proxy vs carve_all: max |diff| {im['max_abs_diff']}/255, "
              f"{100 * im['pixels_differing_max']:.4f} % of pixels differ at most")
        im = r["no_inpaint_vs_carve_all_no_inpaint"]
        print(f"  no inpaint vs carve_all no inpaint: max |diff| {im['max_abs_diff']}/255, "
              f"{100 * im['pixels_differing_max']:.4f} % of pixels differ at most")
        im = r["image_vs_no_cull"]
        print(f"  proxy vs no cull: {100 * im['pixels_differing_mean']:.3f} % of pixels differ on average, "
              f"{100 * im['pixels_differing_max']:.3f} % at most")
