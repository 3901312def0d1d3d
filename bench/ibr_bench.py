"""``pibr bench ibr``: the client methods' quality against ground truth and their speed.

Quality runs the real pipeline in one process on the virtual clock's schedule
(``pibr.common.link.SessionSchedule``, the same arithmetic the processes follow, checked by the
integration test): the server's renderer, packer and libx264 encoder make each frame, the
client's H.264 decoder, textures and methods re-render every displayed tick, and the ground
truth renderer scores it. No sockets, so nothing but the methods differs between them.

Speed: median display ms of ``proxy`` at 960x540 and 1280x720 beside a floor measured in the
same run — one full-screen pass at the same resolution doing the same texture lookups per
pixel as the proxy pass (two depth fetches, three colour-plane samples). The LoD trade:
ms, triangles drawn and DSSIM for several LoD targets and forced levels.
"""
from __future__ import annotations

import sys

import numpy as np

from pibr.common.link import SessionSchedule
from pibr.common.replay import display_samples

from .results import write_result
from .simulation import BENCH_VIEW_SIZE, Simulation, bench_server_config, evaluate_methods, load_proxies, summarize


def run_ibr_bench(scene_spec="room", windows=None, latency_ms=128.0, rate_hz=30.0, view_size=BENCH_VIEW_SIZE,
                  out_size=(960, 540), stride=2, lod_targets=(), lod_levels=(),
                  speed_sizes=((960, 540), (1280, 720)), speed_frames=20, out_dir="out/bench",
                  progress=True) -> dict:
    """Per window (default: the evaluation windows of bench/windows.py): quality of none,
    rotation and proxy and the LoD variants; proxy's speed against the floor."""
    from pibr.scenes.registry import load_scene

    from .windows import EVALUATION_WINDOWS, windows_json

    windows = tuple(windows or EVALUATION_WINDOWS)
    scene = load_scene(scene_spec)
    proxies, bundle = load_proxies(scene, progress)
    schedule = SessionSchedule.round_trip(rate_hz, latency_ms)
    result = {"scene": scene.name, "windows": windows_json(windows, "reporting"), "latency_ms": latency_ms,
              "rate_hz": rate_hz, "output": list(out_size), "view_size": list(view_size), "stride": stride,
              "proxies": bundle.info(1 << 20) | {"build_s": bundle.seconds}, "quality": {}, "lod": {}, "speed": {}}
    samples = {w.label: display_samples(scene, w.trace, w.start_s, w.duration_s, schedule)[::stride]
               for w in windows}
    traces = list(samples)
    quality_variants = {"none": ("none", {}), "rotation": ("rotation", {}), "proxy": ("proxy", {})}
    lod_variants = {f"proxy lod {t:g}px": ("proxy", {"lod_target_px": t}) for t in lod_targets}
    lod_variants.update({f"proxy all {lv}": ("proxy", {"lod_level": lv}) for lv in lod_levels})
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=sum(len(s) for s in samples.values()) * (2 if lod_variants else 1)
                   + len(speed_sizes) * speed_frames,
                   unit="frame", desc="bench ibr", file=sys.stderr, leave=False, disable=None)
    try:
        for tr in traces:
            sim = Simulation(scene, bench_server_config(view_size), out_size, proxies=proxies)
            try:
                q = evaluate_methods(sim, samples[tr], quality_variants, bar=bar)
                result["quality"][tr] = {k: summarize(v) for k, v in q.items()}
                if lod_variants:
                    lod = evaluate_methods(sim, samples[tr], lod_variants, bar=bar)
                    result["lod"][tr] = {k: summarize(v) for k, v in lod.items()}
                result.setdefault("video_kbps", {})[tr] = float(np.mean(sim.bytes) * 8 * sim.fps / 1000)
            finally:
                sim.close()
                sim.ctx.release()
        speed_samples = [x for tr in traces for x in samples[tr]][:speed_frames]
        for size in speed_sizes:
            sim = Simulation(scene, bench_server_config(view_size), size, proxies=proxies)
            try:
                s = evaluate_methods(sim, speed_samples, {"proxy": ("proxy", {}), "floor": ("floor", {})},
                                     with_quality=False, bar=bar)
                key = f"{size[0]}x{size[1]}"
                result["speed"][key] = {"proxy_ms": summarize(s["proxy"])["client_ms_median"],
                                        "floor_ms": summarize(s["floor"])["client_ms_median"]}
                result["speed"][key]["ratio"] = result["speed"][key]["proxy_ms"] / result["speed"][key]["floor_ms"]
            finally:
                sim.close()
                sim.ctx.release()
    finally:
        if bar is not None:
            bar.close()
    write_result(out_dir, "ibr.json", result)
    return result


def print_ibr_tables(r: dict) -> None:
    print(f"pibr bench ibr: scene {r['scene']}, {r['latency_ms']:g} ms round trip, output "
          f"{r['output'][0]}x{r['output'][1]}, every {r['stride']} tick(s)")
    p = r["proxies"]
    print(f"proxies: {p['objects']} objects, {p['triangles']['original']} -> {p['triangles']['proxy']} triangles, "
          f"{p['bytes'] / 1e6:.2f} MB compressed")
    for tr, q in r["quality"].items():
        uniform = next(iter(q.values()))["nearly_uniform_frames"]
        if uniform:
            print(f"\nwarning: {uniform} of {next(iter(q.values()))['frames']} ground-truth frames of {tr} are nearly "
                  "one colour (sky or a wall filling the view); every method scores well on them")
        print(f"\n{tr}:{'':<14}{'PSNR dB':>9}{'SSIM':>8}{'DSSIM':>8}{'holes %':>9}{'ms':>8}{'triangles':>11}")
        for label, s in list(q.items()) + list(r["lod"].get(tr, {}).items()):
            print(f"  {label:<20}{s['psnr_mean']:>9.2f}{s['ssim_mean']:>8.4f}{s['dssim_mean']:>8.4f}"
                  f"{100 * s['hole_fraction_mean']:>9.2f}{s['client_ms_median']:>8.1f}{s['triangles_mean']:>11.0f}")
    print("\nspeed (median ms per output frame, same run):")
    for size, s in r["speed"].items():
        print(f"  {size:>9}: proxy {s['proxy_ms']:.1f}  floor {s['floor_ms']:.1f}  ratio {s['ratio']:.2f}")
