"""OpenGL contexts, created in one place, each owned by one thread.

The server renders, the client re-renders and the benchmarks render ground truth, all with
moderngl on a headless EGL context (Mesa llvmpipe here, a GPU where there is one). A GL
context belongs to the thread that made it current, so each user gets a :class:`GLThread`:
a single worker thread that creates the context and runs every GL call, keeping GL work off
the asyncio event loop (``await gl.run(fn, ...)``).
"""
from __future__ import annotations

import asyncio
import concurrent.futures
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
