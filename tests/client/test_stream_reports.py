"""What a client of an adapting stream measures for its reports (client/app.py, issue 28): the
link's rate from frames that arrived while the link was busy with them, and whether a frame
arrived queued past the threshold (the report then goes at once)."""
from types import SimpleNamespace

import pytest

from pibr.client.app import MAX_STAGE_MS, Client, stream_left_us
from pibr.protocol.age_baseline import AgeBaseline
from pibr.protocol.messages import STREAM_BASELINE_S, STREAM_QUEUE_HIGH_MS


def _client():
    return SimpleNamespace(_stream_ages=AgeBaseline(STREAM_BASELINE_S * 1e6), _stream_urgent=False, _link_bits_us=[0.0, 0.0],
                           _stream_arrived=[])


def _arrive(c, render_ms, arrival_ms, size):
    Client._stream_arrival(c, int(arrival_ms * 1000), int((arrival_ms - render_ms) * 1000), size)


def test_frames_arriving_back_to_back_measure_the_link_and_idle_gaps_do_not():
    c = _client()
    # 10 fps, each frame 90 ms after it was rendered: the link idles between them
    for k in range(5):
        _arrive(c, 100 * k, 100 * k + 90, 100_000)
    assert c._link_bits_us == [0.0, 0.0] and not c._stream_urgent
    # the link slows to 4 Mbit/s: 125 kB frames take 250 ms each, rendered every 100 ms, and
    # from the third on each waits behind the one before it
    arrivals = [590, 840, 1090, 1340, 1590]
    for k, a in enumerate(arrivals):
        _arrive(c, 500 + 100 * k, a, 125_000)
    bits, gaps_us = c._link_bits_us
    # the second one followed a link idle since the first (which arrived before the second could
    # have): only the last three measure it, 1 Mbit each over 250 ms
    assert bits == 3 * 1_000_000 and gaps_us == 3 * 250_000
    assert 1e3 * bits / gaps_us == pytest.approx(4000.0)


def test_a_frame_queued_past_the_threshold_makes_the_report_urgent():
    c = _client()
    for k in range(3):
        _arrive(c, 100 * k, 100 * k + 90, 50_000)
    _arrive(c, 300, 300 + 90 + STREAM_QUEUE_HIGH_MS - 1, 50_000)
    assert not c._stream_urgent
    _arrive(c, 400, 400 + 90 + STREAM_QUEUE_HIGH_MS + 1, 50_000)
    assert c._stream_urgent
    assert [size for _, size in c._stream_arrived] == [50_000] * 5


def _frame(render_ms, stages_ms):
    return SimpleNamespace(render_t_us=int(render_ms * 1000), timings_ms=tuple(stages_ms))


def test_on_the_wall_clock_a_busy_server_is_not_read_as_a_queue():
    """A server whose frames take 60 ms to make, then 260 (its core busy), on a link that takes
    30 ms: the ages the reports give stay at the link's, so no report goes at once, where the age
    from the render alone would grow by the 200 ms the server took."""
    c = _client()
    for k in range(12):
        stages = (40.0, 1.0, 4.0, 15.0) if k < 8 else (240.0, 1.0, 4.0, 15.0)
        f = _frame(100 * k, stages)
        arrival_us = f.render_t_us + int(1000 * (sum(stages) + 30))
        Client._stream_arrival(c, arrival_us, arrival_us - stream_left_us(f, wall_clock=True), 50_000)
    assert not c._stream_urgent
    assert [age for age, _ in c._stream_arrived] == [30_000] * 12
    # the same frames counted from their render: the last four queued 200 ms, past the threshold
    old = _client()
    for k in range(12):
        stages = (40.0, 1.0, 4.0, 15.0) if k < 8 else (240.0, 1.0, 4.0, 15.0)
        arrival_us = 100_000 * k + int(1000 * (sum(stages) + 30))
        Client._stream_arrival(old, arrival_us, arrival_us - 100_000 * k, 50_000)
    assert old._stream_urgent


def test_the_virtual_clock_counts_from_the_render_and_bogus_stage_times_count_as_none():
    f = _frame(500, (40.0, 1.0, 4.0, 15.0))
    assert stream_left_us(f, wall_clock=False) == 500_000
    assert stream_left_us(f, wall_clock=True) == 560_000
    bogus = _frame(500, (float("nan"), float("inf"), -5.0, 20_000.0))
    assert stream_left_us(bogus, wall_clock=True) == 500_000
    assert stream_left_us(_frame(500, (MAX_STAGE_MS, 0.0, 0.0, 0.0)), wall_clock=True) == 500_000 + 1000 * MAX_STAGE_MS
