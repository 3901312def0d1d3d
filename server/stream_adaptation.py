"""A session's stream adapted to its link: the colour's bitrate, the edge codec's rate and the
frame rate chosen from what the client reports, so that frames stay young rather than the link
full (issue 28, item 2).

The client reports every ``STREAM_REPORT_MS`` (protocol/messages.py): the median age at arrival
of the frames that arrived since its last report (or, when none did, the newest frame's age now)
and the bits they brought over the report's interval. The age less its least over the last
:data:`BASELINE_S` seconds is the time frames spent queued (the propagation and the server's own
delay cancel, and so does an offset between the two clocks). Each report:

* queued more than :data:`QUEUE_HIGH_MS`: the link carries less than the stream. The colour's
  target goes to the link's rate, less a share that drains the queue within about a second
  (never under :data:`MIN_DRAIN_SHARE` of it; nothing delivered at all, an outage: half the
  target). The link's rate is what arrived over the reports of the last
  :data:`RECEIVED_WINDOW_S` that found frames queued: the link was busy all along them, while a
  single report sees whole frames (none, or one in 200 ms). Once a decrease was made, the next
  waits :data:`HOLD_S` and the queue's length (the frames already queued arrive old whatever the
  new rate) unless the link's rate drops further;
* queued less than :data:`QUEUE_LOW_MS`: room, probed by :data:`PROBE_GAIN` per report up to
  the session's bitrate, and never past :data:`RECEIVED_CAP` times what arrived over the last
  :data:`RECEIVED_WINDOW_S` (the bound of Google's congestion control for WebRTC, Carlucci et al.
  2016: the encoder takes a new target at its next group of pictures, seconds later, and probes
  that add up unseen meanwhile would land on the link all at once);
* in between: held.

Under the floor (:data:`FLOOR_SHARE` of the session's bitrate, where a colour atlas stops being
worth its bits) the frame rate halves instead, down to one frame in :data:`MAX_EVERY` ticks, and
comes back first when there is room. The edge codec's rate follows the colour's share of its
bitrate. On the virtual clock the reports are taken as of each frame's time, so the choices are
reproducible. The constants are not fitted to any trace (a declared choice, as in a delay-based
congestion controller: a queue above one frame interval is a congestion signal).
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

#: Reason codes a frame's STREAM_RATE payload carries (index into REASONS).
REASONS = ("start", "hold", "probe", "congested", "outage", "floor", "recovered")
START, HOLD, PROBE, CONGESTED, OUTAGE, FLOOR, RECOVERED = range(len(REASONS))

BASELINE_S = 10.0
QUEUE_HIGH_MS = 100.0
QUEUE_LOW_MS = 40.0
PROBE_GAIN = 1.08
RECEIVED_CAP = 1.5
RECEIVED_WINDOW_S = 1.0
MIN_DRAIN_SHARE = 0.3
HOLD_S = 0.6
FLOOR_SHARE = 0.1
MAX_EVERY = 4


@dataclass(frozen=True)
class StreamChoice:
    """What the next frames are made at: the colour's target, one frame every ``every`` ticks, why."""

    video_kbps: float
    every: int
    reason: int

    @property
    def reason_name(self) -> str:
        return REASONS[self.reason]


class StreamAdaptation:
    """One session's stream adaptation (module docstring). Times in seconds of the session's clock."""

    def __init__(self, max_video_kbps: float, min_video_kbps: float = 16.0):
        self.max_kbps = float(max_video_kbps)
        self.floor_kbps = max(float(min_video_kbps), FLOOR_SHARE * self.max_kbps)
        self.choice = StreamChoice(self.max_kbps, 1, START)
        self._ages: deque = deque()       # (t, age ms) of the reports within BASELINE_S
        self._received: deque = deque()   # (t, kbit/s arrived x every, frames queued?) within RECEIVED_WINDOW_S
        self._last_decrease: tuple | None = None   # (t, hold s, the link's kbit/s) of the last decrease
        self._last_every_change = float("-inf")
        self.reports = 0
        self.reasons = {name: 0 for name in REASONS}   # reports per reason

    @property
    def share(self) -> float:
        """The colour's target as a share of the session's bitrate (the edge codec's follows it)."""
        return self.choice.video_kbps / self.max_kbps

    def queue_ms(self, t: float, age_ms: float) -> float:
        """Record a report's age -> the time its frames spent queued (ms)."""
        self._ages.append((t, age_ms))
        while self._ages and self._ages[0][0] < t - BASELINE_S:
            self._ages.popleft()
        return age_ms - min(a for _, a in self._ages)

    def report(self, t: float, age_ms: float, delivered_kbps: float) -> StreamChoice:
        """Take one report of the client (at ``t`` s) -> the choice for the frames that follow."""
        queue = self.queue_ms(t, age_ms)
        kbps, every = self.choice.video_kbps, self.choice.every
        self._received.append((t, delivered_kbps * every, queue > QUEUE_LOW_MS))
        while self._received[0][0] <= t - RECEIVED_WINDOW_S:
            self._received.popleft()
        received = sum(k for _, k, _ in self._received) / len(self._received)
        # What the link carries: while frames queue it is busy all the time, so what arrived over
        # those reports is its rate (one report alone sees whole frames: none, or one in 200 ms)
        busy = [k for _, k, queued in self._received if queued]
        capacity = sum(busy) / len(busy) if busy else delivered_kbps * every
        reason = HOLD
        if queue > QUEUE_HIGH_MS:
            # After a decrease the frames already queued keep arriving old: wait for them to drain
            # (the hold and the queue's own length) unless the link itself got slower still.
            worse = self._last_decrease is not None and capacity < 0.8 * self._last_decrease[2]
            if self._last_decrease is None or t - self._last_decrease[0] >= self._last_decrease[1] or worse:
                if capacity > 0:
                    share = max(MIN_DRAIN_SHARE, 1.0 - queue / 1000.0 - 0.1)
                    # the colour's part of what arrived: the same share of it the colour had
                    wanted = min(kbps, capacity * share)
                    reason = CONGESTED
                else:
                    wanted, reason = kbps * 0.5, OUTAGE
                if wanted < self.floor_kbps:
                    if kbps <= self.floor_kbps * 1.001 and every < MAX_EVERY:
                        every, reason = every * 2, FLOOR
                        self._last_every_change = t
                    wanted = self.floor_kbps
                kbps = wanted
                # an outage drains nothing: only the hold
                hold = HOLD_S + (queue / 1e3 if capacity > 0 else 0.0)
                self._last_decrease = (t, hold, capacity)
        elif queue < QUEUE_LOW_MS and (self._last_decrease is None or t - self._last_decrease[0] >= HOLD_S):
            if every > 1 and t - self._last_every_change >= HOLD_S:
                every, reason = every // 2, RECOVERED
                self._last_every_change = t
            elif kbps < self.max_kbps and kbps < RECEIVED_CAP * received:
                kbps, reason = min(self.max_kbps, kbps * PROBE_GAIN, RECEIVED_CAP * received), PROBE
        self.choice = StreamChoice(kbps, every, reason)
        self.reports += 1
        self.reasons[REASONS[reason]] += 1
        return self.choice

    def summary(self) -> dict:
        return {"reports": self.reports, "reasons": dict(self.reasons), "video_kbps": round(self.choice.video_kbps, 1),
                "every": self.choice.every, "max_kbps": self.max_kbps, "floor_kbps": self.floor_kbps}
