import pytest

from pibr.common.link import LinkModel, LinkParams, SessionSchedule


def test_fixed_delay():
    m = LinkModel(LinkParams(64.0))
    assert m.arrival_us(0, 100) == 64_000
    assert m.arrival_us(10_000, 100) == 74_000


def test_bandwidth_queues_messages():
    m = LinkModel(LinkParams(10.0, kbps=8000))  # 1 byte per microsecond
    assert m.arrival_us(0, 1000) == 1000 + 10_000
    assert m.arrival_us(0, 1000) == 2000 + 10_000     # waits for the first to leave
    assert m.arrival_us(50_000, 1000) == 51_000 + 10_000


def test_jitter_is_reproducible_and_fifo():
    a = [LinkModel(LinkParams(50.0, jitter_ms=20.0), seed=7).arrival_us(t * 1000, 10) for t in range(200)]
    m1, m2 = LinkModel(LinkParams(50.0, jitter_ms=20.0), seed=7), LinkModel(LinkParams(50.0, jitter_ms=20.0), seed=7)
    s1 = [m1.arrival_us(t * 1000, 10) for t in range(200)]
    s2 = [m2.arrival_us(t * 1000, 10) for t in range(200)]
    assert s1 == s2
    assert all(b >= a for a, b in zip(s1, s1[1:]))    # TCP keeps order
    assert min(s - t * 1000 for t, s in enumerate(s1)) >= 30_000
    assert len(a) == 200


def test_clock_messages_are_lower_bounds():
    m = LinkModel(LinkParams(50.0, jitter_ms=20.0, kbps=100), seed=3)
    t = 0
    for i in range(300):
        bound = m.arrival_us(t, 0, is_clock=True)
        t += 500
        arrive = m.arrival_us(t, 400)
        assert arrive >= bound


@pytest.mark.parametrize("bad", [dict(delay_ms=-1), dict(jitter_ms=float("nan")), dict(kbps=float("inf"))])
def test_bad_params(bad):
    with pytest.raises(ValueError):
        LinkParams(**bad)


def _shown(schedule, ticks, sizes=lambda k: 1000):
    """Per display tick: (render us, pose us) of the newest frame arrived, from the schedule alone."""
    in_flight, shown, out, k = [], None, [], 0
    for t in ticks:
        while (due := schedule.next_due(t)) is not None:
            in_flight.append((schedule.sent(due[0], sizes(k)), due))
            k += 1
        while in_flight and in_flight[0][0] <= t:
            shown = in_flight.pop(0)[1]
        out.append(shown)
    return out


@pytest.mark.parametrize("rate, fps, up, down", [(30.0, 10.0, 64.0, 64.0), (60.0, 20.0, 5.0, 120.0),
                                                 (30.0, 5.0, 0.0, 0.0)])
def test_on_an_ideal_link_the_stateful_schedule_is_the_closed_form(rate, fps, up, down):
    model = SessionSchedule(rate, fps, LinkParams(up), LinkParams(down))
    schedule = SessionSchedule(rate, fps, LinkParams(up), LinkParams(down))
    tick = int(round(1e6 / rate))
    ticks = [i * tick for i in range(int(rate * 3))]
    got = _shown(schedule, ticks)
    for t, frame in zip(ticks, got):
        render, pose = model.frame_for(t)
        assert frame == (render, max(pose, 0)), t
    assert schedule.skipped == 0


def test_a_cap_queues_frames_and_the_in_flight_limit_skips():
    ticks = [i * 33333 for i in range(90)]
    free = _shown(SessionSchedule(30.0, 10.0, LinkParams(32.0), LinkParams(32.0), max_in_flight=None), ticks)
    # 20 kB frames on a 1 Mbit/s link: 160 ms each, longer than the 100 ms between frames
    capped = SessionSchedule(30.0, 10.0, LinkParams(32.0), LinkParams(32.0, 0.0, 1000.0), max_in_flight=None)
    queued = _shown(capped, ticks, lambda k: 20000)
    age = [t - f[0] for t, f in zip(ticks, queued) if f is not None]
    free_age = [t - f[0] for t, f in zip(ticks, free)]
    assert max(free_age) < 200_000
    assert age[-1] > 1_200_000 and age[-1] > age[len(age) // 2] > age[5]   # the queue grows without bound
    limited = SessionSchedule(30.0, 10.0, LinkParams(32.0), LinkParams(32.0, 0.0, 1000.0), max_in_flight=3)
    kept = _shown(limited, ticks, lambda k: 20000)
    kept_age = [t - f[0] for t, f in zip(ticks, kept) if f is not None]
    assert limited.skipped > 0
    assert max(kept_age) < 1_000_000 < age[-1]


def test_jitter_is_seeded_and_bounded():
    ticks = [i * 33333 for i in range(120)]

    def run(seed):
        s = SessionSchedule(30.0, 10.0, LinkParams(64.0, 30.0), LinkParams(64.0, 30.0), seed=seed, max_in_flight=None)
        return _shown(s, ticks)

    a, b, c = run(1), run(1), run(2)
    assert a == b and a != c
    for t, (render, pose) in zip(ticks, a):
        assert t - render <= 20_000 + 94_000 + 100_000 + 1   # delay + most delay down + one interval
        assert render - pose >= 34_000 or pose == 0   # the pose took at least the least delay up (0: none yet)


def test_the_closed_form_refuses_a_link_that_is_not_ideal():
    for schedule in (SessionSchedule(30.0, 10.0, LinkParams(64.0, 5.0)),
                     SessionSchedule(30.0, 10.0, down=LinkParams(64.0, 0.0, 1000.0)),
                     SessionSchedule(30.0, 10.0, max_in_flight=3)):
        assert not schedule.ideal
        with pytest.raises(ValueError, match="ideal link"):
            schedule.frame_for(0)
    assert SessionSchedule.round_trip(30.0, 100.0).ideal
    assert SessionSchedule.round_trip(30.0, 100.0).frame_for(400_000) == (300_000, 233_331)


def test_the_schedule_follows_a_bandwidth_trace_as_the_relay_does():
    """The virtual clock's schedule (the benches' Simulation) uses the same link model: frames on
    a trace that drops from 8 to 0.4 Mbit/s at 1 s queue up and age, and recover after 2 s."""
    from pibr.common.bandwidth import parse_rate_csv

    trace = parse_rate_csv("0,8000\n1,400\n2,8000\n4,8000\n")
    ticks = [i * 33333 for i in range(120)]
    s = SessionSchedule(30.0, 10.0, LinkParams(32.0), LinkParams(32.0, trace=trace), max_in_flight=None)
    assert not s.ideal
    shown = _shown(s, ticks, lambda k: 10000)          # 80 kbit frames: 10 ms at 8 Mbit/s, 200 ms at 0.4
    age = {t: t - f[0] for t, f in zip(ticks, shown) if f is not None}
    assert max(a for t, a in age.items() if t < 900_000) < 200_000
    assert max(a for t, a in age.items() if 1_500_000 <= t < 2_100_000) > 500_000
    assert max(a for t, a in age.items() if t >= 3_500_000) < 200_000
