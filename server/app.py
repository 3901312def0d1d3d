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
from pibr.protocol.gl import GLThread
from pibr.protocol.messages import Error, Hello

from .config import ServerConfig
from .listener import TrackedListener
from .pipeline import FrameProducer
from .session import Session
from .session_plan import plan_session
from .video import H264Encoder

log = logging.getLogger(__name__)


class Server(TrackedListener):
    name = "pibr-server/0.1"

    def __init__(self, config: ServerConfig):
        super().__init__()
        self.config = config
        self.sessions: dict[int, Session] = {}
        self._ids = itertools.count(1)
        self._scenes: dict[str, object] = {}
        self._scene_lock = asyncio.Lock()
        self._renderers: dict = {}  # touched only on the GL thread
        self._bundles: dict = {}    # scene id -> ProxyBundle
        self._bundle_lock = asyncio.Lock()
        self.gl: GLThread | None = None
        self.encode_pool = concurrent.futures.ThreadPoolExecutor(max_workers=max(2, os.cpu_count() or 2),
                                                                 thread_name_prefix="pibr-encode")
        self.recent_timings = deque(maxlen=100)

    # ------------------------------------------------------------------ lifecycle

    async def start(self) -> tuple[str, int]:
        loop = asyncio.get_running_loop()
        self.gl = await loop.run_in_executor(None, GLThread, "pibr-server-gl")
        scene = await self.get_scene(self.config.scene)  # load and upload the default scene before accepting
        await self.gl.run(self._renderer, scene)
        tls = None
        if self.config.tls_cert is not None:
            from pibr.protocol.tls import certificate_fingerprint, server_context

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
        session_id = next(self._ids)
        if len(self.sessions) >= self.config.max_sessions:
            from pibr.protocol.connection import Connection

            conn = Connection()
            conn.send(Error(ConfigError.code, f"server full: {len(self.sessions)} sessions already"))
            writer.write(conn.data_to_send())
            try:
                await writer.drain()
            finally:
                writer.close()
            return
        session = Session(self, reader, writer, session_id)
        self.sessions[session_id] = session
        try:
            await session.run()
        finally:
            self.sessions.pop(session_id, None)

    # ------------------------------------------------------------------ sessions

    async def get_scene(self, spec: str):
        from pibr.scenes.registry import available_scenes, load_scene

        spec = spec or self.config.scene
        allowed = set(available_scenes()) | {self.config.scene}
        if spec not in allowed:
            raise SceneError(f"scene {spec!r} is not served here; available: {', '.join(sorted(allowed))}")
        async with self._scene_lock:
            if spec not in self._scenes:
                loop = asyncio.get_running_loop()
                self._scenes[spec] = await loop.run_in_executor(None, load_scene, spec)
            return self._scenes[spec]

    def _renderer(self, ctx, scene):
        from .renderer import Renderer

        key = (id(scene), self.config.projection)
        if key not in self._renderers:
            self._renderers[key] = Renderer(ctx, scene, self.config.projection,
                                            max_edge_angle_deg=self.config.max_edge_deg)
        return self._renderers[key]

    async def get_bundle(self, scene):
        """The scene's proxy bundle, built (or read from the LoD cache) once per server."""
        async with self._bundle_lock:
            if id(scene) not in self._bundles:
                from .proxies import build_bundle

                loop = asyncio.get_running_loop()
                self._bundles[id(scene)] = await loop.run_in_executor(None, build_bundle, scene,
                                                                      self.config.proxy_settings)
            return self._bundles[id(scene)]

    async def setup_session(self, hello: Hello):
        """Scene, session parameters, GL producer, encoders (and proxy bundle) for a client's Hello."""
        scene = await self.get_scene(hello.scene)
        bundle = await self.get_bundle(scene) if hello.want_proxies else None
        config, spec = plan_session(self.config, scene, hello,
                                    bundle.info(self.proxy_chunk_bytes) if bundle is not None else None)

        def make_producer(ctx):
            return FrameProducer(ctx, self._renderer(ctx, scene), spec)

        producer = await self.gl.run(make_producer)
        cfg = self.config
        encoder = H264Encoder(spec.layout.width, spec.layout.height, cfg.fps, cfg.bitrate_kbps, cfg.keyint, cfg.preset,
                              deterministic=hello.clock == "virtual")
        depth_encoder = None
        if config.depth_codec == "edge":
            from .depth_stream import EdgeDepthEncoder

            depth_encoder = EdgeDepthEncoder(config, cfg.fps, cfg.edge)
        return config, producer, encoder, depth_encoder, bundle

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
