"""What a client of an adapting stream measures for its reports (client/app.py, issue 28): the
link's rate from frames that arrived while the link was busy with them, and whether a frame
arrived queued past the threshold (the report then goes at once)."""
from types import SimpleNamespace

import pytest

from pibr.client.app import Client
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
