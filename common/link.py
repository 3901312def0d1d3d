"""The network link model: one direction of a TCP-like path with delay, jitter and a bandwidth
cap (:class:`LinkModel`), and one session's schedule through a link in each direction
(:class:`SessionSchedule`).

The relay process (``pibr relay``) runs a :class:`LinkModel` per direction; the benchmarks and
the server's scene plan follow a session through the same model in one process. Times are
integer microseconds so the virtual clock stays bit-exact. For a message sent at ``t`` of
``n`` bytes::

    tx_start = max(t, link_free)                 # the link sends one message at a time
    tx       = n * 8 / kbps                      # serialisation at the bandwidth cap (0: none),
                                                 # or until a bandwidth trace has carried n bytes
    arrive   = tx_start + tx + max(0, delay + U(-jitter, +jitter))
    arrive   = max(arrive, previous arrive)      # TCP delivers in order

``Clock`` messages (null messages of the virtual clock) cost no bandwidth and take the
*least* delay the link can give, so their time stays a valid lower bound for every later
message (see ``messages.Clock``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .bandwidth import BandwidthTrace


@dataclass(frozen=True)
class LinkParams:
    """One direction: ``delay_ms`` one-way, ``jitter_ms`` (uniform +-), ``kbps`` cap (0 = none)
    or a ``trace`` of changing bandwidth (common/bandwidth.py; its time 0 is the link's origin)."""

    delay_ms: float = 64.0
    jitter_ms: float = 0.0
    kbps: float = 0.0
    trace: BandwidthTrace | None = None

    def __post_init__(self):
        for name in ("delay_ms", "jitter_ms", "kbps"):
            v = getattr(self, name)
            if not (v >= 0 and v < 1e9):
                raise ValueError(f"link {name} must be a finite number >= 0, got {v}")
        if self.trace is not None and self.kbps > 0:
            raise ValueError("a link has a fixed bandwidth cap or a bandwidth trace, not both")

    @property
    def capped(self) -> bool:
        """The link's bandwidth is limited (a cap or a trace)."""
        return self.kbps > 0 or self.trace is not None


class LinkModel:
    """Stateful FIFO link (one direction). ``seed`` makes the jitter sequence reproducible."""

    def __init__(self, params: LinkParams, seed: int = 0, origin_us: int = 0):
        """origin_us: the time on the caller's clock at which a bandwidth trace starts."""
        self.params = params
        self.origin_us = int(origin_us)
        self._rng = np.random.default_rng(seed)
        self._delay_us = int(round(params.delay_ms * 1000))
        self._jitter_us = int(round(params.jitter_ms * 1000))
        self._link_free_us: int | None = None
        self._last_arrival_us: int | None = None
        self.messages = 0
        self.bytes = 0

    @property
    def min_delay_us(self) -> int:
        return max(0, self._delay_us - self._jitter_us)

    def arrival_us(self, send_us: int, nbytes: int, is_clock: bool = False) -> int:
        """Arrival time of a message sent at ``send_us`` with ``nbytes`` on the wire."""
        start = send_us if self._link_free_us is None else max(send_us, self._link_free_us)
        if is_clock:
            arrive = start + self.min_delay_us
        else:
            if self.params.trace is not None:
                origin = self.origin_us
                tx = self.params.trace.finish_us(start - origin, nbytes) + origin - start
            else:
                tx = 0 if self.params.kbps <= 0 else int(math.ceil(nbytes * 8000.0 / self.params.kbps))
            self._link_free_us = start + tx
            delay = self._delay_us
            if self._jitter_us:
                delay = max(0, delay + int(self._rng.integers(-self._jitter_us, self._jitter_us + 1)))
            arrive = start + tx + delay
            self.messages += 1
            self.bytes += nbytes
        if self._last_arrival_us is not None:
            arrive = max(arrive, self._last_arrival_us)
        self._last_arrival_us = arrive
        return arrive


class SessionSchedule:
    """The schedule of one session through the link model, frame by frame (protocol/session.py
    describes the virtual clock it follows).

    The client shows a tick every ``1 / rate_hz`` and sends its pose with it, over the uplink.
    The server renders every ``1 / server_fps`` from the newest pose that has reached it and
    sends the frame ``server_delay_ms`` later, over the downlink; the client shows the newest
    frame that has arrived. With ``max_in_flight`` set, the server skips a frame while that many
    it sent are not known to be received (the real clock's rule, server/session.py: the client
    reports what it decoded, the report travelling the uplink); None never skips, as on the
    virtual clock.

    Two ways to follow it:

    * :meth:`frame_for`, closed form: which frame a display tick shows. Only for an ideal link
      (no jitter, no bandwidth cap) that never skips, where nothing depends on frame sizes;
    * :meth:`next_due` and :meth:`sent`, stateful: for any link, frame by frame, since under a
      cap a frame's size decides when it arrives. On an ideal link both give the same frames.
    """

    POSE_BYTES = 80   # a Pose message on the wire (framing header included)

    def __init__(self, rate_hz: float, server_fps: float = 10.0, up: LinkParams = LinkParams(),
                 down: LinkParams = LinkParams(), server_delay_ms: float = 20.0, seed: int = 0,
                 max_in_flight: int | None = None):
        self.rate_hz, self.server_fps, self.up_params, self.down_params = rate_hz, server_fps, up, down
        self.tick_us = int(round(1e6 / rate_hz))
        self.interval_us = int(round(1e6 / server_fps))
        self.delay_us = int(round(server_delay_ms * 1000))
        self.up, self.down = LinkModel(up, seed=2 * seed), LinkModel(down, seed=2 * seed + 1)
        self.max_in_flight = max_in_flight
        self._pose_arrivals: list[int] = []    # per display tick, in order
        self._sent: list[tuple[int, int]] = []  # (render us, arrival us) of every frame sent
        # Pre-roll: the first frames are rendered before the window starts (from its first pose),
        # so that the first display tick has a frame whatever the latency.
        lead = self.delay_us + self.down._delay_us + self.down._jitter_us + 2 * self.interval_us
        self._next_render = -(-lead // self.interval_us) * -self.interval_us
        self._pose_i = 0
        self.skipped = 0

    @classmethod
    def round_trip(cls, rate_hz: float, latency_ms: float = 128.0, server_fps: float = 10.0,
                   server_delay_ms: float = 20.0) -> "SessionSchedule":
        """An ideal link with ``latency_ms`` round trip, split evenly between the directions."""
        half = LinkParams(latency_ms / 2)
        return cls(rate_hz, server_fps, half, half, server_delay_ms)

    @property
    def ideal(self) -> bool:
        """No jitter, no bandwidth cap, no skipped frames: :meth:`frame_for` applies."""
        return (self.max_in_flight is None and not any(
            p.jitter_ms != 0 or p.capped for p in (self.up_params, self.down_params)))

    def frame_for(self, t_us: int) -> tuple[int, int]:
        """-> (render time, client time of the pose used) of the frame shown at display time
        ``t_us``, on an ideal link (:attr:`ideal`). Times before the window's start are the
        pre-roll's: their poses are the window's first."""
        if not self.ideal:
            raise ValueError("frame_for needs an ideal link (no jitter, no cap, no skipped frames); "
                             "follow the schedule with next_due and sent")
        render = ((t_us - self.delay_us - self.down._delay_us) // self.interval_us) * self.interval_us
        return render, self.pose_for(render)

    def pose_for(self, render_us: int) -> int:
        """Client time of the pose the frame rendered at ``render_us`` uses, on an ideal link."""
        return ((render_us - self.up._delay_us) // self.tick_us) * self.tick_us

    def _pose_arrival(self, i: int) -> int:
        while len(self._pose_arrivals) <= i:
            k = len(self._pose_arrivals)
            self._pose_arrivals.append(self.up.arrival_us(k * self.tick_us, self.POSE_BYTES))
        return self._pose_arrivals[i]

    def _pose_tick(self, render_us: int) -> int:
        """Client time of the newest pose that reached the server by ``render_us`` (0 if none);
        render times only grow, and so do arrivals (the link is FIFO)."""
        while self._pose_arrival(self._pose_i + 1) <= render_us:
            self._pose_i += 1
        return self._pose_i * self.tick_us

    def next_due(self, t_us: int):
        """The next server frame to render whose send time is at or before display time ``t_us``:
        (render us, client us of its pose), or None; frames skipped on the way are counted in
        ``skipped``. Report each with :meth:`sent` before asking for the next."""
        while self._next_render + self.delay_us <= t_us:
            r = self._next_render
            self._next_render += self.interval_us
            if self.max_in_flight is not None:
                known = sum(1 for _, a in self._sent if a + self.up.min_delay_us <= r)
                if len(self._sent) - known >= self.max_in_flight:
                    self.skipped += 1
                    continue
            return r, self._pose_tick(r)
        return None

    def sent(self, render_us: int, nbytes: int) -> int:
        """Record the frame rendered at ``render_us`` of ``nbytes`` on the wire -> its arrival us."""
        arrival = self.down.arrival_us(render_us + self.delay_us, nbytes)
        self._sent.append((render_us, arrival))
        return arrival
