"""``pibr bench trade``: a tiny sweep's JSON and relations."""
import json
import os


def test_tiny_trade_sweep(tmp_path):
    from pibr.bench.trade import StreamPoint, print_trade_tables, run_trade_bench
    from pibr.bench.windows import Window

    stream = StreamPoint(bitrate_kbps=2000.0, view_size=(128, 128))
    r = run_trade_bench(knobs=("bitrate", "latency", "cap", "tau"), windows=(Window("pred6dof-1", 30.0, 0.8),),
                        stride=2, out_size=(160, 96), flip_every=2, stream=stream,
                        values={"bitrate": (300.0,), "latency": (0.0, 256.0), "cap": (300.0,), "tau": (0.4,)},
                        out_dir=str(tmp_path), progress=False)
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
