"""Who may say what, and when: each end's message order in a session, sans-I/O.

A :class:`~pibr.protocol.connection.Connection` turns bytes into messages; a *side* holds one
connection and decides whether each message may come at that moment of the session. The
asyncio adapters (server/session.py, client/connection.py) only read, write, time out and
schedule; every order rule is here, so it is tested with bytes alone::

    side = ServerSide(token=...)
    side.receive_data(chunk)                  # from the socket, any chunking
    while (env := side.next_event()) is not None:
        ...                                   # the Hello first, then poses and clocks
    sock.sendall(side.data_to_send())

**Checked when taken.** A message is checked when the session takes it with
:meth:`next_event`, against the state in force then (the server's next frame time, what the
client asked for), not when its bytes are parsed: the messages before it act first, as they
would over a socket. :meth:`next_event` returns the next message the session may act on, or
None when it needs more bytes, and raises:

* :class:`~pibr.protocol.errors.ProtocolError`: the stream does not parse (the connection's
  error; an ``Error`` is queued for the peer) or a message breaks a rule here (nothing is
  queued: the adapter decides what to tell the peer, the server an ``Error`` through
  :meth:`Connection.fail`, the client a ``Bye`` when it closes);
* :class:`~pibr.protocol.errors.SessionEnded` (``ClientClosed`` / ``ServerClosed``) when the
  peer ended the session (the client's view of the server's ``Error`` is a ``RemoteError``).

Once a side has raised, the session is over: :meth:`next_event` raises the same again.

The server (:class:`ServerSide`): awaiting the Hello, open, closed.

* The first message must be a ``Hello`` with the configured token (checked before anything
  else, so a guess learns nothing more) and this protocol version.
* After it, only ``Pose`` and ``Clock``. On the virtual clock their virtual time never goes
  backwards, and the client's clock may run at most ``max_lead_us`` ahead of the session's next
  frame (the session says which with :meth:`ServerSide.next_frame` before it takes a message).
* ``Stats`` are taken in passing into :attr:`ServerSide.client_stats`, in any state, and
  never handed out; a ``Bye`` or an ``Error`` ends the session.

The client (:class:`ClientSide`): idle, awaiting the Welcome, receiving proxies, streaming,
closed.

* Idle (no Hello said yet): nothing is expected, messages are handed out as they come.
* After :meth:`ClientSide.send_hello` the first answer must be a ``Welcome`` of our protocol
  version whose config parses, runs the clock the Hello asked for, lays its atlas out as its
  views need, and announces proxies when the Hello asked for them.
* Then, when proxies were asked for, only ``ProxyChunk`` until the announced bundle is
  complete (:attr:`ClientSide.proxies` collects it).
* Then only ``Frame``, ``Clock`` and ``Stats``; on the virtual clock their virtual time never
  goes backwards.
* A ``Bye`` ends the session (``ServerClosed``), an ``Error`` too (``RemoteError``), in any state.
"""
from __future__ import annotations

import enum
from collections import deque

from .access import token_matches
from .connection import Connection, Envelope
from .errors import (AccessDenied, ClientClosed, RemoteError, ServerClosed, SessionEnded, UnexpectedMessage,
                     UnsupportedVersion)
from .framing import DEFAULT_MAX_MESSAGE_SIZE
from .messages import (PROTOCOL_VERSION, Bye, Clock, Error, Frame, Hello, Message, PoseMsg, ProxyChunk, Stats,
                       Welcome)
from .proxy import BundleAssembler, BundleInfo
from .session import SessionConfig, check_atlas_layout

#: The client's ``Stats`` a server side keeps in order (ServerSide.stats_log).
STATS_KEPT = 256

class _Side:
    """What both sides share: the connection, the messages parsed and not taken yet, the end."""

    #: Who the peer is, and what its end of stream raises ("client closed the connection").
    PEER = ""
    PEER_CLOSED: type[SessionEnded] = SessionEnded

    def __init__(self, max_message_size: int):
        self.conn = Connection(max_message_size)
        self._pending: deque[Envelope] = deque()
        self._ended: BaseException | None = None

    @property
    def buffered_bytes(self) -> int:
        """Bytes received of a message not yet complete."""
        return self.conn.buffered_bytes

    def receive_data(self, data: bytes) -> None:
        self.conn.receive_data(data)

    def receive_eof(self) -> None:
        self.conn.receive_eof()

    def data_to_send(self) -> bytes:
        return self.conn.data_to_send()

    def next_event(self) -> Envelope | None:
        """The next message the session may act on, checked now; None when more bytes are needed.
        Raises ProtocolError, SessionEnded or (the client) RemoteError: see the module docstring."""
        if self._ended is not None:
            raise self._ended
        try:
            while True:
                self._pending.extend(self.conn.events_received())
                if not self._pending:
                    if self.conn.failed:
                        raise self.conn.error
                    if self.conn.eof:
                        raise self.PEER_CLOSED(f"{self.PEER} closed the connection")
                    return None
                env = self._take(self._pending.popleft())
                if env is not None:
                    return env
        except Exception as exc:   # whatever ends the session: a broken rule, the peer's end, a bad stream
            self._end(exc)
            raise

    def _end(self, exc: BaseException) -> None:
        self._ended = exc
        self._pending.clear()

    def _take(self, env: Envelope) -> Envelope | None:  # pragma: no cover - each side has its rules
        """Check ``env`` against the rules in force; -> it, or None when it is taken in passing."""
        raise NotImplementedError


class ServerState(enum.Enum):
    AWAITING_HELLO = "awaiting Hello"
    OPEN = "open"
    CLOSED = "closed"


class ServerSide(_Side):
    """The server's end of one session (see the module docstring for its rules).

    token            : the token a Hello must carry (None: no token is needed)
    max_message_size : the connection's per-message limit
    """

    PEER = "client"
    PEER_CLOSED = ClientClosed

    def __init__(self, token: str | None = None, max_message_size: int = DEFAULT_MAX_MESSAGE_SIZE):
        super().__init__(max_message_size)
        self.token = token
        #: The client's Hello, once accepted.
        self.hello: Hello | None = None
        #: What the client's ``Stats`` said, newest value per key.
        self.client_stats: dict = {}
        #: The client's last ``Stats`` in order, each (virtual time, values): a consumer that must
        #: see them as of a virtual time (the stream adaptation) takes them from here.
        self.stats_log: deque = deque(maxlen=STATS_KEPT)
        #: Virtual clock: every later message from the client has a virtual time >= this (None: none yet).
        self.horizon_us: int | None = None
        self._next_frame_us: int | None = None
        self._max_lead_us = 0

    @property
    def state(self) -> ServerState:
        if self._ended is not None:
            return ServerState.CLOSED
        return ServerState.AWAITING_HELLO if self.hello is None else ServerState.OPEN

    def next_frame(self, t_us: int | None, max_lead_us: int) -> None:
        """Virtual clock: the session's next frame is at ``t_us`` (None: none is scheduled yet);
        a message taken from now on stamped more than ``max_lead_us`` after it is refused."""
        self._next_frame_us, self._max_lead_us = t_us, max_lead_us

    def _take(self, env: Envelope) -> Envelope | None:
        msg = env.message
        if isinstance(msg, Error):
            raise ClientClosed(f"client reported error {msg.code}: {msg.text}")
        if isinstance(msg, Bye):
            raise ClientClosed(f"client said bye ({msg.reason or 'no reason'})")
        if isinstance(msg, Stats):
            self.client_stats.update(msg.values)
            self.stats_log.append((env.vtime_us, dict(msg.values)))
            return None
        if self.hello is None:
            self._accept_hello(msg)
            return env
        if self.hello.clock == "virtual":
            self._check_time(env.vtime_us)
        if not isinstance(msg, (PoseMsg, Clock)):
            raise UnexpectedMessage(f"unexpected {msg.NAME} from the client")
        return env

    def _accept_hello(self, hello: Message) -> None:
        if not isinstance(hello, Hello):
            raise UnexpectedMessage(f"expected Hello as the first message, got {hello.NAME}")
        if self.token is not None and not token_matches(self.token, hello.token):   # before anything else is told
            raise AccessDenied("bad or missing token")
        if hello.protocol != PROTOCOL_VERSION:
            raise UnsupportedVersion(f"client speaks protocol {hello.protocol}, this server speaks {PROTOCOL_VERSION}")
        self.hello = hello

    def _check_time(self, vtime_us: int) -> None:
        horizon, next_us, max_lead_us = self.horizon_us, self._next_frame_us, self._max_lead_us
        if horizon is not None and vtime_us < horizon:
            raise UnexpectedMessage(f"virtual time went backwards ({vtime_us} us after {horizon} us)")
        if next_us is not None and vtime_us - next_us > max_lead_us:
            lead = (vtime_us - next_us) / 1e6
            raise UnexpectedMessage(f"the client's clock ({vtime_us} us) runs {lead:g} s ahead of the next "
                                    f"frame ({next_us} us), more than the {max_lead_us / 1e6:g} s allowed")
        self.horizon_us = vtime_us


class ClientState(enum.Enum):
    IDLE = "idle"
    AWAITING_WELCOME = "awaiting Welcome"
    PROXIES = "receiving proxies"
    STREAMING = "streaming"
    CLOSED = "closed"


class ClientSide(_Side):
    """The client's end of one session (see the module docstring for its rules).

    max_message_size : the connection's per-message limit
    """

    PEER = "server"
    PEER_CLOSED = ServerClosed

    def __init__(self, max_message_size: int = DEFAULT_MAX_MESSAGE_SIZE):
        super().__init__(max_message_size)
        self._state = ClientState.IDLE
        #: The Hello we sent (None before :meth:`send_hello`).
        self.hello: Hello | None = None
        #: The server's Welcome and its config, once taken.
        self.welcome: Welcome | None = None
        self.config: SessionConfig | None = None
        #: The proxy bundle being collected (None unless the Hello asked for proxies).
        self.proxies: BundleAssembler | None = None
        #: Virtual clock: every later message from the server has a virtual time >= this (None: none yet).
        self.horizon_us: int | None = None

    @property
    def state(self) -> ClientState:
        return ClientState.CLOSED if self._ended is not None else self._state

    def send_hello(self, hello: Hello) -> None:
        """Queue our Hello; the server's first answer must then be its Welcome."""
        if self._state is not ClientState.IDLE:
            raise RuntimeError(f"a Hello was already sent (the session is {self.state.value})")
        self.conn.send(hello)
        self.hello = hello
        self._state = ClientState.AWAITING_WELCOME

    def _take(self, env: Envelope) -> Envelope:
        msg = env.message
        if isinstance(msg, Error):
            raise RemoteError(msg.code, msg.text)
        if isinstance(msg, Bye):
            raise ServerClosed(f"server said bye ({msg.reason or 'no reason'})")
        state = self._state
        if state is ClientState.AWAITING_WELCOME:
            self._accept_welcome(msg)
        elif state is ClientState.PROXIES:
            if not isinstance(msg, ProxyChunk):
                raise UnexpectedMessage(f"expected ProxyChunk, got {msg.NAME}")
            self.proxies.add(msg)
            if self.proxies.complete:
                self._state = ClientState.STREAMING
        elif state is ClientState.STREAMING:
            if self.hello.clock == "virtual":
                if self.horizon_us is not None and env.vtime_us < self.horizon_us:
                    raise UnexpectedMessage(f"server's virtual time went backwards ({env.vtime_us} < "
                                            f"{self.horizon_us})")
                self.horizon_us = env.vtime_us
            if not isinstance(msg, (Frame, Clock, Stats)):
                raise UnexpectedMessage(f"unexpected {msg.NAME} from the server")
        return env

    def _accept_welcome(self, welcome: Message) -> None:
        hello = self.hello
        if not isinstance(welcome, Welcome):
            raise UnexpectedMessage(f"expected Welcome, got {welcome.NAME}")
        self.welcome = welcome
        if welcome.protocol != hello.protocol:
            raise UnexpectedMessage(f"server speaks protocol {welcome.protocol}, we speak {hello.protocol}")
        self.config = config = SessionConfig.from_json(welcome.config)
        if config.clock != hello.clock:
            raise UnexpectedMessage(f"server runs the {config.clock} clock, we asked for {hello.clock}")
        check_atlas_layout(config)
        self._state = ClientState.STREAMING
        if hello.want_proxies:
            if not config.proxies:
                raise UnexpectedMessage("asked for proxies, but the server's Welcome announces none")
            self.proxies = BundleAssembler(BundleInfo.from_json(config.proxies))
            if not self.proxies.complete:
                self._state = ClientState.PROXIES
