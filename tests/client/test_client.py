"""The client against an in-process server and relay: recordings, determinism, real clock."""
import asyncio
import json
import math

import numpy as np
import pytest

from pibr.client.app import run_client
from pibr.client.config import ClientConfig
from pibr.client.recorder import RECORD_FIELDS, read_records
from pibr.protocol.errors import ConfigError
from pibr.server.app import Server
from pibr.server.config import ServerConfig

from ..loopback import server_behind_relay

pytestmark = pytest.mark.gl


@pytest.fixture
async def relay_endpoint():
    async with server_behind_relay(ServerConfig(port=0, scene="room", view_size=(192, 192), bitrate_kbps=3000)) as ep:
        yield ep


def _cfg(host, port, out, **kw):
    base = dict(host=host, port=port, trace="pred6dof-1", start_s=12.0, duration_s=1.0, rate_hz=30.0,
                methods=("none", "rotation"), out_dir=str(out), width=160, height=96, progress="none")
    base.update(kw)
    return ClientConfig(**base)


def _frames(path):
    import av

    with av.open(path) as c:
        return [f.to_ndarray(format="rgb24") for f in c.decode(video=0)]


async def test_virtual_clock_is_bit_identical(relay_endpoint, tmp_path):
    host, port = relay_endpoint
    r1 = await run_client(_cfg(host, port, tmp_path / "a"))
    r2 = await run_client(_cfg(host, port, tmp_path / "b"))
    assert r1.ticks == r2.ticks == 30
    for m in ("none", "rotation"):
        a = _frames(tmp_path / "a" / f"{m}.lossless.avi")
        b = _frames(tmp_path / "b" / f"{m}.lossless.avi")
        assert len(a) == len(b) == 30
        assert all(np.array_equal(x, y) for x, y in zip(a, b))
        ra = read_records(tmp_path / "a" / f"{m}.records.csv")
        rb = read_records(tmp_path / "b" / f"{m}.records.csv")
        strip = lambda rows: [{k: v for k, v in r.items() if k != "client_ms"} for r in rows]  # wall-clock timing
        assert strip(ra) == strip(rb)
    # Frames are used only once usable, and carry the injected delay.
    rows = read_records(tmp_path / "a" / "rotation.records.csv")
    assert all(r["frame_id"] >= 0 for r in rows)
    for r in rows:
        assert r["frame_arrival_t"] <= r["t"] + 1e-9
        assert r["frame_arrival_t"] - r["frame_render_t"] == pytest.approx(0.020 + 0.064, abs=1e-6)
        assert r["age_ms"] >= 128 + 20 - 1e-6
    info = json.load(open(tmp_path / "a" / "session.json"))
    assert info["session"]["clock"] == "virtual" and info["result"]["frames_received"] > 0


async def test_rotation_follows_the_head_and_none_does_not(relay_endpoint, tmp_path):
    host, port = relay_endpoint
    await run_client(_cfg(host, port, tmp_path, duration_s=0.5))
    none = _frames(tmp_path / "none.lossless.avi")
    rot = _frames(tmp_path / "rotation.lossless.avi")
    rows = read_records(tmp_path / "none.records.csv")
    # Between server frames 'none' shows the same picture; 'rotation' moves with the head.
    same_frame = [i for i in range(1, len(rows)) if rows[i]["frame_id"] == rows[i - 1]["frame_id"]]
    assert same_frame
    assert all(np.array_equal(none[i], none[i - 1]) for i in same_frame)
    assert any(not np.array_equal(rot[i], rot[i - 1]) for i in same_frame)


async def test_real_clock_counts_missed_deadlines(relay_endpoint, tmp_path):
    host, port = relay_endpoint
    result = await run_client(_cfg(host, port, tmp_path, clock="real", duration_s=1.0, rate_hz=20.0))
    rows = read_records(tmp_path / "rotation.records.csv")
    assert len(rows) == result.ticks == 20
    # A missed tick shows the previous image again: same frame, 50 ms older.
    for prev, row in zip(rows, rows[1:]):
        if row["missed"] and prev["frame_id"] >= 0:
            assert row["frame_id"] == prev["frame_id"]
            assert row["age_ms"] == pytest.approx(prev["age_ms"] + 50.0, abs=1e-6)
    used = [r for r in rows if r["frame_id"] >= 0]
    assert used, "no frame arrived on the real clock"
    assert all(r["age_ms"] >= 128 for r in used)   # at least the injected round trip


async def test_real_clock_records_every_tick_even_when_the_preroll_overruns(relay_endpoint, tmp_path):
    # At 1000 Hz nearly every deadline passes while the client works, the pre-roll's too (200 ticks:
    # a client that started late on a loaded machine still shows some), and ticks it skips are
    # still recorded (blank before anything was shown), one row per tick.
    host, port = relay_endpoint
    result = await run_client(_cfg(host, port, tmp_path, clock="real", duration_s=0.2, rate_hz=1000.0,
                                   preroll_s=0.002, methods=("rotation",)))
    rows = read_records(tmp_path / "rotation.records.csv")
    assert [r["tick"] for r in rows] == list(range(result.ticks)) and result.ticks == 200
    # One video frame per tick displayed afresh; a missed tick holds the previous one.
    shown = [r for r in rows if not r["missed"]]
    assert len(_frames(tmp_path / "rotation.lossless.avi")) == len(shown)
    # Checked against the measured time, not the client's own counter: while a tick was being
    # displayed for client_ms, every deadline in that time passed, so at least that many ticks
    # after it must be recorded as missed.
    assert 0 < len(shown) < result.ticks
    for a, b in zip(shown, shown[1:]):
        assert b["tick"] - a["tick"] >= math.floor(a["client_ms"] / 1.0), (a, b)
    assert result.missed_deadlines == result.ticks - len(shown)
    # The evaluation scores every tick, a missed one as the image it held: the same scores as
    # the tick displayed last before it.
    from pibr.bench.evaluate import evaluate_run

    metrics = evaluate_run(str(tmp_path), flip_every=0, workers=1, side_by_side=False, plot=False, progress=False)
    assert metrics["methods"]["rotation"]["frames"] == result.ticks
    import csv

    with open(tmp_path / "metrics_frames.csv", newline="") as f:
        scored = [r for r in csv.DictReader(f) if r["method"] == "rotation"]
    assert len(scored) == result.ticks


def test_config_errors_name_the_problem():
    with pytest.raises(ConfigError, match="unknown method 'warp'"):
        ClientConfig(methods=("warp",))
    with pytest.raises(ConfigError, match="output rate"):
        ClientConfig(rate_hz=0)


def test_records_reader_rejects_other_files(tmp_path):
    p = tmp_path / "x.csv"
    p.write_text("a,b\n1,2\n")
    with pytest.raises(ConfigError, match="not a pibr records file"):
        read_records(p)
    p.write_text(",".join(RECORD_FIELDS) + "\n" + ",".join(["x"] * len(RECORD_FIELDS)) + "\n")
    with pytest.raises(ConfigError, match=":2:"):
        read_records(p)


async def test_proxies_over_the_wire_and_edge_depth_are_deterministic(tmp_path):
    srv = Server(ServerConfig(port=0, scene="room", view_size=(192, 192), bitrate_kbps=3000, depth_codec="edge"))
    host, port = await srv.start()
    task = asyncio.create_task(srv.serve_forever())
    try:
        results = []
        for run in ("a", "b"):
            results.append(await run_client(_cfg(host, port, tmp_path / run, methods=("proxy",), duration_s=0.5)))
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        await srv.close()
    stats = results[0].summary["proxies"]
    assert stats["objects"] == len(load_scene_objects()) and stats["bytes"] > 10_000
    info = json.load(open(tmp_path / "a" / "session.json"))
    assert info["session"]["depth_codec"] == "edge" and info["session"]["motion"] is True
    assert info["session"]["atlas"]["rects"].keys() == {"primary.color", "extra.color"}
    a = _frames(tmp_path / "a" / "proxy.lossless.avi")
    b = _frames(tmp_path / "b" / "proxy.lossless.avi")
    assert len(a) == 15 and all(np.array_equal(x, y) for x, y in zip(a, b))
    rows = read_records(tmp_path / "a" / "proxy.records.csv")
    assert all(r["frame_id"] >= 0 for r in rows) and np.mean([r["hole_fraction"] for r in rows]) < 0.2


def load_scene_objects():
    from pibr.scenes.registry import load_scene

    return load_scene("room").objects


async def test_every_method_runs_in_the_client(relay_endpoint, tmp_path):
    """All methods side by side through the real client (quadtrees asked for in the Hello,
    proxies received), each recording every tick; their views drawn from are in session.json."""
    from pibr.client.methods import method_names

    host, port = relay_endpoint
    names = tuple(method_names())
    result = await run_client(_cfg(host, port, tmp_path, methods=names, duration_s=0.2, start_s=20.0,
                                   options={"step": 8, "threshold": 0.05}))
    assert result.ticks == 6
    info = json.load(open(tmp_path / "session.json"))
    assert info["session"]["options"]["quadtree"]["threshold"] == 0.05
    assert set(info["methods"]) == set(names)
    assert info["methods"]["proxy"]["uses_extra_view"] and not info["methods"]["coarse-meshwarp"]["uses_extra_view"]
    last = {}
    for m in names:
        rows = read_records(tmp_path / f"{m}.records.csv")
        frames = _frames(tmp_path / f"{m}.lossless.avi")
        assert len(rows) == len(frames) == 6, m
        assert rows[-1]["frame_id"] >= 0 and rows[-1]["hole_fraction"] < 0.2, m
        last[m] = frames[-1].astype(int)
        assert last[m].mean() > 20, m             # something was drawn, not a black screen
    # Every method compensates the head's motion since the frame: its image is much closer to
    # proxy's than the uncompensated frame (none) is (measured: at most a third of none's).
    def distance(a, b):
        return float(np.abs(last[a] - last[b]).mean())
    for m in names:
        if m not in ("none", "proxy"):
            assert distance(m, "proxy") < 0.4 * distance("none", "proxy"), (m, distance(m, "proxy"))


async def test_real_clock_warms_up_before_its_clock_and_reports_what_it_decoded(relay_endpoint, tmp_path):
    """The first frame arrives and every method draws it once before tick 0: from the first
    tick on a frame is shown, its age is at least the round trip and at most the time since the
    warm-up began; the server, told what was decoded, never ran more than its window ahead."""
    host, port = relay_endpoint
    result = await run_client(_cfg(host, port, tmp_path, clock="real", duration_s=1.0, rate_hz=10.0,
                                   methods=("rotation",), video=False))
    assert not (tmp_path / "rotation.mp4").exists()                  # records only
    rows = read_records(tmp_path / "rotation.records.csv")
    assert len(rows) == result.ticks == 10
    assert rows[0]["frame_id"] >= 0                                  # warmed up: a frame from tick 0
    arrivals = json.load(open(tmp_path / "session.json"))["result"]["frame_arrivals_s"]
    assert len(arrivals) == result.frames_received and arrivals == sorted(arrivals)
    assert arrivals[0] < 0                                           # the warm-up frame, before tick 0
    for r in rows:
        assert r["frame_arrival_t"] <= r["t"] + 1e-9
        assert 128 <= r["age_ms"] < 128 + 1000 * (r["t"] - arrivals[0]) + 5000


# ------------------------------------------------------------------ the deadline controller (issue 25)

def _table(tmp_path, proxy_ms=None, rotation_ms=(5.0, 3.0, 2.0)):
    from pibr.client.deadline import levels_for

    table = {"rotation": dict(zip([lv.name for lv in levels_for("rotation")], rotation_ms))}
    if proxy_ms is not None:
        table["proxy"] = dict(zip([lv.name for lv in levels_for("proxy")], proxy_ms))
    path = tmp_path / "costs.json"
    path.write_text(json.dumps(table))
    return str(path)


async def test_virtual_clock_levels_come_from_the_cost_table_alone(relay_endpoint, tmp_path):
    """The same table gives the same levels (and images) in every run; a table where the top
    level fits keeps it; one where it does not moves to the best level that fits."""
    host, port = relay_endpoint
    slow = _table(tmp_path, rotation_ms=(40.0, 20.0, 10.0))      # 33.3 ms ticks: 1/2 fits, full does not
    runs = []
    for name in ("a", "b"):
        await run_client(_cfg(host, port, tmp_path / name, methods=("rotation",), cost_table=slow))
        runs.append(read_records(tmp_path / name / "rotation.records.csv"))
    assert [r["level"] for r in runs[0]] == [1] * 30
    assert runs[0][0]["level_reason"] == 1 and {r["level_reason"] for r in runs[0][1:]} == {2}   # down, then held
    assert all(r["predicted_ms"] == 20.0 and r["budget_ms"] == pytest.approx(1000 / 30 - 1) for r in runs[0])
    strip = lambda rows: [{k: v for k, v in r.items() if k != "client_ms"} for r in rows]
    assert strip(runs[0]) == strip(runs[1])
    assert all(np.array_equal(x, y) for x, y in zip(_frames(tmp_path / "a" / "rotation.lossless.avi"),
                                                    _frames(tmp_path / "b" / "rotation.lossless.avi")))
    fast = _table(tmp_path, rotation_ms=(4.0, 3.0, 2.0))
    await run_client(_cfg(host, port, tmp_path / "c", methods=("rotation",), cost_table=fast))
    rows = read_records(tmp_path / "c" / "rotation.records.csv")
    assert {(r["level"], r["level_reason"]) for r in rows} == {(0, 0)}
    info = json.load(open(tmp_path / "c" / "session.json"))
    assert info["deadline"]["adapt"] is False and info["deadline"]["methods"]["rotation"]["share_at_level"]["full"] == 1


async def test_virtual_clock_without_a_table_keeps_todays_behaviour(relay_endpoint, tmp_path):
    host, port = relay_endpoint
    await run_client(_cfg(host, port, tmp_path, methods=("rotation",)))
    rows = read_records(tmp_path / "rotation.records.csv")
    assert {(r["level"], r["level_reason"]) for r in rows} == {(0, 5)}
    assert json.load(open(tmp_path / "session.json"))["deadline"] is None
    with pytest.raises(ConfigError, match="needs --cost-table"):
        await run_client(_cfg(host, port, tmp_path / "x", methods=("rotation",), deadline="on"))


async def test_real_clock_calibrates_every_level_and_records_its_choices(relay_endpoint, tmp_path):
    from pibr.client.deadline import levels_for

    host, port = relay_endpoint
    result = await run_client(_cfg(host, port, tmp_path, clock="real", duration_s=1.0, rate_hz=20.0,
                                   methods=("rotation",)))
    info = json.load(open(tmp_path / "session.json"))
    d = info["deadline"]
    assert d["adapt"] is True and len(d["calibration_ms"]["rotation"]) == len(levels_for("rotation"))
    assert all(ms > 0 for ms in d["calibration_ms"]["rotation"])
    assert sum(d["methods"]["rotation"]["ticks_at_level"].values()) == result.ticks - result.missed_deadlines
    rows = read_records(tmp_path / "rotation.records.csv")
    shown = [r for r in rows if not r["missed"]]
    assert all(0 <= r["level"] < len(levels_for("rotation")) and 0 <= r["level_reason"] <= 4 for r in shown)
    assert all(math.isfinite(r["budget_ms"]) and r["budget_ms"] < 50.0 for r in shown)
    assert info["record_ms"]["ticks"] == len(shown)
    # the server's rate control made every frame at one of the levels it announced, and said which
    levels = info["session"]["options"]["server_levels"]
    assert levels[0] == "full" and all(0 <= r["server_level"] < len(levels) for r in shown if r["frame_id"] >= 0)
    assert len(_frames(tmp_path / "rotation.lossless.avi")) == len(shown)   # encoded after the run
    assert not list(tmp_path.glob(".*.frames.raw"))                         # and the raw images removed
    await run_client(_cfg(host, port, tmp_path / "off", clock="real", duration_s=0.5, rate_hz=20.0,
                          methods=("rotation",), deadline="off"))
    rows = read_records(tmp_path / "off" / "rotation.records.csv")
    assert {r["level"] for r in rows} == {0} and {r["level_reason"] for r in rows if not r["missed"]} == {5}


async def test_a_slow_decoder_never_holds_a_tick(relay_endpoint, tmp_path, monkeypatch):
    """Decoding runs beside the ticks (latest frame wins): with every frame taking 250 ms to
    decode, the display keeps its ticks and shows the frames as they come out."""
    import time as _time

    import pibr.client.app as app

    class SlowDecoder(app.H264Decoder):
        def decode(self, *args, **kwargs):
            _time.sleep(0.25)            # sleeps without the GIL, as PyAV's decoding does
            return super().decode(*args, **kwargs)

    monkeypatch.setattr(app, "H264Decoder", SlowDecoder)
    host, port = relay_endpoint
    result = await run_client(_cfg(host, port, tmp_path, clock="real", duration_s=2.0, rate_hz=20.0,
                                   methods=("rotation",), deadline="off"))
    rows = read_records(tmp_path / "rotation.records.csv")
    shown = [r for r in rows if not r["missed"]]
    assert result.ticks == 40 and len(shown) >= 30          # a tick that waited on 250 ms decodes would miss 5 of 6
    assert len({r["frame_id"] for r in rows if r["frame_id"] >= 0}) >= 3   # and the frames still come through


async def test_a_colour_scaled_session_shows_the_rebuilt_colour(tmp_path):
    """A server sending colour at a quarter of the pixels (--colour-scale 0.5): the client rebuilds
    it and shows what a whole-colour session shows, closely, frame for frame (virtual clock)."""
    from pibr.bench.metrics import psnr

    shown = {}
    for scale in (1.0, 0.5):
        srv = Server(ServerConfig(port=0, scene="room", view_size=(192, 192), bitrate_kbps=3000, depth_codec="edge",
                                  colour_scale=scale))
        host, port = await srv.start()
        task = asyncio.create_task(srv.serve_forever())
        try:
            await run_client(_cfg(host, port, tmp_path / str(scale), methods=("rotation",), duration_s=0.5))
        finally:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
            await srv.close()
        shown[scale] = _frames(tmp_path / str(scale) / "rotation.lossless.avi")
    info = json.load(open(tmp_path / "0.5" / "session.json"))
    assert info["session"]["colour_scale"] == 0.5
    assert info["session"]["atlas"]["rects"]["primary.color"] == [0, 0, 96, 96]
    assert len(shown[0.5]) == len(shown[1.0]) == 15
    # the first frame is a quarter of the pixels interpolated; then the history fills in (measured
    # against the whole colour's: 26.0 dB on the first tick, 29.8-29.9 dB on the last six)
    close = [psnr(a, b) for a, b in zip(shown[1.0], shown[0.5])]
    assert min(close[9:]) > 28.0 and np.mean(close[9:]) > close[0] + 2.0, close
