"""The stream's adaptation to its link (server/stream_adaptation.py, issue 28 item 2): the
controller against scripted reports, the H.264 encoder's new targets, and a session through a
relay whose bandwidth drops."""
import numpy as np
import pytest

from pibr.protocol.errors import MalformedMessage
from pibr.protocol.messages import decode_stream_rate, encode_stream_rate
from pibr.server.stream_adaptation import (CONGESTED, DIP_SHARE, FLOOR, HOLD, HOLD_S, LADDER, MAX_EVERY, OUTAGE,
                                           PROBE, PROBE_GAIN, PROBE_SHARE, RECEIVED_CAP, RECOVERED, START,
                                           START_GAIN, StreamAdaptation)


#: The link of the ladder's integration test (kbit/s) and how long its client runs (s).
LINK_KBPS, LADDER_S = 100, 6.0


def _steady(a, t0, t1, age_ms=90.0, kbps=8000.0, step=0.2):
    t = t0
    while t < t1 - 1e-9:
        a.report(t, age_ms, kbps)
        t += step
    return t


def test_a_link_with_room_keeps_the_whole_rate():
    a = StreamAdaptation(8000.0)
    _steady(a, 0.0, 5.0)
    assert a.choice.video_kbps == 8000.0 and a.choice.every == 1
    assert a.reasons["congested"] == a.reasons["outage"] == 0


def test_a_queue_brings_the_colour_under_what_arrived_and_holds_before_the_next_decrease():
    a = StreamAdaptation(8000.0)
    t = _steady(a, 0.0, 2.0)
    c = a.report(t, 90.0 + 300.0, 3000.0)        # 300 ms queued, 3 Mbit/s arrived
    assert c.reason == CONGESTED
    assert c.video_kbps == pytest.approx(3000.0 * (1 - 0.3 - 0.1))   # drains the queue within about a second
    held = a.report(t + 0.2, 90.0 + 500.0, 3000.0)   # the frames queued before it arrive older still: held
    assert held.video_kbps == c.video_kbps and held.reason != CONGESTED
    held = a.report(t + HOLD_S + 0.2, 90.0 + 400.0, 3000.0)   # the hold is 0.6 s and the queue's 0.3 s
    assert held.video_kbps == c.video_kbps and held.reason != CONGESTED
    again = a.report(t + HOLD_S + 0.31, 90.0 + 320.0, 2900.0)
    assert again.reason == CONGESTED and again.video_kbps < c.video_kbps
    # the link itself slower: down again before the hold ends (the link's rate is what arrived
    # over the last second of reports that found frames queued), and under it within a second
    times = [t + HOLD_S + 0.51 + 0.2 * i for i in range(5)]
    worse = [a.report(u, 90.0 + 320.0, 1000.0) for u in times]
    first = next(u for u, c in zip(times, worse) if c.reason == CONGESTED)
    assert first < t + HOLD_S + 0.31 + HOLD_S + 0.32 and worse[-1].video_kbps / worse[-1].every < 1000.0


def test_a_link_far_under_the_floor_takes_the_stream_down_the_ladder_in_one_decrease():
    """The link measures 300 kbit/s, far under the floor of 800: one report takes the stream to the
    first rung whose floor fits what it may send (a frame every 4 ticks at half the view), not one
    rung per decrease with a hold between (the queue grows meanwhile)."""
    a = StreamAdaptation(8000.0)
    t = _steady(a, 0.0, 3.0)
    assert (a.choice.every, a.choice.view) == (1, 1)
    c = a.report(t, 90.0 + 300.0, 300.0, link_kbps=300.0)
    assert c.reason == FLOOR and (c.every, c.view) == LADDER[-1]
    # on the wire, the share of the link that drains 300 ms of queue: 180 kbit/s, 720 at a frame in 4
    assert c.video_kbps == pytest.approx(4 * 300.0 * (1 - 0.3 - 0.1)) and c.video_kbps > a.rung_floor_kbps(len(LADDER) - 1)
    # a link that fits the second rung's floor stops there
    b = StreamAdaptation(8000.0)
    t = _steady(b, 0.0, 3.0)
    c = b.report(t, 90.0 + 150.0, 1000.0, link_kbps=1000.0)          # may send 750 on the wire
    assert c.reason == FLOOR and (c.every, c.view) == LADDER[1] and c.video_kbps == pytest.approx(2 * 750.0)


def _outage(a, t, reports=30):
    """``reports`` reports where nothing arrives (the newest frame ages) -> (t, colour kbit/s,
    every, view of each choice)."""
    kbps, everies, views = [], [], []
    for i in range(reports):
        c = a.report(t, 90.0 + 200.0 + 200.0 * i, 0.0)
        kbps.append(c.video_kbps)
        everies.append(c.every)
        views.append(c.view)
        t += 0.2
    return t, kbps, everies, views


def test_an_outage_halves_then_steps_down_the_ladder_and_comes_back_in_a_slow_start():
    a = StreamAdaptation(8000.0)
    t = _steady(a, 0.0, 2.0)
    t, kbps, everies, views = _outage(a, t)
    assert a.reasons["outage"] >= 3 and kbps[0] == 4000.0
    assert a.floor_kbps == 800.0 and kbps.index(800.0) < everies.index(2)   # the floor first, then the ladder
    # an outage measures nothing: one rung a decrease, the frame rate halving, then the view (its
    # floor halves), then the frame rate again
    steps = [(e, v) for k, (e, v) in enumerate(zip(everies, views)) if k == 0 or (e, v) != (everies[k - 1], views[k - 1])]
    assert steps == list(LADDER) and a.reasons["floor"] == len(LADDER) - 1
    assert min(kbps) == a.rung_floor_kbps(len(LADDER) - 1) == 400.0
    assert everies[-1] == MAX_EVERY == 4 and views[-1] == 2
    reasons, climbed = [], []
    for _ in range(20):                           # the link is back: nothing queued, all of it carried
        c = a.report(t, 90.0, a.choice.video_kbps / a.choice.every)
        reasons.append(c.reason)
        climbed.append((c.every, c.view, c.video_kbps))
        t += 0.2
    # the outage was a dip, not a slower link: once it cleared (the hold over), back to the rate
    # before it in a slow start, a rung a report and then START_GAIN a report, in 2 s rather than
    # the probes' many seconds
    cleared = reasons.index(RECOVERED)
    assert cleared <= HOLD_S / 0.2 and set(reasons[:cleared]) == {HOLD}
    back = next(k for k, (e, v, kb) in enumerate(climbed) if (e, v, kb) == (1, 1, 8000.0))
    gains = int(np.ceil(np.log(8000.0 / a.rung_floor_kbps(0)) / np.log(START_GAIN)))
    assert back == cleared + len(LADDER) - 1 + gains
    assert all(c == (1, 1, 8000.0) for c in climbed[back:]) and not a.starting
    # each step up at most doubles the rate on the wire (a rung: twice the frames, or the view's
    # side twice), and every rung is at least its floor
    wire = [k / e for e, _, k in climbed]
    assert all(after <= 2.0 * before * (1 + 1e-9) for before, after in zip(wire, wire[1:]))
    assert all(k >= a.floor_kbps / v * (1 - 1e-9) for _, v, k in climbed)


def test_a_slower_link_is_no_dip_and_the_stream_climbs_back_by_probes():
    """A link that still carries more than DIP_SHARE of the stream when it queues got slower: after
    the decrease the stream probes up within what arrives, one rung at a time, no slow start."""
    a = StreamAdaptation(8000.0)
    t = _steady(a, 0.0, 3.0)
    c = a.report(t, 90.0 + 400.0, 3000.0, link_kbps=3000.0)
    assert c.reason == CONGESTED and not a.starting
    t += 1.5
    for _ in range(30):
        c = a.report(t, 90.0, a.choice.video_kbps / a.choice.every)
        assert not a.starting and c.reason in (HOLD, PROBE)
        t += 0.2
    assert a.choice.video_kbps == 8000.0
    # the same queue with next to nothing arriving is a dip: a slow start back once it clears
    b = StreamAdaptation(8000.0)
    t = _steady(b, 0.0, 3.0)
    b.report(t, 90.0 + 400.0, DIP_SHARE * 8000.0 * 0.9, link_kbps=3000.0)
    t += 1.5
    assert b.report(t, 90.0, b.choice.video_kbps).reason == RECOVERED and b.starting
    # a slow start that overshoots a slow link finds next to nothing arriving too: it ends there,
    # no dip to come back from (else it would climb back to its own overshoot)
    s = StreamAdaptation(8000.0)
    t = _steady(s, 0.0, 1.0)
    assert s.starting and s.choice.video_kbps > 1000.0
    assert s.report(t, 90.0 + 400.0, 100.0).reason in (CONGESTED, FLOOR) and not s.starting
    t += 1.5
    for _ in range(10):
        s.report(t, 90.0, s.choice.video_kbps / s.choice.every)
        assert not s.starting
        t += 0.2


def test_probes_stay_within_half_again_what_arrives():
    """The encoder takes a new target only at its next group of pictures: while what arrives stays
    at 3 Mbit/s, probing stops at 1.5 times it instead of climbing to the session's 16."""
    a = StreamAdaptation(16000.0)
    t = _steady(a, 0.0, 1.0, kbps=16000.0)
    a.report(t, 90.0 + 300.0, 3000.0)            # congested: down to what arrived, less a share
    t += 0.2
    for _ in range(40):                          # nothing queued, 3 Mbit/s keeps arriving
        a.report(t, 90.0, 3000.0)
        t += 0.2
    assert a.reasons["probe"] > 0
    assert a.choice.video_kbps == pytest.approx(RECEIVED_CAP * 3000.0)


def test_frames_sent_that_are_overdue_make_the_backlog_the_arrived_ones_do_not_yet_show():
    """The link halves: the first frame arrives just past the queue threshold, but the frames sent
    after it at the old rate are already late (sent longer ago than the least age, not arrived).
    Their bits over the link's rate are the backlog: the colour drops at once as far as a queue of
    that length asks, not as far as the first frame's 120 ms. Without the newest frame id the
    report is read as before."""
    def run(with_frames):
        a = StreamAdaptation(16000.0)
        t, frame = 0.0, 0
        while t < 2.0 - 1e-9:                      # 10 fps, 1.6 Mbit a frame, each arrives 90 ms later
            a.sent(frame, t, 1_600_000)
            if t >= 0.1:
                a.report(t, 90.0, 16000.0, newest_frame=frame - 1 if with_frames else None)
            t, frame = round(t + 0.1, 6), frame + 1
        for k in range(5):                         # the link drops to 8 Mbit/s at 2.0 s: five more go out
            a.sent(frame + k, 2.0 + 0.1 * k, 1_600_000)
        # at 2.4 s the client has frame 19 (sent at 1.9, 210 ms old): 20..23 are overdue
        return a.report(2.4, 210.0, 8000.0, link_kbps=8000.0, newest_frame=frame - 1 if with_frames else None)

    backlog, arrived_only = run(True), run(False)
    assert backlog.reason == arrived_only.reason == CONGESTED
    # overdue: frames 20, 21, 22, 23 (sent by 2.3 = 2.4 - 90 ms), 20 on the wire: the 4.8 Mbit
    # behind it at 8 Mbit/s are 600 ms queued
    assert backlog.video_kbps == pytest.approx(8000.0 * 0.3)          # the least share: drain at once
    assert arrived_only.video_kbps == pytest.approx(8000.0 * (1 - 0.12 - 0.1))


def test_a_report_with_no_arrival_reads_the_queue_from_the_frame_sent_after_the_newest_not_its_age():
    """At a frame every 4 ticks, a report between two frames finds nothing arrived and the newest
    frame 300 ms old: that is the gap between frames, not a queue (it once read as congestion and
    kept such a stream at the ladder's foot). A frame sent after the newest and not arrived is one:
    its age now (the newest's less the 400 ms between them) less the least age. The same with the
    client's clock 7 s off the server's (on the wall clock the ages hold the offset; the server's
    own clock must not be mixed with them: that kept every wall-clock stream at the foot)."""
    for offset_ms in (0.0, -7000.0, 7000.0):
        a = StreamAdaptation(16000.0)
        t, frame = 0.0, 0
        while t < 3.0 - 1e-9:      # the foot's rung: a frame every 0.4 s, each arriving 90 ms later
            a.sent(frame, t, 80_000)
            a.report(t + 0.09, 90.0 + offset_ms, 800.0, newest_frame=frame)
            t, frame = round(t + 0.4, 6), frame + 1
        before = a.choice
        # 0.3 s after the newest frame was made, nothing sent since: no queue
        between = a.report(t - 0.1, 300.0 + offset_ms, 0.0, newest_frame=frame - 1)
        assert between.reason not in (CONGESTED, OUTAGE) and between.video_kbps >= before.video_kbps
        a.sent(frame, t, 80_000)
        # 50 ms after the next was sent: on its way, not queued (it takes 90)
        on_way = a.report(t + 0.05, 450.0 + offset_ms, 0.0, newest_frame=frame - 1)
        assert on_way.reason not in (CONGESTED, OUTAGE), offset_ms
        # 0.35 s after the next was sent (0.75 s after the newest): 350 - 90 ms queued
        late = a.report(t + 0.35, 750.0 + offset_ms, 0.0, newest_frame=frame - 1)
        assert late.reason in (CONGESTED, OUTAGE), offset_ms


def test_the_clients_measure_of_the_link_is_its_rate_and_reports_weigh_by_their_span():
    a = StreamAdaptation(8000.0)
    t = _steady(a, 0.0, 2.0, kbps=8000.0)
    c = a.report(t, 90.0 + 300.0, 6000.0, link_kbps=2500.0)   # 6 Mbit/s arrived, the link carries 2.5
    assert c.reason == CONGESTED and c.video_kbps == pytest.approx(2500.0 * (1 - 0.3 - 0.1))
    b = StreamAdaptation(16000.0)
    t = _steady(b, 0.0, 2.0, kbps=2000.0)          # 2 Mbit/s arrives in reports of 200 ms
    b.report(t + 0.1, 90.0, 40000.0, span_ms=50.0)  # one frame in a report sent early: a burst, not a rate
    # the last second of reports, each weighed by its span (an average of rates would say 9.6 Mbit/s)
    assert b.received_kbps == pytest.approx((0.8 * 2000.0 + 0.05 * 40000.0) / 0.85)


def test_the_baseline_is_the_least_age_so_a_clock_offset_cancels():
    a, b = StreamAdaptation(8000.0), StreamAdaptation(8000.0)
    for i in range(40):
        age = 90.0 + (250.0 if 20 <= i < 25 else 0.0)
        ca = a.report(i * 0.2, age, 5000.0)
        cb = b.report(i * 0.2, age - 7_654_321.0, 5000.0)   # another clock's zero
        assert ca == cb


def test_the_stream_rate_payload_round_trips_and_refuses_bad_bytes():
    assert encode_stream_rate(4000, 2, CONGESTED, 2) == b"\xa0\x0f\x00\x00\x02\x03\x02"
    assert encode_stream_rate(4000, 2, CONGESTED) == b"\xa0\x0f\x00\x00\x02\x03\x01"   # the whole view
    assert decode_stream_rate(b"\xa0\x0f\x00\x00\x02\x03\x02") == (4000, 2, CONGESTED, 2)
    for bad, why in ((b"\xa0\x0f\x00\x00\x02\x03", "7 bytes"), (b"\xa0\x0f\x00\x00\x00\x03\x01", "every 0"),
                     (b"\xa0\x0f\x00\x00\x02\x03\x00", "1/0")):
        with pytest.raises(MalformedMessage, match=why):
            decode_stream_rate(bad)
    for every, view in ((0, 1), (1, 0)):
        with pytest.raises(ValueError):
            encode_stream_rate(4000, every, FLOOR, view)
    assert OUTAGE != CONGESTED


def test_a_new_target_far_below_restarts_x264_at_once_and_near_it_waits_for_the_group():
    from pibr.server.video import H264Encoder

    def frame(i):   # noise anew each frame: x264 spends all it is given
        y = np.random.default_rng(i).integers(0, 256, (64, 128), dtype=np.uint8)
        return np.concatenate([y, np.full((32, 128), 128, np.uint8)])
    enc = H264Encoder(128, 64, 10.0, 2000.0, keyint=30, deterministic=True)
    sizes, keys = [], []
    for i in range(12):
        if i == 6:
            enc.retarget(1800.0)          # within the keep range: no keyframe
        data, key = enc.encode(frame(i))
        sizes.append(len(data)); keys.append(key)
    assert keys == [True] + [False] * 11
    enc.retarget(300.0)                   # far below: x264 starts again
    after = [enc.encode(frame(12 + i)) for i in range(10)]
    assert after[0][1] and not any(k for _, k in after[1:])
    mean_before = np.mean(sizes[3:]) * 8 * 10 / 1000
    mean_after = np.mean([len(d) for d, _ in after[3:]]) * 8 * 10 / 1000
    assert mean_after < 0.4 * mean_before and mean_after < 300.0 * 1.6


def test_small_steps_that_add_up_far_from_the_running_target_restart_x264():
    """Each step within the keep range of the one before, together far from what x264 runs at:
    compared with the last target asked for, x264 ran at the first until its next group."""
    from pibr.server.video import RETARGET_KEEP, H264Encoder

    enc = H264Encoder(128, 64, 10.0, 2000.0, keyint=30, deterministic=True)
    grey = np.full((96, 128), 128, np.uint8)
    assert enc.encode(grey)[1]
    kbps = 2000.0
    for _ in range(3):                    # 0.9 ** 3 = 0.73 of the running target
        kbps *= 0.9
        assert kbps / 2000.0 < RETARGET_KEEP[1]
        enc.retarget(kbps)
    assert enc.encode(grey)[1] and enc.applied_kbps == kbps
    enc.retarget(kbps * 1.2)              # near the running target again: no keyframe
    assert not enc.encode(grey)[1] and enc.applied_kbps == kbps
    enc.retarget(kbps * 1.2, at_once=True)   # the slow start's: at the next frame all the same
    assert enc.encode(grey)[1] and enc.applied_kbps == kbps * 1.2


def test_a_link_measured_on_the_proxies_starts_the_stream_at_half_its_rate():
    """StreamAdaptation.probe: the stream starts at PROBE_SHARE of the rate the proxy bundle
    measured, on the first rung from the top whose floor fits it, with no slow start (the link is
    known): it probes from there within what arrives. A probe after the first report, or one that
    measured nothing, changes nothing."""
    a = StreamAdaptation(16000.0)
    c = a.probe(10000.0)
    assert (c.every, c.view, c.reason) == (1, 1, START) and c.video_kbps == pytest.approx(PROBE_SHARE * 10000.0)
    assert not a.starting and a.rung == 0
    up = a.report(0.0, 90.0, 5000.0)           # nothing queued: a probe, not the slow start's half again
    assert up.reason == PROBE and up.video_kbps == pytest.approx(5000.0 * PROBE_GAIN)
    assert a.probe(1000.0) == up               # reports came first: the probe is too late
    assert StreamAdaptation(16000.0).probe(40000.0).video_kbps == 16000.0   # never past the session's bitrate
    # a link slower than the floor (1600 kbit/s): down the ladder to the first rung that fits
    slow = StreamAdaptation(16000.0)
    c = slow.probe(1000.0)
    rung = LADDER.index((c.every, c.view))
    assert rung > 0 and slow.rung_floor_kbps(rung - 1) > PROBE_SHARE * 1000.0 * LADDER[rung - 1][0]
    assert c.video_kbps == pytest.approx(max(PROBE_SHARE * 1000.0 * c.every, slow.rung_floor_kbps(rung)))
    # measured nothing, or a client's nonsense: the ladder's foot, as without a probe
    for bad in (0.0, -5.0, float("nan"), float("inf")):
        none = StreamAdaptation(16000.0)
        assert none.probe(bad) == StreamAdaptation(16000.0).choice and (none.choice.every, none.choice.view) == LADDER[-1]


def test_a_stream_starts_at_the_ladders_foot_and_climbs_at_once_until_frames_queue():
    """The slow start: from the ladder's last rung at its floor, a rung up each report that finds
    nothing queued, then the target half again each report, with no cap from what arrived (each
    step reaches x264 at once), until a report finds frames queued; then the usual probes, within
    half again what arrives."""
    a = StreamAdaptation(16000.0)
    first = a.choice
    assert (first.every, first.view) == LADDER[-1] and first.video_kbps == a.rung_floor_kbps(len(LADDER) - 1) == 800.0
    assert a.starting
    t, climbed = 0.0, []
    for _ in range(len(LADDER) + 2):
        c = a.report(t, 90.0, 100.0)                # little arrived yet: no cap
        climbed.append((c.every, c.view, c.video_kbps))
        t += 0.2
    rungs = [(e, v) for e, v, _ in climbed]
    assert rungs[:len(LADDER) - 1] == list(reversed(LADDER[:-1])) and a.starting
    assert [k for _, _, k in climbed[len(LADDER) - 1:]] == pytest.approx([1600.0 * START_GAIN ** k for k in (1, 2, 3)])
    held = a.report(t, 90.0 + 60.0, 12000.0)      # 60 ms queued: the slow start ends, held
    assert not a.starting and held.reason != PROBE and held.video_kbps == climbed[-1][2]
    later = [a.report(t + 0.2 * k, 90.0, 12000.0) for k in range(1, 16)]   # room again: the usual probes
    steps = [b.video_kbps / c.video_kbps for c, b in zip([held] + later, later)]
    assert max(steps) == pytest.approx(PROBE_GAIN) and later[-1].video_kbps == 16000.0
    # a stream that reaches the session's bitrate ends its slow start there
    b = StreamAdaptation(16000.0)
    for k in range(len(LADDER) + 6):
        b.report(0.2 * k, 90.0, 100.0)
    assert b.choice.video_kbps == 16000.0 and not b.starting


@pytest.mark.gl
async def test_through_a_link_that_drops_the_adapting_stream_keeps_its_frames_young(tmp_path):
    """Server, relay and client in one process on the virtual clock: the downlink carries 20
    Mbit/s for a second, then 1.2 Mbit/s, about half the stream. Without adaptation the frames
    queue and age by the second; with it the colour's target starts low and climbs, then falls (the
    records say to what), the queue drains and the age comes back. The run is reproducible: a second one records the same."""
    from pibr.client.app import run_client
    from pibr.client.config import ClientConfig
    from pibr.client.recorder import read_records
    from pibr.common.bandwidth import parse_rate_csv
    from pibr.server.config import ServerConfig

    from ..loopback import server_behind_relay

    trace = parse_rate_csv("0,20000\n1,1200\n60,1200\n")
    runs = []
    for adapt in ("off", "on", "on"):
        config = ServerConfig(port=0, scene="room", view_size=(192, 192), bitrate_kbps=2400, adapt=adapt)
        async with server_behind_relay(config, down_trace=trace) as (host, port):
            out = tmp_path / f"run{len(runs)}"
            await run_client(ClientConfig(host=host, port=port, trace="pred6dof-1", start_s=12.0, duration_s=4.0,
                                          rate_hz=30.0, methods=("rotation",), out_dir=str(out), width=96,
                                          height=64, progress="none"))
        runs.append(read_records(out / "rotation.records.csv"))
    off, on, again = runs
    late = lambda rows: [r["age_ms"] for r in rows if r["t"] >= 3.2]
    assert min(late(off)) > 1000.0                   # queued: a second old and growing
    assert max(late(on)) < 400.0                     # drained: the delays and a frame interval
    assert max(r["age_ms"] for r in on) < 0.8 * max(r["age_ms"] for r in off)
    assert {r["stream_kbps"] for r in off} == {-1}
    kbps = [r["stream_kbps"] for r in on if r["frame_id"] >= 0]
    # it starts at the ladder's foot, climbs while the link has room, then falls under what the link carries
    assert kbps[0] == 240 / LADDER[-1][1] and max(kbps) > 240 and max(kbps[-10:]) < 1200
    strip = lambda rows: [{k: v for k, v in r.items() if k != "client_ms"} for r in rows]
    assert strip(on) == strip(again)


@pytest.mark.gl
async def test_the_link_measured_on_the_proxies_is_where_the_stream_starts(tmp_path):
    """Server, relay and client on the virtual clock, the downlink at 6 Mbit/s: the relay stamps the
    Welcome and the proxy bundle with their arrival through the link, the client measures the link
    on them (the bundle's bits over the time from the Welcome's arrival to its last chunk's) and
    tells the server. With --adapt-start probe the stream starts at PROBE_SHARE of that rate on the
    whole view; with the default, foot, at the ladder's foot all the same."""
    import json

    from pibr.client.app import run_client
    from pibr.client.config import ClientConfig
    from pibr.client.recorder import read_records
    from pibr.common.bandwidth import parse_rate_csv
    from pibr.server.config import ServerConfig

    from ..loopback import server_behind_relay

    trace = parse_rate_csv("0,6000\n")
    first, probes = {}, {}
    for start in ("probe", "foot"):
        config = ServerConfig(port=0, scene="room", view_size=(192, 192), bitrate_kbps=16000, adapt="on",
                              adapt_start=start)
        out = tmp_path / start
        async with server_behind_relay(config, down_trace=trace) as (host, port):
            await run_client(ClientConfig(host=host, port=port, trace="pred6dof-1", start_s=12.0, duration_s=1.0,
                                          rate_hz=30.0, methods=("proxy",), out_dir=str(out), width=96, height=64,
                                          progress="none"))
        first[start] = next(r for r in read_records(out / "proxy.records.csv") if r["frame_id"] >= 0)
        probes[start] = json.loads((out / "session.json").read_text())["proxies"]["probe_kbps"]
    assert probes["probe"] == pytest.approx(6000.0, rel=0.05) and probes["foot"] == pytest.approx(probes["probe"])
    assert first["probe"]["stream_kbps"] == round(PROBE_SHARE * probes["probe"]) and first["probe"]["stream_view"] == 1
    assert first["foot"]["stream_kbps"] == 1600 / LADDER[-1][1] and first["foot"]["stream_view"] == 2


@pytest.mark.gl
async def test_a_bundle_that_took_no_time_starts_the_stream_at_its_bitrate(tmp_path):
    """On the virtual clock with no modelled link (no relay) the proxy bundle arrives in no time:
    the client reports a link with room for anything (MAX_BANDWIDTH_KBPS), and --adapt-start probe
    starts the stream at the session's bitrate on the whole view, with no slow start."""
    import json

    from pibr.client.app import run_client
    from pibr.client.config import ClientConfig
    from pibr.client.recorder import read_records
    from pibr.protocol.messages import MAX_BANDWIDTH_KBPS
    from pibr.server.config import ServerConfig

    from ..loopback import running_server

    config = ServerConfig(port=0, scene="room", view_size=(192, 192), bitrate_kbps=16000, adapt="on",
                          adapt_start="probe")
    async with running_server(config) as (_, host, port):
        await run_client(ClientConfig(host=host, port=port, trace="pred6dof-1", start_s=12.0, duration_s=0.5,
                                      rate_hz=30.0, methods=("proxy",), out_dir=str(tmp_path), width=96, height=64,
                                      progress="none"))
    assert json.loads((tmp_path / "session.json").read_text())["proxies"]["probe_kbps"] == MAX_BANDWIDTH_KBPS
    shown = [r for r in read_records(tmp_path / "proxy.records.csv") if r["frame_id"] >= 0]
    assert shown and all(r["stream_kbps"] == 16000 and r["stream_view"] == 1 for r in shown)


def test_the_adapting_streams_start_is_checked():
    from pibr.protocol.errors import ConfigError
    from pibr.server.config import ServerConfig

    assert ServerConfig(adapt="on", adapt_start="probe").adapt_start == "probe"
    with pytest.raises(ConfigError, match="starts at foot or probe, got 'top'"):
        ServerConfig(adapt="on", adapt_start="top")


@pytest.mark.gl
async def test_a_link_under_the_floor_gets_fewer_frames_and_a_smaller_view_and_the_records_say_so(tmp_path, caplog):
    """Server, relay and client on the virtual clock, the downlink at LINK_KBPS, far under the
    colour's floor: the stream starts at the ladder's foot (a frame every 4 ticks, the primary view
    rendered at half its side), climbs to the whole view while frames do not queue, and goes back
    down to the rung that fits once they do (the records carry each shown frame's view, the server
    counts the ticks without a frame and the frames it made smaller)."""
    import logging
    import re

    from pibr.client.app import run_client
    from pibr.client.config import ClientConfig
    from pibr.client.recorder import read_records
    from pibr.common.bandwidth import parse_rate_csv
    from pibr.server.config import ServerConfig

    from ..loopback import server_behind_relay

    trace = parse_rate_csv(f"0,{LINK_KBPS}\n")
    config = ServerConfig(port=0, scene="room", view_size=(192, 192), bitrate_kbps=2400, adapt="on")
    with caplog.at_level(logging.INFO, logger="pibr.server.session"):
        async with server_behind_relay(config, down_trace=trace) as (host, port):
            await run_client(ClientConfig(host=host, port=port, trace="pred6dof-1", start_s=12.0, duration_s=LADDER_S,
                                          rate_hz=30.0, methods=("rotation",), out_dir=str(tmp_path), width=96,
                                          height=64, progress="none"))
    rows = [r for r in read_records(tmp_path / "rotation.records.csv") if r["frame_id"] >= 0]
    views = [r["stream_view"] for r in rows]
    # from the ladder's foot up to the whole view while the link has room, then down again
    assert views[0] == 2 and 1 in views and views[-1] == 2
    summary = [line for line in caplog.messages if "stream adaptation:" in line]
    assert len(summary) == 1
    found = re.search(r"(\d+) ticks without a frame, (\d+) with a smaller primary view", summary[0])
    thinned, shrunk = int(found.group(1)), int(found.group(2))
    assert thinned > 0 and shrunk > 0


def test_an_edge_stream_without_a_cap_codes_at_a_share_of_what_it_spent_and_comes_back():
    from pibr.protocol.depth_codecs import edge_quantizer
    from pibr.protocol.pose import Pose
    from pibr.server.depth_encoders import EdgeDepthStream

    q = edge_quantizer(0.1, 50.0)
    stream = EdgeDepthStream(64, 48, q, 10.0)          # no cap: no rate control
    yy, xx = np.mgrid[0:48, 0:64]
    def frame(i):   # boxes that move: every frame has edges to code
        d = np.full((48, 64), 8.0, np.float32)
        d[(np.abs(yy - 24) < 10) & (np.abs(xx - 10 - 3 * i) < 8)] = 2.0
        return d
    bits = [stream.encode(frame(i), Pose.identity())[1].total_bits for i in range(6)]
    assert stream.rate is None
    stream.set_share(0.25)
    assert stream.rate.target == pytest.approx(0.25 * stream._mean_bits) and stream._mean_bits > 0
    stream.set_share(1.0)
    assert stream.rate is None and len(bits) == 6
