"""One client's session: handshake, then frames on the virtual or the real clock.

The session drives the sans-I/O :class:`~pibr.protocol.sides.ServerSide` (its connection and
the session's message order: the Hello first, then poses and clocks, time never backwards) with
its own socket. Rendering runs on the server's GL thread and encoding in its worker pool, both
shared fairly between sessions (fair_queue.py); a slow or misbehaving client only ever stalls its
own session. Any protocol error closes this connection with an ``Error`` naming the problem.

Deadlines no peer can stretch: the whole Hello within ``hello_timeout_s`` of connecting (a
connection counts toward ``max_sessions`` only once its Hello is valid; until then the server
keeps at most ``max_pending`` of them and drops the oldest); after it, each pose or clock within
the clock's idle timeout, and every byte we send read within it too. On the virtual clock a
client's clock may run at most ``max_clock_lead_s`` ahead of the next frame it asks for.
"""
from __future__ import annotations

import asyncio
import dataclasses
import logging
import ssl
import time
from collections import deque

from pibr.protocol.connection import Envelope
from pibr.protocol.errors import ClientClosed, ConfigError, PeerTimeout, ProtocolError, SceneError
from pibr.protocol.messages import (ARRIVAL_AGE_MS, DELIVERED_KBPS, DISPLAY_AGE_MS, FRAMES_DECODED, LINK_KBPS,
                                    NEWEST_FRAME, PROBE_KBPS, REPORT_SPAN_MS, STREAM_REPORT_MS, Bye, Clock, Error,
                                    Hello, PoseMsg, Welcome, encode_stream_rate)
from pibr.protocol.sides import ServerSide
from pibr.protocol.stereo import CENTRE, eye_pose, frame_eyes

from .pipeline import EncodedFrame
from .producer import FULL
from .rate_control import RateControl, server_levels

log = logging.getLogger(__name__)

READ_CHUNK = 1 << 16


class Session:
    def __init__(self, server, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, session_id: int):
        self.server, self.reader, self.writer, self.id = server, reader, writer, session_id
        #: the session's message order (sans-I/O); ``conn``, its connection, carries our messages
        self.side = ServerSide(server.config.token, server.config.max_message_size)
        self.conn = self.side.conn
        self.peer = writer.get_extra_info("peername")
        self.pipeline = None            # the session's SessionPipeline (server/pipeline.py), after the Hello
        self.rate: RateControl | None = None   # its frames' levels on the wall clock (server/rate_control.py)
        self.config = None
        self.frames_sent = 0
        self.stereo: dict | None = None   # {"reference", "ipd_mm"} of a two-eye client (protocol/stereo.py)
        self.predictor = None           # the head-pose predictor (server/pose_prediction.py), if on
        self.server_ticks = 0           # ticks that made frames (a stereo session's eyes follow it)
        self.frames_skipped = 0
        self.frames_held = 0            # real clock: ticks not rendered while the client caught up
        self.tick_overruns = 0          # real clock: frames that overran their interval (the next began at once)
        self.adaptation = None          # the stream's adaptation to the link (server/stream_adaptation.py), if on
        self._adapt_ticks = 0
        self.frames_thinned = 0         # ticks without a frame: the adaptation lowered the frame rate
        self.frames_shrunk = 0          # ticks whose primary view the adaptation rendered smaller
        self.idle_timeout_s: float | None = None   # set by the Hello's clock
        self._accepted = asyncio.get_running_loop().time()
        self._hello_deadline: asyncio.Timeout | None = None
        self._evicted_among = 0                     # > 0: dropped as the oldest of this many pending
        self._unsent_since: float | None = None     # real clock: since when a frame waits to leave
        self._unsent_bytes = 0
        #: when the Welcome (and the proxies) had been sent, and when the first pose came (loop time)
        self.welcomed_at: float | None = None
        self.first_pose_at: float | None = None
        self._task: asyncio.Task | None = None
        self._yielded: str | None = None            # why this session gave its slot to a waiting client

    # ------------------------------------------------------------------ I/O

    async def _flush(self) -> None:
        data = self.conn.data_to_send()
        if data:
            self.writer.write(data)
            try:
                async with asyncio.timeout(self.idle_timeout_s):
                    await self.writer.drain()
            except TimeoutError:
                raise PeerTimeout(f"the client read nothing for {self.idle_timeout_s:g} s") from None

    async def _recv(self) -> Envelope:
        """Next pose or clock from the client; raises ClientClosed at its end, ProtocolError on bad
        input or a message out of order, and PeerTimeout when none arrives within the idle timeout
        (``Stats`` do not count: they are taken in passing)."""
        try:
            async with asyncio.timeout(self.idle_timeout_s):
                env = await self._next_message()
                if self.first_pose_at is None and isinstance(env.message, PoseMsg):
                    self.first_pose_at = asyncio.get_running_loop().time()
                return env
        except TimeoutError as exc:
            if isinstance(exc, PeerTimeout):
                raise
            raise PeerTimeout(f"no message from the client for {self.idle_timeout_s:g} s (idle timeout)") from None

    async def _next_message(self) -> Envelope:
        """The next message the side lets the session take, reading as long as it needs bytes."""
        while (env := self.side.next_event()) is None:
            data = await self.reader.read(READ_CHUNK)
            if data:
                self.side.receive_data(data)
            else:
                self.side.receive_eof()
        return env

    # ------------------------------------------------------------------ lifecycle

    async def run(self) -> None:
        log.info("session %d: connection from %s", self.id, self.peer)
        self._task = asyncio.current_task()
        try:
            hello = await self._receive_hello()
            self.server.check_scene(hello.scene)   # a Hello the server cannot serve takes no slot
            await self.server.admit(self)
            await self._set_up(hello)
            if hello.clock == "virtual":
                await self._run_virtual()
            else:
                await self._run_real()
        except ClientClosed as exc:
            log.info("session %d: %s", self.id, exc)
        except ProtocolError as exc:
            log.warning("session %d: protocol error from %s: %s", self.id, self.peer, exc)
            self.conn.fail(exc)
        except (SceneError, ConfigError) as exc:
            log.warning("session %d: %s", self.id, exc)
            self.conn.send(Error(exc.code, str(exc)))
        except (ConnectionError, ssl.SSLError, asyncio.IncompleteReadError) as exc:
            log.info("session %d: connection lost: %s", self.id, exc)
        except asyncio.CancelledError:
            if self._yielded is not None:   # its slot went to a client waiting for one
                log.warning("session %d: %s", self.id, self._yielded)
                self.conn.send(Error(ConfigError.code, self._yielded))
            else:   # the server is shutting down: say so, close, and end this handler normally
                self.conn.send(Bye("server shutting down"))
        except Exception as exc:  # a bug must not take the server down: report it, end this session only
            log.exception("session %d: internal error", self.id)
            self.conn.send(Error(1, f"internal server error: {type(exc).__name__}: {exc}"))
        finally:
            self.server.release(self)   # the slot is free as soon as the peer learns why it ends
            await self._close()

    def silent_since(self) -> float | None:
        """Loop time since when this session holds a slot without having sent a pose after its
        Welcome (None: it has sent one, or is still being set up)."""
        return self.welcomed_at if self.first_pose_at is None else None

    def yield_slot(self, reason: str) -> None:
        """End this session (silent since its Welcome) so that a waiting client gets its slot."""
        self._yielded = reason
        if self._task is not None:
            self._task.cancel()

    def evict(self, waiting: int) -> None:
        """Drop this connection, the oldest of ``waiting`` still to send a Hello."""
        self._evicted_among = waiting
        if self._hello_deadline is not None:
            self._hello_deadline.reschedule(asyncio.get_running_loop().time())

    async def _close(self) -> None:
        # The session's summary first: its counts are final, and a server shutting down cancels
        # this coroutine at its first wait (the flush, the socket's close, the GL release).
        log.info("session %d: closed after %d frames (%d skipped for a slow connection, %d held while the client "
                 "decoded, %d tick overruns)", self.id, self.frames_sent, self.frames_skipped, self.frames_held,
                 self.tick_overruns)
        if self.adaptation is not None:
            a = self.adaptation.summary()
            log.info("session %d: stream adaptation: %d reports (%s), colour at %.0f of %.0f kbit/s, a frame every "
                     "%d ticks and the primary view at 1/%d of its side at the end, %d ticks without a frame, %d with a "
                     "smaller primary view", self.id, a["reports"],
                     ", ".join(f"{k} {v}" for k, v in a["reasons"].items() if v), a["video_kbps"], a["max_kbps"],
                     a["every"], a["view"], self.frames_thinned, self.frames_shrunk)
        if self.rate is not None:
            made = self.rate.summary()["frames_at_level"]
            log.info("session %d: frames by rate-control level: %s", self.id,
                     "; ".join(f"{name}: {n}" for name, n in made.items() if n) or "none")
        try:
            await asyncio.wait_for(self._flush(), 2.0)
        except (ConnectionError, ssl.SSLError, asyncio.TimeoutError, RuntimeError):
            pass  # the peer is gone; nothing more to tell it
        self.writer.close()
        try:
            await asyncio.wait_for(self.writer.wait_closed(), 2.0)
        except (ConnectionError, ssl.SSLError, asyncio.TimeoutError):
            pass  # TLS: the client may still have been sending when we closed
        if self.pipeline is not None:
            pipeline, self.pipeline = self.pipeline, None
            await self.server.gl.run(lambda ctx: pipeline.release())

    async def _receive_hello(self) -> Hello:
        """The client's Hello, whole within ``hello_timeout_s`` of connecting, however it trickles in
        (the side refuses any other first message, a bad token and another protocol version)."""
        limit = self.server.config.hello_timeout_s
        try:
            async with asyncio.timeout_at(self._accepted + limit) as self._hello_deadline:
                self.server.add_pending(self)
                env = await self._next_message()
        except TimeoutError:
            if self._evicted_among:
                raise PeerTimeout(f"server busy: {self._evicted_among} connections are waiting to send a Hello; "
                                  f"this one, the oldest, is dropped") from None
            raise PeerTimeout(f"no complete Hello within {limit:g} s of connecting") from None
        finally:
            self._hello_deadline = None
        return env.message

    async def _set_up(self, hello: Hello) -> None:
        """Prepare the session, send the Welcome (and the proxies when asked for)."""
        t_hello = time.monotonic()
        cfg = self.server.config
        self.idle_timeout_s = cfg.idle_timeout_virtual_s if hello.clock == "virtual" else cfg.idle_timeout_s
        self.pipeline, bundle = await self.server.setup_session(self.id, hello)
        self.config = self.pipeline.session
        self.stereo = self.config.options.get("stereo")
        if self.config.options.get("predict"):
            from .pose_prediction import make_predictor

            self.predictor = make_predictor(self.config.options["predict"])
        if self.config.options.get("adapt"):
            from .scene_plan import MIN_VIDEO_KBPS
            from .stream_adaptation import StreamAdaptation

            self.adaptation = StreamAdaptation(self.config.video_bitrate_kbps, MIN_VIDEO_KBPS)
            # it starts below the session's bitrate: the first frame is made at its start
            self.pipeline.adapt_stream(self.adaptation.choice.video_kbps, self.adaptation.share, at_once=True)
        if "server_levels" in self.config.options:   # the plan turned the rate control on (session_plan.py)
            self.rate = RateControl(server_levels(self.config.extra is not None), cfg.fps)
        setup_us = int((time.monotonic() - t_hello) * 1e6)
        self.conn.send(Welcome(server=self.server.name, session=self.id, config=self.config.to_json(),
                               setup_us=setup_us))
        await self._flush()
        if bundle is not None:  # sent ahead of the first frame, outside the simulated timeline
            for chunk in bundle.chunks(self.server.proxy_chunk_bytes):
                self.conn.send(chunk)
                await self._flush()
        self.welcomed_at = asyncio.get_running_loop().time()
        log.info("session %d: scene %s, %s clock, %dx%d output at %g Hz", self.id, self.config.scene["name"],
                 hello.clock, hello.output.width, hello.output.height, hello.output.rate_hz)

    # ------------------------------------------------------------------ frames

    async def _send_tick(self, pose_msg: PoseMsg, t_us: int, vtime_us: int, force_keyframe: bool = False,
                         level: tuple | None = None) -> bool:
        """The frames of one server tick: one from the head's pose, or a stereo session's eyes for
        this tick (protocol/stereo.py: one alternating eye, or both, each a frame of its own).
        -> whether they were made as ``level`` says (not when the stream adaptation made none, or
        made the primary view smaller still: their cost is not the level's)."""
        reference = self.stereo["reference"] if self.stereo else None
        stream_rate, view = None, 1
        if self.adaptation is not None:
            choice = self._adapt(t_us)
            self._adapt_ticks += 1
            if (self._adapt_ticks - 1) % choice.every:
                self.frames_thinned += 1
                return False   # the adaptation makes one frame every `every` ticks
            view = choice.view
            stream_rate = encode_stream_rate(choice.video_kbps, choice.every, choice.reason, view)
            if view > 1:
                self.frames_shrunk += 1
        pose_msg = self._predicted(pose_msg)
        for i, eye in enumerate(frame_eyes(reference, self.server_ticks)):
            await self._send_frame(pose_msg, t_us, vtime_us, force_keyframe and i == 0, level, eye, stream_rate, view)
        self.server_ticks += 1
        return level is None or level[1].scale <= 1.0 / view

    def _adapt(self, t_us: int):
        """The stream adaptation's choice for a tick at ``t_us`` (server/stream_adaptation.py): the
        client's reports up to then taken in order (on the virtual clock, those stamped by then:
        reproducible), the pipeline told when the colour's target moves."""
        adaptation, stats = self.adaptation, self.side.stats_log
        virtual = self.side.hello.clock == "virtual"
        before, probed = adaptation.choice, False
        # (the handshake's probe is taken whenever it comes: it was measured before the stream)
        while stats and (not virtual or stats[0][0] <= t_us or PROBE_KBPS in stats[0][1]):
            vtime_us, values = stats.popleft()
            if PROBE_KBPS in values:
                if self.server.config.adapt_start == "probe":
                    c, probed = adaptation.probe(float(values[PROBE_KBPS])), True
                    log.info("session %d: the link measured %.0f kbit/s on the proxies: the stream starts at colour "
                             "%.0f kbit/s, a frame every %d ticks, view 1/%d", self.id, values[PROBE_KBPS],
                             c.video_kbps, c.every, c.view)
                else:
                    log.info("session %d: the link measured %.0f kbit/s on the proxies; the stream starts at its "
                             "ladder's foot (--adapt-start foot)", self.id, values[PROBE_KBPS])
                continue
            age, delivered = values.get(ARRIVAL_AGE_MS), values.get(DELIVERED_KBPS)
            if age is None or delivered is None:
                continue
            t = vtime_us / 1e6 if virtual else t_us / 1e6
            span, link, newest = values.get(REPORT_SPAN_MS, STREAM_REPORT_MS), values.get(LINK_KBPS), values.get(NEWEST_FRAME)
            c = adaptation.report(t, float(age), max(0.0, float(delivered)), float(span),
                                  None if link is None else float(link), None if newest is None else int(newest))
            log.debug("session %d: stream report at %.3f s: age %.0f ms, %.0f kbit/s arrived -> colour %.0f kbit/s, "
                      "a frame every %d ticks (%s)", self.id, t, age, delivered, c.video_kbps, c.every, c.reason_name)
        choice = adaptation.choice
        if choice.video_kbps != before.video_kbps:
            self.pipeline.adapt_stream(choice.video_kbps, adaptation.share, at_once=adaptation.starting or probed)
        return choice

    def _take_pose(self, msg: PoseMsg) -> None:
        """A pose the session will render from: the predictor sees every one, in order."""
        if self.predictor is not None:
            self.predictor.update(msg.t_us / 1e6, msg.pose)

    def _predicted(self, pose_msg: PoseMsg) -> PoseMsg:
        """``pose_msg`` with the head pose predicted as far ahead as the client reports its frames
        are seen (DISPLAY_AGE_MS); unchanged without a predictor or before the first report. Its
        time stays the pose's, so the client's ages stay measured from what it sent."""
        age_ms = self.side.client_stats.get(DISPLAY_AGE_MS)
        if self.predictor is None or not isinstance(age_ms, (int, float)) or not self.predictor.poses:
            return pose_msg
        ahead = max(0.0, age_ms / 1e3 - (self.predictor.times[-1] - pose_msg.t_us / 1e6))
        return PoseMsg(pose_msg.seq, pose_msg.t_us, self.predictor.predict(ahead))

    async def _send_frame(self, pose_msg: PoseMsg, t_us: int, vtime_us: int, force_keyframe: bool = False,
                          level: tuple | None = None, eye: str = CENTRE, stream_rate: bytes | None = None,
                          view: int = 1) -> None:
        """The pipeline's stages (server/pipeline.py) where they belong: rendering on the shared GL
        thread, the encoders in the pool, the H.264 encode and the quadtrees side by side.
        ``level``: (index, FrameLevel) of the rate control (server/rate_control.py), or None;
        ``eye``: rendered for that eye of the head at the pose (a stereo session), or its centre;
        ``view``: the stream adaptation's primary view at 1/``view`` of its side at most."""
        pipeline = self.pipeline
        made, frame_id = FULL if level is None else level[1], self.frames_sent
        if made.scale > 1.0 / view:
            made = dataclasses.replace(made, scale=1.0 / view)
        pose = pose_msg.pose if eye == CENTRE else eye_pose(pose_msg.pose, eye, self.stereo["ipd_mm"])
        produced = await self.server.render(self.id, lambda ctx: pipeline.produce(pose, t_us * 1e-6, made, frame_id))
        t0 = time.perf_counter()
        jobs = [self.server.encode(self.id, pipeline.encode_video, produced, force_keyframe)]
        if pipeline.quadtree_threshold > 0:
            jobs.append(self.server.encode(self.id, pipeline.encode_quadtree, produced))
        (video, key), *quadtree = await asyncio.gather(*jobs)
        depth, motion = [], None
        if pipeline.depth.sends_payloads:
            depth = await self.server.encode(self.id, pipeline.encode_depth, produced)
        if produced.motion is not None:   # a scene that moves: its flow, whatever the depth codec
            motion = await self.server.encode(self.id, pipeline.encode_motion, produced)
        encoded = EncodedFrame(video, key, depth, quadtree[0] if quadtree else None, produced.object_poses, motion,
                               None if level is None else level[0], None if eye == CENTRE else eye, stream_rate)
        encode_ms = (time.perf_counter() - t0) * 1e3   # H.264 and, with the edge codec, depth (and quadtrees)
        frame = pipeline.frame(frame_id, t_us, pose_msg.t_us, pose_msg.seq, produced, encoded,
                               (produced.render_ms, produced.readback_ms, produced.pack_ms, encode_ms))
        self.conn.send(frame, vtime_us=vtime_us)
        if self.adaptation is not None:
            self.adaptation.sent(frame_id, t_us / 1e6, 8 * encoded.nbytes)
        self.frames_sent += 1
        self.server.record_frame_timings(frame.timings_ms, encoded.nbytes)

    async def _run_virtual(self) -> None:
        """Deterministic schedule (see protocol/session.py): frame k at k * interval.

        Before waiting for the client the session promises (``Clock``) the earliest virtual
        time its next message can have, so the client can advance meanwhile; with the
        client doing the same, neither ever waits on the other forever.
        """
        interval = self.config.frame_interval_us
        delay = self.config.server_delay_us
        # A client's clock runs ahead of the next frame by its own tick and the link's delays; past
        # this it only makes the session render frames nobody waits for, as fast as it can.
        max_lead_us = int(round(self.server.config.max_clock_lead_s * 1e6)) + interval + delay
        side = self.side        # side.horizon_us: every later client message has a virtual time >= this
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
            side.next_frame(None if k is None else k * interval, max_lead_us)
            env = await self._recv()    # a pose or a clock, its time checked by the side
            if isinstance(env.message, PoseMsg):
                poses.append((env.vtime_us, env.message))

        while True:
            if k is None:
                if poses:   # first tick at or after the first pose arrives
                    k = -(-poses[0][0] // interval)
                    continue
                if side.horizon_us is not None:  # no frame before a pose arrives, and none arrives before horizon
                    await promise(-(-side.horizon_us // interval) * interval + delay)
                await receive()
                continue
            t_k = k * interval
            while side.horizon_us <= t_k:
                await promise(t_k + delay)
                await receive()
            while poses and poses[0][0] <= t_k:
                current = poses.popleft()[1]
                self._take_pose(current)
            await self._send_tick(current, t_k, t_k + delay)
            promised = t_k + delay
            await self._flush()
            k += 1

    def _client_behind(self) -> bool:
        """Real clock: ``max_in_flight`` frames sent are not decoded yet by a client that reports
        what it decoded (``FRAMES_DECODED``). A new frame now would only queue behind them and
        be stale when shown; the next tick renders the newest pose instead."""
        decoded = self.side.client_stats.get(FRAMES_DECODED)
        return decoded is not None and self.frames_sent - decoded >= self.server.config.max_in_flight

    def _previous_frame_unsent(self, now: float) -> bool:
        """Real clock: part of the last frame still waits in our buffer for a slow connection. A
        new frame now would queue behind it and be stale when it arrives; the next tick renders
        the newest pose instead, so a slow reader gets the newest frame, not a backlog. Raises
        PeerTimeout when the client has read nothing for the idle timeout."""
        unsent = self.writer.transport.get_write_buffer_size()
        if not unsent:
            self._unsent_since = None
            return False
        if self._unsent_since is None or unsent < self._unsent_bytes:   # still draining
            self._unsent_since, self._unsent_bytes = now, unsent
        elif now - self._unsent_since > self.idle_timeout_s:
            raise PeerTimeout(f"the client read nothing for {self.idle_timeout_s:g} s")
        return True

    async def _run_real(self) -> None:
        """Wall clock: render at the server's own rate with the newest pose received."""
        interval = 1.0 / self.config.server_fps
        newest: list = [None]
        receiver = asyncio.create_task(self._receive_poses(newest), name=f"session-{self.id}-receiver")
        loop = asyncio.get_running_loop()
        start = loop.time()
        due = start   # when the next frame is due
        need_keyframe = False
        try:
            while True:
                wait = due - loop.time()
                if wait > 0:
                    done, _ = await asyncio.wait({receiver}, timeout=wait)
                if receiver.done():
                    receiver.result()  # re-raises the receiver's error, or ClientClosed
                    return
                if newest[0] is not None:
                    if self._previous_frame_unsent(loop.time()):
                        self.frames_skipped += 1
                    elif self._client_behind():
                        self.frames_held += 1
                    else:
                        if self.rate is not None and not self.rate.calibration_ms:
                            await self._calibrate(newest[0].pose)
                            due = loop.time()   # the frames' rate counts from here
                        level = None
                        if self.rate is not None:
                            index, _, made = self.rate.choose()
                            level = (index, made)
                        t0 = loop.time()
                        t_us = int(round((t0 - start) * 1e6))
                        as_chosen = await self._send_tick(newest[0], t_us, t_us, need_keyframe, level)
                        if self.rate is not None and as_chosen:
                            self.rate.observe(level[0], (loop.time() - t0) * 1e3, level[1].extra)
                        need_keyframe = False
                        self.writer.write(self.conn.data_to_send())  # no drain: never wait on one client
                due += interval
                now = loop.time()
                if now > due:
                    # This frame overran its interval: the next starts at once, not at the next
                    # slot of a fixed grid (which would skip a whole interval for a frame a few ms
                    # late and halve the rate of a server whose frames cost about an interval).
                    # Up to one interval behind, the grid is kept, so frames that cost less make
                    # up for one that cost more (the extra view rendered every few frames): the
                    # rate holds whenever the mean cost fits, which is what the rate control
                    # predicts (rate_control.py). Further behind, the grid starts again from now.
                    self.tick_overruns += 1
                    if now > due + interval:
                        due = now
        finally:
            receiver.cancel()
            try:
                await receiver
            except (asyncio.CancelledError, ClientClosed, ProtocolError, ConnectionError):
                pass  # its outcome, if it mattered, was raised above

    async def _receive_poses(self, newest: list) -> None:
        while True:
            env = await self._recv()    # a pose or a clock (the side refuses anything else)
            if isinstance(env.message, PoseMsg):
                newest[0] = env.message
                self._take_pose(env.message)

    async def _calibrate(self, pose) -> None:
        """The rate control's first cost estimates: every level made on the GL thread, in this
        session's fair turn, before its first frame (server/rate_control.py)."""
        pipeline, rate = self.pipeline, self.rate
        costs = await self.server.render(self.id, lambda ctx: rate.calibrate(pipeline, pose, 0.0))
        log.info("session %d: rate control calibrated: %s", self.id,
                 ", ".join(f"{name} {ms:.0f} ms" for name, ms in zip(rate.names, costs)))

    def stats(self) -> dict:
        return {"frames_sent": self.frames_sent, "frames_skipped": self.frames_skipped,
                "frames_held": self.frames_held, "tick_overruns": self.tick_overruns,
                "frames_thinned": self.frames_thinned}

