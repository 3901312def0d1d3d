"""A TCP listener whose connection handlers are tracked, so closing it stops them all.

Both the server and the relay accept connections this way: each connection runs in its own
task; :meth:`TrackedListener.close` stops accepting, cancels every handler still running
and waits for them, so nothing outlives a shutdown.
"""
from __future__ import annotations

import asyncio
import errno
import logging
import os
import socket

from pibr.protocol.errors import ListenError

log = logging.getLogger(__name__)
#: Longest wait at shutdown for the sockets of cancelled handlers to close.
CLOSE_TIMEOUT_S = 5.0


class TrackedListener:
    """Subclasses implement :meth:`handle`; one task per connection."""

    def __init__(self):
        self._server: asyncio.AbstractServer | None = None
        self._tasks: set[asyncio.Task] = set()

    async def listen(self, host: str, port: int, ssl=None, ssl_handshake_timeout: float | None = None
                     ) -> tuple[str, int]:
        """Start accepting on ``host:port`` (0: any free port) -> the bound (host, port); with
        ``ssl`` (an SSLContext) every connection is TLS, and one whose TLS handshake fails or
        takes longer than ``ssl_handshake_timeout`` seconds is dropped before :meth:`handle`.

        Raises :class:`ListenError` naming the address when it cannot be bound."""
        try:
            self._server = await asyncio.start_server(self._run_handler, host, port, ssl=ssl,
                                                      ssl_handshake_timeout=ssl_handshake_timeout if ssl else None)
        except OSError as exc:
            hint = {errno.EADDRINUSE: "another process is listening there: stop it or choose another port, "
                                      "0 for any free one",
                    errno.EACCES: "ports below 1024 need privileges; choose a port above 1024",
                    errno.EADDRNOTAVAIL: "this machine has no such address; use 127.0.0.1 or 0.0.0.0"
                    }.get(exc.errno, "check the host and port")
            # asyncio wraps bind errors in a long message of its own; the errno's text is enough
            plain = exc.errno and exc.errno > 0 and not isinstance(exc, socket.gaierror)
            reason = os.strerror(exc.errno) if plain else (exc.strerror or str(exc))
            raise ListenError(f"cannot listen on {host}:{port}: {reason}; {hint}") from None
        return self._server.sockets[0].getsockname()[:2]

    async def handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        raise NotImplementedError

    async def _run_handler(self, reader, writer) -> None:
        task = asyncio.current_task()
        self._tasks.add(task)
        try:
            await self.handle(reader, writer)
        except asyncio.CancelledError:
            pass  # shutting down; the handler released what it could on the way out
        finally:
            self._tasks.discard(task)

    async def serve_forever(self) -> None:
        async with self._server:
            await self._server.serve_forever()

    async def close(self) -> None:
        """Stop accepting, cancel the running handlers and wait for them, then for their sockets."""
        if self._server is not None:
            self._server.close()
        for task in list(self._tasks):
            task.cancel()
        if self._tasks:
            await asyncio.gather(*self._tasks, return_exceptions=True)
        if self._server is not None:
            # Since Python 3.12 wait_closed() waits for every accepted socket to close, so it comes
            # after the handlers, which close theirs: first, it would wait on a connected peer for ever.
            try:
                await asyncio.wait_for(self._server.wait_closed(), CLOSE_TIMEOUT_S)
            except asyncio.TimeoutError:
                log.warning("%s: connections still open %g s after closing; leaving them", type(self).__name__,
                            CLOSE_TIMEOUT_S)
