"""``pibr bench network``: the stream on links whose bandwidth changes, static bitrates against the
adapting stream (issue 28, item 5).

Every run is real processes on the virtual clock (reproducible): a server (``--adapt on`` or a
static ``--bitrate-kbps``), a relay replaying a bandwidth trace on the downlink (common/bandwidth.py;
64 ms each way), and a client showing one method over a head-trace window; what it showed is
scored against ground truth afterwards. Per run: frame age p50/p95 at display, stalls (no new
frame for longer than :data:`STALL_MS`: how many, the longest), the DSSIM of what was shown, and
the bitrate that arrived. Per link trace, each :data:`SEGMENT_S` segment's DSSIM of the adapting
stream beside the best static setting *in hindsight* for that segment. Nothing here fits a
default; the head-trace window is an evaluation window and is named in the JSON.
"""
from __future__ import annotations

import csv
import os
import platform
import sys

import numpy as np

from pibr.common.bandwidth import BUILTIN, load_bandwidth_trace
from pibr.protocol.messages import CLOCKS

from .results import write_result

STALL_MS = 250.0
SEGMENT_S = 5.0
#: The time step of each run's series in the JSON (what the plot draws).
SERIES_STEP_S = 0.25
GOALS = {"age_p95_over_rtt_ms_max": 300.0, "stall_ms_max": 1000.0, "dssim_of_best_static_max": 1.10}


def _records_summary(out: str, method: str, duration_s: float) -> dict:
    from pibr.client.recorder import read_records

    from .evaluate import read_session

    rows = read_records(os.path.join(out, f"{method}.records.csv"))
    ages = np.array([r["age_ms"] for r in rows], float)
    ages = ages[np.isfinite(ages)]
    changes = [r["t"] for prev, r in zip(rows, rows[1:]) if r["frame_id"] != prev["frame_id"] and r["frame_id"] >= 0]
    gaps = np.diff(changes) * 1e3 if len(changes) > 1 else np.array([duration_s * 1e3])
    session = read_session(out)["result"]
    arrivals = np.array(session.get("frame_arrivals_s", []), float)
    sizes = np.array(session.get("frame_bytes", []), float)
    on_clock = (arrivals >= 0) & (arrivals <= duration_s) if len(arrivals) == len(sizes) else slice(None)
    kbps = [r["stream_kbps"] for r in rows if r["stream_kbps"] >= 0]
    views = [r["stream_view"] for r in rows if r["stream_view"] >= 1]
    server_levels = [r["server_level"] for r in rows if r["server_level"] >= 0]
    return {"age_ms_p50": float(np.percentile(ages, 50)) if len(ages) else None,
            "age_ms_p95": float(np.percentile(ages, 95)) if len(ages) else None,
            "stalls": int(np.count_nonzero(gaps > STALL_MS)), "longest_stall_ms": float(gaps.max()),
            "arrived_kbps": float(sizes[on_clock].sum() * 8 / duration_s / 1e3),
            "frames": int(len(changes)),
            "colour_kbps_chosen": {"min": min(kbps), "max": max(kbps), "mean": float(np.mean(kbps))} if kbps else None,
            # the share of ticks that showed a frame whose primary view the adaptation made smaller
            "smaller_view_share": float(np.mean(np.array(views) > 1)) if views else None,
            # what each end's own deadline chose, which moves what is shown as much as the link
            # does on the wall clock: the client's level per tick (0 its method's best) and the
            # server's rate-control level of the frame shown (0 its best; None: no rate control),
            # and the ticks that missed their deadline
            "client_level_mean": float(np.mean([r["level"] for r in rows])) if rows else None,
            "server_level_mean": float(np.mean(server_levels)) if server_levels else None,
            "missed_ticks": int(sum(r["missed"] for r in rows))}


def _series(out: str, method: str, duration_s: float, step_s: float = SERIES_STEP_S) -> dict:
    """Per ``step_s`` of display time: the largest frame age shown and the colour bitrate the
    frames shown were made at (the stream's choice; -1 when no frame says)."""
    from pibr.client.recorder import read_records

    rows = read_records(os.path.join(out, f"{method}.records.csv"))
    t = np.array([r["t"] for r in rows], float)
    age = np.array([r["age_ms"] for r in rows], float)
    kbps = np.array([r["stream_kbps"] for r in rows], float)
    edges = np.arange(0.0, duration_s + 1e-9, step_s)
    ages, rates = [], []
    for a, b in zip(edges, edges[1:]):
        inside = (t >= a) & (t < b) & np.isfinite(age)
        ages.append(round(float(age[inside].max()), 1) if inside.any() else None)
        chosen = inside & (kbps >= 0)
        rates.append(round(float(kbps[chosen][-1]), 1) if chosen.any() else None)
    return {"step_s": step_s, "age_ms_max": ages, "stream_kbps": rates}


def _dssim_by_segment(out: str, method: str, duration_s: float, segment_s: float) -> list:
    with open(os.path.join(out, "metrics_frames.csv")) as f:
        rows = [r for r in csv.DictReader(f) if r["method"] == method]
    t = np.array([float(r["t"]) for r in rows])
    d = np.array([float(r["dssim"]) for r in rows])
    edges = np.arange(0.0, duration_s + 1e-9, segment_s)
    return [float(d[(t >= a) & (t < b)].mean()) if np.any((t >= a) & (t < b)) else None
            for a, b in zip(edges, edges[1:])]


def run_network_bench(out_dir="out/bench", links=tuple(BUILTIN),
                      static_kbps=(2000.0, 4000.0, 8000.0, 16000.0), adapt_kbps: float = 16000.0,
                      method: str = "proxy", scene: str = "room", trace: str = "pred6dof-1", start_s: float = 30.0,
                      duration_s: float = 30.0, rate_hz: float = 30.0, size=(480, 270), view_size=(512, 512),
                      latency_ms: float = 128.0, server_fps: float = 10.0, segment_s: float = SEGMENT_S,
                      clock: str = "virtual", placement: str = "split", progress: bool = True,
                      plot: bool = True, adapt_starts=("foot",)) -> dict:
    """Every link trace x (each static bitrate, the adapting stream); writes ``out_dir/network.json``
    (and ``network.png`` with ``plot``: per link, its rate and the stream's choice, and the frame
    age shown, over time).

    ``clock``: ``virtual`` (reproducible: the link model schedules every message) or ``real`` (the
    wall clock: the relay replays each link from the client's tick 0, and a client or server too
    busy to keep up makes frames wait as a full link does, which the adapting stream reads as
    congestion); on the real clock ``placement`` says which cores each process may use
    (bench/processes.py: ``split``, the server and relay on one core and the client on the other,
    as on two machines). ``adapt_starts``: one adapting run per start (``pibr serve --adapt-start``;
    the first is the ``adapt KBPS`` row the verdict reads, the others ``adapt KBPS START``, each
    with a verdict of its own in ``verdicts``)."""
    if clock not in CLOCKS:
        raise ValueError(f"clock must be one of {', '.join(CLOCKS)}, got {clock!r}")
    from .evaluate import evaluate_run
    from .processes import run_sessions

    half = latency_ms / 2.0
    root = os.path.join(out_dir, "network")
    settings = [(f"static {k:g}", ["--bitrate-kbps", f"{k:g}", "--adapt", "off"]) for k in static_kbps]
    for k, start in enumerate(adapt_starts):
        settings.append((f"adapt {adapt_kbps:g}" + ("" if k == 0 else f" {start}"),
                         ["--bitrate-kbps", f"{adapt_kbps:g}", "--adapt", "on", "--adapt-start", start]))
    result = {"benchmark": "network", "machine": {"cpus": os.cpu_count(), "platform": platform.platform()},
              "settings": {"scene": scene, "trace": trace, "start_s": start_s, "duration_s": duration_s,
                           "rate_hz": rate_hz, "size": list(size), "view_size": list(view_size),
                           "latency_ms": latency_ms, "server_fps": server_fps, "method": method,
                           "links": list(links), "static_kbps": list(static_kbps), "adapt_kbps": adapt_kbps,
                           "adapt_starts": list(adapt_starts),
                           "stall_ms": STALL_MS, "segment_s": segment_s, "clock": clock,
                           "placement": placement if clock == "real" else None,
                           "window": f"{trace} from {start_s:g} s (an evaluation window; nothing is fitted here)"},
              "goals": GOALS, "links": {}}
    plan = [(link, name, args) for link in links for name, args in settings]
    for k, (link, name, args) in enumerate(plan):
        summary = load_bandwidth_trace(link).summary()
        label = run_label(link, name)
        if progress:
            print(f"[{k + 1}/{len(plan)}] {link}: {name} ...", file=sys.stderr, flush=True)
        out = os.path.join(root, label)
        run_sessions(out, ["--scene", scene, "--fps", f"{server_fps:g}", "--view-size",
                           f"{view_size[0]}x{view_size[1]}", *args],
                     ["--up-ms", f"{half:g}", "--down-ms", f"{half:g}", "--down-trace", link],
                     [["--trace", trace, "--start", f"{start_s:g}", "--duration", f"{duration_s:g}",
                       "--rate", f"{rate_hz:g}", "--size", f"{size[0]}x{size[1]}", "--clock", clock,
                       "--method", method]], verbose_server=True,
                     placement=placement if clock == "real" else "shared")
        scored = evaluate_run(out, scene_spec=scene, flip_every=0, side_by_side=False, plot=False,
                              progress=False)["methods"][method]
        entry = result["links"].setdefault(link, {"trace": summary, "runs": {}})
        entry["runs"][name] = {**_records_summary(out, method, duration_s), "dssim_mean": scored["dssim_mean"],
                               "psnr_mean": scored["psnr_mean"],
                               "dssim_by_segment": _dssim_by_segment(out, method, duration_s, segment_s),
                               "series": _series(out, method, duration_s)}
    for link, entry in result["links"].items():
        entry["verdict"] = _verdict(entry["runs"], latency_ms)
        if len(adapt_starts) > 1:
            entry["verdicts"] = {k: _verdict(entry["runs"], latency_ms, k) for k in entry["runs"] if k.startswith("adapt")}
    write_result(out_dir, "network.json", result)
    if plot:
        from .plots import plot_network

        plot_network(result, os.path.join(out_dir, "network.png"))
    return result


def compare_starts(results: list, provenance: str = "") -> dict:
    """The adapting stream's two starts (``--adapt-start foot`` and ``probe``) side by side, from
    run_network_bench results made with ``adapt_starts=("foot", "probe")`` (one per head-trace
    window, statics not needed): per window and link, each start's age p50 / p95, stalls, DSSIM
    and its first segment's (the seconds the start decides), and how often probe came out ahead."""
    rows = []
    for r in results:
        st = r["settings"]
        window = f"{st['trace']} from {st['start_s']:g} s"
        foot_key, probe_key = f"adapt {st['adapt_kbps']:g}", f"adapt {st['adapt_kbps']:g} probe"
        for link, entry in r["links"].items():
            pair = {}
            for start, key in (("foot", foot_key), ("probe", probe_key)):
                v = entry["runs"][key]
                pair[start] = {"age_ms_p50": v["age_ms_p50"], "age_ms_p95": v["age_ms_p95"], "stalls": v["stalls"],
                               "longest_stall_ms": v["longest_stall_ms"], "arrived_kbps": v["arrived_kbps"],
                               "dssim_mean": v["dssim_mean"], "dssim_first_segment": v["dssim_by_segment"][0],
                               "dssim_by_segment": v["dssim_by_segment"]}
            rows.append({"window": window, "link": link, **pair})
    n = len(rows)
    count = lambda f: sum(1 for row in rows if f(row["foot"], row["probe"]))
    summary = {"runs": n,
               "first_segment_lower_with_probe": count(lambda a, b: b["dssim_first_segment"] < a["dssim_first_segment"]),
               "dssim_lower_with_probe": count(lambda a, b: b["dssim_mean"] < a["dssim_mean"]),
               "age_p95_higher_with_probe": count(lambda a, b: b["age_ms_p95"] > a["age_ms_p95"]),
               "age_p95_lower_with_probe": count(lambda a, b: b["age_ms_p95"] < a["age_ms_p95"]),
               "first_segment_ratio_mean": float(np.mean([row["probe"]["dssim_first_segment"]
                                                          / row["foot"]["dssim_first_segment"] for row in rows])),
               "dssim_ratio_mean": float(np.mean([row["probe"]["dssim_mean"] / row["foot"]["dssim_mean"]
                                                  for row in rows]))}
    first = results[0]["settings"]
    settings = {k: first[k] for k in ("scene", "duration_s", "rate_hz", "size", "view_size", "latency_ms",
                                      "server_fps", "method", "adapt_kbps", "segment_s", "clock")}
    settings["windows"] = sorted({row["window"] for row in rows})
    settings["links"] = sorted({row["link"] for row in rows})
    settings["purpose"] = ("reporting: evaluation windows and links nothing was fitted on (PROBE_SHARE is a "
                           "declared half, not a fit)")
    return {"benchmark": "network-start", "machine": results[0]["machine"], "settings": settings, "rows": rows,
            "summary": summary, "provenance": provenance}


def run_label(link: str, setting: str) -> str:
    """The folder of one run under ``out_dir/network``: the link's name (a file's base name, so a
    link given as a path stays under ``out_dir``) and the setting."""
    return f"{os.path.basename(os.path.normpath(link))}-{setting.replace(' ', '-')}"


def _verdict(runs: dict, rtt_ms: float, adapt_key: str | None = None) -> dict:
    """The adapting stream (the first adapting run, or ``adapt_key``'s) against the goals: age p95
    over the round trip, the longest stall, and per segment its DSSIM over the best static setting's
    in hindsight."""
    adapt = runs.get(adapt_key) if adapt_key else next((v for k, v in runs.items() if k.startswith("adapt")), None)
    statics = {k: v for k, v in runs.items() if k.startswith("static")}
    if adapt is None or not statics:
        return {}
    ratios = []
    for i, d in enumerate(adapt["dssim_by_segment"]):
        best = min((v["dssim_by_segment"][i] for v in statics.values() if v["dssim_by_segment"][i] is not None),
                   default=None)
        ratios.append(None if d is None or not best else d / best)
    worst = max((r for r in ratios if r is not None), default=None)
    return {"age_p95_over_rtt_ms": {"value": adapt["age_ms_p95"] - rtt_ms,
                                    "met": adapt["age_ms_p95"] - rtt_ms <= GOALS["age_p95_over_rtt_ms_max"]},
            "longest_stall_ms": {"value": adapt["longest_stall_ms"],
                                 "met": adapt["longest_stall_ms"] <= GOALS["stall_ms_max"]},
            "dssim_of_best_static": {"per_segment": ratios, "worst": worst,
                                     "met": worst is not None and worst <= GOALS["dssim_of_best_static_max"]}}


def print_network(result: dict) -> None:
    s = result["settings"]
    print(f"pibr bench network: {s['scene']}, {s['method']}, {s['trace']} from {s['start_s']:g} s for "
          f"{s['duration_s']:g} s, {s['latency_ms']:g} ms round trip, downlink from each bandwidth trace")
    head = f"{'link':>12} {'setting':>13} {'age p50':>8} {'age p95':>8} {'stalls':>6} {'longest':>8} " \
           f"{'kbit/s':>7} {'DSSIM':>7}"
    print(head)
    print("-" * len(head))
    for link, entry in result["links"].items():
        for name, r in entry["runs"].items():
            print(f"{link:>12} {name:>13} {r['age_ms_p50']:8.0f} {r['age_ms_p95']:8.0f} {r['stalls']:6d} "
                  f"{r['longest_stall_ms']:8.0f} {r['arrived_kbps']:7.0f} {r['dssim_mean']:7.4f}")
        v = entry.get("verdict") or {}
        if v:
            w = v["dssim_of_best_static"]["worst"]
            print(f"{'':>12} adapting: age p95 {v['age_p95_over_rtt_ms']['value']:+.0f} ms over the round trip "
                  f"({'met' if v['age_p95_over_rtt_ms']['met'] else 'not met'}), longest stall "
                  f"{v['longest_stall_ms']['value']:.0f} ms ({'met' if v['longest_stall_ms']['met'] else 'not met'}), "
                  f"worst segment {'-' if w is None else f'{w:.2f}'}x the best static DSSIM "
                  f"({'met' if v['dssim_of_best_static']['met'] else 'not met'})")
