"""``pibr bench fuzz``: mutation fuzzing of every parser a peer or a file feeds.

For each parser (:mod:`.fuzz_targets`: wire, edge, quadtree, proxy, trace, scene) the valid
seed inputs are built once, in this process, from pibr's own writers; input ``i`` is seed
``i mod seeds`` mutated (:mod:`.fuzz_mutate`) by a generator seeded with ``(seed, parser,
i)``, so any input is reproduced from its number alone (inputs ``0 .. seeds - 1`` are the
seeds themselves, which must be accepted).

Inputs run in a forked worker process, in batches, in-process there (cheap: the parsers
need no I/O beyond a temporary file). The worker publishes the number of the input it is
running in shared memory; this process watches it, and an input still running after
``timeout_s`` is a *hang*: the worker is killed, the input saved, and a fresh worker
re-runs the batch without it. A worker that dies (a crash) is handled the same way and
counts as an undocumented exception. Per parser the report gives inputs, accepted inputs,
documented errors by class, undocumented exceptions (must be 0; the first few with their
input saved under ``OUT/fuzz_inputs/`` and a traceback), hangs (must be 0), the worker's
peak RSS (``ru_maxrss``) and the input that raised it most, the slowest input and inputs/s.
``pibr bench fuzz --replay FILE`` runs one saved input again, in this process.
"""
from __future__ import annotations

import multiprocessing
import os
import random
import resource
import shutil
import sys
import tempfile
import time
import traceback
from collections import Counter
from dataclasses import dataclass, field

DEFAULT_INPUTS = 100_000
DEFAULT_TIMEOUT_S = 10.0
#: Inputs a worker runs before reporting back (a hang or crash re-runs at most this many).
BATCH = 250
#: Undocumented exceptions and hangs kept with their inputs, per parser.
MAX_EXAMPLES = 5
#: How long a fresh worker may take to start its first input.
START_TIMEOUT_S = 120.0


def make_input(target, seed: int, index: int) -> tuple[str, bytes]:
    """(kind, bytes) of input ``index`` of ``target``: its seeds first, then mutants."""
    base = target.seeds[index % len(target.seeds)]
    if index < len(target.seeds):
        return base.kind, base.data
    return base.kind, target.mutate(random.Random(f"{seed}:{target.name}:{index}"), base)


@dataclass
class _Tally:
    """What a worker saw in one batch."""

    inputs: int = 0
    accepted: int = 0
    documented: Counter = field(default_factory=Counter)
    undocumented: Counter = field(default_factory=Counter)
    examples: list = field(default_factory=list)   # dicts, with the input bytes under "data"
    seeds_rejected: list = field(default_factory=list)
    slowest: tuple = (0.0, -1)                       # (seconds, index)
    rss_jump: tuple = (0, -1)                        # (KiB the peak rose by, index)
    start_rss_kb: int = 0
    peak_rss_kb: int = 0


def _worker(target, seed: int, conn, current) -> None:
    """Forked: run the batches ``conn`` sends, report a :class:`_Tally` per batch."""
    import logging
    import warnings

    logging.disable(logging.CRITICAL)   # importers log what they fixed; a million times says nothing
    warnings.simplefilter("ignore")
    workdir = tempfile.mkdtemp(prefix=f"pibr-fuzz-{target.name}-")
    try:
        target.setup(workdir)
        while True:
            job = conn.recv()
            if job is None:
                return
            start, stop, skip = job
            tally = _Tally()
            peak = tally.start_rss_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
            for i in range(start, stop):
                if i in skip:
                    continue
                current.value = i
                kind, data = make_input(target, seed, i)
                t0 = time.perf_counter()
                try:
                    target.run(kind, data)
                    tally.accepted += 1
                except target.documented as exc:
                    tally.documented[type(exc).__name__] += 1
                    if i < len(target.seeds):
                        tally.seeds_rejected.append(f"seed {i} ({kind}): {type(exc).__name__}: {exc}")
                except Exception as exc:   # the point of fuzzing: every other exception is a finding
                    name = type(exc).__name__
                    tally.undocumented[name] += 1
                    if len(tally.examples) < MAX_EXAMPLES:
                        tally.examples.append({"index": i, "kind": kind, "class": name, "message": str(exc)[:500],
                                               "traceback": traceback.format_exc(limit=-6)[-3000:], "data": data})
                seconds = time.perf_counter() - t0
                tally.inputs += 1
                if seconds > tally.slowest[0]:
                    tally.slowest = (seconds, i)
                now = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
                if now - peak > tally.rss_jump[0]:
                    tally.rss_jump = (now - peak, i)
                peak = now
            tally.peak_rss_kb = peak
            conn.send(tally)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)


def fuzz_parser(target, inputs: int, seed: int = 0, timeout_s: float = DEFAULT_TIMEOUT_S, out_dir: str | None = None,
                progress=None) -> dict:
    """Run ``inputs`` inputs of ``target`` (a built :class:`~.fuzz_targets.Target`); -> its report.

    ``progress(n)`` is called as inputs finish; failing inputs are written to
    ``out_dir/fuzz_inputs`` when ``out_dir`` is given."""
    ctx = multiprocessing.get_context("fork")
    current = ctx.RawValue("q", -1)
    report = {"inputs": 0, "accepted": 0, "documented_errors": Counter(), "undocumented": Counter(),
              "undocumented_examples": [], "hangs": 0, "hang_examples": [], "seeds": len(target.seeds),
              "seeds_rejected": [], "workers_started": 0, "peak_rss_mb": 0.0, "worker_start_rss_mb": None,
              "largest_rss_rise": {"mb": 0.0, "input": None}, "slowest_input": {"seconds": 0.0, "input": None}}
    worker = None

    def start_worker():
        nonlocal worker
        parent_end, child_end = ctx.Pipe()
        proc = ctx.Process(target=_worker, args=(target, seed, child_end, current), daemon=True,
                           name=f"pibr-fuzz-{target.name}")
        proc.start()
        child_end.close()
        report["workers_started"] += 1
        worker = (proc, parent_end)

    def stop_worker(kill: bool):
        nonlocal worker
        proc, conn = worker
        worker = None
        if kill:
            proc.kill()
        else:
            conn.send(None)
        proc.join(timeout=30)
        if proc.is_alive():
            proc.kill()
            proc.join()
        conn.close()

    def keep(kind_of_list: str, example: dict):
        if len(report[kind_of_list]) < MAX_EXAMPLES:
            data = example.pop("data")
            if out_dir is not None:
                example["input"] = save_input(out_dir, target, example["kind"], example["index"], data)
            report[kind_of_list].append(example)

    t0 = time.perf_counter()
    start_worker()
    skip: set[int] = set()
    start = 0
    try:
        while start < inputs:
            stop = min(inputs, start + BATCH)
            current.value = -1
            proc, conn = worker
            conn.send((start, stop, frozenset(i for i in skip if start <= i < stop)))
            seen, seen_at = -1, time.monotonic()
            while True:
                eof = False
                if conn.poll(min(0.05, timeout_s / 10)):
                    try:
                        tally = conn.recv()
                    except (EOFError, OSError):   # the worker is gone
                        eof = True
                    else:
                        _merge(report, tally, keep)
                        if progress is not None:
                            progress(tally.inputs)
                        start = stop
                        break
                index = current.value
                now = time.monotonic()
                if index != seen:
                    seen, seen_at = index, now
                dead = eof or not proc.is_alive()
                limit = START_TIMEOUT_S if index < 0 else timeout_s
                if not dead and now - seen_at <= limit:
                    continue
                if index < 0:
                    stop_worker(kill=True)
                    raise RuntimeError(f"the fuzz worker for {target.name} " + (
                        f"died before its first input (exit code {proc.exitcode})" if dead else
                        f"did not start an input within {limit} s"))
                kind, data = make_input(target, seed, index)
                if dead:   # a crash: a segfault, an abort, the out-of-memory killer
                    proc.join(timeout=30)
                    stop_worker(kill=True)
                    what = f"WorkerDied({proc.exitcode})"
                    report["undocumented"][what] += 1
                    keep("undocumented_examples", {"index": index, "kind": kind, "class": what, "data": data,
                                                   "message": f"the worker died with exit code {proc.exitcode}"})
                else:
                    stop_worker(kill=True)
                    report["hangs"] += 1
                    keep("hang_examples", {"index": index, "kind": kind,
                                           "message": f"still running after {timeout_s} s", "data": data})
                report["inputs"] += 1
                if progress is not None:
                    progress(1)
                skip.add(index)
                start_worker()
                break   # re-send the batch without the input (the killed worker's counts are lost)
    except BaseException:
        if worker is not None:
            stop_worker(kill=True)
        raise
    stop_worker(kill=False)
    seconds = time.perf_counter() - t0
    report["documented_errors"] = dict(report["documented_errors"].most_common())
    report["undocumented"] = dict(report["undocumented"].most_common())
    report["undocumented_count"] = sum(report["undocumented"].values())
    report["seconds"] = seconds
    report["inputs_per_s"] = report["inputs"] / seconds if seconds > 0 else 0.0
    return report


def _merge(report: dict, tally: _Tally, keep) -> None:
    report["inputs"] += tally.inputs
    report["accepted"] += tally.accepted
    report["documented_errors"].update(tally.documented)
    report["undocumented"].update(tally.undocumented)
    report["seeds_rejected"] += tally.seeds_rejected
    for example in tally.examples:
        keep("undocumented_examples", example)
    mb = tally.peak_rss_kb / 1024
    report["peak_rss_mb"] = max(report["peak_rss_mb"], mb)
    if report["worker_start_rss_mb"] is None:
        report["worker_start_rss_mb"] = tally.start_rss_kb / 1024
    if tally.rss_jump[0] / 1024 > report["largest_rss_rise"]["mb"]:
        report["largest_rss_rise"] = {"mb": tally.rss_jump[0] / 1024, "input": tally.rss_jump[1]}
    if tally.slowest[0] > report["slowest_input"]["seconds"]:
        report["slowest_input"] = {"seconds": tally.slowest[0], "input": tally.slowest[1]}


def save_input(out_dir: str, target, kind: str, index: int, data: bytes) -> str:
    """Write a failing input as ``out_dir/fuzz_inputs/PARSER-KIND-INDEX.SUFFIX`` (what --replay reads)."""
    folder = os.path.join(out_dir, "fuzz_inputs")
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, f"{target.name}-{kind.replace('/', '_')}-{index}{target.suffix}")
    with open(path, "wb") as f:
        f.write(data)
    return path


def run_fuzz_bench(parsers=None, inputs: int = DEFAULT_INPUTS, seed: int = 0, timeout_s: float = DEFAULT_TIMEOUT_S,
                   out_dir: str | None = "out/bench", progress: bool = True, targets=None) -> dict:
    """Fuzz every parser named in ``parsers`` (default all; or ``targets``: Target objects);
    -> the result (also written to ``out_dir/fuzz.json``)."""
    from .fuzz_targets import TARGETS

    if targets is None:
        names = list(TARGETS) if parsers is None else list(parsers)
        unknown = [n for n in names if n not in TARGETS]
        if unknown:
            from pibr.protocol.errors import ConfigError

            raise ConfigError(f"unknown parser(s) {', '.join(unknown)}; choose from {', '.join(TARGETS)}")
        targets = [TARGETS[n]() for n in names]
    from tqdm import tqdm

    tqdm.monitor_interval = 0   # no monitor thread: the workers are forked from this process
    result = {"bench": "fuzz", "seed": seed, "inputs_per_parser": inputs, "timeout_s": timeout_s, "batch": BATCH,
              "parsers": {}}
    for target in targets:
        t0 = time.perf_counter()
        if not target.seeds:
            target.build()
        build_s = time.perf_counter() - t0
        with tqdm(total=inputs, desc=f"fuzz {target.name}", unit="input", file=sys.stderr, leave=False,
                  disable=None if progress else True) as bar:
            report = fuzz_parser(target, inputs, seed, timeout_s, out_dir, bar.update)
        report["seed_build_s"] = build_s
        report["documented"] = [cls.__name__ for cls in target.documented]
        result["parsers"][target.name] = report
    result["undocumented_total"] = sum(r["undocumented_count"] for r in result["parsers"].values())
    result["hangs_total"] = sum(r["hangs"] for r in result["parsers"].values())
    result["seeds_rejected_total"] = sum(len(r["seeds_rejected"]) for r in result["parsers"].values())
    result["ok"] = result["undocumented_total"] == 0 and result["hangs_total"] == 0 and \
        result["seeds_rejected_total"] == 0
    if out_dir is not None:
        from .results import write_result

        result["written"] = write_result(out_dir, "fuzz.json", result)
    return result


def print_fuzz_table(result: dict) -> None:
    print(f"pibr bench fuzz: {result['inputs_per_parser']} inputs per parser, seed {result['seed']}, "
          f"hang after {result['timeout_s']:g} s")
    head = (f"{'parser':<9} {'inputs':>8} {'accepted':>8} {'documented':>10} {'undocumented':>12} {'hangs':>5} "
            f"{'peak MB':>8} {'inputs/s':>9} {'slowest s':>9}")
    print(head)
    print("-" * len(head))
    for name, r in result["parsers"].items():
        documented = sum(r["documented_errors"].values())
        print(f"{name:<9} {r['inputs']:>8} {r['accepted']:>8} {documented:>10} {r['undocumented_count']:>12} "
              f"{r['hangs']:>5} {r['peak_rss_mb']:>8.0f} {r['inputs_per_s']:>9.0f} "
              f"{r['slowest_input']['seconds']:>9.3f}")
    for name, r in result["parsers"].items():
        classes = ", ".join(f"{k} {v}" for k, v in r["documented_errors"].items())
        print(f"  {name}: documented errors: {classes or 'none'}")
        for e in r["undocumented_examples"]:
            print(f"  {name}: UNDOCUMENTED {e['class']} on input {e['index']} ({e['kind']}): {e['message'][:200]}"
                  + (f"\n    input: {e['input']}" if "input" in e else ""))
        for e in r["hang_examples"]:
            print(f"  {name}: HANG on input {e['index']} ({e['kind']})" + (f": {e['input']}" if "input" in e else ""))
        for s in r["seeds_rejected"]:
            print(f"  {name}: SEED REJECTED {s}")
    print("result: " + ("ok, 0 undocumented exceptions and 0 hangs" if result["ok"] else
                        f"FAILED: {result['undocumented_total']} undocumented exceptions, {result['hangs_total']} "
                        f"hangs, {result['seeds_rejected_total']} seeds rejected"))


def replay(path: str) -> int:
    """Run one saved input (``PARSER-KIND-INDEX.SUFFIX``) in this process; print its outcome.
    -> 0 when it is accepted or raises a documented error, 1 otherwise."""
    from pibr.protocol.errors import ConfigError

    from .fuzz_targets import TARGETS

    name = os.path.basename(path)
    parser, _, rest = name.partition("-")
    if parser not in TARGETS:
        raise ConfigError(f"{path}: a replayed input's name starts with its parser ({', '.join(TARGETS)})")
    target = TARGETS[parser]()
    stem = rest[:-len(target.suffix)] if rest.endswith(target.suffix) else rest
    kind = stem.rsplit("-", 1)[0]
    with open(path, "rb") as f:
        data = f.read()
    target.build()
    with tempfile.TemporaryDirectory(prefix=f"pibr-fuzz-{parser}-") as workdir:
        target.setup(workdir)
        try:
            target.run(kind, data)
        except target.documented as exc:
            print(f"{parser} ({kind}): documented {type(exc).__name__}: {exc}")
            return 0
        except Exception:
            print(f"{parser} ({kind}): UNDOCUMENTED exception:")
            traceback.print_exc(file=sys.stdout)
            return 1
    print(f"{parser} ({kind}): accepted")
    return 0
