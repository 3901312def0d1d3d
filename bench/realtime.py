"""``pibr bench realtime``: server, relay and client as separate processes on the wall clock.

Each run starts a server, a relay (the round trip split evenly between the two directions)
and one or more clients on the real clock, replays a trace window at the output rate and
reports what a user of the system would feel:

* server fps: frames each client received per second of its clock;
* output rate: ticks displayed afresh per second (a tick whose deadline passed while the
  client still worked on an earlier one is a missed deadline, shown as a repeat);
* frame age p50 / p99: display time minus the client time of the pose the shown frame was
  rendered for (the round trip, the server's frame time, decoding and any queue);
* CPU share of each process over the client's clock (user + system, all threads; 1.0 is one
  core busy), sampled from /proc.

* the quality levels the controllers chose (client/deadline.py): the share of ticks at each;
* what was *shown*, scored against ground truth at every displayed tick after the run
  (``pibr evaluate``: DSSIM, PSNR; a missed tick scores the image it held), beside the same
  window on the virtual clock without controllers (the quality the wall clock is measured against).

Each method and depth codec runs with the controllers (the client's deadline, the server's rate
control) on and off (``controllers``), on one ``placement`` or both: ``split`` pins the server
and the relay to one core and the client to the other (standing in for a server and a headset on
separate machines; each rasteriser then runs one thread), ``shared`` lets them run anywhere. The clients record what they show with
their encoding deferred to after the run (client/recorder.py), so measuring costs the clock a
copy per tick (reported apart: ``record_ms``).

``cost per session`` runs 1, 2, 4 ... clients against one server: on the virtual clock, the
server's CPU-ms per delivered frame (the clients cannot starve it of time: it is CPU time);
on the real clock, the fps each client gets (those clients record nothing: ``--no-video``).
Timings depend on the machine and on whatever else runs: compare rows of one run.
"""
from __future__ import annotations

import os
import re
import sys
import threading
import time

import numpy as np

from pibr.protocol.depth_codecs import DEPTH_CODECS

from .processes import PLACEMENTS, run_sessions
from .results import write_result

#: The goals of issue 25 on this machine (room, 960x540 at 30 Hz, 128 ms, split placement, proxy with h264 depth).
GOALS = {"server_fps_min": 9.5, "missed_fraction_max": 0.05, "age_ms_p50_max": 350.0,
         "dssim_of_rotation_max": 0.6, "dssim_of_virtual_max": 1.5}

_SESSION_CLOSED = re.compile(r"closed after (\d+) frames \((\d+) skipped .*?, (\d+) held .*?, (\d+) tick overruns\)")
_SERVER_LEVELS = re.compile(r"frames by rate-control level: (.*)$")


class CpuSampler:
    """Samples every process's CPU seconds every ``period`` seconds on a thread.

    samples: name -> [(wall time, cpu seconds)]"""

    def __init__(self, period: float = 0.1):
        self.period = period
        self.samples: dict[str, list] = {}
        self._procs: dict = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="cpu-sampler", daemon=True)

    def start(self, procs: dict) -> None:
        self._procs = dict(procs)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            now = time.perf_counter()
            for name, p in self._procs.items():
                cpu = p.cpu_seconds()
                if cpu is not None:
                    self.samples.setdefault(name, []).append((now, cpu))
            self._stop.wait(self.period)

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2)

    def share(self, name: str, t0: float, t1: float) -> float | None:
        """Cores' worth of CPU the process used between wall times t0 and t1 (samples nearest)."""
        s = self.samples.get(name, [])
        inside = [x for x in s if t0 <= x[0] <= t1]
        if len(inside) < 2 or inside[-1][0] <= inside[0][0]:
            return None
        return (inside[-1][1] - inside[0][1]) / (inside[-1][0] - inside[0][0])


class _Ticks:
    """When the first client's clock ran (its progress lines), in wall time."""

    def __init__(self):
        self.first = self.last = None

    def __call__(self, done: int, total: int) -> None:
        now = time.perf_counter()
        if self.first is None:
            self.first = now
        self.last = now


def _client_summary(out: str, method: str, duration_s: float, rate_hz: float) -> dict:
    from pibr.client.recorder import read_records

    from .evaluate import read_session

    session = read_session(out)
    deadline = session.get("deadline")
    rows = read_records(os.path.join(out, f"{method}.records.csv"))
    ticks = len(rows)
    missed = sum(r["missed"] for r in rows)
    ages = np.array([r["age_ms"] for r in rows], float)
    ages = ages[np.isfinite(ages)]
    fresh = [r["client_ms"] for r in rows if not r["missed"] and r["frame_id"] >= 0]
    arrivals = np.array(session["result"].get("frame_arrivals_s", []), float)
    on_clock = int(np.count_nonzero((arrivals >= 0) & (arrivals <= duration_s)))
    # after the client's first progress line (tick 10), where the server's CPU is measured from
    after_first_line = int(np.count_nonzero(arrivals >= 10 / rate_hz))
    return {
        "ticks": ticks, "missed_deadlines": int(missed), "missed_fraction": missed / ticks if ticks else None,
        "output_hz": (ticks - missed) / duration_s,
        "frames_received": on_clock, "server_fps": on_clock / duration_s,
        "age_ms_p50": float(np.percentile(ages, 50)) if len(ages) else None,
        "age_ms_p99": float(np.percentile(ages, 99)) if len(ages) else None,
        "client_ms_median": float(np.median(fresh)) if fresh else None,
        "frames_before_clock": int(np.count_nonzero(arrivals < 0)),
        "frames_after_first_progress": after_first_line,
        "levels": None if deadline is None else deadline["methods"][method]["share_at_level"],
        "costs_ms": None if deadline is None else deadline["costs_ms"].get(method),
        "record_ms_median": (session.get("record_ms") or {}).get("median"),
    }


def _server_sessions(log_path: str) -> list[dict]:
    """Each closed session's counts from the server's log, with the frames its rate control made
    at each level (``levels``: name -> frames; absent without rate control)."""
    out = []
    with open(log_path) as f:
        for line in f:
            m = _SESSION_CLOSED.search(line)
            if m:
                sent, skipped, held, overruns = (int(x) for x in m.groups())
                out.append({"frames_sent": sent, "skipped_slow_connection": skipped, "held_for_client": held,
                            "tick_overruns": overruns})
                continue
            m = _SERVER_LEVELS.search(line.rstrip())
            if m and out and m.group(1) != "none":
                out[-1]["levels"] = {name: int(n) for name, n in (part.rsplit(": ", 1) for part in m.group(1).split("; "))}
    return out


def run_one(out_dir: str, method: str, depth_codec: str, clients: int = 1, clock: str = "real",
            scene: str = "room", trace: str = "pred6dof-1", start_s: float = 30.0, duration_s: float = 20.0,
            rate_hz: float = 30.0, size=(960, 540), latency_ms: float = 128.0, server_fps: float = 10.0,
            server_args=(), placement: str = "shared", controllers: bool = True, score: bool = False) -> dict:
    """One run: a server, a relay and ``clients`` clients replaying the same window at once.
    ``controllers``: the client's deadline controller and the server's rate control on (off: always
    the best level, every frame whole);
    ``score``: record what a single client shows and score it against ground truth afterwards."""
    half = latency_ms / 2.0
    server_args = (*server_args, "--rate-control", "on" if controllers else "off")
    client_args = ["--trace", trace, "--start", str(start_s), "--duration", str(duration_s), "--rate", str(rate_hz),
                   "--size", f"{size[0]}x{size[1]}", "--clock", clock, "--method", method,
                   "--depth-codec", depth_codec, "--deadline", "auto" if controllers else "off"]
    if not score:
        client_args.append("--no-video")
    sampler = CpuSampler()
    ticks = _Ticks()
    cpu_end: dict = {}

    server_log = os.path.join(out_dir, "logs", "server.log")

    def before_stop(procs):
        cpu_end.update({name: p.cpu_seconds() for name, p in procs.items()})
        # The server logs a session when it sees the client's end, a moment after the client
        # exits: wait for every session's line before stopping it.
        give_up = time.perf_counter() + 10.0
        while len(_server_sessions(server_log)) < clients and time.perf_counter() < give_up:
            time.sleep(0.1)

    t0 = time.perf_counter()
    try:
        run_sessions(out_dir, ["--scene", scene, "--fps", str(server_fps), "--depth-codec", depth_codec,
                               *server_args],
                     ["--up-ms", str(half), "--down-ms", str(half)], [client_args] * clients,
                     on_progress=ticks, on_started=sampler.start, before_stop=before_stop, verbose_server=True,
                     placement=placement)
    finally:
        sampler.stop()
    wall = time.perf_counter() - t0
    outs = [out_dir] if clients == 1 else [os.path.join(out_dir, f"client-{k + 1}") for k in range(clients)]
    per_client = [_client_summary(o, method, duration_s, rate_hz) for o in outs]
    result = {"method": method, "depth_codec": depth_codec, "clients": clients, "clock": clock,
              "placement": placement, "controllers": controllers, "wall_s": wall, "per_client": per_client,
              "server": _server_sessions(server_log)}
    if score:
        result["shown"] = _score(out_dir, method, scene)
    if ticks.first is not None and ticks.last is not None:
        names = ["server", "relay"] + (["client"] if clients == 1 else [f"client-{k + 1}" for k in range(clients)])
        result["cpu_share"] = {n: sampler.share(n, ticks.first, ticks.last) for n in names}
    # The server's CPU from the first client's first progress line (sessions set up, frames
    # flowing) to the clients' end, over the frames delivered meanwhile.
    server_cpu = cpu_end.get("server")
    before_first = [c for t, c in sampler.samples.get("server", []) if ticks.first is not None and t <= ticks.first]
    delivered = sum(c["frames_after_first_progress"] for c in per_client)
    if server_cpu is not None and before_first and delivered:
        result["server_cpu_ms_per_frame"] = (server_cpu - before_first[-1]) * 1e3 / delivered
    return result


def _score(out_dir: str, method: str, scene: str) -> dict:
    """What the client showed at every tick, scored against ground truth (a missed tick as the image it held)."""
    from .evaluate import evaluate_run

    m = evaluate_run(out_dir, scene_spec=scene, flip_every=0, side_by_side=False, plot=False,
                     progress=False)["methods"][method]
    return {"dssim_mean": m["dssim_mean"], "psnr_mean": m["psnr_mean"], "frames": m["frames"]}


def run_realtime_bench(out_dir="out/bench", methods=("rotation", "proxy"), depth_codecs=tuple(DEPTH_CODECS),
                       clients=(1, 2, 4), duration_s: float = 20.0, scaling_duration_s: float = 6.0,
                       scene="room", trace="pred6dof-1", start_s: float = 30.0, rate_hz: float = 30.0,
                       size=(960, 540), latency_ms: float = 128.0, server_fps: float = 10.0,
                       scaling_method: str = "rotation", progress=True, server_args=(), placements=("split",),
                       controllers=(True, False), score: bool = True) -> dict:
    """Every method x depth codec x placement x controllers on the real clock (what was shown
    scored after each run, with ``score``; and each method x codec on the virtual clock without
    controllers as the reference), then the cost per session. Writes ``out_dir/realtime.json``."""
    import platform

    for p in placements:
        if p not in PLACEMENTS:
            raise ValueError(f"placement must be one of {', '.join(PLACEMENTS)}, got {p!r}")
    root = os.path.join(out_dir, "realtime")
    common = dict(scene=scene, trace=trace, start_s=start_s, rate_hz=rate_hz, size=size, latency_ms=latency_ms,
                  server_fps=server_fps)
    run_args = dict(common, server_args=tuple(server_args))
    result = {"benchmark": "realtime", "machine": {"cpus": os.cpu_count(), "platform": platform.platform()},
              "settings": {**common, "size": list(size), "duration_s": duration_s, "server_args": list(server_args),
                           "scaling_duration_s": scaling_duration_s, "scaling_method": scaling_method,
                           "placements": list(placements), "controllers": [bool(c) for c in controllers],
                           "window": f"{trace} from {start_s:g} s (speed only: no default is fitted here)"},
              "goals": GOALS, "runs": [], "virtual": [], "scaling": []}
    plan = [("runs", m, d, 1, "real", duration_s, p, c) for p in placements for c in controllers
            for m in methods for d in depth_codecs]
    if score:
        plan += [("virtual", m, d, 1, "virtual", duration_s, "shared", False) for m in methods for d in depth_codecs]
    plan += [("scaling", scaling_method, "h264", n, clock, scaling_duration_s if clock == "virtual" else duration_s,
              "shared", True) for clock in ("virtual", "real") for n in clients]
    for k, (kind, method, codec, n, clock, dur, placement, ctl) in enumerate(plan):
        label = f"{kind}-{method}-{codec}-{n}x-{clock}" + (f"-{placement}-{'on' if ctl else 'off'}"
                                                           if kind == "runs" else "")
        if progress:
            print(f"[{k + 1}/{len(plan)}] {label} ...", file=sys.stderr, flush=True)
        r = run_one(os.path.join(root, label), method, codec, clients=n, clock=clock, duration_s=dur,
                    placement=placement, controllers=ctl, score=score and kind != "scaling", **run_args)
        result[kind].append(r)
    result["verdicts"] = verdicts(result)
    write_result(out_dir, "realtime.json", result)
    return result


def verdicts(result: dict) -> list[dict]:
    """Each real-clock run of ``proxy`` against the goals (:data:`GOALS`): the measured figure and
    whether it meets its goal; DSSIM against ``rotation``'s in the same placement and controller
    setting, and against the virtual clock's (same window, no controllers)."""
    out = []
    runs = result.get("runs", [])
    virtual = {(r["method"], r["depth_codec"]): r.get("shown") for r in result.get("virtual", [])}
    for r in runs:
        if r["method"] != "proxy":
            continue
        c = r["per_client"][0]
        rotation = next((x for x in runs if x["method"] == "rotation" and x["depth_codec"] == r["depth_codec"]
                         and x["placement"] == r["placement"] and x["controllers"] == r["controllers"]), None)
        shown = r.get("shown") or {}
        rot = (rotation or {}).get("shown") or {}
        virt = virtual.get((r["method"], r["depth_codec"])) or {}
        ratio_rot = shown["dssim_mean"] / rot["dssim_mean"] if shown and rot else None
        ratio_virt = shown["dssim_mean"] / virt["dssim_mean"] if shown and virt else None
        checks = {"server_fps": (c["server_fps"], c["server_fps"] >= GOALS["server_fps_min"]),
                  "missed_fraction": (c["missed_fraction"], c["missed_fraction"] <= GOALS["missed_fraction_max"]),
                  "age_ms_p50": (c["age_ms_p50"], c["age_ms_p50"] is not None
                                 and c["age_ms_p50"] <= GOALS["age_ms_p50_max"]),
                  "dssim_of_rotation": (ratio_rot, ratio_rot is not None
                                        and ratio_rot <= GOALS["dssim_of_rotation_max"]),
                  "dssim_of_virtual": (ratio_virt, ratio_virt is not None
                                       and ratio_virt <= GOALS["dssim_of_virtual_max"])}
        out.append({"depth_codec": r["depth_codec"], "placement": r["placement"], "controllers": r["controllers"],
                    "checks": {k: {"value": v, "met": bool(ok)} for k, (v, ok) in checks.items()}})
    return out


def _fmt(x, spec):
    return "-" if x is None else format(x, spec)


def print_realtime(result: dict) -> None:
    s = result["settings"]
    print(f"\nreal clock, {s['scene']}, {s['window']}, {s['duration_s']:g} s, output {s['size'][0]}x{s['size'][1]} "
          f"at {s['rate_hz']:g} Hz, server asked for {s['server_fps']:g} fps, {s['latency_ms']:g} ms round trip"
          + (f", server {' '.join(s['server_args'])}" if s.get("server_args") else ""))
    print(f"{'placement':>9} {'ctl':>3} {'method':>9} {'depth':>5} {'server fps':>10} {'output Hz':>9} "
          f"{'missed %':>8} {'age p50':>8} {'age p99':>8} {'client ms':>9} {'DSSIM':>7}   CPU share: server relay client")
    for r in result["runs"]:
        c = r["per_client"][0]
        cpu = r.get("cpu_share", {})
        dssim = (r.get("shown") or {}).get("dssim_mean")
        print(f"{r.get('placement', 'shared'):>9} {'on' if r.get('controllers', False) else 'off':>3} "
              f"{r['method']:>9} {r['depth_codec']:>5} {c['server_fps']:>10.1f} {c['output_hz']:>9.1f} "
              f"{100 * c['missed_fraction']:>8.1f} {_fmt(c['age_ms_p50'], '8.0f')} {_fmt(c['age_ms_p99'], '8.0f')} "
              f"{_fmt(c['client_ms_median'], '9.1f')} {_fmt(dssim, '7.4f')}   {_fmt(cpu.get('server'), '6.2f')} "
              f"{_fmt(cpu.get('relay'), '5.2f')} {_fmt(cpu.get('client'), '6.2f')}")
        if c.get("levels"):
            used = ", ".join(f"{name} {100 * share:.0f} %" for name, share in c["levels"].items() if share > 0)
            print(f"{'':>15}client levels: {used}")
        made = (r.get("server") or [{}])[0].get("levels")
        if made:
            print(f"{'':>15}server levels: " + "; ".join(f"{name} {n}" for name, n in made.items()))
    for r in result.get("virtual", []):
        shown = r.get("shown") or {}
        print(f"{'virtual':>9} {'off':>3} {r['method']:>9} {r['depth_codec']:>5} {'(the reference: no deadline)':>38} "
              f"{'':>17} {_fmt(shown.get('dssim_mean'), '7.4f')}")
    for v in result.get("verdicts", []):
        met = ", ".join(f"{k} {_fmt(x['value'], '.3g')} {'met' if x['met'] else 'NOT met'}" for k, x in v["checks"].items())
        print(f"goals, proxy {v['depth_codec']} {v['placement']} controllers {'on' if v['controllers'] else 'off'}: "
              f"{met}")
    if result["scaling"]:
        print(f"\ncost per session ({s['scaling_method']}, h264 depth): clients on one server")
        print(f"{'clock':>8} {'clients':>7} {'server CPU-ms/frame':>19} {'fps per client':>24}")
        for r in result["scaling"]:
            fps = ", ".join(f"{c['server_fps']:.1f}" for c in r["per_client"]) if r["clock"] == "real" else "-"
            print(f"{r['clock']:>8} {r['clients']:>7} {_fmt(r.get('server_cpu_ms_per_frame'), '19.0f')} {fps:>24}")
