"""OpenGL contexts, created in one place, each owned by one thread.

The server renders, the client re-renders and the benchmarks render ground truth, all with
moderngl on a headless EGL context (Mesa llvmpipe here, a GPU where there is one). A GL
context belongs to the thread that made it current, so each user gets a :class:`GLThread`:
a single worker thread that creates the context and runs every GL call, keeping GL work off
the asyncio event loop (``await gl.run(fn, ...)``).

Off the loop is not enough on its own: moderngl holds the GIL in every call, and ``finish()`` and
the readbacks block for as long as the rasteriser draws, tens of milliseconds a tick on llvmpipe.
Meanwhile no other Python thread runs, the event loop included, so on the wall clock frames
arriving then were read (and stamped) late and bunched, and a stream adapting to those stamps
read the delay as a queue. :func:`wait_idle` waits for the GL work with a fence through ctypes,
which releases the GIL: measured here (a 34 ms draw every 40 ms on another thread), the event
loop's lateness p95 went from 33 ms to 0.4 ms (max 40 -> 5), the draws as fast.
"""
from __future__ import annotations

import asyncio
import concurrent.futures
import ctypes
import logging
import os
import threading

from pibr.protocol.errors import GLUnavailable

log = logging.getLogger(__name__)

#: Minimum GL version: 4.0 for tessellation shaders, 3.3 would do without them.
REQUIRED_GL = 400


def create_context(require: int = REQUIRED_GL):
    """A standalone (windowless) moderngl context on the current thread.

    The backend is EGL unless ``PIBR_GL_BACKEND`` names another glcontext backend.
    """
    import moderngl

    backend = os.environ.get("PIBR_GL_BACKEND", "egl")
    try:
        ctx = moderngl.create_standalone_context(require=require, backend=backend)
    except Exception as exc:  # glcontext raises plain Exceptions with the driver's words
        raise GLUnavailable(
            f"no headless OpenGL {require // 100}.{require % 100 // 10} context with the {backend!r} backend "
            f"({exc}); install Mesa's EGL (Debian/Ubuntu: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri)"
        ) from exc
    log.debug("GL context: %s, %s", ctx.info.get("GL_RENDERER"), ctx.info.get("GL_VERSION"))
    return ctx


GL_SYNC_GPU_COMMANDS_COMPLETE = 0x9117
GL_SYNC_FLUSH_COMMANDS_BIT = 0x1
GL_ALREADY_SIGNALED, GL_TIMEOUT_EXPIRED, GL_CONDITION_SATISFIED = 0x911A, 0x911B, 0x911C
GL_RENDERER = 0x1F01
#: The libraries that export the GL entry points (libglvnd's, which dispatch to the context current
#: on the calling thread, EGL's or GLX's), tried in order.
GL_LIBRARIES = ("libOpenGL.so.0", "libGL.so.1")
_sync_lock = threading.Lock()
_NOT_LOADED = object()
_sync_functions = _NOT_LOADED   # then (fence, wait, delete), or None where no library reaches the context


def _load_sync_functions(ctx) -> tuple | None:
    """(glFenceSync, glClientWaitSync, glDeleteSync) as ctypes functions (a foreign call releases
    the GIL) from the first library whose entry points reach ``ctx`` (its glGetString names the
    renderer moderngl's does), or None where none does. Loaded once per process."""
    global _sync_functions
    with _sync_lock:
        if _sync_functions is not _NOT_LOADED:
            return _sync_functions
        _sync_functions = None
        renderer = str(ctx.info.get("GL_RENDERER", "")).encode()
        for name in GL_LIBRARIES:
            try:
                lib = ctypes.CDLL(name)
                get_string, fence = lib.glGetString, lib.glFenceSync
                wait, delete = lib.glClientWaitSync, lib.glDeleteSync
            except (OSError, AttributeError):
                continue
            get_string.restype, get_string.argtypes = ctypes.c_char_p, [ctypes.c_uint]
            if not renderer or get_string(GL_RENDERER) != renderer:
                continue   # its calls would not reach this context
            fence.restype, fence.argtypes = ctypes.c_void_p, [ctypes.c_uint, ctypes.c_uint]
            wait.restype, wait.argtypes = ctypes.c_uint, [ctypes.c_void_p, ctypes.c_uint, ctypes.c_uint64]
            delete.restype, delete.argtypes = None, [ctypes.c_void_p]
            _sync_functions = (fence, wait, delete)
            break
        if _sync_functions is None:
            log.info("no GL library reaches the context with glClientWaitSync (%s): GL waits hold the GIL",
                     ", ".join(GL_LIBRARIES))
        return _sync_functions


def wait_idle(ctx) -> None:
    """Return once every GL command given on ``ctx`` so far has completed, as ``ctx.finish()``
    does, but wait with the GIL released (module docstring), so the event loop and other threads
    run meanwhile. Call it on the context's own thread. Falls back to ``ctx.finish()`` where the
    sync functions are missing or the wait fails."""
    functions = _load_sync_functions(ctx)
    if functions is None:
        ctx.finish()
        return
    fence, wait, delete = functions
    sync = fence(GL_SYNC_GPU_COMMANDS_COMPLETE, 0)
    if not sync:
        ctx.finish()
        return
    try:
        while True:
            status = wait(sync, GL_SYNC_FLUSH_COMMANDS_BIT, 1_000_000_000)   # a second at a time
            if status in (GL_ALREADY_SIGNALED, GL_CONDITION_SATISFIED):
                break
            if status != GL_TIMEOUT_EXPIRED:
                ctx.finish()
                break
    finally:
        delete(sync)


class GLThread:
    """One thread, one GL context. ``call(fn, *a)`` runs ``fn(ctx, *a)`` there and returns its result;
    ``await run(fn, *a)`` does the same without blocking the event loop."""

    def __init__(self, name: str = "gl"):
        self._executor = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix=name)
        self._ctx = None
        self._lock = threading.Lock()
        self.call(lambda ctx: None)  # create the context now, so a missing driver fails early

    def _run(self, fn, args, kwargs):
        if self._ctx is None:
            self._ctx = create_context()
        return fn(self._ctx, *args, **kwargs)

    def call(self, fn, *args, **kwargs):
        return self._executor.submit(self._run, fn, args, kwargs).result()

    async def run(self, fn, *args, **kwargs):
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(self._executor, self._run, fn, args, kwargs)

    def close(self) -> None:
        def release(ctx):
            ctx.release()

        with self._lock:
            if self._ctx is not None:
                try:
                    self._executor.submit(release, self._ctx).result()
                finally:
                    self._ctx = None
            self._executor.shutdown(wait=True)
