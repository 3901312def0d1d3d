"""``pibr bench trade``: the network schedule and a tiny sweep's JSON and relations."""
import json
import os

import pytest

from pibr.bench.coverage import LatencyModel, LinkSchedule
from pibr.protocol.link import LinkParams


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
def test_schedule_without_jitter_or_cap_is_the_latency_model(rate, fps, up, down):
    model = LatencyModel(rate_hz=rate, server_fps=fps, up_ms=up, down_ms=down)
    schedule = LinkSchedule(rate, fps, LinkParams(up), LinkParams(down), max_in_flight=None)
    tick = int(round(1e6 / rate))
    ticks = [i * tick for i in range(int(rate * 3))]
    got = _shown(schedule, ticks)
    for t, frame in zip(ticks, got):
        render, pose = model.frame_for(t)
        assert frame == (render, max(pose, 0)), t
    assert schedule.skipped == 0


def test_a_cap_queues_frames_and_the_in_flight_limit_skips():
    ticks = [i * 33333 for i in range(90)]
    free = _shown(LinkSchedule(30.0, 10.0, LinkParams(32.0), LinkParams(32.0), max_in_flight=None), ticks)
    # 20 kB frames on a 1 Mbit/s link: 160 ms each, longer than the 100 ms between frames
    capped = LinkSchedule(30.0, 10.0, LinkParams(32.0), LinkParams(32.0, 0.0, 1000.0), max_in_flight=None)
    queued = _shown(capped, ticks, lambda k: 20000)
    age = [t - f[0] for t, f in zip(ticks, queued) if f is not None]
    free_age = [t - f[0] for t, f in zip(ticks, free)]
    assert max(free_age) < 200_000
    assert age[-1] > 1_200_000 and age[-1] > age[len(age) // 2] > age[5]   # the queue grows without bound
    limited = LinkSchedule(30.0, 10.0, LinkParams(32.0), LinkParams(32.0, 0.0, 1000.0), max_in_flight=3)
    kept = _shown(limited, ticks, lambda k: 20000)
    kept_age = [t - f[0] for t, f in zip(ticks, kept) if f is not None]
    assert limited.skipped > 0
    assert max(kept_age) < 1_000_000 < age[-1]


def test_jitter_is_seeded_and_bounded():
    ticks = [i * 33333 for i in range(120)]

    def run(seed):
        s = LinkSchedule(30.0, 10.0, LinkParams(64.0, 30.0), LinkParams(64.0, 30.0), seed=seed, max_in_flight=None)
        return _shown(s, ticks)

    a, b, c = run(1), run(1), run(2)
    assert a == b and a != c
    for t, (render, pose) in zip(ticks, a):
        assert t - render <= 20_000 + 94_000 + 100_000 + 1   # delay + most delay down + one interval
        assert render - pose >= 34_000 or pose == 0   # the pose took at least the least delay up (0: none yet)


def test_tiny_trade_sweep(tmp_path):
    from pibr.bench.trade import StreamPoint, print_trade_tables, run_trade_bench
    from pibr.bench.windows import Window

    stream = StreamPoint(bitrate_kbps=2000.0, view_size=(128, 128))
    r = run_trade_bench(knobs=("bitrate", "latency", "cap", "tau"), windows=(Window("pred6dof-1", 30.0, 0.8),),
                        stride=2, out_size=(160, 96), flip_every=2, stream=stream,
                        values={"bitrate": (300.0,), "latency": (0.0, 256.0), "cap": (300.0,), "tau": (0.4,)},
                        out_dir=str(tmp_path), progress=False, workers=0)
    with open(tmp_path / "trade.json") as f:
        assert json.load(f) == json.loads(json.dumps(r))
    for name in ("bitrate", "latency", "cap", "tau"):
        assert os.path.getsize(tmp_path / f"trade_{name}.png") > 1000
    assert r["windows"]["disjoint_from_tuning"] and r["windows"]["used"][0]["duration_s"] == 0.8
    s = r["scenes"]["room"]
    assert s["ticks_scored_per_point"] == 12 and s["frames"] == {"pred6dof-1 30-30.8 s": 12}
    sweeps = s["sweeps"]
    assert [row["value"] for row in sweeps["bitrate"]] == [300.0, 2000.0]
    assert [row["value"] for row in sweeps["latency"]] == [0.0, 128.0, 256.0]
    assert [row["default"] for row in sweeps["latency"]] == [False, True, False]
    competitors = {"rotation", "proxy", "gridwarp", "coarse-meshwarp s=4"}
    # the client knob's proxy variant is scored on the default stream, which every stream sweep's
    # default point is: tables and plots show the methods of every point
    assert [row["value"] for row in sweeps["tau"]] == [0.1, 0.4] and set(sweeps["tau"][1]["methods"]) == {"proxy"}
    for name in ("bitrate", "latency", "cap"):
        for row in sweeps[name]:
            assert set(row["methods"]) == competitors | ({"proxy tau=0.4"} if row["default"] else set())
    for rows in sweeps.values():
        for row in rows:
            for m in row["methods"].values():
                assert m["frames"] + row["stream"]["ticks_without_frame"] == 12
                assert 0 < m["dssim"] < 0.5 and 5 < m["psnr"] < 60 and 0 < m["flip"] < 1
                assert 0 <= m["geometric_holes"] < 1 and m["client_cpu_ms"] > 0
            assert row["stream"]["server_cpu_ms"] > 0
    low, high = sweeps["bitrate"]
    assert low["stream"]["bits_per_frame"] < 0.5 * high["stream"]["bits_per_frame"]
    zero, default, slow = sweeps["latency"]
    assert zero["stream"]["age_ms_mean"] < default["stream"]["age_ms_mean"] < slow["stream"]["age_ms_mean"]
    for method in ("proxy", "rotation"):
        assert zero["methods"][method]["frames"] == slow["methods"][method]["frames"] == 12
        assert zero["methods"][method]["dssim"] <= slow["methods"][method]["dssim"]
        # the holes of the frame shown, not of one still in flight
        assert zero["methods"][method]["geometric_holes"] < slow["methods"][method]["geometric_holes"]
    free, capped = sweeps["cap"]
    assert free["value"] == 0.0 and capped["value"] == 300.0
    assert capped["stream"]["age_ms_mean"] > free["stream"]["age_ms_mean"] + 50
    # the link delivers no more than its cap over the run; uncapped, about what the encoder made
    assert capped["stream"]["delivered_kbps"] <= 300.0 < free["stream"]["delivered_kbps"]
    assert capped["stream"]["frames_skipped"] > 0 == free["stream"]["frames_skipped"]
    print_trade_tables(r)


def test_the_default_stream_is_the_servers_with_the_view_its_plan_sizes_for_the_output():
    from pibr.bench.trade import default_stream
    from pibr.server.config import ServerConfig

    c = ServerConfig()
    s = default_stream((960, 540))
    assert (s.bitrate_kbps, s.preset, s.keyint, s.extra_scale, s.fps) == (c.bitrate_kbps, c.preset, c.keyint,
                                                                         c.extra_scale, c.fps)
    assert s.view_size == (1088, 1088)           # 1.12 x the output's density (server/scene_plan.py)
    assert default_stream((1280, 720)).view_size == (1440, 1440)
