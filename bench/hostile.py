"""Hostile peers: every way issue 13 found to misbehave towards a pibr server, as asyncio tasks.

``pibr bench soak`` runs them beside legitimate clients. Each kind connects, misbehaves,
watches how the server answers (the first message it sends back, and how long it kept the
connection) and starts again until told to stop:

==================== ==============================================================
kind                 what it does
==================== ==============================================================
nested-json          a Hello whose body is 100,000 ``[`` then 100,000 ``]``
huge-number          a Hello whose ``fov_deg`` is a 400-digit integer
bad-framing          64 random bytes instead of a frame
oversized            a frame header announcing a 4 GiB payload
unknown-type         a frame of message type 200
wrong-order          a Pose before any Hello
bad-scene            a Hello asking for the scene ``../../../../etc/passwd``
half-hello           half a frame header, then end of stream
connect-reset        connects and resets at once, as fast as it can
slowloris            a valid Hello, one byte every few seconds
idle-before-hello    connects and says nothing
silent-after-hello   a valid Hello, then nothing (reads what comes)
far-future-clock     a valid Hello, a Pose, then a Clock promise at 2**62 us; reads and drops frames
non-reader           a valid Hello on the real clock, a pose every 100 ms; never reads
==================== ==============================================================

Nothing here is needed by a normal run; it exists so that a server's robustness is measured
by the same code every time.
"""
from __future__ import annotations

import asyncio
import os
import socket
import struct
import time
from collections import Counter
from dataclasses import dataclass, field

from pibr.protocol.connection import Connection
from pibr.protocol.framing import FRAMING_VERSION, HEADER, MAGIC, encode_frame
from pibr.protocol.messages import Clock, Error, Hello, OutputConfig, PoseMsg, Welcome
from pibr.protocol.pose import Pose

#: Kinds that hold a session after a valid Hello (a server counts them as sessions).
SESSION_HOLDERS = ("silent-after-hello", "far-future-clock", "non-reader")
KINDS = ("nested-json", "huge-number", "bad-framing", "oversized", "unknown-type", "wrong-order", "bad-scene",
         "half-hello", "connect-reset", "slowloris", "idle-before-hello", *SESSION_HOLDERS)
#: A hostile connection gives up by itself after this long (a server that never closes it).
GIVE_UP_S = 60.0


@dataclass
class Tally:
    """What one kind of hostile peer saw: connections made and how the server answered each."""

    kind: str
    connections: int = 0
    answers: Counter = field(default_factory=Counter)   # e.g. "Error 3: server full", "Welcome", "closed"
    held_s: list = field(default_factory=list)          # connect -> server closed (or we gave up)
    gave_up: int = 0                                    # connections the server never closed

    def summary(self) -> dict:
        held = sorted(self.held_s)
        return {"connections": self.connections, "answers": dict(self.answers.most_common(6)),
                "held_s_median": held[len(held) // 2] if held else None, "held_s_max": held[-1] if held else None,
                "server_never_closed": self.gave_up}


def _hello(clock: str = "virtual", **output) -> Hello:
    return Hello(client="pibr-hostile", clock=clock,
                 output=OutputConfig(**{"width": 64, "height": 36, "fov_deg": 90.0, "rate_hz": 10.0, **output}))


def _frame(msg, vtime_us: int = 0) -> bytes:
    return encode_frame(msg.TYPE, msg.serialize(), vtime_us)


def _pose(seq: int, t_us: int) -> PoseMsg:
    return PoseMsg(seq, t_us, Pose.make((0.0, 1.6, 0.0), (1.0, 0.0, 0.0, 0.0)))


def _answer(conn: Connection) -> str | None:
    """The first message of interest the server sent, as a short label."""
    for env in conn.events_received():
        msg = env.message
        if isinstance(msg, Error):
            return f"Error {msg.code}: {msg.text[:48]}"
        if not isinstance(msg, Clock):
            return msg.NAME
    if conn.failed:
        return f"unparseable reply: {type(conn.error).__name__}"
    return None


class _Peer:
    """One hostile connection: its socket streams, a parser of the server's replies, a tally."""

    def __init__(self, tally: Tally, reader, writer):
        self.tally, self.reader, self.writer = tally, reader, writer
        self.conn = Connection()
        self.answer: str | None = None
        self.t0 = time.monotonic()

    def _take(self, data: bytes) -> None:
        self.conn.receive_data(data)
        if self.answer is None:
            self.answer = _answer(self.conn)

    async def read_until_closed(self, stop: asyncio.Event) -> bool:
        """Read (parsing the replies) until the server closes, ``stop`` is set or we give up.
        -> True when the server closed the connection."""
        closed = await self.read_for(stop, self.t0 + GIVE_UP_S - time.monotonic())
        if not closed and not stop.is_set():
            self.tally.gave_up += 1
        return closed

    async def read_for(self, stop: asyncio.Event, seconds: float) -> bool:
        """Read the server's replies for ``seconds`` (or until ``stop``). -> True when it closed
        the connection meanwhile."""
        end = time.monotonic() + seconds
        while not stop.is_set() and time.monotonic() < end:
            try:
                data = await asyncio.wait_for(self.reader.read(1 << 16), max(0.01, min(0.5, end - time.monotonic())))
            except asyncio.TimeoutError:
                continue
            except ConnectionError:
                return True
            if not data:
                return True
            self._take(data)
        return False

    async def wait_welcome(self, stop: asyncio.Event) -> bool:
        """Read until the server's Welcome (True) or until it closes/refuses (False)."""
        deadline = self.t0 + GIVE_UP_S
        while not stop.is_set() and time.monotonic() < deadline:
            try:
                data = await asyncio.wait_for(self.reader.read(1 << 16), 0.5)
            except asyncio.TimeoutError:
                continue
            except ConnectionError:
                return False
            if not data:
                return False
            self.conn.receive_data(data)
            for env in self.conn.events_received():
                if self.answer is None and not isinstance(env.message, Clock):
                    self.answer = (f"Error {env.message.code}: {env.message.text[:48]}"
                                   if isinstance(env.message, Error) else env.message.NAME)
                if isinstance(env.message, Welcome):
                    return True
                if isinstance(env.message, Error):
                    return False
        return False

    def finish(self, closed_by_server: bool) -> None:
        self.tally.answers[self.answer or ("closed" if closed_by_server else "no answer")] += 1
        self.tally.held_s.append(time.monotonic() - self.t0)
        self.writer.transport.abort()


async def _one(kind: str, host: str, port: int, stop: asyncio.Event, tally: Tally, rng, slow_byte_s: float) -> None:
    try:
        reader, writer = await asyncio.wait_for(asyncio.open_connection(host, port), 10)
    except (OSError, asyncio.TimeoutError) as exc:
        tally.answers[f"connect failed: {type(exc).__name__}"] += 1
        await asyncio.sleep(0.2)
        return
    tally.connections += 1
    peer = _Peer(tally, reader, writer)
    send = writer.write
    closed = False
    try:
        if kind == "connect-reset":
            sock = writer.get_extra_info("socket")
            if sock is not None:   # an RST rather than an orderly FIN
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            closed = True
        elif kind == "idle-before-hello":
            closed = await peer.read_until_closed(stop)
        elif kind == "slowloris":
            data = _frame(_hello())
            for i in range(len(data)):
                if stop.is_set() or writer.is_closing():
                    break
                send(data[i:i + 1])
                await writer.drain()
                closed = await peer.read_for(stop, slow_byte_s)
                if closed:
                    break
            if not closed:
                closed = await peer.read_until_closed(stop)
        elif kind in SESSION_HOLDERS:
            clock = "real" if kind == "non-reader" else "virtual"
            send(_frame(_hello(clock)))
            await writer.drain()
            if kind == "non-reader":
                seq = 0
                deadline = peer.t0 + GIVE_UP_S
                while not stop.is_set() and not writer.is_closing() and time.monotonic() < deadline:
                    send(_frame(_pose(seq, int((time.monotonic() - peer.t0) * 1e6))))
                    seq += 1
                    try:
                        await asyncio.wait_for(writer.drain(), 0.5)
                    except asyncio.TimeoutError:
                        pass
                    except ConnectionError:
                        closed = True
                        break
                    await asyncio.sleep(0.1)
                    if reader.at_eof() or writer.transport.is_closing():
                        closed = True
                        break
                if not closed and not stop.is_set():
                    tally.gave_up += 1
            elif await peer.wait_welcome(stop):
                if kind == "far-future-clock":
                    send(_frame(_pose(0, 0), 0) + _frame(Clock(), 1 << 62))
                    await writer.drain()
                closed = await peer.read_until_closed(stop)
            else:
                closed = True
        else:
            send(_misbehaviour(kind, rng))
            if kind == "half-hello":
                writer.write_eof()
            await writer.drain()
            closed = await peer.read_until_closed(stop)
    except OSError:   # reset, not connected, broken pipe: the server dropped us
        closed = True
    finally:
        peer.finish(closed)


def _misbehaviour(kind: str, rng) -> bytes:
    if kind == "nested-json":
        return encode_frame(Hello.TYPE, b"[" * 100_000 + b"]" * 100_000)
    if kind == "huge-number":
        body = _hello().serialize().replace(b'"fov_deg":90.0', b'"fov_deg":' + b"9" * 400)
        return encode_frame(Hello.TYPE, body)
    if kind == "bad-framing":
        return bytes(rng.integers(0, 256, 64, dtype="uint8"))
    if kind == "oversized":
        return HEADER.pack(MAGIC, FRAMING_VERSION, Hello.TYPE, 0, 0, 0xFFFFFFFF)
    if kind == "unknown-type":
        return encode_frame(200, b"x" * 16)
    if kind == "wrong-order":
        return _frame(_pose(0, 0))
    if kind == "bad-scene":
        return _frame(Hello(client="pibr-hostile", scene="../../../../etc/passwd"))
    if kind == "half-hello":
        return _frame(_hello())[:10]
    raise ValueError(f"unknown hostile kind {kind!r}")


async def hostile_loop(kind: str, host: str, port: int, stop: asyncio.Event, tally: Tally, seed: int = 0,
                       slow_byte_s: float = 4.0, pause_s: float = 0.2) -> None:
    """Connect as ``kind`` again and again until ``stop`` is set."""
    import numpy as np

    if kind not in KINDS:
        raise ValueError(f"unknown hostile kind {kind!r}; kinds: {', '.join(KINDS)}")
    rng = np.random.default_rng([seed, KINDS.index(kind)])
    while not stop.is_set():
        try:
            await _one(kind, host, port, stop, tally, rng, slow_byte_s)
        except Exception as exc:   # the peer's own failure: counted and shown, never silent
            tally.answers[f"hostile peer failed: {type(exc).__name__}: {exc}"[:80]] += 1
        try:
            await asyncio.wait_for(stop.wait(), 0.02 if kind == "connect-reset" else pause_s)
        except asyncio.TimeoutError:
            pass


async def run_hostile(host: str, port: int, stop: asyncio.Event, tallies: dict[str, Tally],
                      copies: dict | None = None, seed: int = 0, slow_byte_s: float = 4.0) -> dict[str, Tally]:
    """Every kind in ``tallies`` at once (``copies[kind]`` parallel peers of it, default 1)
    until ``stop``; each kind's outcomes go to its tally."""
    kinds = list(tallies)
    tasks = [asyncio.create_task(hostile_loop(k, host, port, stop, tallies[k], seed * 1000 + i, slow_byte_s),
                                 name=f"hostile-{k}-{i}")
             for k in kinds for i in range((copies or {}).get(k, 1))]
    try:
        await asyncio.gather(*tasks)
    finally:
        for t in tasks:
            t.cancel()
    return tallies


def process_memory(pid: int) -> tuple[int | None, int | None]:
    """(resident bytes, open file descriptors) of a process, from /proc (None where unreadable)."""
    rss = fds = None
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    rss = int(line.split()[1]) * 1024
                    break
        fds = len(os.listdir(f"/proc/{pid}/fd"))
    except OSError:
        pass
    return rss, fds
