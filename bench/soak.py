"""``pibr bench soak``: a server under legitimate clients and hostile peers for a stated time.

1. **Solo runs**: one server process; each legitimate client (a short trace window of its
   own, virtual clock, records only) runs alone, one after the other. Their records are the
   reference: on the virtual clock a session's frames and records do not depend on anything
   else the server does.
2. **Soak**: a fresh server; every legitimate client runs again and again, all at once, while
   hostile peers of every kind in :mod:`pibr.bench.hostile` connect and misbehave beside them
   for ``duration`` seconds after every legitimate client has finished its first run (the
   warm-up: the server has then loaded what its sessions need). Each legitimate run must
   equal its solo run (frame count, and every record except the client's own wall-clock
   milliseconds).
3. **Server health**: resident memory and open files sampled every half second (flat: over
   the ``duration`` after the warm-up, the last quarter's peak within 10 % + 32 MB of the
   second quarter's, open files back to their level before the soak once the peers are gone)
   and no traceback or internal error in its log.

The server gets ``--max-sessions`` = legitimate clients + the hostile kinds that hold a
session after a valid Hello (they are sessions until the server's idle timeout closes them);
connections that never complete a Hello must not take a slot.
"""
from __future__ import annotations

import asyncio
import os
import threading
import time

from .hostile import KINDS, SESSION_HOLDERS, Tally, process_memory, run_hostile
from .processes import PibrProcess, ProcessFailed
from .results import write_result

#: Columns of a client's records that measure its own wall clock, not the session.
_TIMING_COLUMNS = ("client_ms",)
#: The longest wait for every legitimate client's first run before the soak's measured time starts.
WARM_UP_LIMIT_S = 300.0


def _client_args(trace: str, start_s: float, duration_s: float, method: str, scene: str) -> list[str]:
    return ["--clock", "virtual", "--no-video", "--size", "160x90", "--rate", "10", "--trace", trace,
            "--start", f"{start_s:g}", "--duration", f"{duration_s:g}", "--method", method,
            "--progress", "none", *(["--scene", scene] if scene else [])]


def read_run(out_dir: str, method: str) -> dict:
    """What must not change between a solo and a soaked run: the records without timing
    columns, the frame count and arrival times."""
    from pibr.client.recorder import read_records

    from .evaluate import read_session

    result = read_session(out_dir)["result"]
    rows = read_records(os.path.join(out_dir, f"{method}.records.csv"))
    records = [{k: v for k, v in r.items() if k not in _TIMING_COLUMNS} for r in rows]
    return {"frames_received": result["frames_received"], "ticks": result["ticks"],
            "missed_deadlines": result["missed_deadlines"], "frame_arrivals_s": result["frame_arrivals_s"],
            "records": records}


def _differences(solo: dict, run: dict) -> list[str]:
    out = [f"{k}: solo {solo[k]} soak {run[k]}" for k in ("frames_received", "ticks", "missed_deadlines")
           if solo[k] != run[k]]
    if solo["frame_arrivals_s"] != run["frame_arrivals_s"]:
        out.append("frame arrival times differ")
    if len(solo["records"]) != len(run["records"]):
        out.append(f"records: solo {len(solo['records'])} rows, soak {len(run['records'])}")
    else:
        for a, b in zip(solo["records"], run["records"]):
            if a != b:
                col = next(k for k in a if a[k] != b.get(k))
                out.append(f"tick {a.get('tick')}: {col} solo {a[col]} soak {b.get(col)}")
                break
    return out


class _Sampler:
    """Resident memory and open files of one process, every ``period`` seconds, on a thread."""

    def __init__(self, pid: int, period: float = 0.5):
        self.pid, self.period = pid, period
        self.samples: list[tuple[float, int, int]] = []   # (seconds since start, rss bytes, fds)
        self._stop = threading.Event()
        self._t0 = time.monotonic()
        self._thread = threading.Thread(target=self._run, name="soak-sampler", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            rss, fds = process_memory(self.pid)
            if rss is not None and fds is not None:
                self.samples.append((time.monotonic() - self._t0, rss, fds))
            self._stop.wait(self.period)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2)


def _flat(samples: list, t_start: float, t_end: float) -> dict:
    """Peaks of resident memory in the second and last quarters of [t_start, t_end]."""
    span = t_end - t_start

    def peak(a, b):
        xs = [s[1] for s in samples if t_start + a * span <= s[0] <= t_start + b * span]
        return max(xs) if xs else None

    q2, q4 = peak(0.25, 0.5), peak(0.75, 1.0)
    ok = q2 is not None and q4 is not None and q4 <= q2 * 1.10 + 32 * 2**20
    return {"rss_mb_second_quarter_peak": q2 / 2**20 if q2 else None,
            "rss_mb_last_quarter_peak": q4 / 2**20 if q4 else None, "flat": ok}


def run_soak(out_dir: str, duration_s: float = 60.0, clients: int = 8, kinds=KINDS, scene: str = "room",
             trace: str = "pred6dof-1", method: str = "rotation", run_s: float = 1.0,
             view_size: str = "256x256", slow_byte_s: float = 4.0, server_args=(), seed: int = 0,
             log=print) -> dict:
    """Solo runs, then the soak; -> the result (also written to ``out_dir/soak.json``)."""
    if clients < 1:
        raise ValueError("a soak needs at least one legitimate client")
    logs = os.path.join(out_dir, "logs")
    max_sessions = clients + sum(1 for k in kinds if k in SESSION_HOLDERS)
    serve = ["-v", "serve", "--port", "0", "--scene", scene, "--view-size", view_size,
             "--max-sessions", str(max_sessions), *server_args]
    starts = [k * (run_s + 1.0) for k in range(clients)]

    def client(name: str, target: str, k: int, out: str) -> PibrProcess:
        return PibrProcess(name, ["client", "--connect", target, "--out", out,
                                  *_client_args(trace, starts[k], run_s, method, scene)],
                           os.path.join(logs, f"{name}.log"))

    # 1. the reference: each client alone
    solo: list[dict] = []
    server = PibrProcess("solo-server", serve, os.path.join(logs, "solo-server.log"))
    try:
        target = "%s:%d" % server.wait_listening()
        t0 = time.monotonic()
        for k in range(clients):
            out = os.path.join(out_dir, "solo", f"client-{k + 1}")
            p = client(f"solo-client-{k + 1}", target, k, out)
            if p.wait(600) != 0:
                raise ProcessFailed(f"solo client {k + 1} failed:\n{p.tail()}")
            p.stop()
            solo.append(read_run(out, method))
        solo_s = time.monotonic() - t0
        log(f"soak: {clients} solo runs in {solo_s:.1f} s")
    finally:
        server.stop()

    # 2. the soak
    server = PibrProcess("server", serve, os.path.join(logs, "server.log"))
    runs: list[list[dict]] = [[] for _ in range(clients)]
    failures: list[str] = []
    try:
        host, port = server.wait_listening()
        target = f"{host}:{port}"
        sampler = _Sampler(server.proc.pid)
        time.sleep(1.0)
        fds_before = process_memory(server.proc.pid)[1]
        stop_flag = threading.Event()
        tallies = {k: Tally(k) for k in kinds}

        def hostile_thread():
            async def main():
                stop = asyncio.Event()

                async def watch():
                    while not stop_flag.is_set():
                        await asyncio.sleep(0.1)
                    stop.set()

                watcher = asyncio.create_task(watch())
                copies = {"idle-before-hello": 20}
                await run_hostile(host, port, stop, tallies, copies, seed, slow_byte_s)
                await watcher
            try:
                asyncio.run(main())
            except Exception as exc:
                failures.append(f"the hostile peers stopped: {type(exc).__name__}: {exc}")

        warm = [threading.Event() for _ in range(clients)]

        def legit_thread(k: int):
            n = 0
            while not stop_flag.is_set():
                if n == 1:
                    warm[k].set()
                n += 1
                out = os.path.join(out_dir, "soak", f"client-{k + 1}", f"run-{n}")
                p = client(f"client-{k + 1}-run-{n}", target, k, out)
                try:
                    code = p.wait(600)
                except ProcessFailed as exc:
                    failures.append(str(exc))
                    p.stop()
                    break
                p.stop()
                if code != 0:
                    failures.append(f"client {k + 1} run {n} exited with code {code}: {p.tail()[-400:]}")
                    continue
                run = read_run(out, method)
                diff = _differences(solo[k], run)
                runs[k].append({"run": n, "frames_received": run["frames_received"], "equal_to_solo": not diff,
                                "differences": diff[:5]})
            warm[k].set()

        hostile = threading.Thread(target=hostile_thread, name="hostile", daemon=True)
        hostile.start()
        legit = [threading.Thread(target=legit_thread, args=(k,), name=f"legit-{k}", daemon=True)
                 for k in range(clients)]
        for t in legit:
            t.start()
        # Memory is judged from the moment every legitimate client has finished a run: before
        # that the server is still loading what its sessions need (slower on a loaded machine).
        warm_deadline = time.monotonic() + WARM_UP_LIMIT_S
        for w in warm:
            w.wait(max(0.0, warm_deadline - time.monotonic()))
        t_start = sampler.samples[-1][0] if sampler.samples else 0.0
        warm_up_s = t_start
        time.sleep(duration_s)
        stop_flag.set()
        t_end = sampler.samples[-1][0] if sampler.samples else 0.0
        for t in legit:
            t.join(900)
        hostile.join(GIVE_UP_JOIN_S)
        time.sleep(3.0)   # the server closes what the peers left behind
        fds_after = process_memory(server.proc.pid)[1]
        sampler.stop()
        if server.proc.poll() is not None:
            failures.append(f"the server exited with code {server.proc.returncode}")
    finally:
        server.stop()

    with open(os.path.join(logs, "server.log")) as f:
        server_log = f.read()
    tracebacks = server_log.count("Traceback")
    internal = server_log.count("internal error")
    memory = _flat(sampler.samples, t_start, t_end)
    legit_runs = sum(len(r) for r in runs)
    equal = sum(x["equal_to_solo"] for r in runs for x in r)
    result = {
        "scene": scene, "trace": trace, "method": method, "clients": clients, "duration_s": duration_s,
        "run_s": run_s, "warm_up_s": round(warm_up_s, 2), "view_size": view_size, "max_sessions": max_sessions,
        "seed": seed,
        "solo": [{"frames_received": s["frames_received"], "ticks": s["ticks"]} for s in solo],
        "legitimate_runs": legit_runs, "runs_equal_to_solo": equal,
        "runs": [{"client": k + 1, "runs": r} for k, r in enumerate(runs)],
        "hostile": {k: t.summary() for k, t in tallies.items()},
        "server": {**memory, "open_files_before": fds_before, "open_files_after": fds_after,
                   "tracebacks": tracebacks, "internal_errors": internal,
                   "samples": [(round(t, 2), rss // 2**20, fds) for t, rss, fds in sampler.samples[::4]]},
        "failures": failures,
    }
    fds_ok = fds_before is not None and fds_after is not None and fds_after <= fds_before + 2
    result["passed"] = bool(not failures and legit_runs >= clients and equal == legit_runs and memory["flat"]
                            and fds_ok and tracebacks == 0 and internal == 0)
    write_result(out_dir, "soak.json", result)
    return result


GIVE_UP_JOIN_S = 90.0


def print_soak(r: dict) -> None:
    print(f"soak: {r['clients']} legitimate clients and {len(r['hostile'])} hostile kinds for {r['duration_s']:g} s "
          f"({r['scene']}, server view {r['view_size']}, --max-sessions {r['max_sessions']})")
    for c in r["runs"]:
        runs = c["runs"]
        bad = [x for x in runs if not x["equal_to_solo"]]
        print(f"  client {c['client']}: {len(runs)} runs, {len(runs) - len(bad)} equal to its solo run"
              + (f"; first difference: {bad[0]['differences'][:1]}" if bad else ""))
    print(f"  {'hostile kind':20s} {'conns':>6s} {'held med/max s':>15s}  server's answers")
    for k, t in r["hostile"].items():
        med, mx = t["held_s_median"], t["held_s_max"]
        held = "-" if med is None else f"{med:.1f}/{mx:.1f}"
        never = f", never closed {t['server_never_closed']}" if t["server_never_closed"] else ""
        print(f"  {k:20s} {t['connections']:6d} {held:>15s}  {t['answers']}{never}")
    s = r["server"]
    mb = lambda x: "?" if x is None else f"{x:.0f}"   # noqa: E731
    print(f"  server RSS peak {mb(s['rss_mb_second_quarter_peak'])} MB (2nd quarter) -> "
          f"{mb(s['rss_mb_last_quarter_peak'])} MB (last quarter): {'flat' if s['flat'] else 'GROWING'}; "
          f"open files {s['open_files_before']} -> {s['open_files_after']}; tracebacks {s['tracebacks']}, "
          f"internal errors {s['internal_errors']}")
    for f in r["failures"][:5]:
        print(f"  failure: {f}")
    print("PASSED" if r["passed"] else "FAILED")
