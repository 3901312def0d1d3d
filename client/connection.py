"""The client's side of a session: connect, handshake, send poses, receive messages.

An asyncio adapter over the sans-I/O :class:`~pibr.protocol.sides.ClientSide`, which owns the
connection and the session's message order (the Welcome first, then the proxies when asked for,
then frames and clocks; virtual time never backwards). This adapter reads, writes and times out.
"""
from __future__ import annotations

import asyncio
import logging
import ssl

from pibr.common.tls import ClientTLS, open_connection
from pibr.protocol.connection import Envelope
from pibr.protocol.errors import (AccessDenied, PeerTimeout, ProtocolError, RemoteError,
                                  ServerClosed, TLSError)  # ServerClosed: still importable from here
from pibr.protocol.framing import DEFAULT_MAX_MESSAGE_SIZE
from pibr.protocol.messages import Bye, Hello, Message, Welcome
from pibr.protocol.session import SessionConfig
from pibr.protocol.sides import ClientSide

log = logging.getLogger(__name__)


class ClientConnection:
    """``receive_timeout_s``: longest silence (no byte from the server) a :meth:`recv` waits
    through before raising :class:`PeerTimeout`; None waits for ever."""

    def __init__(self, reader, writer, max_message_size: int = DEFAULT_MAX_MESSAGE_SIZE,
                 receive_timeout_s: float | None = None, peer: str = "the server"):
        self.reader, self.writer = reader, writer
        #: the session's message order (sans-I/O); ``conn``, its connection, carries our messages
        self.side = ClientSide(max_message_size)
        self.conn = self.side.conn
        self.bytes_received = 0
        self.tls: ClientTLS | None = None
        self.receive_timeout_s = receive_timeout_s
        self.peer = peer

    @property
    def welcome(self) -> Welcome | None:
        """The server's Welcome, once the handshake has taken it."""
        return self.side.welcome

    @property
    def config(self) -> SessionConfig | None:
        """The session's parameters from the Welcome."""
        return self.side.config

    @classmethod
    async def open(cls, host: str, port: int, timeout: float = 10.0, tls: ClientTLS | None = None,
                   **kw) -> "ClientConnection":
        """Connect (over TLS when ``tls`` says how to verify the server). Raises ConnectionError,
        or TLSError naming why the server's certificate was refused."""
        reader, writer = await open_connection(host, port, tls, timeout, what="pibr server")
        conn = cls(reader, writer, peer=f"pibr server {host}:{port}", **kw)
        conn.tls = tls
        return conn

    async def send(self, message: Message, vtime_us: int = 0, flush: bool = True) -> None:
        self.conn.send(message, vtime_us)
        self.writer.write(self.conn.data_to_send())
        if flush:
            await self.writer.drain()

    async def recv(self, timeout: float | None = None) -> Envelope:
        """Next message, as the side allows it now; raises RemoteError on the server's Error,
        ServerClosed at its end, ProtocolError on bad input or a message out of order, and
        PeerTimeout when the server sends nothing for ``timeout`` (default: the receive timeout)."""
        timeout = self.receive_timeout_s if timeout is None else timeout
        while True:
            try:
                env = self.side.next_event()
            except ProtocolError as exc:
                if exc is self.conn.error:   # the stream broke: tell the server why before raising
                    await self._flush_quietly()
                raise
            if env is not None:
                return env
            read = self.reader.read(1 << 16)
            try:
                data = await (asyncio.wait_for(read, timeout) if timeout else read)
            except ssl.SSLError as exc:
                raise TLSError(f"the TLS connection to the server broke: {exc.reason or exc}") from None
            except asyncio.TimeoutError:
                raise PeerTimeout(f"{self.peer} sent nothing for {timeout:g} s") from None
            if not data:
                self.side.receive_eof()
                continue
            self.bytes_received += len(data)
            self.side.receive_data(data)

    async def handshake(self, hello: Hello, timeout: float = 120.0) -> SessionConfig:
        """Send Hello, wait for Welcome (the server may first load and prepare the scene). The side
        checks the Welcome against the Hello (protocol, clock, atlas, proxies announced when asked for)."""
        self.side.send_hello(hello)
        self.writer.write(self.conn.data_to_send())
        await self.writer.drain()
        try:
            await self.recv(max(timeout, self.receive_timeout_s or 0))
        except PeerTimeout as exc:
            raise PeerTimeout(f"{exc} after our Hello: no Welcome") from None
        except RemoteError as exc:
            if exc.code == AccessDenied.code:
                raise AccessDenied(f"{exc.text}: give the server's token with PIBR_TOKEN or --token-file") from None
            raise
        except ServerClosed:
            if self.tls is None and not self.bytes_received:
                raise ServerClosed("server closed the connection without answering the Hello; if it serves TLS, "
                                   "connect with --tls-ca FILE or --tls-pin SHA256") from None
            raise
        return self.config

    async def _flush_quietly(self) -> None:
        data = self.conn.data_to_send()
        if data:
            try:
                self.writer.write(data)
                await self.writer.drain()
            except (ConnectionError, ssl.SSLError, RuntimeError):
                pass

    async def close(self, reason: str = "done") -> None:
        try:
            if not self.conn.failed and not self.writer.is_closing():
                self.conn.send(Bye(reason))
            await asyncio.wait_for(self._flush_quietly(), 2.0)
        except asyncio.TimeoutError:
            pass
        self.writer.close()
        try:
            await asyncio.wait_for(self.writer.wait_closed(), 2.0)
        except (ConnectionError, ssl.SSLError, asyncio.TimeoutError):
            pass  # TLS: the server may still have been sending when we closed
