"""Sans-I/O connection: bytes in, messages out; messages in, bytes out.

Modelled on websockets' protocol core. The asyncio adapters of the server, client and
relay, and the tests, all drive this one implementation::

    conn = Connection()
    conn.receive_data(chunk)            # from the socket, any chunking
    for env in conn.events_received():  # parsed messages with their virtual time
        ...
    conn.send(PoseMsg(...), vtime_us=t)
    sock.sendall(conn.data_to_send())

A protocol error never raises out of :meth:`receive_data`: the connection records it in
:attr:`error`, queues an ``Error`` message naming the problem for the peer, and stops
producing events; the adapter flushes :meth:`data_to_send` and closes that one connection.
"""
from __future__ import annotations

from dataclasses import dataclass

from .errors import ProtocolError
from .framing import DEFAULT_MAX_MESSAGE_SIZE, FrameReader, encode_frame
from .messages import Error, Message, parse_message


@dataclass(frozen=True)
class Envelope:
    """A received message, the virtual time stamped on it, and its size on the wire."""

    message: Message
    vtime_us: int
    wire_size: int


class Connection:
    def __init__(self, max_message_size: int = DEFAULT_MAX_MESSAGE_SIZE):
        self._reader = FrameReader(max_message_size)
        self._events: list[Envelope] = []
        self._out: list[bytes] = []
        #: The protocol error this end detected (an ``Error`` has been queued for the peer).
        self.error: ProtocolError | None = None
        #: True once the peer closed its side.
        self.eof = False
        self.bytes_sent = 0

    @property
    def failed(self) -> bool:
        return self.error is not None

    @property
    def max_message_size(self) -> int:
        return self._reader.max_message_size

    @property
    def buffered_bytes(self) -> int:
        """Bytes received of a message not yet complete."""
        return self._reader.buffered

    def receive_data(self, data: bytes) -> None:
        if self.failed or self.eof:
            return
        try:
            frames = self._reader.feed(data)
        except ProtocolError as exc:
            self.fail(exc)
            return
        for f in frames:
            try:
                msg = parse_message(f.type, f.payload)
            except ProtocolError as exc:
                self.fail(exc)
                return
            self._events.append(Envelope(msg, f.vtime_us, f.wire_size))
        if self._reader.error is not None:   # garbage after the frames above
            self.fail(self._reader.error)

    def receive_eof(self) -> None:
        if self.eof:
            return
        self.eof = True
        if self.failed:
            return
        try:
            self._reader.eof()
        except ProtocolError as exc:
            self.error = exc  # nobody left to tell

    def events_received(self) -> list[Envelope]:
        ev, self._events = self._events, []
        return ev

    def send(self, message: Message, vtime_us: int = 0) -> None:
        data = message.serialize()
        if len(data) > self.max_message_size:
            raise ValueError(f"{message.NAME} of {len(data)} bytes exceeds the message size limit "
                             f"of {self.max_message_size} bytes")
        frame = encode_frame(message.TYPE, data, vtime_us)
        self._out.append(frame)
        self.bytes_sent += len(frame)

    def fail(self, exc: ProtocolError) -> None:
        """Record ``exc`` and queue an ``Error`` telling the peer why we close."""
        if self.failed:
            return
        self.error = exc
        self.send(Error(exc.code, str(exc)))

    def data_to_send(self) -> bytes:
        out = b"".join(self._out)
        self._out.clear()
        return out
