"""In-process server (and relay) on loopback for tests, and a minimal virtual-clock client loop."""
from __future__ import annotations

import asyncio
import contextlib

from pibr.common.link import LinkParams
from pibr.protocol.messages import Clock, Frame, PoseMsg
from pibr.server.app import Server
from pibr.server.config import ServerConfig
from pibr.server.relay import Relay, RelayConfig


@contextlib.asynccontextmanager
async def running_server(config: ServerConfig):
    """Start a server in this event loop and serve until the block ends -> (server, host, port)."""
    srv = Server(config)
    host, port = await srv.start()
    task = asyncio.create_task(srv.serve_forever())
    try:
        yield srv, host, port
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        await srv.close()


@contextlib.asynccontextmanager
async def server_behind_relay(config: ServerConfig, up_ms: float = 64.0, down_ms: float = 64.0, jitter_ms: float = 0.0,
                              down_trace=None, **relay_kw):
    """Start a server and a relay in front of it (``down_trace``: the downlink's bandwidth trace;
    ``relay_kw``: more RelayConfig fields); yields the relay's (host, port)."""
    async with running_server(config) as (_, host, port):
        relay = Relay(RelayConfig(("127.0.0.1", 0), (host, port), LinkParams(up_ms, jitter_ms),
                                  LinkParams(down_ms, jitter_ms, trace=down_trace), **relay_kw))
        rhost, rport = await relay.start()
        rtask = asyncio.create_task(relay.serve_forever())
        try:
            yield rhost, rport
        finally:
            rtask.cancel()
            await asyncio.gather(rtask, return_exceptions=True)
            await relay.close()


async def exchange_virtual(conn, origin, pose_times_us, interval_us: int) -> list:
    """Send a pose at each virtual time (ids 0, 1, ...) with a clock promise one interval on,
    read until the server's horizon passes it; -> [(virtual arrival us, Frame)]."""
    frames, horizon = [], None
    for i, t in enumerate(pose_times_us):
        await conn.send(PoseMsg(i, t, origin), vtime_us=t, flush=False)
        await conn.send(Clock(), vtime_us=t + interval_us)
        while horizon is None or horizon <= t:
            env = await conn.recv(timeout=60)
            horizon = env.vtime_us
            if isinstance(env.message, Frame):
                frames.append((env.vtime_us, env.message))
    return frames



class ScriptedPeer:
    """One connection of :func:`scripted_server`, driven by hand through a sans-I/O Connection."""

    def __init__(self, reader, writer):
        from collections import deque

        from pibr.protocol.connection import Connection

        self.reader, self.writer = reader, writer
        self.conn = Connection()
        self._inbox = deque()

    async def send(self, message, vtime_us: int = 0) -> None:
        self.conn.send(message, vtime_us)
        self.writer.write(self.conn.data_to_send())
        await self.writer.drain()

    async def recv(self, timeout: float = 10.0):
        """The next message (None at the end of the stream)."""
        while not self._inbox:
            data = await asyncio.wait_for(self.reader.read(65536), timeout)
            if not data:
                return None
            self.conn.receive_data(data)
            self._inbox.extend(e.message for e in self.conn.events_received())
        return self._inbox.popleft()


@contextlib.asynccontextmanager
async def scripted_server(script):
    """A hand-written server on loopback: ``await script(peer)`` per connection, with a
    :class:`ScriptedPeer`. Yields (host, port). For hostile or broken servers."""

    async def handle(reader, writer):
        try:
            await script(ScriptedPeer(reader, writer))
        finally:
            writer.close()

    srv = await asyncio.start_server(handle, "127.0.0.1", 0)
    try:
        yield srv.sockets[0].getsockname()[:2]
    finally:
        srv.close()
        await srv.wait_closed()
