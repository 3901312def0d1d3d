"""Bandwidth traces (common/bandwidth.py): the two file formats, the built-ins, and when a
message has left a link whose rate changes."""
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from pibr.common.bandwidth import (BUILTIN, BandwidthTrace, load_bandwidth_trace, parse_mahimahi,
                                   parse_rate_csv)
from pibr.common.link import LinkModel, LinkParams
from pibr.protocol.errors import ConfigError


def test_a_constant_trace_sends_as_a_fixed_cap_does():
    trace = parse_rate_csv("t,kbps\n0,8000\n")
    capped = LinkModel(LinkParams(10.0, kbps=8000))
    traced = LinkModel(LinkParams(10.0, trace=trace))
    for t, n in [(0, 1000), (500, 3000), (100_000, 1), (-2_000_000, 123_457)]:
        assert traced.arrival_us(t, n) == capped.arrival_us(t, n)


def test_one_mahimahi_opportunity_a_millisecond_is_12_mbit():
    trace = parse_mahimahi("\n".join(str(m) for m in range(1, 1001)))
    assert trace.period_us == 1_000_000 and trace.mean_kbps == pytest.approx(12_000)
    assert trace.finish_us(0, 1500) == 1000
    assert trace.finish_us(0, 15_000) == 10_000
    two_a_ms = parse_mahimahi("\n".join(f"{m}\n{m}" for m in range(1, 11)))
    assert two_a_ms.finish_us(0, 3000) == 1000


def test_a_message_across_a_step_is_sent_at_both_rates():
    trace = parse_rate_csv("0,8000\n1,2000\n2,8000\n")     # 1 byte/us, then 0.25 byte/us, period 3 s
    assert trace.period_us == 3_000_000
    # 100 000 bytes from 0.95 s: 50 000 by 1 s, the other 50 000 at 0.25 byte/us take 200 ms
    assert trace.finish_us(950_000, 100_000) == 1_200_000
    # and the trace loops: the same a period later, and a period earlier
    assert trace.finish_us(3_950_000, 100_000) == 4_200_000
    assert trace.finish_us(-2_050_000, 100_000) == -1_800_000
    # bits carried from the trace's start, across periods: 8e6 in the first second, then 2e6 a second
    assert trace.bits_until([0, 1_000_000, 1_500_000, 3_000_000, 4_000_000]).tolist() == \
        [0, 8e6, 9e6, 18e6, 26e6]


def test_an_outage_holds_a_message_until_it_ends():
    trace = load_bandwidth_trace("outage")                 # 16 Mbit/s, nothing from 10 to 11 s
    assert trace.finish_us(10_200_000, 2000) == 11_001_000
    assert trace.finish_us(9_999_000, 2000) == 10_000_000  # 2 bytes/us: all of it just before
    assert trace.finish_us(9_999_000, 2002) == 11_000_001  # two bytes more wait out the outage


def test_the_link_queues_messages_behind_each_other_on_the_trace():
    trace = parse_rate_csv("0,8000\n1,800\n")             # 1 byte/us for 1 s, 0.1 byte/us for 1 s
    m = LinkModel(LinkParams(5.0, trace=trace), origin_us=1_000_000)
    a = m.arrival_us(1_000_000, 500_000)                   # trace time 0: 0.5 s at 1 byte/us
    b = m.arrival_us(1_000_000, 600_000)                   # waits for a, then 0.5 s fast + 100 000 slow
    assert a == 1_500_000 + 5000
    assert b == 2_000_000 + 1_000_000 + 5000


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(1, 3000), st.floats(0, 50_000, allow_nan=False)), min_size=1, max_size=12),
       st.integers(-10_000_000, 10_000_000), st.integers(1, 3_000_000))
@example(segments=[(375, 32.0)], start=-1, nbytes=1)   # float rounding made it leave 1 us late
@example(segments=[(1039, 32295.0), (136, 1.0)], start=-135583, nbytes=1)   # so did a slow segment after a fast one
def test_a_message_leaves_when_the_trace_has_carried_its_bits(segments, start, nbytes):
    lengths = np.array([s[0] for s in segments], dtype=np.int64) * 1000
    rates = np.array([round(s[1]) for s in segments], dtype=float)
    if float((rates * lengths).sum()) / 1e3 < 12_000:
        with pytest.raises(ConfigError, match="never delivers"):
            BandwidthTrace("random", np.concatenate([[0], np.cumsum(lengths)]), rates)
        return
    trace = BandwidthTrace("random", np.concatenate([[0], np.cumsum(lengths)]), rates)
    end = trace.finish_us(start, nbytes)

    def carried(t0, t1):     # bits between two times, integrating the rate 1 us at a time where it matters
        edges = np.concatenate([[t0], np.arange(t0 - t0 % 1000 + 1000, t1, 1000), [t1]])
        edges = np.unique(np.clip(edges, t0, t1))
        mids = (edges[:-1] + edges[1:]) // 2
        return float((trace.kbps_at(mids) / 1e3 * np.diff(edges)).sum())
    if end - start > 5_000_000:
        return       # too long to integrate cheaply; the short ones check the same arithmetic
    assert carried(start, end) >= nbytes * 8 - 1e-3
    assert carried(start, end - 1) < nbytes * 8
    assert trace.finish_us(start, nbytes + 1) >= end
    assert trace.finish_us(start + trace.period_us, nbytes) == end + trace.period_us


@pytest.mark.parametrize("name", sorted(BUILTIN))
def test_builtins_round_trip_through_both_formats(name, tmp_path):
    trace = load_bandwidth_trace(name)
    assert trace.summary()["mean_kbps"] == pytest.approx(trace.mean_kbps, abs=0.1)
    (tmp_path / "t.csv").write_text(trace.to_csv())
    again = load_bandwidth_trace(str(tmp_path / "t.csv"))
    assert again.period_us == trace.period_us
    assert np.array_equal(again.kbps_at(np.arange(0, trace.period_us, 50_000)),
                          trace.kbps_at(np.arange(0, trace.period_us, 50_000)))
    (tmp_path / "t.mm").write_text(trace.to_mahimahi())
    mm = load_bandwidth_trace(str(tmp_path / "t.mm"))
    assert mm.period_us == trace.period_us
    assert mm.mean_kbps == pytest.approx(trace.mean_kbps, rel=2e-3)   # whole packets, one ms each


def test_builtins_are_the_same_every_time():
    assert np.array_equal(load_bandwidth_trace("cellular").rates_kbps, load_bandwidth_trace("cellular").rates_kbps)
    steps = load_bandwidth_trace("steps")
    assert list(steps.kbps_at([0, 15_000_000, 25_000_000, 35_000_000, 45_000_000, 55_000_000])) == \
        [20000, 8000, 3000, 8000, 20000, 20000]


def test_other_seeds_of_the_cellular_model_are_realisations_of_their_own(tmp_path):
    """cellular:SEED draws the built-in cellular model with another seed: the same for one seed, a
    different trace for another, the built-in itself for its own seed; a seed that is not a
    non-negative integer is refused by name, and a file of that name is still read as a file."""
    from pibr.common.bandwidth import CELLULAR_SEED

    builtin = load_bandwidth_trace("cellular")
    own = load_bandwidth_trace(f"cellular:{CELLULAR_SEED}")
    assert own.name == "cellular" and np.array_equal(own.rates_kbps, builtin.rates_kbps)
    a, again, b = (load_bandwidth_trace(s) for s in ("cellular:13", "cellular:13", "cellular:14"))
    assert a.name == "cellular:13" and np.array_equal(a.rates_kbps, again.rates_kbps)
    assert not np.array_equal(a.rates_kbps, b.rates_kbps) and not np.array_equal(a.rates_kbps, builtin.rates_kbps)
    assert a.period_us == builtin.period_us == 60_000_000 and len(a.rates_kbps) == 600
    for bad in ("cellular:", "cellular:-3", "cellular:x1", "cellular:1.5", "cellular:\u00b2", "cellular:" + "9" * 19):
        with pytest.raises(ConfigError, match="non-negative integer seed"):
            load_bandwidth_trace(bad)
    f = tmp_path / "cellular:7"
    f.write_text("t,kbps\n0,1234\n")
    import os
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        assert load_bandwidth_trace("cellular:7").mean_kbps == 1234.0
    finally:
        os.chdir(cwd)


def test_a_steady_link_at_any_rate(tmp_path, monkeypatch):
    """steady:KBPS is the steady link at another rate (the slow links where even the colour's floor
    does not fit); the built-in's own rate is the built-in; a rate that is not a positive number
    up to the cap is refused by name; a file of that name is still read as a file."""
    from pibr.common.bandwidth import MAX_KBPS, STEADY_KBPS

    slow = load_bandwidth_trace("steady:600")
    assert slow.name == "steady:600" and slow.mean_kbps == 600.0 and slow.summary()["min_kbps"] == 600.0
    assert load_bandwidth_trace("steady:2.5").mean_kbps == 2.5
    assert load_bandwidth_trace(f"steady:{STEADY_KBPS:g}").name == "steady"
    assert slow.period_us == load_bandwidth_trace("steady").period_us
    for bad in ("steady:", "steady:0", "steady:-5", "steady:fast", "steady:nan", "steady:inf", "steady:\u00b2",
                f"steady:{MAX_KBPS * 2:g}"):
        with pytest.raises(ConfigError, match="steady:KBPS takes a rate"):
            load_bandwidth_trace(bad)
    (tmp_path / "steady:7").write_text("t,kbps\n0,1234\n")
    monkeypatch.chdir(tmp_path)
    assert load_bandwidth_trace("steady:7").mean_kbps == 1234.0


@pytest.mark.parametrize("text, fmt, message", [
    ("t,kbps\n1,100\n", "csv", "first row must be at t = 0"),
    ("0,100\n2,100\n1,100\n", "csv", "times must increase"),
    ("0,100\n1,-5\n", "csv", "kbps must be in"),
    ("0,100\n1,nan\n", "csv", "kbps must be in"),
    ("t,kbps\n0,100\nfoo,bar\n", "csv", "line 3: expected two numbers"),
    ("0,100,3\n", "csv", "expected 't,kbps'"),
    ("0,0\n1,0\n", "csv", "never delivers"),
    ("", "csv", "no 't,kbps' rows"),
    ("5\n3\n", "mm", "line 2: timestamps must be >= 0 and never decrease"),
    ("1\nabc\n", "mm", "line 2: expected a whole number"),
    ("0\n0\n", "mm", "no delivery opportunity after 0 ms"),
])
def test_bad_trace_files_name_the_problem(text, fmt, message):
    parse = parse_rate_csv if fmt == "csv" else parse_mahimahi
    with pytest.raises(ConfigError, match=message):
        parse(text, "bad")


def test_a_missing_trace_names_the_builtins():
    with pytest.raises(ConfigError, match="neither a file nor a built-in.*steps"):
        load_bandwidth_trace("no/such/trace")


def test_a_cap_and_a_trace_on_one_link_are_refused():
    with pytest.raises(ValueError, match="not both"):
        LinkParams(10.0, kbps=1000, trace=load_bandwidth_trace("steps"))
    assert LinkParams(10.0, trace=load_bandwidth_trace("steps")).capped
    osc = load_bandwidth_trace("oscillation").summary()
    assert (osc["min_kbps"], osc["max_kbps"], osc["period_s"]) == (3001.0, 19999.0, 60.0)
