"""Every exception pibr raises on purpose, in one place.

::

    PibrError
    ├── ProtocolError            a peer sent something the protocol does not allow
    │   ├── BadMagic             the stream does not start a pibr frame
    │   ├── UnsupportedVersion   framing or handshake version mismatch
    │   ├── MessageTooLarge      a length on the wire exceeds the configured limit
    │   ├── UnknownMessageType   the frame's type byte names no message
    │   ├── MalformedMessage     the payload does not parse as its message type
    │   ├── TruncatedMessage     the connection ended in the middle of a frame
    │   ├── UnexpectedMessage    a valid message at the wrong moment of the session
    │   ├── AccessDenied         the Hello's token is missing or not the one configured
    │   └── PeerTimeout          the peer sent nothing (or no whole message) within a deadline
    ├── InvalidPose              NaN/inf components or a zero quaternion
    ├── JSONError                a JSON text breaks the bounded reader's syntax or limits
    │                            (protocol/bounded_json.py; callers turn it into their own error)
    ├── TraceError               a head-trace file or its columns do not parse (names the line)
    ├── SceneError               unknown scene, unreadable asset, bad scene description
    ├── CodecError               a video or edge-codec payload does not decode
    ├── ConfigError              a command-line or configuration value is out of range
    ├── ListenError              a server or relay cannot listen on its address (port in use, ...)
    ├── TLSError                 a TLS connection failed: certificate not verified, pin mismatch, no TLS
    └── GLUnavailable            no headless OpenGL context on this machine (EGL missing)

Every :class:`ProtocolError` carries a numeric ``code`` that goes on the wire in an
``Error`` message, so the peer learns what was wrong before the connection closes.

The peer ending a session is no error of ours; :mod:`pibr.protocol.sides` raises these when
the session takes the end of it::

    SessionEnded
    ├── ClientClosed             the client said Bye, reported an Error or closed its stream
    │                            (the server's view)
    └── ServerClosed             the server said Bye or closed its stream (the client's view;
                                 an Error from the server is a RemoteError)
"""
from __future__ import annotations


class PibrError(Exception):
    """Base of all errors pibr raises on purpose."""


class ProtocolError(PibrError):
    code = 1


class BadMagic(ProtocolError):
    code = 2


class UnsupportedVersion(ProtocolError):
    code = 3


class MessageTooLarge(ProtocolError):
    code = 4


class UnknownMessageType(ProtocolError):
    code = 5


class MalformedMessage(ProtocolError):
    code = 6


class TruncatedMessage(ProtocolError):
    code = 7


class UnexpectedMessage(ProtocolError):
    code = 8


class AccessDenied(ProtocolError):
    """The peer's ``Hello`` carries no token, or not the one this end was given. The ``Error``
    it gets says only that, so a guess learns nothing else."""

    code = 13


class PeerTimeout(ProtocolError, TimeoutError):
    """The peer was silent past a deadline: the server's handshake and idle timeouts, the
    client's receive timeout. The message names the peer and how long it was silent."""

    code = 14


class InvalidPose(PibrError, ValueError):
    code = 9


class JSONError(PibrError, ValueError):
    """Not JSON, or JSON past a limit of :mod:`pibr.protocol.bounded_json`; the message names
    the problem and where (a path such as ``objects[2].position`` or a line)."""


class TraceError(PibrError, ValueError):
    """A trace file does not parse; the message names the file and line."""


class SceneError(PibrError):
    code = 10


class CodecError(PibrError):
    code = 11


class ConfigError(PibrError, ValueError):
    code = 12


class ListenError(PibrError, OSError):
    """A server or relay cannot bind its address; the message says which and what to do."""


class TLSError(PibrError, ConnectionError):
    """A TLS connection could not be set up; the message names the address and why (the
    certificate did not verify, its fingerprint is not the pinned one, the peer speaks no TLS)."""


class GLUnavailable(PibrError, RuntimeError):
    """No OpenGL context could be created; the message names the backend and how to install it."""


class SessionEnded(Exception):
    """The peer ended the session: it said ``Bye``, reported an ``Error`` or closed its stream.
    The message says which (and the peer's reason or error)."""


class ClientClosed(SessionEnded):
    """The client ended the session (``Bye``, ``Error`` or end of stream)."""


class ServerClosed(SessionEnded):
    """The server ended the session (``Bye`` or end of stream)."""


class RemoteError(PibrError):
    """The peer closed the session with an ``Error`` message."""

    def __init__(self, code: int, text: str):
        super().__init__(f"peer reported error {code}: {text}")
        self.code = code
        self.text = text
