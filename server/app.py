"""The asyncio server: accepts clients, one :class:`~pibr.server.session.Session` each.

Shared by all sessions: one GL thread (renderers are cached per scene), one small pool of
encoder threads and the loaded scenes. Nothing a session does with its socket can block
another session; an error in one session closes only that session.
"""
from __future__ import annotations

import asyncio
import concurrent.futures
import itertools
import logging
import os
from collections import deque

import numpy as np

from pibr.protocol.errors import ConfigError, SceneError
from pibr.common.gl import GLThread
from pibr.protocol.messages import Hello

from .config import ServerConfig
from .fair_queue import FairQueue
from .listener import TrackedListener
from .pipeline import SessionPipeline
from .session import Session

log = logging.getLogger(__name__)

#: How often a Hello waiting for a slot looks again for a silent session to reclaim (s).
RECLAIM_CHECK_S = 0.25


class Server(TrackedListener):
    name = "pibr-server/0.1"

    def __init__(self, config: ServerConfig):
        super().__init__()
        self.config = config
        #: sessions past a valid Hello: these count toward ``max_sessions``
        self.sessions: dict[int, Session] = {}
        self._slot_waiters: dict[int, asyncio.Future] = {}   # Hellos waiting for a slot, oldest first
        #: connections still to send their Hello, oldest first (bounded by ``max_pending``)
        self.pending: dict[int, Session] = {}
        self._ids = itertools.count(1)
        self._scenes: dict[str, asyncio.Future] = {}    # spec -> its load (one per scene)
        self._renderers: dict = {}  # touched only on the GL thread
        self._bundles: dict[int, asyncio.Future] = {}   # id(scene) -> its ProxyBundle's build
        self._coverage: dict[int, asyncio.Future] = {}  # id(scene) -> its extra view's coverage measurement
        self.gl: GLThread | None = None
        workers = max(2, os.cpu_count() or 2)
        self.encode_pool = concurrent.futures.ThreadPoolExecutor(max_workers=workers, thread_name_prefix="pibr-encode")
        #: the GL thread and the encoder pool, shared fairly between sessions (fair_queue.py)
        self.gl_queue = FairQueue(1)
        self.encode_queue = FairQueue(workers)
        self.recent_timings = deque(maxlen=100)

    # ------------------------------------------------------------------ lifecycle

    async def start(self) -> tuple[str, int]:
        loop = asyncio.get_running_loop()
        self.gl = await loop.run_in_executor(None, GLThread, "pibr-server-gl")
        scene = await self.get_scene(self.config.scene)  # load and upload the default scene before accepting
        await self.gl.run(self._renderer, scene)
        await self.get_coverage(scene)
        tls = None
        if self.config.tls_cert is not None:
            from pibr.common.tls import certificate_fingerprint, server_context

            tls = server_context(self.config.tls_cert, self.config.tls_key)
            log.info("pibr server: TLS certificate sha256 %s", certificate_fingerprint(self.config.tls_cert))
        host, port = await self.listen(self.config.host, self.config.port, ssl=tls,
                                       ssl_handshake_timeout=self.config.hello_timeout_s)
        log.info("pibr server listening on %s:%d%s (default scene %s, %s)", host, port, " (TLS)" if tls else "",
                 scene.name, "token required" if self.config.token is not None else "no token")
        return host, port

    async def close(self) -> None:
        await super().close()
        if self.gl is not None:
            def release_all(ctx):
                for r in self._renderers.values():
                    r.release()
                self._renderers.clear()
            await self.gl.run(release_all)
            self.gl.close()
            self.gl = None
        self.encode_pool.shutdown(wait=False, cancel_futures=True)

    async def handle(self, reader, writer) -> None:
        await Session(self, reader, writer, next(self._ids)).run()

    # ------------------------------------------------------------------ admission

    def add_pending(self, session: Session) -> None:
        """A new connection waits for its Hello outside the session slots. Past ``max_pending``
        such connections the oldest is dropped, so idle peers cannot keep others out."""
        self.pending[session.id] = session
        while len(self.pending) > self.config.max_pending:
            oldest = next(iter(self.pending.values()))
            del self.pending[oldest.id]
            oldest.evict(len(self.pending) + 1)

    async def admit(self, session: Session) -> None:
        """After a valid Hello: take a session slot, waiting up to ``admit_wait_s`` for one to
        free (first come, first served); ConfigError when none does.

        A session whose client has just left may not have noticed yet (it learns when it next
        reads or writes, which can be a render later), so a client that reconnects at once
        would otherwise be told the server is full."""
        self.pending.pop(session.id, None)
        if len(self.sessions) >= self.config.max_sessions:
            self._reclaim_silent_slot()
        if len(self.sessions) >= self.config.max_sessions or self._slot_waiters:
            loop = asyncio.get_running_loop()
            self._slot_waiters[session.id] = loop.create_future()
            try:
                async with asyncio.timeout(self.config.admit_wait_s):
                    while True:
                        # a silent session may become reclaimable while this one waits
                        done, _ = await asyncio.wait({self._slot_waiters[session.id]}, timeout=RECLAIM_CHECK_S)
                        if not done:
                            self._reclaim_silent_slot()
                            continue
                        if len(self.sessions) < self.config.max_sessions:
                            break
                        self._slot_waiters[session.id] = loop.create_future()   # keeps its place
            except TimeoutError:
                raise ConfigError(f"server full: {len(self.sessions)} sessions already (waited "
                                  f"{self.config.admit_wait_s:g} s for one to end)") from None
            finally:
                del self._slot_waiters[session.id]
                self._wake_next()   # runs once this one is counted below: no await in between
        self.sessions[session.id] = session

    def _reclaim_silent_slot(self) -> None:
        """A client waits for a slot: the session that has sent no pose for the longest since its
        Welcome, if longer than ``silent_slot_s``, gives its slot up. A client that said Hello and
        then nothing (say, re-sent every idle timeout) can thus keep nobody out, while every client
        that runs (it sends a pose each tick) keeps its slot."""
        now = asyncio.get_running_loop().time()
        silent = [(since, s) for s in self.sessions.values()
                  if (since := s.silent_since()) is not None and now - since > self.config.silent_slot_s]
        if silent:
            since, session = min(silent, key=lambda item: item[0])
            session.yield_slot(f"no pose {now - since:.1f} s after the Welcome while another client waited for a "
                               f"slot (--silent-slot-s {self.config.silent_slot_s:g})")

    def _wake_next(self) -> None:
        """A slot is free: wake the longest-waiting Hello (it checks again when it runs)."""
        if len(self.sessions) < self.config.max_sessions and self._slot_waiters:
            first = next(iter(self._slot_waiters.values()))
            if not first.done():
                first.set_result(None)

    def release(self, session: Session) -> None:
        self.pending.pop(session.id, None)
        self.sessions.pop(session.id, None)
        self.gl_queue.forget(session.id)
        self.encode_queue.forget(session.id)
        self._wake_next()

    async def render(self, session_id: int, fn, *args):
        """``fn(ctx, *args)`` on the GL thread, in this session's fair turn."""
        return await self.gl_queue.run(session_id, lambda: self.gl.run(fn, *args))

    async def encode(self, session_id: int, fn, *args):
        """``fn(*args)`` in the encoder pool, in this session's fair turn."""
        loop = asyncio.get_running_loop()
        return await self.encode_queue.run(session_id, lambda: loop.run_in_executor(self.encode_pool, fn, *args))

    # ------------------------------------------------------------------ sessions

    async def get_scene(self, spec: str):
        """The scene ``spec`` names, loaded once per server. Each scene loads on its own: a session
        for a loaded scene never waits on another scene's load."""
        from pibr.scenes.registry import load_scene

        spec = self.check_scene(spec)
        return await self._once(self._scenes, spec, load_scene, spec)

    def check_scene(self, spec: str) -> str:
        """The scene a Hello's ``spec`` names (empty: the default); SceneError if not served here."""
        from pibr.scenes.registry import available_scenes

        spec = spec or self.config.scene
        allowed = set(available_scenes()) | {self.config.scene}
        if spec not in allowed:
            raise SceneError(f"scene {spec!r} is not served here; available: {', '.join(sorted(allowed))}")
        return spec

    @staticmethod
    async def _once(cache: dict, key, fn, *args):
        """``fn(*args)`` in a worker thread once per key; concurrent callers share the one run, a
        caller that gives up does not cancel it, and a failure is not cached (the next caller retries)."""
        future = cache.get(key)
        if future is None:
            future = asyncio.get_running_loop().run_in_executor(None, fn, *args)
            cache[key] = future

            def forget_failure(f):
                if (f.cancelled() or f.exception() is not None) and cache.get(key) is f:
                    del cache[key]
            future.add_done_callback(forget_failure)
        return await asyncio.shield(future)

    def _renderer(self, ctx, scene):
        from .renderer import Renderer

        key = (id(scene), self.config.projection)
        if key not in self._renderers:
            self._renderers[key] = Renderer(ctx, scene, self.config.projection,
                                            max_edge_angle_deg=self.config.max_edge_deg)
        return self._renderers[key]

    async def get_bundle(self, scene):
        """The scene's proxy bundle, built (or read from the LoD cache) once per server and scene."""
        from .proxies import build_bundle

        return await self._once(self._bundles, id(scene), build_bundle, scene, self.config.proxy_settings)

    async def get_coverage(self, scene, session_id: int | None = None) -> dict | None:
        """How much the extra view covers in ``scene`` (scene_plan.py), measured on the GL thread once
        per server and scene (in ``session_id``'s fair turn when a session asks), or read from the
        on-disk cache; None unless ``extra_view`` is auto."""
        if self.config.extra_view != "auto":
            return None
        future = self._coverage.get(id(scene))
        if future is None:
            from .scene_plan import cached_extra_view
            from .session_plan import extra_offset_for

            def measure(ctx):
                return cached_extra_view(ctx, scene, extra_offset_for(self.config, scene), self.config.projection,
                                         renderer=self._renderer(ctx, scene))
            future = asyncio.ensure_future(self.gl.run(measure) if session_id is None
                                           else self.render(session_id, measure))
            self._coverage[id(scene)] = future

            def forget_failure(f):
                if (f.cancelled() or f.exception() is not None) and self._coverage.get(id(scene)) is f:
                    del self._coverage[id(scene)]
            future.add_done_callback(forget_failure)
        measured = await asyncio.shield(future)
        if not measured.get("cached"):
            log.info("extra view coverage of %s: %.2f %% -> %.2f %% uncovered in %.1f s", scene.name,
                     100 * measured["uncovered_primary"], 100 * measured["uncovered_with_extra"], measured["seconds"])
        return measured

    async def setup_session(self, session_id: int, hello: Hello):
        """-> (the session's pipeline, opened on the GL thread; its proxy bundle or None) for a client's Hello."""
        scene = await self.get_scene(hello.scene)
        bundle = await self.get_bundle(scene) if hello.want_proxies else None
        try:
            proxies = bundle.info(self.proxy_chunk_bytes) if bundle is not None else None
        except ValueError as exc:   # a bundle too big for the protocol's chunk limit
            raise ConfigError(f"proxies of scene {scene.name!r}: {exc}") from None
        coverage = await self.get_coverage(scene, session_id)
        pipeline = SessionPipeline(self.config, scene, hello, proxies, coverage,
                                   bundle.levels if bundle is not None else None)
        plan = pipeline.session.options["plan"]
        log.info("session %d plan: extra view %s, motion %s, view %dx%d, depth %s at %g kbit/s video", session_id,
                 "on" if plan["extra_view"]["value"] else "off", "on" if plan["motion"]["value"] else "off",
                 *plan["view_size"]["value"], plan["depth_codec"]["value"]["codec"],
                 plan["depth_codec"]["value"]["video_kbps"])

        await self.render(session_id, lambda ctx: pipeline.open(ctx, self._renderer(ctx, scene)))
        return pipeline, bundle

    @property
    def proxy_chunk_bytes(self) -> int:
        """Proxy chunks stay well inside the message size limit."""
        return max(1024, min(1 << 20, self.config.max_message_size // 2))

    def record_frame_timings(self, timings_ms, nbytes: int) -> None:
        self.recent_timings.append((*timings_ms, nbytes))
        if len(self.recent_timings) == self.recent_timings.maxlen:
            t = np.array(self.recent_timings)
            log.info("server: last %d frames: render %.1f ms, read back %.1f, pack %.1f, encode %.1f, %.0f kB/frame",
                     len(t), *np.median(t[:, :4], axis=0), np.mean(t[:, 4]) / 1e3)
            self.recent_timings.clear()


async def run_server(config: ServerConfig, ready=None) -> None:
    """Run until cancelled. ``ready(host, port)`` is called once listening."""
    server = Server(config)
    try:
        host, port = await server.start()
        if ready is not None:
            ready(host, port)
        await server.serve_forever()
    finally:
        await server.close()
