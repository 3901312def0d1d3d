"""Length-prefixed framing, sans-I/O: bytes in, frames out.

Every frame is a 20-byte little-endian header followed by ``length`` payload bytes::

    offset size field
    0      4    magic      b"PIBR"
    4      1    version    FRAMING_VERSION
    5      1    type       message type (see messages.py)
    6      2    flags      reserved, must be 0
    8      8    vtime_us   virtual time (int64 microseconds) at which the message is
                           available to its receiver; the sender writes its send time and
                           a relay adds the link's delay (see link.py). Ignored on the real clock.
    16     4    length     payload length, checked against the reader's limit *before* use

:class:`FrameReader` accepts data in chunks of any size; the relay uses it directly (it only
needs frames), :class:`~pibr.protocol.connection.Connection` adds message parsing on top.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

from .errors import BadMagic, MessageTooLarge, TruncatedMessage, UnsupportedVersion, MalformedMessage

MAGIC = b"PIBR"
FRAMING_VERSION = 1
HEADER = struct.Struct("<4sBBHqI")
HEADER_SIZE = HEADER.size  # 20
#: Default limit on one message's payload. Frames of a 2048x1536 atlas at 40 Mbit/s are
#: ~0.5 MB; proxy chunks are cut to fit well below this.
DEFAULT_MAX_MESSAGE_SIZE = 16 * 1024 * 1024


@dataclass(frozen=True)
class RawFrame:
    """One frame off the wire: type byte, flags, virtual time and the payload bytes."""

    type: int
    vtime_us: int
    payload: bytes
    flags: int = 0

    @property
    def wire_size(self) -> int:
        return HEADER_SIZE + len(self.payload)


def encode_frame(msg_type: int, payload: bytes, vtime_us: int = 0, flags: int = 0) -> bytes:
    """Header + payload bytes for one frame."""
    if not 0 <= msg_type <= 255:
        raise ValueError(f"message type must fit in a byte, got {msg_type}")
    return HEADER.pack(MAGIC, FRAMING_VERSION, msg_type, flags, int(vtime_us), len(payload)) + payload


#: First bytes of a TLS record: handshake (0x16) or alert (0x15), version 3.x.
_TLS_RECORD_STARTS = (b"\x16\x03", b"\x15\x03")


def _bad_magic(got: bytes) -> BadMagic:
    hint = ""
    if got[:2] in _TLS_RECORD_STARTS or got == b"\x16":
        hint = " (a TLS record: the peer speaks TLS and this end does not, or the other way round)"
    return BadMagic(f"expected magic {MAGIC!r}, got {got!r}{hint}")


class FrameReader:
    """Incremental frame parser. Feed bytes with :meth:`feed`; take frames with :meth:`frames`.

    Raises a :class:`~pibr.protocol.errors.ProtocolError` subclass on bad magic, version,
    flags or an oversized length; after an error the reader stays failed.
    """

    def __init__(self, max_message_size: int = DEFAULT_MAX_MESSAGE_SIZE):
        if max_message_size < 0:
            raise ValueError("max_message_size must be >= 0")
        self.max_message_size = max_message_size
        self._buf = bytearray()
        self._pos = 0
        self._failed: Exception | None = None
        self.bytes_received = 0

    @property
    def error(self) -> Exception | None:
        """The protocol error the stream failed with (None while it is sound)."""
        return self._failed

    @property
    def buffered(self) -> int:
        """Bytes received of a frame not yet complete."""
        return len(self._buf) - self._pos

    def feed(self, data: bytes) -> list[RawFrame]:
        """Add received bytes; return the frames they complete (possibly none).

        Whole frames before a protocol error in the same bytes are returned (a peer's last valid
        message is not lost to garbage after it); the error is then :attr:`error` at once and is
        raised by the next call to :meth:`feed` or :meth:`eof`. With no frame before it, it is
        raised here."""
        if self._failed is not None:
            raise self._failed
        self.bytes_received += len(data)
        self._buf += data
        out = []
        try:
            while True:
                frame = self._next()
                if frame is None:
                    break
                out.append(frame)
        except Exception as exc:  # remember, so a reader is never used past a protocol error
            self._failed = exc
            if not out:
                raise
        finally:
            if self._pos:
                del self._buf[: self._pos]
                self._pos = 0
        return out

    def eof(self) -> None:
        """The peer closed the stream: raises :class:`TruncatedMessage` if a frame was cut short,
        or the error :meth:`feed` found after the frames it returned."""
        if self._failed is not None:
            raise self._failed
        pending = len(self._buf) - self._pos
        if self._failed is None and pending:
            if pending < HEADER_SIZE:
                self._failed = TruncatedMessage(f"connection closed inside a frame header ({pending} of {HEADER_SIZE} bytes)")
            else:
                length = HEADER.unpack_from(self._buf, self._pos)[5]
                self._failed = TruncatedMessage(
                    f"connection closed inside a frame: {pending - HEADER_SIZE} of {length} payload bytes received")
            raise self._failed

    def _next(self) -> RawFrame | None:
        avail = len(self._buf) - self._pos
        if avail < 4:
            # Check the magic's prefix early so garbage fails fast rather than waiting for 20 bytes.
            if avail and bytes(self._buf[self._pos:self._pos + avail]) != MAGIC[:avail]:
                raise _bad_magic(bytes(self._buf[self._pos:self._pos + avail]))
            return None
        if bytes(self._buf[self._pos:self._pos + 4]) != MAGIC:
            raise _bad_magic(bytes(self._buf[self._pos:self._pos + 4]))
        if avail < HEADER_SIZE:
            return None
        magic, version, mtype, flags, vtime, length = HEADER.unpack_from(self._buf, self._pos)
        if version != FRAMING_VERSION:
            raise UnsupportedVersion(f"framing version {version} not supported (this end speaks {FRAMING_VERSION})")
        if flags != 0:
            raise MalformedMessage(f"reserved header flags must be 0, got {flags:#06x}")
        if length > self.max_message_size:
            raise MessageTooLarge(f"message of {length} bytes exceeds the limit of {self.max_message_size} bytes")
        if avail < HEADER_SIZE + length:
            return None
        start = self._pos + HEADER_SIZE
        payload = bytes(self._buf[start:start + length])
        self._pos = start + length
        return RawFrame(mtype, vtime, payload, flags)
