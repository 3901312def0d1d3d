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

#: The first answer (the Welcome) may take this many receive timeouts: the server may load and
#: prepare the scene first (30 s -> 120 s by default).
WELCOME_WAIT_FACTOR = 4.0


class ClientConnection:
    """``receive_timeout_s``: longest a :meth:`recv` waits for one *whole* message before raising
    :class:`PeerTimeout` (a server that drips a byte now and then does not stretch it); None waits
    for ever. ``session_timeout_s``: the connection's whole life, from its opening, is bounded too
    (a server sending small messages slowly for ever is cut off); None: unbounded."""

    def __init__(self, reader, writer, max_message_size: int = DEFAULT_MAX_MESSAGE_SIZE,
                 receive_timeout_s: float | None = None, peer: str = "the server",
                 session_timeout_s: float | None = None):
        self.reader, self.writer = reader, writer
        #: the session's message order (sans-I/O); ``conn``, its connection, carries our messages
        self.side = ClientSide(max_message_size)
        self.conn = self.side.conn
        self.bytes_received = 0
        self.tls: ClientTLS | None = None
        self.receive_timeout_s = receive_timeout_s
        self.peer = peer
        self.session_timeout_s = session_timeout_s
        self.welcome_arrival: tuple | None = None   # (virtual us, loop s) when the Welcome arrived
        self._session_deadline = (None if session_timeout_s is None
                                  else asyncio.get_running_loop().time() + session_timeout_s)

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
        PeerTimeout when no whole message arrives within ``timeout`` (default: the receive
        timeout) or the session's time is up."""
        timeout = self.receive_timeout_s if timeout is None else timeout
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout if timeout else None
        while True:
            try:
                env = self.side.next_event()
            except ProtocolError as exc:
                if exc is self.conn.error:   # the stream broke: tell the server why before raising
                    await self._flush_quietly()
                raise
            if env is not None:
                return env
            ends = [d for d in (deadline, self._session_deadline) if d is not None]
            remaining = min(ends) - loop.time() if ends else None
            if remaining is not None and remaining <= 0:
                raise self._timed_out(deadline, timeout)
            read = self.reader.read(1 << 16)
            try:
                data = await (asyncio.wait_for(read, remaining) if remaining is not None else read)
            except ssl.SSLError as exc:
                raise TLSError(f"the TLS connection to the server broke: {exc.reason or exc}") from None
            except asyncio.TimeoutError:
                raise self._timed_out(deadline, timeout) from None
            if not data:
                self.side.receive_eof()
                continue
            self.bytes_received += len(data)
            self.side.receive_data(data)

    def _timed_out(self, deadline, timeout) -> PeerTimeout:
        if self._session_deadline is not None and (deadline is None or self._session_deadline <= deadline):
            return PeerTimeout(f"the session with {self.peer} ran past its {self.session_timeout_s:g} s limit")
        if self.side.buffered_bytes:
            return PeerTimeout(f"{self.peer} sent {self.side.buffered_bytes} bytes of a message but not all of it "
                               f"within {timeout:g} s")
        return PeerTimeout(f"{self.peer} sent nothing for {timeout:g} s")

    async def handshake(self, hello: Hello, timeout: float | None = None) -> SessionConfig:
        """Send Hello, wait for Welcome (the server may first load and prepare the scene: by default
        :data:`WELCOME_WAIT_FACTOR` receive timeouts, 120 s without one). The side checks the Welcome
        against the Hello (protocol, clock, atlas, proxies announced when asked for)."""
        if timeout is None:
            timeout = WELCOME_WAIT_FACTOR * self.receive_timeout_s if self.receive_timeout_s else 120.0
        self.side.send_hello(hello)
        self.writer.write(self.conn.data_to_send())
        await self.writer.drain()
        try:
            welcome = await self.recv(timeout)
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
        # when the Welcome arrived: on the server's virtual clock as a relay stamps it, and here
        self.welcome_arrival = (welcome.vtime_us, asyncio.get_running_loop().time())
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
