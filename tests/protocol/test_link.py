import pytest

from pibr.protocol.link import LinkModel, LinkParams


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
