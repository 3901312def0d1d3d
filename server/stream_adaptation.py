"""A session's stream adapted to its link: the colour's bitrate, the edge codec's rate and the
frame rate chosen from what the client reports, so that frames stay young rather than the link
full (issue 28, item 2).

The client reports every ``STREAM_REPORT_MS`` (protocol/messages.py), and at once when a frame
arrives queued more than :data:`QUEUE_HIGH_MS`: the median age at arrival of the frames that
arrived since its last report (or, when none did, the newest frame's age now), the bits they
brought over the report's interval, the link's rate measured from the frames that arrived while
the link was busy with them (each one's bits over the time since the one before arrived), and the
newest frame it has. The age less its least over the last :data:`BASELINE_S` seconds is the time
frames spent queued (the propagation and the server's own delay cancel, and so does an offset
between the two clocks). A report where nothing arrived is read from the frame sent after the
newest one the client has: its age now (the newest's less the time between the two were made),
less the least; nothing sent since, no queue (at a frame every few ticks the newest frame's age
is the gap between frames). Each report:

* queued more than :data:`QUEUE_HIGH_MS`: the link carries less than the stream. The colour's
  target goes to the link's rate, less a share that drains the queue within about a second
  (never under :data:`MIN_DRAIN_SHARE` of it; nothing delivered at all, an outage: half the
  target). Once frames queue, the queue is the larger of what the arrived frames say and the
  frames still on their way that should have arrived by the report (sent before it, less the
  least age, and after the newest frame the client has: bytes in flight, as in TCP; the first of
  them is on the wire) over the link's rate; the frames already sent at the old rate make the
  backlog, and they have not spoken yet. The link's rate
  is the client's measure when the report has one, else what arrived over the reports of the last
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
worth its bits) the stream goes down :data:`LADDER`: the frame rate halves, or the primary view
is rendered at half its side and upsampled into the atlas (the server's own smaller views,
server/producer.py), which halves the floor (smooth content keeps its quality on fewer bits). A
decrease goes at once to the first rung whose floor fits (an outage, which measures nothing: a
rung at a time). With room, the stream climbs a rung once the rung's rate on the wire is within
:data:`RECEIVED_CAP` of what arrives (as a probe is), and probes within its rung until then.

A decrease that finds the link carrying less than :data:`DIP_SHARE` of the stream on the wire (by
the client's measure, or by what arrived: the measure is of the frames before) is a dip, an outage
or a handover, rather than a slower link. Once no queue is left (:data:`HOLD_S` after the last
decrease) the stream goes back to the rate it had before the dip's decreases in a slow start, as
at its beginning: climbing back by probes took more than 9 s after the built-in outage, each
capped by what arrived, which a lower rung's encoder keeps under its target. A link that is slower
queues again on the way up, which ends the slow start as it ends the first (the decrease that
ends a slow start is no dip, whatever it finds: a slow start overshoots by design).

A stream starts at the ladder's foot, its last rung at that rung's floor, and climbs in a slow
start: a rung a report, then :data:`START_GAIN` a report, with no cap from what arrived, since
each step restarts the encoder at once (video.py); it reaches a link with room within two
seconds. The first report that finds frames queued ends it; one that finds them queued past
:data:`QUEUE_HIGH_MS` decreases as any congestion does. Starting low matters twice. The queue is
measured against the least age seen, so that least must come from frames that did not queue: a
stream that starts above its link queues from its first frame, learns a baseline that holds the
queue, and sees congestion only once it has grown past that (the `cellular` link's frames were
up to 2.2 s old in its first 4 s starting at the session's bitrate). And nothing is known of the
link before the first frame arrives: the frames sent meanwhile are all queued on a link slower
than them (starting at a quarter of 16 Mbit/s on a 300 kbit/s link, the first frame took 2.7 s
and the frames sent until the first report kept every later one 15 s old or more).

Where the client measured the link before the stream (the proxy bundle sent ahead of it, its bits
over the time from the Welcome's arrival to its last chunk's: PROBE_KBPS), with ``--adapt-start
probe`` the stream starts at :data:`PROBE_SHARE` of that rate instead, on the first rung from the
top whose floor fits it, and probes from there as on any link with room
(:meth:`StreamAdaptation.probe`): a known rate is a start that does not queue, half of it leaves
room for what one measure gets wrong, and a slow start is for a link nothing is known of. Without
proxies nothing is measured; on the virtual clock a bundle that took no time crossed no modelled
link (no relay, or one without a bandwidth trace), and the client reports MAX_BANDWIDTH_KBPS: the
stream starts at the session's bitrate, as a static one does. It is not the default:
measured on two evaluation windows and seven links it made the first seconds better in 12 of 14
runs and the age p95 higher in 7 (docs/results/network-start.json).

The edge codec's rate follows the colour's share of its bitrate. On the virtual clock the
reports are taken as of each frame's time, so the choices are reproducible. The constants are
not fitted to any trace (a declared choice, as in a delay-based congestion controller: a queue
above one frame interval is a congestion signal). :data:`DIP_SHARE` was chosen knowing the
built-in links: a quarter lies between their steps' drops (to 0.4 and 0.375 of the rate before)
and a handover's (0.05); it was judged on other draws of the cellular model (README).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from pibr.protocol.age_baseline import AgeBaseline
from pibr.protocol.messages import STREAM_BASELINE_S, STREAM_QUEUE_HIGH_MS, STREAM_REPORT_MS

#: Reason codes a frame's STREAM_RATE payload carries (index into REASONS).
REASONS = ("start", "hold", "probe", "congested", "outage", "floor", "recovered")
START, HOLD, PROBE, CONGESTED, OUTAGE, FLOOR, RECOVERED = range(len(REASONS))

BASELINE_S = STREAM_BASELINE_S
QUEUE_HIGH_MS = STREAM_QUEUE_HIGH_MS
QUEUE_LOW_MS = 40.0
PROBE_GAIN = 1.08
START_GAIN = 1.5
RECEIVED_CAP = 1.5
RECEIVED_WINDOW_S = 1.0
MIN_DRAIN_SHARE = 0.3
#: The share of the link's rate measured on the handshake (the proxy bundle) a stream starts at.
PROBE_SHARE = 0.5
#: Where a stream starts (``pibr serve --adapt-start``): its ladder's foot, or, where the client
#: measured the link on the proxies, PROBE_SHARE of it (StreamAdaptation.probe).
STARTS = ("foot", "probe")
HOLD_S = 0.6
#: A decrease whose link carries less than this share of the stream on the wire is a dip (an
#: outage, a handover), not a slower link: once it clears the stream comes back in a slow start.
DIP_SHARE = 0.25
FLOOR_SHARE = 0.1
#: The rungs under the floor, from the top: (one frame every ``every`` ticks, the primary view
#: rendered at 1/``view`` of its side). Each view step halves the floor.
LADDER = ((1, 1), (2, 1), (2, 2), (4, 2))
MAX_EVERY = max(every for every, _ in LADDER)
MAX_SENT_KEPT = 256


@dataclass(frozen=True)
class StreamChoice:
    """What the next frames are made at: the colour's target, one frame every ``every`` ticks, the
    primary view rendered at 1/``view`` of its side, and why."""

    video_kbps: float
    every: int
    reason: int
    view: int = 1

    @property
    def reason_name(self) -> str:
        return REASONS[self.reason]


class StreamAdaptation:
    """One session's stream adaptation (module docstring). Times in seconds of the session's clock."""

    def __init__(self, max_video_kbps: float, min_video_kbps: float = 16.0):
        self.max_kbps = float(max_video_kbps)
        self.floor_kbps = max(float(min_video_kbps), FLOOR_SHARE * self.max_kbps)
        # the start: the ladder's last rung at its floor (module docstring)
        self.rung = len(LADDER) - 1       # the index in LADDER of (every, view)
        every, view = LADDER[self.rung]
        self.choice = StreamChoice(min(self.max_kbps, self.rung_floor_kbps(self.rung)), every, START, view)
        #: in the slow start (module docstring): a new target should reach the encoder at once
        self.starting = True
        #: the slow start's ceiling on the wire (kbit/s): the session's bitrate, or after a dip the
        #: rate before it
        self._start_ceiling = self.max_kbps
        self._before_dip: float | None = None   # the rate on the wire before a dip, while it lasts
        self._before_decreases = self.choice.video_kbps / every   # on the wire, before the latest run of decreases
        self._ages = AgeBaseline(BASELINE_S)   # the reports' ages (ms) over BASELINE_S
        self._received: deque = deque()   # (t, kbit arrived, span s, frames queued?) within RECEIVED_WINDOW_S
        self._sent: deque = deque()       # (frame id, t sent, bits) not known to have arrived
        self._acked: tuple | None = None  # (frame id, t sent) of the newest frame the client has
        #: what arrived over the last RECEIVED_WINDOW_S of reports, each weighed by its span (kbit/s)
        self.received_kbps = 0.0
        self._last_decrease: tuple | None = None   # (t, hold s, the link's kbit/s) of the last decrease
        self._last_rung_change = float("-inf")
        self.reports = 0
        self.reasons = {name: 0 for name in REASONS}   # reports per reason

    @property
    def share(self) -> float:
        """The colour's target as a share of the session's bitrate (the edge codec's follows it)."""
        return self.choice.video_kbps / self.max_kbps

    def rung_floor_kbps(self, rung: int) -> float:
        """The least colour target at ``rung`` of LADDER: the floor, halved per view step."""
        return self.floor_kbps / LADDER[rung][1]

    def _target_at(self, rung: int, kbps: float, every: int) -> float:
        """The colour target at ``rung`` that keeps the rate on the wire of ``kbps`` made one frame
        every ``every`` ticks, at least the rung's floor."""
        return max(kbps * LADDER[rung][0] / every, self.rung_floor_kbps(rung))

    def queue_ms(self, t: float, age_ms: float) -> float:
        """Record a report's age -> the time its frames spent queued (ms)."""
        return self._ages.add(t, age_ms)

    def sent(self, frame_id: int, t: float, bits: int) -> None:
        """A frame of ``bits`` went out at ``t`` s (for the bytes in flight)."""
        self._sent.append((frame_id, t, bits))
        if len(self._sent) > MAX_SENT_KEPT:
            self._sent.popleft()

    def overdue_bits(self, t: float, newest_frame: int) -> int:
        """Bits of the frames sent after ``newest_frame`` (the newest the client has at ``t``) that
        would have arrived by ``t`` had they not queued (sent more than the least age before it),
        less the first of them: on the wire, not waiting (on a slow link a frame's own
        transmission outlasts the least age, measured when the link was fast)."""
        while self._sent and self._sent[0][0] <= newest_frame:
            frame = self._sent.popleft()
            if frame[0] == newest_frame:
                self._acked = frame[:2]
        overdue = [bits for _, sent, bits in self._sent if sent < t - self._least_s()]
        return sum(overdue[1:])

    def _least_s(self) -> float:
        # (on the real clock the least age holds the two clocks' offset too: never below 0)
        return max(0.0, self._ages.least / 1e3)

    def probe(self, link_kbps: float) -> StreamChoice:
        """Before the first report: the link's rate (kbit/s) measured on the handshake (the proxy
        bundle's bits over their time, PROBE_KBPS) -> where the stream starts: the first rung from
        the top whose floor fits :data:`PROBE_SHARE` of it on the wire, at that share, with no slow
        start (module docstring). A later probe, or one that measured nothing, changes nothing."""
        if self.reports or not math.isfinite(link_kbps) or link_kbps <= 0:
            return self.choice
        wanted = PROBE_SHARE * float(link_kbps)
        rung = 0
        while rung + 1 < len(LADDER) and self.rung_floor_kbps(rung) > wanted * LADDER[rung][0]:
            rung += 1
        every, view = LADDER[rung]
        kbps = min(self.max_kbps, max(wanted * every, self.rung_floor_kbps(rung)))
        self.rung = rung
        self.choice = StreamChoice(kbps, every, START, view)
        self._before_decreases = kbps / every
        self.starting = False   # the link is known: probes from here, each within what arrives
        return self.choice

    def report(self, t: float, age_ms: float, delivered_kbps: float, span_ms: float = STREAM_REPORT_MS,
               link_kbps: float | None = None, newest_frame: int | None = None) -> StreamChoice:
        """Take one report of the client (at ``t`` s, over its last ``span_ms``; ``link_kbps``: its
        measure of the link, if any; ``newest_frame``: the newest frame id it has) -> the choice for
        the frames that follow. Rates on the wire (what arrived, the link) are kbit/s of the
        stream as sent; the colour's target is the encoder's, made one frame every ``every`` ticks."""
        overdue = None if newest_frame is None else self.overdue_bits(t, newest_frame)
        if overdue is not None and delivered_kbps <= 0 and self._acked is not None and self._acked[0] == newest_frame:
            # Nothing arrived: the newest frame's age now tells how long ago it was made (at a
            # frame every few ticks, the gap between frames too), not how long frames queue. The
            # frame sent after it does: its age now (the newest's less the time between the two
            # were made, on the server's clock, so any offset between the clocks stays in both
            # ages and cancels against the least), less the least; nothing sent since: no queue.
            after = self._sent[0][1] if self._sent else None
            queue = 0.0 if after is None else max(0.0, age_ms - (after - self._acked[1]) * 1e3 - self._ages.least)
        else:
            queue = self.queue_ms(t, age_ms)
        was_starting = self.starting
        if queue >= QUEUE_LOW_MS or self.choice.video_kbps / self.choice.every >= self._start_ceiling * (1 - 1e-9):
            self.starting = False   # (the report after the one that reached the ceiling: that one applied at once)
        kbps, every = self.choice.video_kbps, self.choice.every
        span = max(float(span_ms), 1.0) / 1e3
        self._received.append((t, delivered_kbps * span, span, queue > QUEUE_LOW_MS))
        while self._received[0][0] <= t - RECEIVED_WINDOW_S:
            self._received.popleft()
        received = sum(k for _, k, _, _ in self._received) / sum(s for _, _, s, _ in self._received)
        self.received_kbps = received
        # What the link carries: the client's measure, else what arrived over the reports that
        # found frames queued (the link busy all along them; one report alone sees whole frames:
        # none, or one in 200 ms)
        busy = [(k, s) for _, k, s, queued in self._received if queued]
        if link_kbps is not None and link_kbps > 0:
            link = float(link_kbps)
        else:
            link = sum(k for k, _ in busy) / sum(s for _, s in busy) if busy else delivered_kbps
        if overdue and link > 0 and queue > QUEUE_LOW_MS:
            # frames queue: the backlog the frames already sent make is what they will wait
            queue = max(queue, overdue / link)   # bits / (kbit/s) = ms
        reason = HOLD
        if queue > QUEUE_HIGH_MS:
            # After a decrease the frames already queued keep arriving old: wait for them to drain
            # (the hold and the queue's own length) unless the link itself got slower still.
            worse = self._last_decrease is not None and link < 0.8 * self._last_decrease[2]
            if self._last_decrease is None or t - self._last_decrease[0] >= self._last_decrease[1] or worse:
                if self._last_decrease is None or t - self._last_decrease[0] > RECEIVED_WINDOW_S:
                    self._before_decreases = kbps / every
                # a dip: the rate before its decreases is the one to come back to (what arrived
                # says too: the client's measure of the link is of the frames before). A slow
                # start's overshoot is none: it ends the slow start.
                dip = min(link, delivered_kbps) < DIP_SHARE * kbps / every
                if dip and self._before_dip is None and not was_starting:
                    self._before_dip = self._before_decreases
                if link > 0:
                    share = max(MIN_DRAIN_SHARE, 1.0 - queue / 1000.0 - 0.1)
                    # on the wire: the stream's rate, no more than that share of the link
                    wanted = min(kbps / every, link * share)
                    rung, reason = self.rung, CONGESTED
                    # down the ladder at once to the first rung whose floor that fits
                    while rung + 1 < len(LADDER) and self.rung_floor_kbps(rung) > wanted * LADDER[rung][0]:
                        rung, reason = rung + 1, FLOOR
                    wanted *= LADDER[rung][0]
                else:
                    # nothing arrived: half the target, a rung down once it is at the floor
                    wanted, reason, rung = kbps * 0.5, OUTAGE, self.rung
                    floor = self.rung_floor_kbps(rung)
                    if wanted < floor and kbps <= floor * 1.001 and rung + 1 < len(LADDER):
                        rung, reason = rung + 1, FLOOR
                        wanted *= LADDER[rung][0] / every
                if rung != self.rung:
                    self.rung, self._last_rung_change = rung, t
                kbps = max(wanted, self.rung_floor_kbps(self.rung))
                # an outage drains nothing: only the hold
                hold = HOLD_S + (queue / 1e3 if link > 0 else 0.0)
                self._last_decrease = (t, hold, link)
        elif self.starting and queue < QUEUE_LOW_MS:
            # the slow start: up the ladder a rung a report, then the target by START_GAIN a
            # report, applied at once (``starting``), until the first report that finds frames queued
            if self.rung > 0:
                self.rung, reason, self._last_rung_change = self.rung - 1, PROBE, t
                kbps = self._target_at(self.rung, kbps, every)
            else:
                kbps, reason = min(self.max_kbps, kbps * START_GAIN, self._start_ceiling), PROBE
        elif queue < QUEUE_LOW_MS and self._before_dip is not None and t - self._last_decrease[0] >= HOLD_S:
            # a dip cleared (no queue left): back towards the rate before it in a slow start from
            # the next report on
            self.starting, self._start_ceiling, self._before_dip = True, self._before_dip, None
            reason = RECOVERED
        elif queue < QUEUE_LOW_MS and (self._last_decrease is None or t - self._last_decrease[0] >= HOLD_S):
            # room: a rung up once its rate is within RECEIVED_CAP of what arrives, else a probe
            # within the rung (both on the wire)
            up = self.rung - 1
            up_kbps = self._target_at(up, kbps, every) if up >= 0 else 0.0
            if (up >= 0 and t - self._last_rung_change >= HOLD_S
                    and up_kbps / LADDER[up][0] <= RECEIVED_CAP * received):
                self.rung, reason, self._last_rung_change = up, RECOVERED, t
                kbps = up_kbps
            elif kbps < self.max_kbps and kbps / every < RECEIVED_CAP * received:
                kbps, reason = min(self.max_kbps, kbps * PROBE_GAIN, RECEIVED_CAP * received * every), PROBE
        every, view = LADDER[self.rung]
        self.choice = StreamChoice(kbps, every, reason, view)
        self.reports += 1
        self.reasons[REASONS[reason]] += 1
        return self.choice

    def summary(self) -> dict:
        return {"reports": self.reports, "reasons": dict(self.reasons), "video_kbps": round(self.choice.video_kbps, 1),
                "every": self.choice.every, "view": self.choice.view, "max_kbps": self.max_kbps,
                "floor_kbps": self.floor_kbps}
