"""``pibr bench split``: a level that arrives as one mesh, whole against cut into pieces.

A generated stand-in for a one-mesh atrium (``atrium_mesh``: a floor, walls, two galleries
round a well, columns and railings, 167k triangles, merged into a single PLY mesh) is
served twice through scene descriptions that differ only in ``split``: 0 (one object: one
proxy for everything, the LoD selection picks its original mesh wherever the viewer stands,
nothing to cull) and the default piece size (scenes/split.py). Per variant: objects, LoD
build time (parallel pieces), proxy triangles, and on synthetic walks and look-arounds
inside the atrium at 128 ms: ``proxy``'s client ms per frame, triangles drawn, DSSIM and PSNR,
with ``rotation`` as the reference.
"""
from __future__ import annotations

import math
import os
import sys
import time

import numpy as np

from .results import write_result
from .simulation import BENCH_VIEW_SIZE


def atrium_mesh():
    """(vertices (n, 3) float64, faces (m, 3) int64): one mesh, metres, +Y up, centred on the origin."""
    import trimesh

    parts = []

    def grid_box(extents, centre, divisions):
        box = trimesh.creation.box(extents)
        for _ in range(divisions):
            box = box.subdivide()
        box.apply_translation(centre)
        parts.append(box)

    grid_box((30.0, 0.2, 30.0), (0, -0.1, 0), 6)                       # floor
    for x, z, ext in ((15, 0, (0.3, 12, 30)), (-15, 0, (0.3, 12, 30)), (0, 15, (30, 12, 0.3)), (0, -15, (30, 12, 0.3))):
        grid_box(ext, (x, 6, z), 4)                                      # walls
    for level in (4.0, 8.0):                                             # galleries round a 14 m well
        for x, z, ext in ((11, 0, (8, 0.3, 30)), (-11, 0, (8, 0.3, 30)), (0, 11, (14, 0.3, 8)), (0, -11, (14, 0.3, 8))):
            grid_box(ext, (x, level, z), 3)
        for x, z, ext in ((7, 0, (0.08, 1.0, 14)), (-7, 0, (0.08, 1.0, 14)), (0, 7, (14, 1.0, 0.08)), (0, -7, (14, 1.0, 0.08))):
            grid_box(ext, (x, level + 0.65, z), 2)                      # railings
    for i in range(16):                                                  # columns
        angle = 2 * math.pi * i / 16
        col = trimesh.creation.cylinder(radius=0.4, height=12.0, sections=96)
        col = col.subdivide().subdivide()
        col.apply_translation((9.5 * math.cos(angle), 6.0, 9.5 * math.sin(angle)))
        parts.append(col)
    mesh = trimesh.util.concatenate(parts)
    return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)


def write_atrium(directory: str) -> dict:
    """atrium.ply and two descriptions of it -> {"whole": path, "pieces": path}."""
    import trimesh

    os.makedirs(directory, exist_ok=True)
    ply = os.path.join(directory, "atrium.ply")
    if not os.path.isfile(ply):
        v, f = atrium_mesh()
        trimesh.Trimesh(v, f, process=False).export(ply)
    out = {}
    for label, split in (("whole", "split = 0"), ("pieces", "")):
        path = os.path.join(directory, f"atrium-{label}.toml")
        with open(path, "w") as fh:
            fh.write(f'name = "atrium-{label}"\nnear = 0.1\nfar = 200.0\nextra_view = true\n\n'
                     '[viewer_origin]\nposition = [0.0, 1.6, 4.0]\nyaw_deg = 0.0\n\n'
                     f'[[objects]]\nasset = "atrium.ply"\nup = "y"\n{split}\n')
        out[label] = path
    return out


def run_split_bench(out_dir="out/bench", traces=("synth-walk", "synth-look"), start_s=5.0, duration_s=6.0,
                    rate_hz=30.0, latency_ms=128.0, stride=6, view_size=BENCH_VIEW_SIZE, out_size=(960, 540),
                    progress=True) -> dict:
    from pibr.scenes.registry import load_scene

    from pibr.common.link import SessionSchedule
    from pibr.common.replay import display_samples

    from .simulation import Simulation, bench_server_config, evaluate_methods, load_proxies, summarize

    specs = write_atrium(os.path.join(out_dir, "atrium"))
    schedule = SessionSchedule.round_trip(rate_hz, latency_ms)
    result = {"traces": list(traces), "start_s": start_s, "duration_s": duration_s, "latency_ms": latency_ms,
              "output": list(out_size), "variants": {}}
    bar = None
    for label, spec in specs.items():
        scene = load_scene(spec)
        t0 = time.perf_counter()
        proxies, bundle = load_proxies(scene, progress=progress)
        build_s = time.perf_counter() - t0
        row = {"objects": len(scene.objects), "triangles": scene.triangle_count, "lod_seconds": build_s,
               "proxy_triangles": bundle.triangles["proxy"], "notes": list(scene.notes), "quality": {}}
        sim = Simulation(scene, bench_server_config(view_size), out_size, proxies=proxies)
        try:
            for tr in traces:
                samples = display_samples(scene, tr, start_s, duration_s, schedule)[::stride]
                if progress and bar is None:
                    from tqdm import tqdm

                    bar = tqdm(total=len(samples) * len(traces) * len(specs), unit="frame", desc="bench split",
                               file=sys.stderr, leave=False, disable=None)
                q = evaluate_methods(sim, samples, {"rotation": ("rotation", {}), "proxy": ("proxy", {})}, bar=bar)
                row["quality"][tr] = {m: summarize(s) for m, s in q.items()}
        finally:
            sim.close()
            sim.ctx.release()
        result["variants"][label] = row
    if bar is not None:
        bar.close()
    write_result(out_dir, "split.json", result)
    return result


def print_split_table(r: dict) -> None:
    print(f"pibr bench split: a one-mesh atrium, whole or cut into pieces; {r['latency_ms']:g} ms, "
          f"{r['output'][0]}x{r['output'][1]}, {', '.join(r['traces'])}")
    print(f"{'variant':<8}{'objects':>8}{'LoD s':>8}{'proxy tris':>11}  trace         method   "
          f"{'ms':>7}{'tris drawn':>11}{'DSSIM':>8}{'PSNR':>7}")
    for label, v in r["variants"].items():
        first = True
        for tr, q in v["quality"].items():
            for m, s in q.items():
                head = (f"{label:<8}{v['objects']:>8}{v['lod_seconds']:>8.1f}{v['proxy_triangles']:>11}"
                        if first else " " * 35)
                first = False
                print(f"{head}  {tr:<13} {m:<8}{s['client_ms_median']:>7.1f}{s['triangles_mean']:>11.0f}"
                      f"{s['dssim_mean']:>8.4f}{s['psnr_mean']:>7.2f}")
