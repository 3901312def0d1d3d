"""The README's benchmark tables, rendered from the result files committed under ``docs/results/``.

A table in the README is announced by a marker on the line before it::

    <!-- table: pareto from docs/results/pareto.json -->

naming a renderer of :data:`RENDERERS` and the result file(s) it reads (comma-separated, paths
from the repository's root). :func:`check` renders every announced table and compares it with
the README's lines (bold marks ``**`` are the README's emphasis and, like the spaces around a cell, are ignored), and reports
every table of the benchmark section that no marker announces; ``tests/docs`` runs it, so a
table cannot go stale silently. ``python -m pibr.bench.readme_tables --write`` rewrites the
announced tables from their files after a re-run (keeping no emphasis: add it again by hand).
"""
from __future__ import annotations

import argparse
import json
import os
import re
import sys

MARKER = re.compile(r"^<!-- table: (?P<name>[\w-]+) from (?P<files>[^ ]+(?:, ?[^ ]+)*) -->\s*$")
#: The README's section whose every table must come from a result file.
SECTION = ("## Benchmarks", "## Known limitations")


def _row(cells) -> str:
    return "| " + " | ".join(str(c) for c in cells) + " |"


def _table(head, rows) -> list[str]:
    return [_row(head), _row(["---"] * len(head)), *(_row(r) for r in rows)]


def _pct(x, digits=2) -> str:
    return "—" if x is None else f"{100 * x:.{digits}f}"


def _num(x, fmt) -> str:
    return "—" if x is None else format(x, fmt)


# -- renderers: result dicts -> markdown lines --------------------------------------------------------------------

def realtime(r: dict) -> list[str]:
    """``pibr bench realtime``: one row per placement x controllers x method, and the virtual clock."""
    rows = []
    for run in r["runs"]:
        c = run["per_client"][0]
        rows.append([run["placement"], "on" if run["controllers"] else "off", run["method"],
                     f"{c['server_fps']:.1f}", f"{c['output_hz']:.1f}", f"{100 * c['missed_fraction']:.1f}",
                     f"{c['age_ms_p50']:.0f}", f"{c['age_ms_p99']:.0f}", f"{c['client_ms_median']:.1f}",
                     f"{run['shown']['dssim_mean']:.4f}", f"{run['cpu_share']['server']:.2f}",
                     f"{run['cpu_share']['client']:.2f}"])
    virtual = r.get("virtual", [])
    if virtual:
        s = r["settings"]
        missed = max(100 * v["per_client"][0]["missed_fraction"] for v in virtual)
        rows.append(["virtual clock (the reference)", "—", " / ".join(v["method"] for v in virtual),
                     f"{s['server_fps']:g}", f"{s['rate_hz']:g}", f"{missed:.0f}", "", "", "",
                     " / ".join(f"{v['shown']['dssim_mean']:.4f}" for v in virtual), "", ""])
    return _table(["placement", "controllers", "method", "server fps", "output Hz", "missed %", "age p50 ms",
                   "p99 ms", "client ms", "DSSIM shown", "CPU server", "client"], rows)


def levels(r: dict) -> list[str]:
    """``pibr bench levels``: every level of every method."""
    rows = [[method, lv["name"], f"{lv['ms_median']:.1f}", f"{lv['cpu_ms_median']:.1f}", f"{lv['ms_of_top']:.2f}",
             f"{lv['dssim_mean']:.4f}", f"{lv['psnr_mean']:.2f}", _pct(lv["own_holes_mean"])]
            for method, table in r["methods"].items() for lv in table]
    return _table(["method", "level", "wall ms", "CPU ms", "× top", "DSSIM", "PSNR", "own holes %"], rows)


def upsampling(*results: dict) -> list[str]:
    """``pibr bench upsampling``, one file per depth codec: per stream, bits, server ms and quality."""
    def q(x):
        return f"{x['psnr_mean']:.2f} / {x['dssim_mean']:.4f}"

    rows = []
    for r in results:
        for name, s in r["streams"].items():
            t = s["times_ms_median"]
            whole = s["colour_scale"] == 1.0
            label = {"whole": "whole", "quarter": "quarter", "quarter-bits": "quarter, ¼ bits"}.get(name, name)
            rows.append([r["settings"]["depth_codec"], label, f"{s['video_kbps']:.0f}",
                         f"{t['render_ms']:.1f} / {t['pack_ms']:.1f} / {t['video_cpu_ms']:.1f}",
                         f"{t['colour_ms']:.1f}", "—" if whole else f"{t['rebuild_ms']:.1f}",
                         q(s["still"]["primary"]["rebuilt"]), q(s["moving"]["primary"]["rebuilt"]),
                         "—" if whole else q(s["moving"]["primary"]["bilinear"]),
                         q(s["moving"]["extra"]["rebuilt"]), "—" if whole else q(s["moving"]["extra"]["bilinear"])])
    return _table(["depth", "stream", "colour kbit/s", "server: render / pack / H.264 ms", "colour ms",
                   "client rebuild ms", "primary, still", "primary, moving", "moving, bilinear",
                   "extra view, moving", "extra, bilinear"], rows)


def pareto(r: dict, scene: str = "room") -> list[str]:
    """``pibr bench pareto``: every variant's means over all windows and its speed."""
    s = r["scenes"][scene]
    sizes = list(next(iter(s["variants"].values()))["speed"])
    rows = []
    for label, v in s["variants"].items():
        qv, sp = v["quality"], v["speed"]
        rows.append([label, f"{qv['dssim_mean']:.4f}", f"{qv['psnr_mean']:.2f}", _num(qv["flip_mean"], ".3f"),
                     _pct(qv["geometric_holes_mean"]), _pct(qv["own_holes_mean"]),
                     *(f"{sp[z]['ms_median']:.1f}" if z in sp else "—" for z in sizes),
                     f"{qv['primitives_per_view_pixel']:.3f}"])
    return _table(["method (knob)", "DSSIM", "PSNR dB", "FLIP", "geo holes %", "own holes %",
                   *(f"ms {z.replace('x', '×')}" for z in sizes), "primitives / view px"], rows)


def pareto_windows(r: dict, scene: str = "room") -> list[str]:
    """``pibr bench pareto``: each variant's DSSIM per window (the oracle aside), and each window's winner."""
    s = r["scenes"][scene]
    windows = list(s["per_window"])
    labels = [k for k in s["variants"] if any(k in s["per_window"][w]["dssim"] for w in windows)]
    short = [w.replace(" s", "") for w in windows]
    rows = [[label, *(_num(s["per_window"][w]["dssim"].get(label), ".4f") for w in windows)] for label in labels]
    rows.append(["**winner**", *(s["per_window"][w]["winner"] for w in windows)])
    rows.append(["best competitor", *(s["per_window"][w].get("best_competitor", "—") for w in windows)])
    return _table(["variant", *short], rows)


def coverage(r: dict) -> list[str]:
    """``pibr bench coverage``: uncovered pixels per window and variant, and over all windows."""
    variants = ("primary", "peel_no_offset", "offset_no_peel", "offset_peel", "floor")
    titles = ("primary only", "extra: peeling, no offset", "extra: offset, no peeling", "extra: offset + peeling",
              "no latency (floor)")
    rows = [[w, *(_pct(d["means"][k]) for k in variants)] for w, d in r["per_window"].items()]
    rows.append(["all", *(_pct(r["means"][k]) for k in variants)])
    rows.append(["all, geometry only", *(_pct(r["means"][k + ":geometry"]) for k in variants)])
    return _table(["window", *titles], rows)


def dynamic(r: dict, scene: str = "dynamic") -> list[str]:
    """``pibr bench dynamic``: DSSIM over the whole frame / over the moving objects' pixels per
    motion mode and latency, and the motion bits per frame at the middle latency."""
    from pibr.client.object_motion import DEFAULT_MOTION

    s = r["scenes"][scene]
    latencies = [f"{x:g}" for x in r["latencies_ms"]]
    middle = latencies[len(latencies) // 2]
    rows = []
    for key, m in s["latency"][middle]["methods"].items():
        if m["method"] == "proxy":
            mode = m["options"]["motion"]
            label = f"proxy, {mode}" + (" (default)" if mode == DEFAULT_MOTION else "") + \
                (" (benchmarks only)" if mode == "oracle" else "")
        else:
            label = key.replace("+", ", ")
        cells = []
        for lat in latencies:
            x = s["latency"][lat]["methods"][key]
            cells.append(f"{x['dssim']:.4f}"[1:] + " / " + _num(x["dssim_moving"], ".4f")[1:])
        rows.append([label, *cells, f"{m['motion_bits_per_frame']:,.0f}"])
    return _table(["method", *(f"{x} ms" for x in latencies), f"motion bits per frame ({middle} ms)"], rows)


def ibr(r: dict) -> list[str]:
    """``pibr bench ibr``: DSSIM (PSNR dB) of none, rotation and proxy per window, proxy's own holes."""
    rows = []
    for w, q in r["quality"].items():
        best = min(q, key=lambda k: q[k]["dssim_mean"])
        cells = [(f"**{q[k]['dssim_mean']:.4f}**" if k == best else f"{q[k]['dssim_mean']:.4f}")
                 + f" ({q[k]['psnr_mean']:.1f})" for k in ("none", "rotation", "proxy")]
        rows.append([w, *cells, _pct(q["proxy"]["hole_fraction_mean"])])
    return _table(["window", "none", "rotation", "proxy", "proxy's own holes %"], rows)


def split(r: dict) -> list[str]:
    """``pibr bench split``: the one-mesh level whole and cut into pieces."""
    rows = []
    for label, v in r["variants"].items():
        cells = []
        for tr, q in v["quality"].items():
            s = q["proxy"]
            cells.append(f"{s['client_ms_median']:.1f}, {s['triangles_mean'] / 1000:.0f}k, {s['dssim_mean']:.4f}")
        rows.append([{"whole": "whole", "pieces": "cut into pieces"}.get(label, label), v["objects"],
                     f"{v['lod_seconds']:.1f} s", v["proxy_triangles"], *cells])
    traces = list(next(iter(r["variants"].values()))["quality"])
    return _table(["", "objects", "LoD build", "proxy triangles",
                   *(f"{t}: proxy ms, triangles drawn, DSSIM" for t in traces)], rows)


def server_projection(r: dict) -> list[str]:
    """``pibr bench server``: median ms per stage and kbit/s per projection and extra view."""
    rows = []
    for x in r["rows"]:
        rows.append([x["projection"], "on" if x["extra_view"] else "off", f"{x['atlas'][0]}×{x['atlas'][1]}",
                     f"{x['rasterised_triangles']:,}", f"{x['render_ms']:.1f}", f"{x['readback_ms']:.1f}",
                     f"{x['pack_ms']:.1f}", f"{x['encode_ms']:.1f}", f"{x['total_ms']:.1f}", f"{x['kbps']:.0f}"])
    return _table(["projection", "extra view", "atlas", "triangles", "render", "read back", "pack", "encode (x264)",
                   "total", "kbit/s"], rows)


def server_edges(r: dict) -> list[str]:
    """``pibr bench server --max-edge-deg ... --accuracy``: the pre-tessellation's edge angle."""
    from pibr.server.config import MAX_EDGE_ANGLE_DEG

    rows = [[f"{x['max_edge_deg']:g}°" + (" (default)" if x["max_edge_deg"] == MAX_EDGE_ANGLE_DEG else ""),
             f"{x['rasterised_triangles']:,}", f"{x['render_ms']:.1f}",
             f"{x['total_ms']:.1f}", f"{x['psnr_vs_reference_db']:.1f} dB", f"{100 * x['distance_off_fraction']:.3f} %"]
            for x in r["rows"]]
    return _table(["edge angle", "triangles", "render ms", "total ms",
                   f"colour PSNR vs {r['reference_edge_deg']:g}°", "pixels > 1 % off in distance"], rows)


def codec_matched(r: dict) -> list[str]:
    """``pibr bench codec``: per edge threshold, the edge codec at 8, 10 and 12 bits and H.264
    depth alone at the rate of the edge curve of its precision: kbit/frame, disparity PSNR, share
    of pixels more than 1 % off in distance."""
    from pibr.protocol.edgecodec.codec import DEFAULT_THRESHOLD

    def cell(v):
        return "—" if v is None else f"{v['bits_per_frame'] / 1000:.1f}, {v['psnr_db']:.1f} dB, {100 * v['outliers_1pct']:.1f} %"

    names = [n for n in ("edge-8bit", "h264-8bit", "edge-10bit", "h264-10bit", "edge")
             if any(n in m for m in r["matched"])]
    titles = {"edge-8bit": "edge 8-bit", "h264-8bit": "H.264 8-bit at its rate", "edge-10bit": "edge 10-bit",
              "h264-10bit": "H.264 10-bit at its rate", "edge": "edge 12-bit (default)"}
    rows = [[f"{m['threshold']:g}" + (" (default)" if m["threshold"] == DEFAULT_THRESHOLD else ""),
             *(cell(m.get(n)) for n in names)] for m in sorted(r["matched"], key=lambda m: -m["threshold"])]
    return _table(["edge threshold", *(titles[n] for n in names)], rows)


def codec_end_to_end(r: dict) -> list[str]:
    """``pibr bench codec``: proxy DSSIM at equal total bitrate per depth codec (— where its depth
    leaves the colour too little)."""
    e2e = r["end_to_end"]
    codecs = list(dict.fromkeys(v["codec"] for v in e2e["results"].values()))
    totals = list(dict.fromkeys(v["total_kbps"] for v in e2e["results"].values()))
    rows = []
    for t in totals:
        cells = []
        for c in codecs:
            v = e2e["results"].get(f"{t:g}/{c}")
            cells.append("—" if v is None or not v["feasible"] else f"{v['dssim_mean']:.4f}")
        rows.append([f"{t / 1000:g} Mbit/s", *cells])
    return _table(["total", *codecs], rows)


def lod_target(r: dict) -> list[str]:
    """The LoD target's study (docs/results/lod-target.json): per scene and output size, proxy's
    mean DSSIM over the windows at each target in pixels of that output; the default's angle
    (6 px of a 960-wide output) is marked where a target of that run equals it."""
    from pibr.client.lod_select import DEFAULT_TARGET_PX, REFERENCE_FOCAL_PX

    rows, targets = [], None
    for name, run in r["runs"].items():
        per = next(iter(run["lod"].values()))
        targets = targets or list(per)
        width = run["output"][0]
        now = DEFAULT_TARGET_PX * width / (2 * REFERENCE_FOCAL_PX)   # 90-degree outputs
        cells = []
        for label in targets:
            px = float(label.split()[-1].rstrip("px"))
            mean = sum(run["lod"][w][label]["dssim_mean"] for w in run["lod"]) / len(run["lod"])
            cells.append(f"{mean:.4f}" + (" ←" if abs(px - now) < 1e-9 else ""))
        rows.append([name.replace("x", "×"), *cells])
    return _table(["scene, output", *(t.replace("proxy lod ", "") for t in targets)], rows)


def stereo(r: dict) -> list[str]:
    """``pibr bench stereo``: per scene, method and server reference, the per-eye quality against
    the mono view's, the binocular consistency and the client's CPU ms per pair against one view."""
    rows = []
    for scene, s in r["scenes"].items():
        for v in s["variants"].values():
            rows.append([scene, v["method"], v["mode"], f"{v['dssim_mean']:.4f}", _num(v.get("dssim_vs_mono"), ".2f"),
                         f"{v['psnr_mean']:.2f}", _pct(v["geometric_holes_mean"]), _pct(v["inconsistent_mean"], 1),
                         f"{v['cpu_ms_median']:.1f}", _num(v.get("cpu_ms_vs_mono"), ".2f")])
    return _table(["scene", "method", "reference", "DSSIM per eye", "× mono", "PSNR", "geo holes %",
                   "inconsistent %", "CPU ms", "× mono"], rows)


def stereo_server(r: dict) -> list[str]:
    """``pibr bench stereo``: per scene and reference stream, bits per second and server CPU ms."""
    rows = [[scene, ", ".join(srv["modes"]), f"{srv['frames_per_tick']:.0f}", f"{srv['bits_per_second'] / 1e6:.2f}",
             f"{srv['server_cpu_ms_per_frame']:.0f}"]
            for scene, s in r["scenes"].items() for srv in s["server"].values()]
    return _table(["scene", "references", "frames a tick", "Mbit/s", "server CPU ms a frame"], rows)


def predict(r: dict) -> list[str]:
    """``pibr bench predict``: mean angular error (degrees) / position error (mm) per predictor and look-ahead."""
    look = [f"{a:g}" for a in r["look_aheads_ms"]]
    rows = [[name, *(f"{p['overall'][a]['angle_deg_mean']:.2f} / {p['overall'][a]['position_mm_mean']:.1f}"
                     for a in look)] for name, p in r["predictors"].items()]
    return _table(["predictor", *(f"{a} ms" for a in look)], rows)


def predict_quality(r: dict) -> list[str]:
    """``pibr bench predict``: DSSIM of rotation / proxy per predictor and round trip, the server
    rendering for the predicted pose."""
    q = r["quality"]["by_latency_ms"]
    latencies = list(q)
    names = list(next(iter(q.values())))
    rows = [[name, *(" / ".join(f"{v['dssim_mean']:.4f}" for v in q[lat][name].values()) for lat in latencies)]
            for name in names]
    methods = " / ".join(next(iter(next(iter(q.values())).values())))
    return _table(["predictor", *(f"{lat} ms ({methods})" for lat in latencies)], rows)


def network(r: dict) -> list[str]:
    """``pibr bench network``: per bandwidth trace and setting, frame age p50 / p95, stalls (the
    longest), the bitrate that arrived and DSSIM of what was shown."""
    rows = []
    for link, entry in r["links"].items():
        for name, v in entry["runs"].items():
            rows.append([link, name, f"{v['age_ms_p50']:.0f} / {v['age_ms_p95']:.0f}",
                         f"{v['stalls']} ({v['longest_stall_ms']:.0f} ms)", f"{v['arrived_kbps']:.0f}",
                         f"{v['dssim_mean']:.4f}"])
    return _table(["link", "setting", "age ms p50 / p95", "stalls > 250 ms (longest)", "kbit/s arrived", "DSSIM"],
                  rows)


def network_start(r: dict) -> list[str]:
    """bench/network_bench.py compare_starts: the adapting stream from its ladder's foot against
    from half the link its proxies measured, per head-trace window and link."""
    rows = []
    for row in r["rows"]:
        a, b = row["foot"], row["probe"]
        rows.append([row["window"], row["link"], f"{a['age_ms_p95']:.0f} / {b['age_ms_p95']:.0f}",
                     f"{a['stalls']} / {b['stalls']}", f"{a['dssim_first_segment']:.4f} / {b['dssim_first_segment']:.4f}",
                     f"{a['dssim_mean']:.4f} / {b['dssim_mean']:.4f}"])
    return _table(["window", "link", "age p95 ms (foot / probe)", "stalls", "first 5 s DSSIM", "DSSIM"], rows)


def network_repeats(r: dict) -> list[str]:
    """docs/results/network-real-repeats.json: the adapting and static 16000 rows of the wall-clock
    run again, each run's DSSIM and, in brackets, its age p95, per link."""
    def cells(v) -> str:
        ages = {round(a) for a in v["age_ms_p95"]}
        age = f"{ages.pop()} each" if len(ages) == 1 and len(v["age_ms_p95"]) > 1 else \
            ", ".join(f"{a:.0f}" for a in v["age_ms_p95"])
        return ", ".join(f"{d:.4f}" for d in v["dssim_mean"]) + f" ({age})"

    rows = [[link, cells(s["adapt 16000"]), cells(s["static 16000"])] for link, s in r["summary"].items()]
    return _table(["link", "adapt 16000: DSSIM (age p95 ms)", "static 16000: DSSIM (age p95 ms)"], rows)


def live(r: dict) -> list[str]:
    """``pibr bench live``: the client alone and watched by the live page, and the page's share."""
    s = r["summary"]
    rows = [[k, f"{s[k]['client_ms_median']:.1f}", f"{s[k]['client_ms_p95']:.1f}", f"{100 * s[k]['missed_fraction']:.1f}",
             "—" if k == "alone" else f"{100 * s['loop_share_of_tick_time']:.2f}",
             "—" if k == "alone" else f"{100 * s['thread_share_of_tick_time']:.2f}"] for k in ("alone", "watched")]
    return _table(["client", "render ms p50", "p95", "missed %", "page: event loop % of tick time",
                   "page: image thread %"], rows)


def cluster(r: dict) -> list[str]:
    """``pibr bench cluster``: one trade sweep in this process and on 1 and 2 Ray workers."""
    rows = []
    for run in r["runs"]:
        p = run["placement"]
        where = "this process (default)" if p["mode"] == "in-process" else f"Ray, {p['workers']} worker" + (
            "s" if p["workers"] > 1 else "")
        one, here = run.get("speedup_over_one_worker"), run.get("speedup_over_in_process")
        rows.append([where, str(run["points"]), f"{run['seconds']:.0f}", "—" if one is None else f"{one:.2f}×",
                     "—" if here is None else f"{here:.2f}×", "yes" if run["same_numbers_as_in_process"] else "NO"])
    return _table(["where the points run", "points", "seconds", "speed-up over 1 worker", "over this process",
                   "same numbers"], rows)


def scoring(r: dict) -> list[str]:
    """``pibr bench scoring``: the demo's session streamed, then scored (wall and CPU seconds)."""
    rows = [[phase, f"{r[key]['seconds']:.1f}", f"{r[key]['cpu_seconds']:.0f}"]
            for phase, key in (("streaming (server, relay, client)", "streaming"),
                               ("scoring (ground truth, metrics, holes, video)", "scoring"))]
    rows.append(["scoring / streaming", f"{r['scoring_over_streaming']:.2f}", ""])
    return _table(["phase", "seconds", "CPU seconds"], rows)


def scoring_stages(r: dict) -> list[str]:
    """``pibr bench scoring``: each stage's CPU ms per tick, pibr's beside the library's."""
    rows = [[st["stage"], f"{st['ms_per_tick']:.1f}",
             "—" if st["library_ms_per_tick"] is None else f"{st['library_ms_per_tick']:.1f}"] for st in r["stages"]]
    return _table(["stage", "pibr, CPU ms a tick", "the library's, same run"], rows)


RENDERERS = {"realtime": realtime, "levels": levels, "upsampling": upsampling, "pareto": pareto,
             "pareto-windows": pareto_windows, "coverage": coverage, "dynamic": dynamic, "ibr": ibr,
             "split": split, "server-projection": server_projection, "server-edges": server_edges,
             "codec-matched": codec_matched, "codec-end-to-end": codec_end_to_end, "lod-target": lod_target,
             "stereo": stereo, "stereo-server": stereo_server, "predict": predict,
             "predict-quality": predict_quality, "network": network, "network-start": network_start,
             "network-repeats": network_repeats, "live": live,
             "cluster": cluster, "scoring": scoring, "scoring-stages": scoring_stages}


# -- the README ---------------------------------------------------------------------------------------------------

def _unbold(line: str) -> str:
    """A table line as compared: no emphasis, each cell's surrounding spaces dropped."""
    return "|".join(c.strip() for c in line.replace("**", "").rstrip().split("|"))


def _table_at(lines: list[str], i: int) -> list[str]:
    """The markdown table starting at line ``i`` (its rows up to the first line not starting with '|')."""
    j = i
    while j < len(lines) and lines[j].startswith("|"):
        j += 1
    return lines[i:j]


def _is_table_head(lines, i) -> bool:
    return lines[i].startswith("|") and i + 1 < len(lines) and lines[i + 1].startswith("| ---") and \
        (i == 0 or not lines[i - 1].startswith("|"))


def announced(lines: list[str]) -> list[tuple[int, str, list[str]]]:
    """(line index of the table, renderer name, result files) of every marker."""
    out = []
    for i, line in enumerate(lines):
        m = MARKER.match(line)
        if m:
            out.append((i + 1, m["name"], [f.strip() for f in m["files"].split(",")]))
    return out


def render(name: str, files: list[str], root: str) -> list[str]:
    if name not in RENDERERS:
        raise KeyError(f"unknown README table {name!r}; known: {', '.join(RENDERERS)}")
    results = []
    for f in files:
        with open(os.path.join(root, f)) as fh:
            results.append(json.load(fh))
    return RENDERERS[name](*results)


def check(readme: str, root: str) -> list[str]:
    """Every disagreement between the README at ``readme`` and the result files under ``root``,
    and every benchmark table no marker announces; [] when they all agree."""
    with open(readme) as f:
        lines = f.read().split("\n")
    problems = []
    marked = set()
    for i, name, files in announced(lines):
        marked.add(i)
        if i >= len(lines) or not _is_table_head(lines, i):
            problems.append(f"line {i}: the marker for {name!r} is not followed by a table")
            continue
        try:
            want = render(name, files, root)
        except (OSError, KeyError, ValueError) as e:
            problems.append(f"line {i}: table {name!r}: {e}")
            continue
        have = [_unbold(x) for x in _table_at(lines, i)]
        want = [_unbold(x) for x in want]
        if have != want:
            diff = next((k for k, (a, b) in enumerate(zip(have, want)) if a != b), min(len(have), len(want)))
            problems.append(f"line {i + 1 + diff}: table {name!r} from {', '.join(files)} differs:\n"
                            f"  README: {have[diff] if diff < len(have) else '(missing)'}\n"
                            f"  result: {want[diff] if diff < len(want) else '(missing)'}")
    inside = False
    for i, line in enumerate(lines):
        if line.startswith("## "):
            inside = line.startswith(SECTION[0]) or (inside and not line.startswith(SECTION[1]))
        if inside and _is_table_head(lines, i) and i not in marked:
            problems.append(f"line {i + 1}: a benchmark table with no result file announced ({line[:60]}...)")
    return problems


def write(readme: str, root: str) -> int:
    """Rewrite every announced table from its files; -> how many changed."""
    with open(readme) as f:
        lines = f.read().split("\n")
    changed = 0
    for i, name, files in reversed(announced(lines)):
        old = _table_at(lines, i)
        new = render(name, files, root)
        if [_unbold(x) for x in old] != [_unbold(x) for x in new]:
            lines[i:i + len(old)] = new
            changed += 1
    with open(readme, "w") as f:
        f.write("\n".join(lines))
    return changed


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m pibr.bench.readme_tables",
                                description="Check (or rewrite) the README's benchmark tables against docs/results/.")
    p.add_argument("--readme", default="README.md")
    p.add_argument("--root", default=".", help="where the paths in the markers start (default: .)")
    p.add_argument("--write", action="store_true", help="rewrite the announced tables from their files")
    a = p.parse_args(argv)
    if not os.path.isfile(a.readme):
        print(f"no README at {a.readme!r}: run from the repository's root or pass --readme", file=sys.stderr)
        return 2
    if a.write:
        print(f"{write(a.readme, a.root)} table(s) rewritten")
    problems = check(a.readme, a.root)
    for x in problems:
        print(x)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
