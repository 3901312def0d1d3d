"""A stand-in pibr server for relay tests, with no rendering: the relay parses only framing and
the client's Hello, so frames of any bytes exercise it."""
from __future__ import annotations

import asyncio
import contextlib

from pibr.protocol.framing import FrameReader, encode_frame
from pibr.protocol.messages import Frame, Hello, Welcome


class FakeUpstream:
    """Answers each Hello with a Welcome-typed frame, then sends ``frames`` Frame-typed frames of
    ``frame_bytes`` each, stamped every ``interval_us``, and ends its side of the stream;
    ``per_client`` maps a Hello's client name to its own (frames, frame_bytes).

    Records per connection the Hello and the (type, vtime) of every frame received after it,
    and how many bytes its writes have handed to the kernel (``sent``).
    """

    def __init__(self, frames: int = 10, frame_bytes: int = 100, interval_us: int = 100_000,
                 per_client: dict | None = None, ssl=None):
        self.frames, self.frame_bytes, self.interval_us = frames, frame_bytes, interval_us
        self.per_client, self.ssl = per_client or {}, ssl
        self.connections = 0
        self.hellos: list[Hello] = []
        self.received: list[list] = []     # per connection: [(type, vtime_us)]
        self.sent: dict[str, int] = {}     # client name -> bytes written
        self._server = None
        self._tasks: set = set()

    async def start(self) -> tuple[str, int]:
        self._server = await asyncio.start_server(self._handle, "127.0.0.1", 0, ssl=self.ssl)
        return self._server.sockets[0].getsockname()[:2]

    async def close(self) -> None:
        self._server.close()
        for t in list(self._tasks):
            t.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        await self._server.wait_closed()

    async def _handle(self, reader, writer) -> None:
        self._tasks.add(asyncio.current_task())
        self.connections += 1
        received: list = []
        self.received.append(received)
        frames = FrameReader()
        got = []
        collect = None
        try:
            while not got:
                data = await reader.read(1 << 16)
                if not data:
                    return
                got = frames.feed(data)
            hello = Hello.parse(got[0].payload)
            self.hellos.append(hello)
            received += [(f.type, f.vtime_us) for f in got[1:]]
            collect = asyncio.create_task(self._collect(reader, frames, received))
            writer.write(encode_frame(Welcome.TYPE, b"{}"))
            count, size = self.per_client.get(hello.client, (self.frames, self.frame_bytes))
            payload = bytes(size)
            self.sent[hello.client] = 0
            for k in range(count):
                data = encode_frame(Frame.TYPE, payload, k * self.interval_us)
                writer.write(data)
                await writer.drain()
                self.sent[hello.client] += len(data)
            if writer.can_write_eof():
                writer.write_eof()
            await collect
        except (ConnectionError, asyncio.CancelledError):
            pass
        finally:
            if collect is not None:
                collect.cancel()
            writer.close()
            with contextlib.suppress(Exception):
                await writer.wait_closed()
            self._tasks.discard(asyncio.current_task())

    @staticmethod
    async def _collect(reader, frames: FrameReader, received: list) -> None:
        try:
            while data := await reader.read(1 << 16):
                received += [(f.type, f.vtime_us) for f in frames.feed(data)]
        except ConnectionError:
            pass


async def read_frames(reader, limit: int | None = None, timeout: float = 30.0) -> list:
    """Read a relay's frames until it closes (or ``limit`` frames) -> [(type, vtime_us, payload size)]."""
    frames, out = FrameReader(), []
    while limit is None or len(out) < limit:
        data = await asyncio.wait_for(reader.read(1 << 16), timeout)
        if not data:
            break
        out += [(f.type, f.vtime_us, len(f.payload)) for f in frames.feed(data)]
    return out
