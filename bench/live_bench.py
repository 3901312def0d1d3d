"""What watching a session live costs the client (``pibr bench live``).

Server, relay and client run as processes on the wall clock, the same session twice in turn per
repeat: ``alone`` (no live page) and ``watched`` (``--live``, with the page open in a headless
Chromium on this machine, polling as a user's browser would). Per run, from the client's records:
the median and 95th percentile of its render ms per tick and the share of ticks missed (the
client at its top level, ``--deadline off``: a controller choosing levels would make the render ms
of two runs measure different work); for the
watched runs, what the page cost the client's event loop and its image thread (``session.json``'s
``live``, as shares of the ticks' time). Alone and watched alternate so that a machine whose speed
drifts affects both alike.
"""
from __future__ import annotations

import os
import threading
import time
import urllib.request

import numpy as np

from pibr.protocol.errors import ConfigError

from .processes import chromium_path, free_port, run_pipeline
from .results import write_result

#: The issue's goal: the live page costs the client under this share of its tick time.
GOAL_SHARE = 0.02


def _reachable(url: str) -> bool:
    try:
        with urllib.request.urlopen(url, timeout=1) as r:
            return r.status == 200
    except OSError:
        return False


def _run_stats(run_dir: str, method: str) -> dict:
    import json

    from pibr.client.recorder import read_records

    rows = read_records(os.path.join(run_dir, f"{method}.records.csv"))
    drawn = [r["client_ms"] for r in rows if not r["missed"]]
    with open(os.path.join(run_dir, "session.json")) as f:
        info = json.load(f)
    return {"ticks": len(rows), "missed_fraction": sum(r["missed"] for r in rows) / max(len(rows), 1),
            "client_ms_median": float(np.median(drawn)) if drawn else None,
            "client_ms_p95": float(np.percentile(drawn, 95)) if drawn else None, "live": info.get("live")}


def run_live_bench(out_dir: str = "out/bench", method: str = "proxy", size=(640, 360), rate_hz: float = 30.0,
                   duration_s: float = 20.0, repeats: int = 2, trace: str = "pred6dof-1", start_s: float = 30.0,
                   latency_ms: float = 128.0, view_size=(1024, 1024)) -> dict:
    from playwright.sync_api import sync_playwright

    chromium = chromium_path()
    if chromium is None:
        raise ConfigError("pibr bench live needs Chromium (apt-get install chromium, or PIBR_CHROMIUM=PATH)")
    server_args = ["--view-size", "%dx%d" % tuple(view_size)]
    relay_args = ["--up-ms", str(latency_ms / 2), "--down-ms", str(latency_ms / 2)]
    runs = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, args=["--no-sandbox"])
        try:
            for r in range(repeats):
                for watched in (False, True):
                    name = f"{'watched' if watched else 'alone'}-{r + 1}"
                    run_dir = os.path.join(out_dir, "live", name)
                    port = free_port()
                    client_args = ["--trace", trace, "--start", str(start_s), "--duration", str(duration_s),
                                   "--rate", str(rate_hz), "--size", "%dx%d" % tuple(size), "--method", method,
                                   "--clock", "real", "--no-video", "--deadline", "off"] + (
                                       ["--live", str(port)] if watched else [])
                    failure = []

                    def stream():
                        try:
                            run_pipeline(run_dir, server_args, relay_args, client_args, timeout=600)
                        except BaseException as exc:   # re-raised below, in this thread
                            failure.append(exc)
                    thread = threading.Thread(target=stream, name=f"live-bench-{name}")
                    thread.start()
                    polls = 0
                    if watched:
                        url = f"http://127.0.0.1:{port}/"
                        while thread.is_alive() and not _reachable(url + "series.json"):
                            time.sleep(0.2)
                        if thread.is_alive():
                            page = browser.new_page()
                            page.goto(url)
                            while thread.is_alive():
                                page.wait_for_timeout(250)
                            polls = int(page.inner_text("#ticks") or 0)
                            page.close()
                    thread.join()
                    if failure:
                        raise failure[0]
                    stats = _run_stats(run_dir, method)
                    runs.append({"name": name, "watched": watched, **stats,
                                 **({"ticks_seen_by_page": polls} if watched else {})})
                    print(f"  {name}: client ms median {stats['client_ms_median']:.1f}, "
                          f"missed {100 * stats['missed_fraction']:.1f} %", flush=True)
        finally:
            browser.close()

    def mean(key, watched):
        vals = [x[key] for x in runs if x["watched"] == watched and x[key] is not None]
        return float(np.mean(vals)) if vals else None
    live = [x["live"] for x in runs if x["watched"] and x["live"]]
    loop = float(np.mean([c["loop_share_of_tick_time"] for c in live])) if live else None
    thread = float(np.mean([c["thread_share_of_tick_time"] for c in live])) if live else None
    summary = {w: {k: mean(k, flag) for k in ("client_ms_median", "client_ms_p95", "missed_fraction")}
               for w, flag in (("alone", False), ("watched", True))}
    a, w = summary["alone"]["client_ms_median"], summary["watched"]["client_ms_median"]
    summary["client_ms_ratio"] = w / a if a and w else None
    summary["loop_share_of_tick_time"] = loop
    summary["thread_share_of_tick_time"] = thread
    summary["goal_share"] = GOAL_SHARE
    summary["goal_met_in_client"] = None if loop is None else (loop + thread) < GOAL_SHARE
    result = {"benchmark": "live", "settings": {"method": method, "size": list(size), "rate_hz": rate_hz,
                                                 "duration_s": duration_s, "repeats": repeats, "trace": trace,
                                                 "start_s": start_s, "latency_ms": latency_ms,
                                                 "view_size": list(view_size), "clock": "real"},
              "windows": "an evaluation window (nothing is fitted here)", "runs": runs, "summary": summary}
    write_result(out_dir, "live.json", result)
    return result
