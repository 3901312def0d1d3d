"""The client's side of a session: connect, handshake, send poses, receive messages.

An asyncio adapter over the sans-I/O :class:`~pibr.protocol.connection.Connection`.
"""
from __future__ import annotations

import asyncio
import logging
import ssl
from collections import deque

from pibr.protocol.connection import Connection, Envelope
from pibr.protocol.errors import AccessDenied, PeerTimeout, RemoteError, TLSError, UnexpectedMessage
from pibr.protocol.framing import DEFAULT_MAX_MESSAGE_SIZE
from pibr.protocol.messages import Bye, Error, Hello, Message, Welcome
from pibr.protocol.session import SessionConfig
from pibr.common.tls import ClientTLS, open_connection

log = logging.getLogger(__name__)


class ServerClosed(Exception):
    """The server ended the session (Bye or end of stream)."""


class ClientConnection:
    """``receive_timeout_s``: longest silence (no byte from the server) a :meth:`recv` waits
    through before raising :class:`PeerTimeout`; None waits for ever."""

    def __init__(self, reader, writer, max_message_size: int = DEFAULT_MAX_MESSAGE_SIZE,
                 receive_timeout_s: float | None = None, peer: str = "the server"):
        self.reader, self.writer = reader, writer
        self.conn = Connection(max_message_size)
        self._pending: deque[Envelope] = deque()
        self.welcome: Welcome | None = None
        self.config: SessionConfig | None = None
        self.bytes_received = 0
        self.tls: ClientTLS | None = None
        self.receive_timeout_s = receive_timeout_s
        self.peer = peer

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
        """Next message; raises RemoteError on the server's Error, ServerClosed at its end and
        PeerTimeout when the server sends nothing for ``timeout`` (default: the receive timeout)."""
        timeout = self.receive_timeout_s if timeout is None else timeout
        while not self._pending:
            if self.conn.failed:
                await self._flush_quietly()
                raise self.conn.error
            read = self.reader.read(1 << 16)
            try:
                data = await (asyncio.wait_for(read, timeout) if timeout else read)
            except ssl.SSLError as exc:
                raise TLSError(f"the TLS connection to the server broke: {exc.reason or exc}") from None
            except asyncio.TimeoutError:
                raise PeerTimeout(f"{self.peer} sent nothing for {timeout:g} s") from None
            if not data:
                self.conn.receive_eof()
                if self.conn.error is not None:
                    raise self.conn.error
                raise ServerClosed("server closed the connection")
            self.bytes_received += len(data)
            self.conn.receive_data(data)
            self._pending.extend(self.conn.events_received())
        env = self._pending.popleft()
        if isinstance(env.message, Error):
            raise RemoteError(env.message.code, env.message.text)
        if isinstance(env.message, Bye):
            raise ServerClosed(f"server said bye ({env.message.reason or 'no reason'})")
        return env

    async def handshake(self, hello: Hello, timeout: float = 120.0) -> SessionConfig:
        """Send Hello, wait for Welcome (the server may first load and prepare the scene)."""
        await self.send(hello)
        try:
            env = await self.recv(max(timeout, self.receive_timeout_s or 0))
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
        if not isinstance(env.message, Welcome):
            raise UnexpectedMessage(f"expected Welcome, got {env.message.NAME}")
        self.welcome = env.message
        if self.welcome.protocol != hello.protocol:
            raise UnexpectedMessage(f"server speaks protocol {self.welcome.protocol}, we speak {hello.protocol}")
        self.config = SessionConfig.from_json(self.welcome.config)
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
