"""``pibr bench lod``: encaging LoD proxies (Reinert et al. 2016) per object -- size, enclosure, time.

For every object of each scene (built-in names or asset files, loaded with
:func:`pibr.scenes.registry.load_scene`) the proxy is read through the LoD cache (generated and
stored there if missing; the seconds are those of its generation) or, with ``use_cache=False``
(``--no-cache``), generated afresh on this machine, and reported with
its triangle counts, kind (simplified / box), the enclosed fraction of the original vertices
and the largest distance of one outside the proxy, measured on the proxy itself.
"""
from __future__ import annotations

import os
import platform
import time
from pathlib import Path

from pibr.scenes import data as _scene_data
from .results import write_result

#: The real asset measured by default: Keenan Crane's "Spot" (CC0), see scenes/data/assets/README.md.
REAL_ASSET = Path(_scene_data.__file__).resolve().parent / "assets" / "spot_triangulated.obj"


def default_assets() -> tuple[str, ...]:
    """The shipped real asset(s) that exist in this installation."""
    return (str(REAL_ASSET),) if REAL_ASSET.is_file() else ()


def run_lod_bench(scene_specs=("room",), assets=None, resolution=128, target_fraction=0.005,
                  out_dir="out/bench", use_cache=True, min_triangles=12, progress=None) -> dict:
    """Generate (or read cached) LoDs of every object; write ``out_dir/lod.json``; return the result.

    assets   : asset file paths (None: :func:`default_assets`)
    progress : callable(str) told which object is being done, or None
    """
    from pibr.scenes.lod import simplify_encaging
    from pibr.scenes.lod_cache import cached_lod
    from pibr.scenes.registry import load_scene

    specs = list(scene_specs) + list(default_assets() if assets is None else assets)
    scenes = []
    t_all = time.perf_counter()
    for spec in specs:
        scene = load_scene(spec)
        rows = []
        for obj in scene.objects:
            if progress is not None:
                progress(f"{scene.name}/{obj.name}")
            if use_cache:
                r = cached_lod(obj.mesh, resolution=resolution, target_fraction=target_fraction,
                               min_triangles=min_triangles)
            else:
                r = simplify_encaging(obj.mesh, resolution=resolution, target_fraction=target_fraction,
                                      min_triangles=min_triangles)
            rows.append({
                "object": obj.name, "kind": r.kind,
                "triangles_original": r.triangles_original, "triangles_proxy": r.triangles_proxy,
                "target_triangles": r.params.get("target_triangles", 0),
                "enclosed_fraction": r.enclosed_fraction, "max_outside_distance": r.max_outside_distance,
                "tolerance": r.params.get("tolerance", 0.0), "voxel_size": r.params.get("voxel_size", 0.0),
                "resolution_used": r.params.get("resolution_used"),
                "volume_ratio_to_box": r.params.get("volume_ratio_to_box"),
                "iterations": r.iterations, "seconds": r.seconds, "note": r.note,
            })
        scenes.append({"scene": scene.name, "spec": spec, "objects": rows, "totals": _totals(rows)})
    all_rows = [row for s in scenes for row in s["objects"]]
    result = {
        "bench": "lod",
        "resolution": resolution, "target_fraction": target_fraction, "min_triangles": min_triangles,
        "cached": bool(use_cache),
        "machine": {"python": platform.python_version(), "cpu_count": os.cpu_count(), "platform": platform.platform()},
        "scenes": scenes,
        "totals": _totals(all_rows),
        "wall_seconds": time.perf_counter() - t_all,
    }
    write_result(out_dir, "lod.json", result)
    return result


def _totals(rows: list[dict]) -> dict:
    """Sums and extremes over object rows (``enclosed_fraction``: vertex-weighted is not kept per
    row, so both the minimum and the object mean are given)."""
    n = len(rows)
    return {
        "objects": n,
        "simplified": sum(r["kind"] == "simplified" for r in rows),
        "box": sum(r["kind"] == "box" for r in rows),
        "empty": sum(r["kind"] == "empty" for r in rows),
        "triangles_original": sum(r["triangles_original"] for r in rows),
        "triangles_proxy": sum(r["triangles_proxy"] for r in rows),
        "enclosed_fraction_min": min((r["enclosed_fraction"] for r in rows), default=1.0),
        "enclosed_fraction_mean": sum(r["enclosed_fraction"] for r in rows) / n if n else 1.0,
        "max_outside_distance": max((r["max_outside_distance"] for r in rows), default=0.0),
        "seconds": sum(r["seconds"] for r in rows),
    }


def print_lod_table(result: dict) -> None:
    """Per object and per scene, as a fixed-width table on stdout."""
    print(f"pibr bench lod: requested resolution {result['resolution']}, target "
          f"{100 * result['target_fraction']:g} % of the original triangles (at least {result['min_triangles']}), "
          f"{'through the LoD cache' if result['cached'] else 'generated afresh (--no-cache)'}")
    head = (f"{'object':<28} {'kind':<10} {'tris':>7} {'proxy':>6} {'enclosed':>9} {'max out m':>10} "
            f"{'vol/box':>7} {'res':>4} {'s':>7}")
    for s in result["scenes"]:
        print(f"\n{s['scene']} ({s['spec']})")
        print(head)
        print("-" * len(head))
        for r in s["objects"]:
            ratio = "" if r["volume_ratio_to_box"] is None else f"{r['volume_ratio_to_box']:.2f}"
            res = "" if r["kind"] != "simplified" or r["resolution_used"] is None else str(r["resolution_used"])
            print(f"{r['object'][:28]:<28} {r['kind']:<10} {r['triangles_original']:>7} {r['triangles_proxy']:>6} "
                  f"{r['enclosed_fraction']:>9.4f} {r['max_outside_distance']:>10.2g} {ratio:>7} {res:>4} "
                  f"{r['seconds']:>7.2f}")
            if r["resolution_used"] not in (None, result["resolution"]) and r["note"]:
                print(f"{'':<28}   resolution {r['resolution_used']}, not {result['resolution']}: {r['note']}")
        _print_totals(s["totals"], head)
    if len(result["scenes"]) > 1:
        print("\nall scenes")
        _print_totals(result["totals"], head)


def _print_totals(t: dict, head: str) -> None:
    print("-" * len(head))
    print(f"{'total (' + str(t['objects']) + ' objects)':<28} {str(t['simplified']) + ' simpl.':<10} "
          f"{t['triangles_original']:>7} {t['triangles_proxy']:>6} {t['enclosed_fraction_min']:>9.4f} "
          f"{t['max_outside_distance']:>10.2g} {'':>7} {'':>4} {t['seconds']:>7.2f}")
    print(f"  ({t['box']} box, {t['empty']} empty; enclosed: minimum over objects; proxy = "
          f"{100 * t['triangles_proxy'] / max(t['triangles_original'], 1):.2f} % of the triangles)")
