"""``pibr relay``: a latency-injecting relay any client and server can sit behind.

For each client connection the relay opens one upstream connection and pumps frames both
ways through a :class:`~pibr.protocol.link.LinkModel` per direction. It reads the client's
``Hello`` to learn the session's clock:

* **virtual**: frames are forwarded at once, their header ``vtime_us`` rewritten to the
  modelled arrival time (deterministic: jitter comes from a seeded generator); the
  handshake (``Hello``, ``Welcome``, the proxies' ``ProxyChunk``) precedes the simulated
  timeline and passes unchanged;
* **real**: frames are held until their modelled arrival on the wall clock, unchanged.

The relay parses framing (never payloads, except the first ``Hello``), so a peer sending
garbage gets an ``Error`` and its connection pair is closed; other pairs carry on. Queues
are bounded: a receiver that does not read stalls only its own sender.
"""
from __future__ import annotations

import asyncio
import itertools
import logging
from dataclasses import dataclass

from pibr.protocol.connection import Connection
from pibr.protocol.errors import ProtocolError, UnexpectedMessage
from pibr.protocol.framing import DEFAULT_MAX_MESSAGE_SIZE, FrameReader, encode_frame
from pibr.protocol.link import LinkModel, LinkParams
from pibr.protocol.messages import Clock, Error, Hello, ProxyChunk, Welcome

from .listener import TrackedListener

log = logging.getLogger(__name__)

QUEUE_FRAMES = 512


@dataclass
class RelayConfig:
    listen: tuple = ("127.0.0.1", 7451)
    upstream: tuple = ("127.0.0.1", 7450)
    up: LinkParams = LinkParams(64.0)
    down: LinkParams = LinkParams(64.0)
    seed: int = 0
    max_message_size: int = DEFAULT_MAX_MESSAGE_SIZE


class _Pair:
    """One client connection and its upstream connection."""

    def __init__(self, relay, number, c_reader, c_writer):
        self.relay, self.number = relay, number
        self.c_reader, self.c_writer = c_reader, c_writer
        cfg = relay.config
        self.up_model = LinkModel(cfg.up, seed=cfg.seed * 2 + number * 1000)
        self.down_model = LinkModel(cfg.down, seed=cfg.seed * 2 + 1 + number * 1000)
        self.clock: asyncio.Future = asyncio.get_running_loop().create_future()

    async def run(self) -> None:
        cfg = self.relay.config
        try:
            s_reader, s_writer = await asyncio.open_connection(*cfg.upstream)
        except OSError as exc:
            log.warning("relay %d: upstream %s:%d unreachable: %s", self.number, *cfg.upstream, exc)
            self._send_error(self.c_writer, Error(1, f"relay: upstream server {cfg.upstream[0]}:{cfg.upstream[1]} "
                                                     f"is unreachable ({exc})"))
            await _close(self.c_writer)
            return
        up = asyncio.create_task(self._pump(self.c_reader, s_writer, self.up_model, "up", self.c_writer))
        down = asyncio.create_task(self._pump(s_reader, self.c_writer, self.down_model, "down", s_writer))
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

    def _send_error(self, writer, err: Error) -> None:
        conn = Connection()
        conn.send(err)
        try:
            writer.write(conn.data_to_send())
        except (ConnectionError, RuntimeError):
            pass

    async def _pump(self, reader, writer, model: LinkModel, direction: str, source_writer) -> None:
        loop = asyncio.get_running_loop()
        frames = FrameReader(self.relay.config.max_message_size)
        queue: asyncio.Queue = asyncio.Queue(QUEUE_FRAMES)
        sender = asyncio.create_task(self._send_loop(queue, writer))
        try:
            while True:
                data = await reader.read(1 << 16)
                if not data:
                    frames.eof()
                    break
                for f in frames.feed(data):
                    if not self.clock.done():
                        if direction != "up" or f.type != Hello.TYPE:
                            raise UnexpectedMessage(f"relay: expected the client's Hello first, got type {f.type}")
                        self.clock.set_result(Hello.parse(f.payload).clock)
                    clock = await self.clock
                    is_clock = f.type == Clock.TYPE
                    if clock == "virtual" and f.type in (Hello.TYPE, Welcome.TYPE, ProxyChunk.TYPE):
                        # The handshake and the proxies sent with it come before the simulated
                        # timeline starts; through the link model they would push the link's
                        # FIFO clock past the first ticks.
                        await queue.put((None, encode_frame(f.type, f.payload, f.vtime_us)))
                    elif clock == "virtual":
                        arrive = model.arrival_us(f.vtime_us, f.wire_size, is_clock)
                        await queue.put((None, encode_frame(f.type, f.payload, arrive)))
                    else:
                        now_us = int(loop.time() * 1e6)
                        arrive = model.arrival_us(now_us, f.wire_size, is_clock)
                        await queue.put((arrive / 1e6, encode_frame(f.type, f.payload, f.vtime_us)))
        except ProtocolError as exc:
            log.warning("relay %d: %s from the %s: %s", self.number, type(exc).__name__,
                        "client" if direction == "up" else "server", exc)
            self._send_error(source_writer, Error(exc.code, f"relay: {exc}"))
        finally:
            await queue.put(None)
            await sender

    async def _send_loop(self, queue: asyncio.Queue, writer) -> None:
        loop = asyncio.get_running_loop()
        while True:
            item = await queue.get()
            if item is None:
                return
            due, data = item
            if due is not None and due > loop.time():
                await asyncio.sleep(due - loop.time())
            try:
                writer.write(data)
                await writer.drain()
            except (ConnectionError, RuntimeError):
                return


async def _close(writer) -> None:
    try:
        writer.close()
        await asyncio.wait_for(writer.wait_closed(), 2.0)
    except (ConnectionError, asyncio.TimeoutError, RuntimeError):
        pass


class Relay(TrackedListener):
    def __init__(self, config: RelayConfig):
        super().__init__()
        self.config = config
        self._numbers = itertools.count(1)

    async def start(self) -> tuple[str, int]:
        host, port = await self.listen(*self.config.listen)
        c = self.config
        log.info("pibr relay on %s:%d -> %s:%d (up %g ms, down %g ms, jitter %g/%g ms, cap %g/%g kbit/s)",
                 host, port, *c.upstream, c.up.delay_ms, c.down.delay_ms, c.up.jitter_ms, c.down.jitter_ms,
                 c.up.kbps, c.down.kbps)
        return host, port

    async def handle(self, reader, writer) -> None:
        try:
            await _Pair(self, next(self._numbers), reader, writer).run()
        except Exception:  # one pair's bug must not stop the relay; log it loudly
            log.exception("relay: connection pair failed")


async def run_relay(config: RelayConfig, ready=None) -> None:
    relay = Relay(config)
    try:
        host, port = await relay.start()
        if ready is not None:
            ready(host, port)
        await relay.serve_forever()
    finally:
        await relay.close()
