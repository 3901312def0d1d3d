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
    CPU is all it has)."""

    def __init__(self, score_processes: int = 0):
        self.score_processes = score_processes
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

    def to_json(self, actual_workers: int | None = None) -> dict:
        if not self.uses_ray:
            return {"mode": "in-process", "workers": 1,
                    "note": "points in order in one process, scored on one extra process"}
        return {"mode": "ray", "workers": actual_workers or self.workers, "address": self.ray_address or "local",
                "gpus_per_worker": self.gpus_per_worker,
                "note": "timings (ms per display, server CPU ms) were taken beside the other workers' points"}


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
               on_result: Callable[[int, Any], None] | None = None) -> list:
    """Every point's result, in the order of ``points``. ``bar``: a tqdm updated by each finished
    point's ``ticks``; ``on_result(index, result)`` as each finishes (e.g. to write partial results)."""
    if not points:
        return []
    if not placement.uses_ray:
        return _run_here(points, bar, on_result)
    return _run_on_ray(points, placement, bar, on_result)


def _run_here(points, bar, on_result) -> list:
    worker = Worker(score_processes=1)
    out = []
    try:
        for i, p in enumerate(points):
            out.append(worker.run(p.function, p.kwargs))
            if bar is not None:
                bar.update(p.ticks)
            if on_result is not None:
                on_result(i, out[-1])
    finally:
        worker.close()
    return out


def _ray_worker_count(ray, placement: Placement) -> int:
    if placement.workers is not None:
        return placement.workers
    resources = ray.cluster_resources()
    if placement.gpus_per_worker > 0:
        return max(1, int(resources.get("GPU", 0) / placement.gpus_per_worker))
    return max(1, int(resources.get("CPU", 1)))


def _run_on_ray(points, placement: Placement, bar, on_result) -> list:
    ray = import_ray()
    started = False
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
        actor_class = ray.remote(num_cpus=1, num_gpus=placement.gpus_per_worker)(Worker)
        actors = [actor_class.remote(0) for _ in range(count)]
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
        log.info("%d points on %d Ray workers", len(points), count)
        return results
    finally:
        for actor in actors:
            ray.kill(actor)
        if started:
            ray.shutdown()
