"""``pibr bench realtime`` end to end: real server, relay and client processes on loopback."""
import json

import pytest

from pibr.bench.realtime import print_realtime, run_one, run_realtime_bench

pytestmark = [pytest.mark.integration, pytest.mark.gl]

SMALL = dict(scene="sphere", size=(160, 96), server_args=("--view-size", "128x128", "--bitrate-kbps", "2000"))


def test_one_real_clock_run_reports_what_the_user_sees(tmp_path):
    r = run_one(str(tmp_path), "rotation", "h264", duration_s=1.5, rate_hz=20.0, **SMALL)
    (c,) = r["per_client"]
    from pibr.client.deadline import levels_for
    from pibr.client.recorder import read_records

    assert c["ticks"] == 30
    assert 0 < c["server_fps"] <= 10.0 + 1.0 / 1.5                 # what the server was asked for, at most
    assert c["age_ms_p50"] >= 128 and c["age_ms_p99"] >= c["age_ms_p50"]
    assert c["frames_before_clock"] >= 1                             # the warm-up frame
    (s,) = r["server"]                                               # the session's line in the server log
    assert s["frames_sent"] >= c["frames_received"]
    assert r["cpu_share"]["server"] > 0 and r["cpu_share"]["client"] > 0
    # The controllers are on (the wall clock's default): every tick says which level it drew and
    # why, every frame which server level made it, and the summaries agree with the records.
    rows = read_records(str(tmp_path / "rotation.records.csv"))
    names = [lv.name for lv in levels_for("rotation")]
    assert all(0 <= row["level"] < len(names) and 0 <= row["level_reason"] <= 4 for row in rows)
    drawn = [names[row["level"]] for row in rows if not row["missed"]]
    assert c["levels"] == pytest.approx({n: drawn.count(n) / len(drawn) for n in names}, abs=0.05)
    assert sum(s["levels"].values()) == s["frames_sent"]
    assert all(row["server_level"] >= 0 for row in rows if row["frame_id"] >= 0)


def test_cost_per_session_counts_every_client(tmp_path, capsys):
    r = run_realtime_bench(str(tmp_path), methods=(), depth_codecs=(), clients=(1, 2), scaling_duration_s=1.5,
                           duration_s=1.0, rate_hz=20.0, progress=False, **{k: v for k, v in SMALL.items()
                                                                            if k != "server_args"},
                           server_args=SMALL["server_args"])
    virtual = [x for x in r["scaling"] if x["clock"] == "virtual"]
    assert [x["clients"] for x in virtual] == [1, 2]
    for x in virtual:
        assert len(x["per_client"]) == len(x["server"]) == x["clients"]
        # The virtual clock delivers the same frames to every client: rendered on the 10 fps grid,
        # usable 20 ms (server) + 64 ms (downlink) later: at 0.084, 0.184, ... 1.384 s of the
        # window, whose last tick is at 1.45 s.
        assert all(c["frames_received"] == 14 for c in x["per_client"])
        assert x["server_cpu_ms_per_frame"] > 0
    saved = json.load(open(tmp_path / "realtime.json"))
    assert [x["clients"] for x in saved["scaling"]] == [1, 2, 1, 2]
    print_realtime(r)
    assert "cost per session" in capsys.readouterr().out
