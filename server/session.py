"""One client's session: handshake, then frames on the virtual or the real clock.

The session drives the sans-I/O :class:`~pibr.protocol.connection.Connection` with its own
socket. Rendering runs on the server's GL thread and encoding in its worker pool; a slow
or misbehaving client only ever stalls its own session. Any protocol error closes this
connection with an ``Error`` naming the problem.
"""
from __future__ import annotations

import asyncio
import logging
import math
import time
from collections import deque

from pibr.protocol.connection import Connection, Envelope
from pibr.protocol.errors import (ConfigError, ProtocolError, SceneError, UnexpectedMessage,
                                  UnsupportedVersion)
from pibr.protocol.messages import (FRAMES_DECODED, PROTOCOL_VERSION, Bye, Clock, Error, Frame, Hello, PayloadKind,
                                    PoseMsg, Stats, Welcome)

from .motion_flow import motion_flow_payload
from .quadtree import quadtree_payload

log = logging.getLogger(__name__)

READ_CHUNK = 1 << 16
#: Real clock: skip rendering while this many bytes still wait for a slow client.
SLOW_CLIENT_BACKLOG = 2 * 1024 * 1024


class SessionClosed(Exception):
    """The peer ended the session (Bye, Error or end of stream)."""


class Session:
    def __init__(self, server, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, session_id: int):
        self.server, self.reader, self.writer, self.id = server, reader, writer, session_id
        self.conn = Connection(server.config.max_message_size)
        self.peer = writer.get_extra_info("peername")
        self.producer = None
        self.encoder = None
        self.depth_encoder = None
        self.config = None
        self.quadtree_threshold = 0.0   # > 0: every frame carries the views' quadtrees
        self.frames_sent = 0
        self.frames_skipped = 0
        self.frames_held = 0            # real clock: ticks not rendered while the client caught up
        self.tick_overruns = 0
        self.client_stats: dict = {}
        self._pending: deque = deque()

    # ------------------------------------------------------------------ I/O

    async def _flush(self) -> None:
        data = self.conn.data_to_send()
        if data:
            self.writer.write(data)
            await self.writer.drain()

    async def _recv(self, timeout: float | None = None) -> Envelope:
        """Next message from the client; raises SessionClosed at its end, ProtocolError on bad input."""
        while True:
            self._pending.extend(self.conn.events_received())
            if self._pending:
                env = self._pending.popleft()
                msg = env.message
                if isinstance(msg, Error):
                    raise SessionClosed(f"client reported error {msg.code}: {msg.text}")
                if isinstance(msg, Bye):
                    raise SessionClosed(f"client said bye ({msg.reason or 'no reason'})")
                if isinstance(msg, Stats):
                    self.client_stats.update(msg.values)
                    continue
                return env
            if self.conn.failed:
                raise self.conn.error
            read = self.reader.read(READ_CHUNK)
            data = await (asyncio.wait_for(read, timeout) if timeout else read)
            if not data:
                self.conn.receive_eof()
                if self.conn.error is not None:
                    raise self.conn.error
                raise SessionClosed("client closed the connection")
            self.conn.receive_data(data)

    # ------------------------------------------------------------------ lifecycle

    async def run(self) -> None:
        log.info("session %d: connection from %s", self.id, self.peer)
        try:
            hello = await self._handshake()
            if hello.clock == "virtual":
                await self._run_virtual()
            else:
                await self._run_real()
        except SessionClosed as exc:
            log.info("session %d: %s", self.id, exc)
        except ProtocolError as exc:
            log.warning("session %d: protocol error from %s: %s", self.id, self.peer, exc)
            self.conn.fail(exc)
        except (SceneError, ConfigError) as exc:
            log.warning("session %d: %s", self.id, exc)
            self.conn.send(Error(exc.code, str(exc)))
        except asyncio.TimeoutError:
            self.conn.send(Error(UnexpectedMessage.code, "no Hello within the handshake timeout"))
        except (ConnectionError, asyncio.IncompleteReadError) as exc:
            log.info("session %d: connection lost: %s", self.id, exc)
        except asyncio.CancelledError:
            # The server is shutting down: say so, close, and end this handler normally.
            self.conn.send(Bye("server shutting down"))
        except Exception as exc:  # a bug must not take the server down: report it, end this session only
            log.exception("session %d: internal error", self.id)
            self.conn.send(Error(1, f"internal server error: {type(exc).__name__}: {exc}"))
        finally:
            await self._close()

    async def _close(self) -> None:
        try:
            await asyncio.wait_for(self._flush(), 2.0)
        except (ConnectionError, asyncio.TimeoutError, RuntimeError):
            pass  # the peer is gone; nothing more to tell it
        self.writer.close()
        try:
            await asyncio.wait_for(self.writer.wait_closed(), 2.0)
        except (ConnectionError, asyncio.TimeoutError):
            pass
        if self.producer is not None:
            producer, self.producer = self.producer, None
            await self.server.gl.run(lambda ctx: producer.release())
        if self.encoder is not None:
            self.encoder.close()
        log.info("session %d: closed after %d frames (%d skipped for a slow connection, %d held while the client "
                 "decoded, %d tick overruns)", self.id, self.frames_sent, self.frames_skipped, self.frames_held,
                 self.tick_overruns)

    async def _handshake(self) -> Hello:
        env = await self._recv(timeout=self.server.config.hello_timeout_s)
        t_hello = time.monotonic()
        hello = env.message
        if not isinstance(hello, Hello):
            raise UnexpectedMessage(f"expected Hello as the first message, got {hello.NAME}")
        if hello.protocol != PROTOCOL_VERSION:
            raise UnsupportedVersion(f"client speaks protocol {hello.protocol}, this server speaks {PROTOCOL_VERSION}")
        setup = await self.server.setup_session(hello)
        self.config, self.producer, self.encoder, self.depth_encoder, bundle = setup
        self.quadtree_threshold = hello.quadtree_threshold
        setup_us = int((time.monotonic() - t_hello) * 1e6)
        self.conn.send(Welcome(server=self.server.name, session=self.id, config=self.config.to_json(),
                               setup_us=setup_us))
        await self._flush()
        if bundle is not None:  # sent ahead of the first frame, outside the simulated timeline
            for chunk in bundle.chunks(self.server.proxy_chunk_bytes):
                self.conn.send(chunk)
                await self._flush()
        log.info("session %d: scene %s, %s clock, %dx%d output at %g Hz", self.id, self.config.scene["name"],
                 hello.clock, hello.output.width, hello.output.height, hello.output.rate_hz)
        return hello

    # ------------------------------------------------------------------ frames

    async def _send_frame(self, pose_msg: PoseMsg, t_us: int, vtime_us: int, force_keyframe: bool = False) -> None:
        produced = await self.server.gl.run(lambda ctx: self.producer.produce(pose_msg.pose, t_us * 1e-6))
        loop = asyncio.get_running_loop()
        t0 = time.perf_counter()
        jobs = [loop.run_in_executor(self.server.encode_pool, self.encoder.encode, produced.yuv, force_keyframe)]
        if self.quadtree_threshold > 0:   # the views' quadtrees, built beside the H.264 encode
            jobs.append(loop.run_in_executor(self.server.encode_pool, quadtree_payload, produced.distances,
                                             self.quadtree_threshold))
        (data, key), *quadtree = await asyncio.gather(*jobs)
        payloads = [(PayloadKind.H264_ATLAS, data)]
        if self.depth_encoder is not None:
            payloads += await loop.run_in_executor(self.server.encode_pool, self.depth_encoder.encode, produced)
        payloads += [(PayloadKind.QUADTREE, q) for q in quadtree]
        if produced.object_poses is not None:
            payloads.append((PayloadKind.OBJECT_POSES, produced.object_poses))
        if produced.motion is not None:   # a scene that moves: its flow, whatever the depth codec
            payloads.append((PayloadKind.MOTION_FLOW, await loop.run_in_executor(
                self.server.encode_pool, motion_flow_payload, produced, self.server.config.flow_coder)))
        encode_ms = (time.perf_counter() - t0) * 1e3   # H.264 and, with the edge codec, depth (and quadtrees)
        frame = Frame(frame_id=self.frames_sent, render_t_us=t_us, pose_t_us=pose_msg.t_us, pose_seq=pose_msg.seq,
                      scene_t_us=t_us, primary_pose=produced.primary_pose, extra_pose=produced.extra_pose,
                      near=self.config.near, far=self.config.far,
                      timings_ms=(produced.render_ms, produced.readback_ms, produced.pack_ms, encode_ms),
                      payloads=tuple(payloads), keyframe=key)
        self.conn.send(frame, vtime_us=vtime_us)
        self.frames_sent += 1
        self.server.record_frame_timings(frame.timings_ms, sum(len(d) for _, d in payloads))

    async def _run_virtual(self) -> None:
        """Deterministic schedule (see protocol/session.py): frame k at k * interval.

        Before waiting for the client the session promises (``Clock``) the earliest virtual
        time its next message can have, so the client can advance meanwhile; with the
        client doing the same, neither ever waits on the other forever.
        """
        interval = self.config.frame_interval_us
        delay = self.config.server_delay_us
        horizon = None          # every later client message has a virtual time >= this
        poses = deque()         # (arrival vtime, PoseMsg) not yet in effect
        current = None
        promised = None
        k = None

        async def promise(vtime_us: int) -> None:
            nonlocal promised
            if promised is None or vtime_us > promised:
                self.conn.send(Clock(), vtime_us=vtime_us)
                await self._flush()
                promised = vtime_us

        async def receive() -> None:
            nonlocal horizon
            env = await self._recv()
            if horizon is not None and env.vtime_us < horizon:
                raise UnexpectedMessage(f"virtual time went backwards ({env.vtime_us} us after {horizon} us)")
            horizon = env.vtime_us
            if isinstance(env.message, PoseMsg):
                poses.append((env.vtime_us, env.message))
            elif not isinstance(env.message, Clock):
                raise UnexpectedMessage(f"unexpected {env.message.NAME} from the client")

        while True:
            if k is None:
                if poses:   # first tick at or after the first pose arrives
                    k = -(-poses[0][0] // interval)
                    continue
                if horizon is not None:  # no frame before a pose arrives, and none arrives before horizon
                    await promise(-(-horizon // interval) * interval + delay)
                await receive()
                continue
            t_k = k * interval
            while horizon <= t_k:
                await promise(t_k + delay)
                await receive()
            while poses and poses[0][0] <= t_k:
                current = poses.popleft()[1]
            await self._send_frame(current, t_k, t_k + delay)
            promised = t_k + delay
            await self._flush()
            k += 1

    def _client_behind(self) -> bool:
        """Real clock: ``max_in_flight`` frames sent are not decoded yet by a client that reports
        what it decoded (``FRAMES_DECODED``). A new frame now would only queue behind them and
        be stale when shown; the next tick renders the newest pose instead."""
        decoded = self.client_stats.get(FRAMES_DECODED)
        return decoded is not None and self.frames_sent - decoded >= self.server.config.max_in_flight

    async def _run_real(self) -> None:
        """Wall clock: render at the server's own rate with the newest pose received."""
        interval = 1.0 / self.config.server_fps
        newest: list = [None]
        receiver = asyncio.create_task(self._receive_poses(newest), name=f"session-{self.id}-receiver")
        loop = asyncio.get_running_loop()
        start = loop.time()
        k = 0
        need_keyframe = False
        try:
            while True:
                wait = start + k * interval - loop.time()
                if wait > 0:
                    done, _ = await asyncio.wait({receiver}, timeout=wait)
                if receiver.done():
                    receiver.result()  # re-raises the receiver's error, or SessionClosed
                    return
                if newest[0] is not None:
                    if self.writer.transport.get_write_buffer_size() > SLOW_CLIENT_BACKLOG:
                        self.frames_skipped += 1
                    elif self._client_behind():
                        self.frames_held += 1
                    else:
                        t_us = int(round((loop.time() - start) * 1e6))
                        await self._send_frame(newest[0], t_us, t_us, need_keyframe)
                        need_keyframe = False
                        self.writer.write(self.conn.data_to_send())  # no drain: never wait on one client
                next_k = max(k + 1, math.floor((loop.time() - start) / interval) + 1)
                self.tick_overruns += next_k - k - 1
                k = next_k
        finally:
            receiver.cancel()
            try:
                await receiver
            except (asyncio.CancelledError, SessionClosed, ProtocolError, ConnectionError):
                pass  # its outcome, if it mattered, was raised above

    async def _receive_poses(self, newest: list) -> None:
        while True:
            env = await self._recv()
            if isinstance(env.message, PoseMsg):
                newest[0] = env.message
            elif not isinstance(env.message, Clock):
                raise UnexpectedMessage(f"unexpected {env.message.NAME} from the client")

    def stats(self) -> dict:
        return {"frames_sent": self.frames_sent, "frames_skipped": self.frames_skipped,
                "frames_held": self.frames_held, "tick_overruns": self.tick_overruns}

