"""``pibr relay``: a latency-injecting relay any client and server can sit behind.

For each client connection the relay reads the client's ``Hello`` (within
``hello_timeout_s``), then opens one upstream connection and pumps frames both ways through
a :class:`~pibr.common.link.LinkModel` per direction. The Hello tells it the session's
clock:

* **virtual**: frames are forwarded at once, their header ``vtime_us`` rewritten to the
  modelled arrival time (deterministic: jitter comes from a seeded generator); the
  handshake (``Hello``, ``Welcome``, the proxies' ``ProxyChunk``) precedes the simulated
  timeline: the Hello passes unchanged, the server's answers are stamped with their arrival
  through a downlink of their own (the same link, its trace from the start, all sent at 0), so
  that the client can measure the link on the proxies before the stream starts;
* **real**: frames are held until their modelled arrival on the wall clock, unchanged.

**Bandwidth.** Each direction has a fixed cap (``--kbps``) or replays a bandwidth trace
(``--up-trace``, ``--down-trace``: Mahimahi delivery opportunities, a ``t,kbps`` CSV or a
built-in, common/bandwidth.py), looping, from the session's start: virtual time 0, or on the
wall clock the client's tick 0 (read from its first tick's pose: the time it carries is the
time since tick 0). The handshake, the proxies and the warm-up before it pass through the trace
from the Hello on; the trace then starts again at tick 0, as the virtual clock's does, so that a
link's events fall where its file puts them in the session (the server and the client calibrate
for several seconds between the Hello and tick 0: from the Hello, the built-in outage at 10 s
fell in the first second of the session's ticks).

**Jitter seeds.** A session's link models are seeded from ``--seed`` and the client's Hello
(all of it but the token), never from how many connections came before: the same client
run through a relay with the same seed sees the same jitter, first run or tenth, alone or
beside others (identical Hellos share a jitter sequence).

**Memory.** Each direction of a pair holds at most ``buffer_bytes`` of frames read and not
yet handed to the kernel; when full, the relay stops reading that direction's sender, so a
client that does not read stalls its own server stream (TCP back-pressure) and nothing else.
Besides that budget a direction holds only what its last read brought and is not queued yet
(at most one message and 64 KiB, the frame being re-stamped twice) and asyncio's read buffer.
At most ``max_connections`` pairs run at once, counted from a client's Hello; one more client
gets an ``Error`` ("relay full"). Connections that have not sent their Hello wait outside those
slots, at most ``max_pending`` of them: past that the oldest is dropped, so idle connections
cannot keep a client out.

**Access.** The relay forwards the Hello unchanged, token included, so a server with a token
checks it. A relay given a token (``--token-file``, ``PIBR_TOKEN``; required when it listens
off loopback) also checks it before connecting upstream: a client without it never reaches
the server. One token for relay and server is the simple set-up. ``--tls-cert``/``--tls-key``
make clients connect with TLS; ``--upstream-tls-ca``/``--upstream-tls-pin`` make the relay
connect to a TLS server.

The relay parses framing (never payloads, except the first ``Hello`` and, on the wall clock, the
poses up to the first tick's, which it only reads), so a peer sending garbage gets an ``Error``
and its connection pair is closed; other pairs carry on.
"""
from __future__ import annotations

import asyncio
import dataclasses
import hashlib
import itertools
import logging
import ssl
from dataclasses import dataclass

from pibr.protocol.access import check_listen_access, token_matches
from pibr.protocol.connection import Connection
from pibr.protocol.errors import AccessDenied, ConfigError, ProtocolError, TLSError, UnexpectedMessage
from pibr.protocol.framing import DEFAULT_MAX_MESSAGE_SIZE, HEADER_SIZE, FrameReader, RawFrame, encode_frame
from pibr.common.link import LinkModel, LinkParams
from pibr.protocol.messages import WARMUP_SEQ, Clock, Error, Hello, PoseMsg, ProxyChunk, Welcome, parse_message
from pibr.common.tls import ClientTLS, check_server_files

from .byte_queue import ByteBudgetQueue
from .listener import TrackedListener

log = logging.getLogger(__name__)

READ_CHUNK = 1 << 16
#: Default buffer per direction of a pair: two messages of the default size limit.
DEFAULT_BUFFER_BYTES = 32 * 1024 * 1024
DEFAULT_MAX_CONNECTIONS = 16


@dataclass
class RelayConfig:
    listen: tuple = ("127.0.0.1", 7451)
    upstream: tuple = ("127.0.0.1", 7450)
    up: LinkParams = LinkParams(64.0)
    down: LinkParams = LinkParams(64.0)
    seed: int = 0
    max_message_size: int = DEFAULT_MAX_MESSAGE_SIZE
    buffer_bytes: int = DEFAULT_BUFFER_BYTES     # per direction of each pair
    max_connections: int = DEFAULT_MAX_CONNECTIONS
    max_pending: int = 64                        # connections yet to send a Hello; beyond, the oldest is dropped
    hello_timeout_s: float = 10.0                # from accepting (TLS handshake included) to the Hello
    token: str | None = None                     # clients must send it; required to listen off loopback
    tls_cert: str | None = None                  # TLS towards clients (with tls_key)
    tls_key: str | None = None
    upstream_tls: ClientTLS | None = None        # TLS towards the server

    def __post_init__(self):
        if not 1 <= self.max_message_size <= 1 << 30:
            raise ConfigError(f"relay message size limit must be in 1..{1 << 30} bytes, got {self.max_message_size}")
        if self.buffer_bytes < self.max_message_size + HEADER_SIZE:
            raise ConfigError(f"relay buffer of {self.buffer_bytes} bytes per direction cannot hold one message of "
                              f"the {self.max_message_size}-byte limit; give at least "
                              f"{-(-(self.max_message_size + HEADER_SIZE) // (1 << 20))} MiB")
        if not 1 <= self.max_connections <= 100_000:
            raise ConfigError(f"relay connection limit must be in 1..100000, got {self.max_connections}")
        if not 1 <= self.max_pending <= 100_000:
            raise ConfigError(f"relay pending-connection limit must be in 1..100000, got {self.max_pending}")
        if not 0 < self.hello_timeout_s <= 3600:
            raise ConfigError(f"relay Hello timeout must be in (0, 3600] s, got {self.hello_timeout_s}")
        check_listen_access("relay", self.listen[0], self.token)
        check_server_files(self.tls_cert, self.tls_key, "relay")


def _bandwidth(link: LinkParams) -> str:
    if link.trace is not None:
        return f"trace {link.trace.name} (mean {link.trace.mean_kbps:.0f} kbit/s, {link.trace.period_us / 1e6:g} s loop)"
    return f"{link.kbps:g} kbit/s" if link.kbps > 0 else "no cap"


def link_seeds(seed: int, hello: Hello) -> tuple[int, int]:
    """(uplink, downlink) jitter seeds of a session: ``seed`` and the client's Hello without its
    token, so the same session replays the same jitter however many connections came before."""
    identity = dataclasses.replace(hello, token="").serialize()
    digest = hashlib.sha256(b"%d\0" % seed + identity).digest()
    return int.from_bytes(digest[:8], "little"), int.from_bytes(digest[8:16], "little")


class _Pair:
    """One client connection and its upstream connection."""

    def __init__(self, relay, number, c_reader, c_writer):
        self.relay, self.number = relay, number
        self.c_reader, self.c_writer = c_reader, c_writer
        self.peer = c_writer.get_extra_info("peername")
        self.hello: Hello | None = None
        self.clock: str | None = None
        self.up_model: LinkModel | None = None
        self.down_model: LinkModel | None = None
        self._ticking = False      # the client's first pose has passed (the real clock's trace origin)
        #: direction ("up", "down") -> its buffer, once the pumps run
        self.queues: dict[str, ByteBudgetQueue] = {}
        self._hello_deadline: asyncio.Timeout | None = None
        self._evicted_among = 0    # > 0: dropped as the oldest of this many connections without a Hello

    def evict(self, waiting: int) -> None:
        """Drop this connection, the oldest of ``waiting`` still to send a Hello."""
        self._evicted_among = waiting
        if self._hello_deadline is not None:
            self._hello_deadline.reschedule(asyncio.get_running_loop().time())

    async def run(self) -> None:
        cfg = self.relay.config
        client_frames = FrameReader(cfg.max_message_size)
        try:
            # asyncio.timeout, not wait_for: in Python 3.11 wait_for can swallow a cancellation
            # (the relay closing) that comes as the Hello does, and the pair would run on.
            async with asyncio.timeout(cfg.hello_timeout_s) as self._hello_deadline:
                if self._evicted_among:
                    raise TimeoutError
                first = await self._read_hello(client_frames)
        except TimeoutError:
            if self._evicted_among:
                log.info("relay %d: dropped %s, the oldest of %d connections without a Hello", self.number,
                         self.peer, self._evicted_among)
                await self._refuse(Error(ConfigError.code, f"relay busy: {self._evicted_among} connections are "
                                                           f"waiting to send a Hello; this one, the oldest, is dropped"))
                return
            log.info("relay %d: no Hello from %s within %g s", self.number, self.peer, cfg.hello_timeout_s)
            await self._refuse(Error(UnexpectedMessage.code, f"relay: no Hello within {cfg.hello_timeout_s:g} s"))
            return
        except ProtocolError as exc:
            log.warning("relay %d: %s from the client %s: %s", self.number, type(exc).__name__, self.peer, exc)
            await self._refuse(Error(exc.code, f"relay: {exc}"))
            return
        except (ConnectionError, EOFError) as exc:
            log.info("relay %d: client %s left before its Hello (%s)", self.number, self.peer, exc or "closed")
            await _close(self.c_writer)
            return
        finally:
            self._hello_deadline = None
            self.relay.pending.pop(self.number, None)
        if cfg.token is not None and not token_matches(cfg.token, self.hello.token):
            log.warning("relay %d: bad or missing token from %s", self.number, self.peer)
            await self._refuse(Error(AccessDenied.code, "relay: bad or missing token"))
            return
        pairs = self.relay.pairs
        if len(pairs) >= cfg.max_connections:
            log.warning("relay %d: refused %s: %d connections already", self.number, self.peer, len(pairs))
            await self._refuse(Error(ConfigError.code, f"relay full: {len(pairs)} connections already "
                                                       f"(--max-connections {cfg.max_connections})"))
            return
        pairs.add(self)
        self.clock = self.hello.clock
        up_seed, down_seed = link_seeds(cfg.seed, self.hello)
        # A bandwidth trace starts with the session: at virtual time 0; on the wall clock now, and
        # again at the client's first pose (_timed).
        origin = 0 if self.clock == "virtual" else int(asyncio.get_running_loop().time() * 1e6)
        self.up_model = LinkModel(cfg.up, seed=up_seed, origin_us=origin)
        self.down_model = LinkModel(cfg.down, seed=down_seed, origin_us=origin)
        # virtual: the handshake's own pass through the downlink, before the simulated timeline
        self.handshake_model = LinkModel(cfg.down, seed=down_seed, origin_us=0)
        from pibr.common.tls import open_connection

        try:
            s_reader, s_writer = await open_connection(*cfg.upstream, cfg.upstream_tls, timeout=cfg.hello_timeout_s,
                                                       what="the upstream server")
        except (ConnectionError, TLSError) as exc:
            log.warning("relay %d: %s", self.number, exc)
            await self._refuse(Error(1, f"relay: {exc}"))
            return
        up = asyncio.create_task(self._pump(self.c_reader, s_writer, self.up_model, "up", self.c_writer,
                                            client_frames, first))
        down = asyncio.create_task(self._pump(s_reader, self.c_writer, self.down_model, "down", s_writer,
                                              FrameReader(cfg.max_message_size), []))
        try:
            done, pending = await asyncio.wait({up, down}, return_when=asyncio.FIRST_COMPLETED)
            # One side finished: let the other deliver what it already holds, briefly.
            if pending:
                await asyncio.wait(pending, timeout=2.0 + max(cfg.up.delay_ms, cfg.down.delay_ms) / 1000)
            for t in (up, down):
                if t.done() and not t.cancelled() and t.exception() is not None:
                    log.warning("relay %d: %s", self.number, t.exception())
        finally:
            # Also when the relay shuts down mid-way: no pump outlives its pair or dies unseen.
            for t in (up, down):
                t.cancel()
            await asyncio.gather(up, down, return_exceptions=True)
            await _close(s_writer)
            await _close(self.c_writer)
            log.info("relay %d: closed (up %d msgs / %d B, down %d msgs / %d B)", self.number,
                     self.up_model.messages, self.up_model.bytes, self.down_model.messages, self.down_model.bytes)

    async def _read_hello(self, frames: FrameReader) -> list[RawFrame]:
        """Read until the client's first frame, which must be a Hello -> every frame read so far."""
        while True:
            data = await self.c_reader.read(READ_CHUNK)
            if not data:
                frames.eof()
                raise EOFError("closed")
            got = frames.feed(data)
            if got:
                if got[0].type != Hello.TYPE:
                    raise UnexpectedMessage(f"expected the client's Hello first, got type {got[0].type}")
                self.hello = parse_message(Hello.TYPE, got[0].payload)
                return got

    async def _refuse(self, err: Error) -> None:
        self._send_error(self.c_writer, err)
        await _close(self.c_writer)

    def _send_error(self, writer, err: Error) -> None:
        conn = Connection()
        conn.send(err)
        try:
            writer.write(conn.data_to_send())
        except (ConnectionError, ssl.SSLError, RuntimeError):
            pass

    def _timed(self, f: RawFrame, model: LinkModel) -> tuple:
        """(due on the loop's clock or None, bytes to send) for one frame through ``model``."""
        is_clock = f.type == Clock.TYPE
        if self.clock == "virtual":
            if f.type in (Hello.TYPE, Welcome.TYPE, ProxyChunk.TYPE):
                # The handshake and the proxies sent with it come before the simulated timeline
                # starts; through the session's link model they would push the link's FIFO clock
                # past the first ticks. The downlink's are stamped with their arrival through a
                # model of their own (the trace from its start, sent at 0): the client measures
                # the link on them.
                if model is self.down_model and f.type != Hello.TYPE:
                    return None, encode_frame(f.type, f.payload, self.handshake_model.arrival_us(0, f.wire_size))
                return None, encode_frame(f.type, f.payload, f.vtime_us)
            return None, encode_frame(f.type, f.payload, model.arrival_us(f.vtime_us, f.wire_size, is_clock))
        loop = asyncio.get_running_loop()
        now_us = int(loop.time() * 1e6)
        if f.type == PoseMsg.TYPE and not self._ticking:
            self._start_ticking(f.payload, now_us)
        arrive = model.arrival_us(now_us, f.wire_size, is_clock)
        return arrive / 1e6, encode_frame(f.type, f.payload, f.vtime_us)

    def _start_ticking(self, pose_payload: bytes, now_us: int) -> None:
        """At the real-clock client's first tick's pose (not a warm-up's), both directions' traces
        start again from its tick 0 (module docstring): its ``t_us`` is the time since then. A pose
        that does not parse is the server's to refuse; it starts nothing here."""
        try:
            pose = PoseMsg.parse(pose_payload)
        except ProtocolError:
            return
        if pose.seq == WARMUP_SEQ:
            return
        self._ticking = True
        self.up_model.origin_us = self.down_model.origin_us = now_us - pose.t_us

    async def _pump(self, reader, writer, model: LinkModel, direction: str, source_writer,
                    frames: FrameReader, pending: list[RawFrame]) -> None:
        queue = ByteBudgetQueue(self.relay.config.buffer_bytes)
        self.queues[direction] = queue
        # drain() then returns only once the transport has handed every byte on (to the kernel, or
        # to TLS, which keeps at most 64 KiB), so the queue's count is what the relay holds of a
        # frame being sent. Not high=0: a TLS transport would then count as full when empty.
        writer.transport.set_write_buffer_limits(high=1, low=0)
        sender = asyncio.create_task(self._send_loop(queue, writer))
        try:
            try:
                while True:
                    for f in pending:
                        due, data = self._timed(f, model)
                        if not await queue.put((due, data), len(data)):
                            return   # the receiver is gone
                    data = await reader.read(READ_CHUNK)
                    if not data:
                        frames.eof()
                        break
                    pending = frames.feed(data)
            except ProtocolError as exc:
                log.warning("relay %d: %s from the %s: %s", self.number, type(exc).__name__,
                            "client" if direction == "up" else "server", exc)
                self._send_error(source_writer, Error(exc.code, f"relay: {exc}"))
            await queue.put(None, 0)
            await sender          # deliver what is queued; a cancellation here reaches the sender too
        finally:
            # Cancelled elsewhere (the pair or the relay closing): the sender may be stuck on a
            # receiver that does not read; it must not outlive the pump.
            sender.cancel()
            await asyncio.gather(sender, return_exceptions=True)

    async def _send_loop(self, queue: ByteBudgetQueue, writer) -> None:
        loop = asyncio.get_running_loop()
        while True:
            item, nbytes = await queue.get()
            if item is None:
                return
            due, data = item
            if due is not None and due > loop.time():
                await asyncio.sleep(due - loop.time())
            try:
                writer.write(data)
                await writer.drain()
            except (ConnectionError, ssl.SSLError, RuntimeError):
                await queue.abandon()
                return
            await queue.done(nbytes)


async def _close(writer) -> None:
    try:
        writer.close()
        await asyncio.wait_for(writer.wait_closed(), 2.0)
    except (ConnectionError, ssl.SSLError, asyncio.TimeoutError, RuntimeError):
        writer.transport.abort()   # a peer that does not read would keep a closing socket for ever


class Relay(TrackedListener):
    def __init__(self, config: RelayConfig):
        super().__init__()
        self.config = config
        self._numbers = itertools.count(1)
        self.pairs: set[_Pair] = set()           # connections past their Hello
        self.pending: dict[int, _Pair] = {}      # connections still to send it, oldest first

    async def start(self) -> tuple[str, int]:
        c = self.config
        tls = None
        if c.tls_cert is not None:
            from pibr.common.tls import server_context

            tls = server_context(c.tls_cert, c.tls_key)
        host, port = await self.listen(*c.listen, ssl=tls, ssl_handshake_timeout=c.hello_timeout_s)
        log.info("pibr relay on %s:%d%s -> %s:%d%s (up %g ms, down %g ms, jitter %g/%g ms, bandwidth %s/%s, "
                 "%d MiB per direction, at most %d connections, %s)", host, port, " (TLS)" if tls else "",
                 *c.upstream, " (TLS)" if c.upstream_tls else "", c.up.delay_ms, c.down.delay_ms, c.up.jitter_ms,
                 c.down.jitter_ms, _bandwidth(c.up), _bandwidth(c.down), c.buffer_bytes >> 20, c.max_connections,
                 "token required" if c.token is not None else "no token")
        return host, port

    async def handle(self, reader, writer) -> None:
        number = next(self._numbers)
        pair = _Pair(self, number, reader, writer)
        self.pending[number] = pair
        while len(self.pending) > self.config.max_pending:
            oldest = next(iter(self.pending.values()))
            del self.pending[oldest.number]
            oldest.evict(len(self.pending) + 1)
        try:
            await pair.run()
        except Exception:  # one pair's bug must not stop the relay; log it loudly
            log.exception("relay: connection pair failed")
        finally:
            self.pending.pop(number, None)
            self.pairs.discard(pair)


async def run_relay(config: RelayConfig, ready=None) -> None:
    relay = Relay(config)
    try:
        host, port = await relay.start()
        if ready is not None:
            ready(host, port)
        await relay.serve_forever()
    finally:
        await relay.close()
