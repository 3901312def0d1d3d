"""``pibr bench cluster``: what spreading a sweep over Ray workers buys on this machine.

The same ``pibr bench trade`` sweep (two knobs by default) runs in this process (the benches'
default: points in order, llvmpipe on every core, metrics on one extra process), then on a local
Ray with 1 worker and with 2 (each worker one CPU: one rasteriser thread, metrics inline).
Per run: the wall time from the call to the written result (Ray's start included), the points,
and whether every number but the timings equals the in-process run's
(:func:`~.cluster.same_numbers`). The speed-up is the 1-worker run's time over the N-worker
run's, measured in one invocation; timings here are noisy, so compare ratios, not seconds across
machines.
"""
from __future__ import annotations

import os
import tempfile
import time

from .results import write_result
from .windows import EVALUATION_WINDOWS, describe_windows


def run_cluster_bench(knobs=("bitrate", "latency"), windows=EVALUATION_WINDOWS, window_s=1.0, stride=4,
                      out_size=(960, 540), workers=(1, 2), values=None, out_dir="out/bench") -> dict:
    """Time the trade sweep of ``knobs`` in this process and on each count of Ray ``workers``;
    write ``cluster.json``."""
    from .cluster import Placement, import_ray, same_numbers
    from .trade import run_trade_bench

    import_ray()
    values = values or {"bitrate": (4000.0, 8000.0), "latency": (64.0, 256.0)}
    placements = [Placement()] + [Placement(workers=n) for n in workers]
    runs = []
    reference = None
    with tempfile.TemporaryDirectory(prefix="pibr-cluster-") as scratch:
        for i, placement in enumerate(placements):
            t0 = time.perf_counter()
            r = run_trade_bench(knobs=knobs, windows=windows, window_s=window_s, stride=stride, out_size=out_size,
                                values={k: v for k, v in values.items() if k in knobs}, placement=placement,
                                out_dir=os.path.join(scratch, str(i)), progress=False)
            seconds = time.perf_counter() - t0
            reference = reference or r
            scene = next(iter(r["scenes"].values()))
            runs.append({"placement": r["placement"], "seconds": seconds,
                         "points": r["points"],
                         "ticks_scored_per_point": scene["ticks_scored_per_point"],
                         "same_numbers_as_in_process": same_numbers(reference, r)})
    by_workers = {run["placement"]["workers"]: run for run in runs[1:]}
    one = by_workers.get(1)
    for run in runs[1:]:
        run["speedup_over_one_worker"] = one["seconds"] / run["seconds"] if one else None
        run["speedup_over_in_process"] = runs[0]["seconds"] / run["seconds"]
    result = {"sweep": {"knobs": list(knobs), "values": {k: list(v) for k, v in values.items() if k in knobs},
                        "window_seconds": window_s, "stride": stride, "output": list(out_size)},
              "windows": reference["windows"], "cpus": os.cpu_count(), "runs": runs,
              "note": "wall seconds from the call to the written trade.json, Ray's start included; the same "
                      "sweep in every run, one after the other in one invocation"}
    write_result(out_dir, "cluster.json", result)
    return result


def print_cluster_table(r: dict) -> None:
    s = r["sweep"]
    print(f"pibr bench cluster: trade sweep of {', '.join(s['knobs'])}, {describe_windows(r['windows'])} "
          f"(first {s['window_seconds']:g} s each), {r['cpus']} CPUs")
    print(f"  {'where':<22}{'points':>7}{'seconds':>9}{'x 1 worker':>12}{'x in-process':>14}  same numbers")
    for run in r["runs"]:
        p = run["placement"]
        where = "this process" if p["mode"] == "in-process" else f"Ray, {p['workers']} worker" + (
            "s" if p["workers"] > 1 else "")
        one = run.get("speedup_over_one_worker")
        here = run.get("speedup_over_in_process")
        print(f"  {where:<22}{run['points']:>7}{run['seconds']:>9.1f}{'-' if one is None else f'{one:.2f}':>12}"
              f"{'-' if here is None else f'{here:.2f}':>14}  {'yes' if run['same_numbers_as_in_process'] else 'NO'}")
