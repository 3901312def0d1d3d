"""A benchmark's independent points, run in this process or spread over Ray workers.

A sweep (``pibr bench trade``, ``pareto``, ``coverage``, ``dynamic``) is a list of
:class:`Point`: a module-level function of pibr and its arguments, each measuring one piece
(a stream point on one window, one window of a scene) from nothing but its arguments, so its
numbers do not depend on which worker runs it or what ran there before. Every worker is a
:class:`Worker` that keeps, between points, what is slow to make and the same for all of them:
one GL context, the scenes it has loaded, and caches a bench asks for (ground truth per tick,
proxy bundles per LoD setting).

``workers=None`` runs the points in order in this process (the benches' own default, scoring on
one extra process as before). ``workers=N`` starts a local Ray with N actors, one per worker,
each on one CPU and scoring inline; ``ray_address`` joins an existing cluster instead (workers
default to its CPUs, or its GPUs with ``gpus_per_worker``). Points are handed out largest
estimated cost first, one at a time to whichever actor is free, so the last points to finish are
small. Ray is the optional extra ``pip install 'pibr[cluster]'``, imported only here and only
when asked for.
"""
from __future__ import annotations

import concurrent.futures
import logging
import multiprocessing
import os
from dataclasses import dataclass, field
from typing import Any, Callable

from pibr.protocol.errors import ConfigError

log = logging.getLogger(__name__)


@dataclass
class Point:
    """One independent piece of a sweep: ``function(worker, **kwargs)`` on some :class:`Worker`.

    ``function`` must be a module-level function (Ray sends it by its qualified name); ``cost`` is
    a relative estimate of its time (larger ones start first); ``ticks``: progress units it covers."""

    function: Callable
    kwargs: dict = field(default_factory=dict)
    cost: float = 1.0
    ticks: int = 1
    name: str = ""


class _Finished:
    """A result already computed, with the interface of a future."""

    def __init__(self, value):
        self.value = value

    def result(self):
        return self.value


class Worker:
    """What one worker keeps between points: a GL context, loaded scenes, named caches.

    ``score_processes``: worker processes for :meth:`submit` (0: inline, as on a Ray actor whose
    CPU is all it has); ``gl_threads``: the software rasteriser's threads (Mesa llvmpipe's
    LP_NUM_THREADS, unless already set; None: llvmpipe's own choice, a thread per core), so that
    workers given one CPU each do not crowd each other's cores."""

    def __init__(self, score_processes: int = 0, gl_threads: int | None = None):
        self.score_processes = score_processes
        if gl_threads is not None:
            os.environ.setdefault("LP_NUM_THREADS", str(gl_threads))
        self._ctx = None
        self._scenes: dict = {}
        self._caches: dict = {}
        self._pool = None

    @property
    def ctx(self):
        if self._ctx is None:
            from pibr.common.gl import create_context

            self._ctx = create_context()
        return self._ctx

    def scene(self, spec: str):
        """The scene named or pointed at by ``spec``, loaded once per worker."""
        if spec not in self._scenes:
            from pibr.scenes.registry import load_scene

            self._scenes[spec] = load_scene(spec)
        return self._scenes[spec]

    def cache(self, name: str) -> dict:
        """A dict kept between points under ``name`` (its keys must say everything the value depends on)."""
        return self._caches.setdefault(name, {})

    def submit(self, fn, *args):
        """``fn(*args)`` on a scoring process, or inline; an object whose ``result()`` gives its value."""
        if self.score_processes <= 0:
            return _Finished(fn(*args))
        if self._pool is None:
            self._pool = concurrent.futures.ProcessPoolExecutor(
                max_workers=self.score_processes, mp_context=multiprocessing.get_context("spawn"))
        return self._pool.submit(fn, *args)

    def run(self, function, kwargs: dict):
        return function(self, **kwargs)

    def gl_renderer(self) -> str | None:
        """The GL renderer this worker's context runs on (None before it made one)."""
        return None if self._ctx is None else self._ctx.info.get("GL_RENDERER")

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None
        self._caches.clear()
        self._scenes.clear()
        if self._ctx is not None:
            self._ctx.release()
            self._ctx = None


@dataclass(frozen=True)
class Placement:
    """Where a sweep runs: ``workers`` None and no address: this process; else Ray."""

    workers: int | None = None
    ray_address: str | None = None
    gpus_per_worker: float = 0.0

    @property
    def uses_ray(self) -> bool:
        return self.workers is not None or self.ray_address is not None

    def to_json(self, ran: dict | None = None) -> dict:
        """What this placement asks for, with ``ran``: what :func:`run_points` found (workers, GL renderers)."""
        if not self.uses_ray:
            out = {"mode": "in-process", "workers": 1,
                   "note": "points in order in one process, scored on one extra process"}
        else:
            out = {"mode": "ray", "workers": self.workers, "address": self.ray_address or "local",
                   "gpus_per_worker": self.gpus_per_worker,
                   "note": "timings (ms per display, server CPU ms) were taken beside the other workers' points"}
        return out | (ran or {})


#: Fields of a sweep's result that are measured times or say where it ran: everything else is
#: the same wherever and in whatever order its points run.
TIMING_KEYS = frozenset({"client_cpu_ms", "server_cpu_ms", "seconds", "placement", "client_ms_median", "speed",
                         "per_server_frame_ms", "encode_ms_median", "decode_ms_median"})


def without_timings(result):
    """``result`` (JSON-like) without the :data:`TIMING_KEYS` fields, at any depth."""
    if isinstance(result, dict):
        return {k: without_timings(v) for k, v in result.items() if k not in TIMING_KEYS}
    if isinstance(result, list):
        return [without_timings(v) for v in result]
    return result


def same_numbers(a, b) -> bool:
    """Whether two results of a sweep agree in every number but the timings (NaN, e.g. a mean over
    no pixels, equal to NaN; compared as their JSON)."""
    import json

    return json.dumps(without_timings(a), sort_keys=True) == json.dumps(without_timings(b), sort_keys=True)


def import_ray():
    """Ray, or a ConfigError saying how to install it."""
    try:
        import ray
    except ImportError as exc:
        raise ConfigError("--workers and --ray-address run a sweep's points on Ray, which is not installed: "
                          "pip install 'pibr[cluster]' (or pip install ray), or leave both out to run in "
                          "this process") from exc
    return ray


def run_points(points: list[Point], placement: Placement = Placement(), bar=None,
               on_result: Callable[[int, Any], None] | None = None, ran: dict | None = None) -> list:
    """Every point's result, in the order of ``points``. ``bar``: a tqdm updated by each finished
    point's ``ticks``; ``on_result(index, result)`` as each finishes (e.g. to write partial results);
    ``ran``: a dict given the workers used and the GL renderers they drew with."""
    ran = {} if ran is None else ran
    if not points:
        return []
    if not placement.uses_ray:
        return _run_here(points, bar, on_result, ran)
    return _run_on_ray(points, placement, bar, on_result, ran)


def _run_here(points, bar, on_result, ran) -> list:
    worker = Worker(score_processes=1)
    out = []
    try:
        for i, p in enumerate(points):
            out.append(worker.run(p.function, p.kwargs))
            if bar is not None:
                bar.update(p.ticks)
            if on_result is not None:
                on_result(i, out[-1])
        ran.update(workers=1, gl_renderers=[r for r in [worker.gl_renderer()] if r])
    finally:
        worker.close()
    return out


def _check_reachable(address: str, timeout_s: float = 5.0) -> None:
    """A ConfigError now, rather than Ray retrying for minutes, when nothing listens at HOST:PORT
    (``ray://HOST:PORT`` or ``HOST:PORT``; ``auto`` and other forms are left to Ray)."""
    import socket

    hostport = address.removeprefix("ray://")
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s).close()
    except OSError as exc:
        raise ConfigError(f"--ray-address {address}: nothing answers at {host}:{port} ({exc}); start a cluster "
                          "with `ray start --head` there, or give its address (HEAD:6379, or ray://HEAD:10001)") from exc


def _check_resources(resources: dict, count: int, gpus_per_worker: float) -> None:
    """A ConfigError when not even one worker fits on the cluster (it would wait forever); a
    warning when only some do (the rest start as the cluster grows or others finish)."""
    cpus, gpus = resources.get("CPU", 0), resources.get("GPU", 0)
    if cpus < 1 or gpus < gpus_per_worker:
        raise ConfigError(f"a worker asks Ray for 1 CPU and {gpus_per_worker:g} GPU(s), and the cluster has "
                          f"{cpus:g} CPU(s) and {gpus:g} GPU(s): start machines with GPUs "
                          "(ray start --num-gpus 1) or leave --gpus-per-worker out")
    if count > cpus or count * gpus_per_worker > gpus:
        log.warning("%d workers ask for %d CPUs and %g GPUs; the cluster has %g and %g: some wait for room",
                    count, count, count * gpus_per_worker, cpus, gpus)


def _ray_worker_count(ray, placement: Placement) -> int:
    if placement.workers is not None:
        return placement.workers
    resources = ray.cluster_resources()
    if placement.gpus_per_worker > 0:
        return max(1, int(resources.get("GPU", 0) / placement.gpus_per_worker))
    return max(1, int(resources.get("CPU", 1)))


def _run_on_ray(points, placement: Placement, bar, on_result, ran) -> list:
    ray = import_ray()
    started = False
    if placement.ray_address is not None:
        _check_reachable(placement.ray_address)
    if not ray.is_initialized():
        kwargs = dict(include_dashboard=False, logging_level=logging.WARNING)
        if placement.ray_address is None:
            # a local Ray with a CPU for each worker asked for, even beyond this machine's count
            # (its workers inherit this process's environment: PIBR_GL_BACKEND, the caches' folders)
            kwargs["num_cpus"] = max(placement.workers or 1, os.cpu_count() or 1)
        try:
            ray.init(address=placement.ray_address, **kwargs)
        except ConnectionError as exc:
            raise ConfigError(f"--ray-address {placement.ray_address}: no Ray cluster answers there ({exc}); "
                              "start one with `ray start --head` or give its address as ray://HOST:10001") from exc
        started = True
    actors = []
    try:
        count = min(_ray_worker_count(ray, placement), len(points))
        _check_resources(ray.cluster_resources(), count, placement.gpus_per_worker)
        actor_class = ray.remote(num_cpus=1, num_gpus=placement.gpus_per_worker)(Worker)
        actors = [actor_class.remote(0, 1) for _ in range(count)]
        order = sorted(range(len(points)), key=lambda i: -points[i].cost)
        results: list = [None] * len(points)
        running: dict = {}
        free = list(actors)
        while order or running:
            while order and free:
                i = order.pop(0)
                actor = free.pop()
                running[actor.run.remote(points[i].function, points[i].kwargs)] = (i, actor)
            done, _ = ray.wait(list(running), num_returns=1)
            i, actor = running.pop(done[0])
            try:
                results[i] = ray.get(done[0])
            except ray.exceptions.RayActorError as exc:
                raise RuntimeError(f"a Ray worker died while measuring {points[i].name or f'point {i}'} "
                                   f"(out of memory, or killed): {exc}") from exc
            free.append(actor)
            if bar is not None:
                bar.update(points[i].ticks)
            if on_result is not None:
                on_result(i, results[i])
        renderers = ray.get([actor.gl_renderer.remote() for actor in actors])
        ran.update(workers=count, gl_renderers=sorted({r for r in renderers if r}))
        log.info("%d points on %d Ray workers", len(points), count)
        return results
    finally:
        for actor in actors:
            ray.kill(actor)
        if started:
            ray.shutdown()
