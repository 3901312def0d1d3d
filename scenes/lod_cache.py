"""On-disk cache of LoD proxies (:mod:`pibr.scenes.lod`): generating them takes seconds per mesh.

One compressed ``.npz`` per mesh and parameter set, named by its key: the sha256 of the
mesh's :meth:`~pibr.scenes.scene.Mesh.digest`, the parameters and :data:`FORMAT_VERSION`.
The directory is ``$PIBR_CACHE_DIR`` when that is set, else ``~/.cache/pibr/lod``.

Files are written to a temporary name in the same directory and renamed into place, so a
reader never sees half a file, even with several processes generating at once. A file that
cannot be read or does not hold what its name promises is logged, deleted and regenerated.
"""
from __future__ import annotations

import hashlib
import io
import json
import logging
import os
import sys
import tempfile
import threading
import zipfile
from pathlib import Path
from typing import Callable

import numpy as np

from pibr.protocol import bounded_json
from pibr.protocol.errors import JSONError, SceneError

from .lod import DEFAULT_MAX_ITERATIONS, LodResult, simplify_encaging
from .scene import Mesh

log = logging.getLogger(__name__)

#: Bump when the generator's output or the file layout changes: old files are then ignored.
FORMAT_VERSION = 1
ENV_VAR = "PIBR_CACHE_DIR"

_stats_lock = threading.Lock()
_stats = {"hits": 0, "misses": 0, "generated": 0, "corrupted": 0, "written": 0, "write_errors": 0}


def cache_dir() -> Path:
    """Where LoD files live: ``$PIBR_CACHE_DIR`` if set (and non-empty), else ``~/.cache/pibr/lod``."""
    env = os.environ.get(ENV_VAR, "").strip()
    return Path(env).expanduser() if env else Path.home() / ".cache" / "pibr" / "lod"


def _params(resolution, target_fraction, min_triangles, tolerance, max_iterations) -> dict:
    return {"resolution": int(resolution), "target_fraction": float(target_fraction),
            "min_triangles": int(min_triangles), "tolerance": None if tolerance is None else float(tolerance),
            "max_iterations": int(max_iterations)}


def cache_key(mesh: Mesh, **params) -> str:
    """sha256 hex of the mesh digest, the generation parameters and the format version."""
    blob = json.dumps({"format": FORMAT_VERSION, "mesh": mesh.digest(), "params": _params(**params)},
                      sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()


def _count(name: str, k: int = 1) -> None:
    with _stats_lock:
        _stats[name] += k


def cache_stats() -> dict:
    """This process's cache counters (hits, misses, generated, corrupted, written, write_errors)
    and the directory's current ``files`` and ``bytes``."""
    directory = cache_dir()
    files = sorted(directory.glob("*.npz")) if directory.is_dir() else []
    size = 0
    for p in files:
        try:
            size += p.stat().st_size
        except FileNotFoundError:  # removed by another process meanwhile
            pass
    with _stats_lock:
        counters = dict(_stats)
    return {"directory": str(directory), "files": len(files), "bytes": size, **counters}


# ----------------------------------------------------------------------------- file format

def _encode(result: LodResult, key: str) -> bytes:
    meta = {"format": FORMAT_VERSION, "key": key, "enclosed_fraction": result.enclosed_fraction,
            "max_outside_distance": result.max_outside_distance, "triangles_original": result.triangles_original,
            "triangles_proxy": result.triangles_proxy, "iterations": result.iterations,
            "seconds": result.seconds, "params": result.params, "kind": result.kind, "note": result.note}
    buf = io.BytesIO()
    np.savez_compressed(buf, proxy_vertices=result.proxy.vertices, proxy_faces=result.proxy.faces,
                        box_vertices=result.box.vertices, box_faces=result.box.faces,
                        meta=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8))
    return buf.getvalue()


def _decode(path: Path, key: str) -> LodResult:
    """Read one cache file; ValueError (any flavour of damage) if it is not a valid entry for ``key``."""
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {name: z[name] for name in ("proxy_vertices", "proxy_faces", "box_vertices", "box_faces",
                                                 "meta")}
    except (OSError, EOFError, KeyError, ValueError, zipfile.BadZipFile) as exc:
        raise ValueError(f"unreadable: {type(exc).__name__}: {exc}") from exc
    try:
        meta = bounded_json.loads(arrays["meta"].tobytes(), what="metadata")
    except JSONError as exc:
        raise ValueError(f"bad metadata: {exc}") from exc
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_VERSION or meta.get("key") != key:
        raise ValueError("metadata does not match the file name's key or format version")
    try:
        proxy = Mesh(arrays["proxy_vertices"], arrays["proxy_faces"])
        box = Mesh(arrays["box_vertices"], arrays["box_faces"])
        result = LodResult(proxy, box, float(meta["enclosed_fraction"]), float(meta["max_outside_distance"]),
                           int(meta["triangles_original"]), int(meta["triangles_proxy"]), int(meta["iterations"]),
                           float(meta["seconds"]), dict(meta["params"]), str(meta["kind"]), str(meta["note"]))
    except (SceneError, KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"bad contents: {exc}") from exc
    if result.triangles_proxy != proxy.triangle_count or result.kind not in LodResult.KINDS:
        raise ValueError("contents are inconsistent")
    return result


def write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` whole or not at all (a temporary file in the same directory, renamed)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem[:16] + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


# ----------------------------------------------------------------------------- API

def cached_lod(mesh: Mesh, resolution: int = 128, target_fraction: float = 0.005, min_triangles: int = 12,
               tolerance: float | None = None, max_iterations: int = DEFAULT_MAX_ITERATIONS,
               progress: Callable[[str], None] | None = None, directory: Path | str | None = None) -> LodResult:
    """:func:`~pibr.scenes.lod.simplify_encaging` through the cache (``directory``: default :func:`cache_dir`).

    A cache that cannot be written (read-only disk) is logged and the result returned anyway.
    """
    params = dict(resolution=resolution, target_fraction=target_fraction, min_triangles=min_triangles,
                  tolerance=tolerance, max_iterations=max_iterations)
    key = cache_key(mesh, **params)
    path = Path(directory).expanduser() if directory is not None else cache_dir()
    path = path / f"{key}.npz"
    if path.is_file():
        try:
            result = _decode(path, key)
        except ValueError as exc:
            _count("corrupted")
            log.warning("LoD cache file %s is corrupted (%s): regenerating it", path, exc)
            try:
                path.unlink()
            except FileNotFoundError:
                pass
        else:
            _count("hits")
            return result
    _count("misses")
    result = simplify_encaging(mesh, progress=progress, **params)
    _count("generated")
    try:
        write_atomic(path, _encode(result, key))
        _count("written")
    except OSError as exc:
        _count("write_errors")
        log.warning("cannot write LoD cache file %s: %s", path, exc)
    return result


def lods_for_scene(scene, resolution: int = 128, target_fraction: float = 0.005, progress: bool = True,
                   min_triangles: int = 12, tolerance: float | None = None,
                   max_iterations: int = DEFAULT_MAX_ITERATIONS,
                   directory: Path | str | None = None, workers: int | None = None) -> dict[str, LodResult]:
    """LoDs of every object of ``scene``: object name -> :class:`~pibr.scenes.lod.LodResult`.

    Cached meshes are read, never regenerated; the others are generated (each distinct mesh once,
    however many objects share it), several at a time in worker processes (``workers``, default
    one per core) when there are several to make, under a tqdm progress bar on stderr (one
    step per mesh, its name shown) when ``progress``.
    """
    from tqdm import tqdm

    params = dict(resolution=resolution, target_fraction=target_fraction, min_triangles=min_triangles,
                  tolerance=tolerance, max_iterations=max_iterations)
    base = Path(directory).expanduser() if directory is not None else cache_dir()
    by_key: dict[str, list] = {}
    for obj in scene.objects:
        by_key.setdefault(cache_key(obj.mesh, **params), []).append(obj)
    todo = [k for k in by_key if not (base / f"{k}.npz").is_file()]
    results: dict[str, LodResult] = {}
    workers = min(os.cpu_count() or 1, len(todo)) if workers is None else min(workers, len(todo))
    with tqdm(total=len(todo), desc=f"LoD proxies ({scene.name})", unit="mesh", file=sys.stderr,
              disable=not progress or not todo, leave=False) as bar:
        if workers > 1:
            results.update(_generate_in_parallel(by_key, todo, workers, base, params, bar))
        for key, objs in by_key.items():
            if key in results:
                continue
            name = objs[0].name
            generating = key in todo

            def stage(text: str, name=name) -> None:
                bar.set_postfix_str(f"{name}: {text}", refresh=True)

            results[key] = cached_lod(objs[0].mesh, progress=stage if generating else None, directory=base, **params)
            if generating:
                bar.update(1)
    by_name = {obj.name: results[key] for key, objs in by_key.items() for obj in objs}
    return {obj.name: by_name[obj.name] for obj in scene.objects}


def _generate_in_parallel(by_key: dict, todo: list, workers: int, directory: Path, params: dict, bar) -> dict:
    """Generate the meshes of ``todo`` (cache keys) in ``workers`` processes -> key -> LodResult.
    Each worker writes its cache file; the counters of this process count what they made."""
    import concurrent.futures
    import multiprocessing

    out = {}
    context = multiprocessing.get_context("spawn")   # no fork of a process that may hold GL or threads
    with concurrent.futures.ProcessPoolExecutor(workers, mp_context=context) as pool:
        # largest meshes first, so that no big one starts last while the other workers idle
        order = sorted(todo, key=lambda k: -by_key[k][0].mesh.triangle_count)
        futures = {pool.submit(cached_lod, by_key[k][0].mesh, directory=directory, **params): k for k in order}
        for future in concurrent.futures.as_completed(futures):
            key = futures[future]
            out[key] = future.result()
            _count("misses")
            _count("generated")
            bar.set_postfix_str(f"{by_key[key][0].name}: done", refresh=True)
            bar.update(1)
    return out
