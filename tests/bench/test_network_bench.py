"""pibr bench network end to end: server, relay (replaying a bandwidth trace) and client processes
on the virtual clock, a static bitrate against the adapting stream (issue 28, items 2 and 5)."""
import json

import pytest

from pibr.bench.network_bench import print_network, run_label, run_network_bench

pytestmark = [pytest.mark.integration, pytest.mark.gl]


def test_a_link_that_drops_ages_the_static_stream_and_not_the_adapting_one(tmp_path, capsys):
    link = tmp_path / "drop.csv"
    link.write_text("t,kbps\n0,20000\n1,1200\n60,1200\n")
    r = run_network_bench(str(tmp_path), links=(str(link),), static_kbps=(2400.0,), adapt_kbps=2400.0,
                          method="rotation", duration_s=3.0, size=(96, 64), view_size=(192, 192), segment_s=1.0,
                          progress=False, adapt_starts=("foot", "probe"))
    runs = r["links"][str(link)]["runs"]
    static, adapt = runs["static 2400"], runs["adapt 2400"]
    # a start of its own per adapting run, each with its verdict; rotation asks for no proxies, so
    # nothing measured the link and the probe start is the foot's, run for run
    probe = runs["adapt 2400 probe"]
    assert r["settings"]["adapt_starts"] == ["foot", "probe"]
    assert set(r["links"][str(link)]["verdicts"]) == {"adapt 2400", "adapt 2400 probe"}
    assert r["links"][str(link)]["verdicts"]["adapt 2400"] == r["links"][str(link)]["verdict"]
    assert probe["series"] == adapt["series"] and probe["dssim_mean"] == adapt["dssim_mean"]
    assert static["age_ms_p95"] > 1000.0                      # the queue behind a link at half the stream
    assert adapt["age_ms_p95"] < 0.7 * static["age_ms_p95"]
    assert static["colour_kbps_chosen"] is None
    # from the ladder's foot it climbs while the link has room, then falls under the link's 1.2 Mbit/s
    chosen = adapt["colour_kbps_chosen"]
    assert chosen["max"] > 1200 > chosen["min"] and chosen["max"] <= 2400
    assert static["smaller_view_share"] is None and 0 < adapt["smaller_view_share"] < 1   # the start's foot
    for run in (static, adapt):   # on the virtual clock neither end chooses by a deadline
        assert (run["client_level_mean"], run["server_level_mean"], run["missed_ticks"]) == (0.0, None, 0)
    assert 0 < static["arrived_kbps"] <= 20000 * 1 / 3 + 1200 * 2 / 3 + 1
    for run in (static, adapt):
        assert len(run["dssim_by_segment"]) == 3 and 0 < run["dssim_mean"] < 1
        assert run["longest_stall_ms"] >= 100.0 and run["stalls"] >= 0
    verdict = r["links"][str(link)]["verdict"]
    assert verdict["age_p95_over_rtt_ms"]["value"] == pytest.approx(adapt["age_ms_p95"] - 128.0)
    assert len(verdict["dssim_of_best_static"]["per_segment"]) == 3
    # the series the plot draws: the static stream's oldest frame grows through the drop, the
    # adapting stream's choice goes below the link's 1.2 Mbit/s
    static_ages = [a for a in static["series"]["age_ms_max"] if a is not None]
    assert len(static["series"]["age_ms_max"]) == 12 and static_ages[-1] > 4 * min(static_ages)
    assert min(k for k in adapt["series"]["stream_kbps"] if k is not None) < 1200
    assert set(static["series"]["stream_kbps"]) == {None}
    assert (tmp_path / "network.png").stat().st_size > 10_000
    with open(tmp_path / "network.json") as f:
        assert json.load(f)["links"][str(link)]["runs"]["adapt 2400"]["frames"] == adapt["frames"]
    print_network(r)
    assert "adapting: age p95" in capsys.readouterr().out


def test_on_the_wall_clock_the_link_starts_with_the_clients_first_tick(tmp_path):
    """``clock="real"``: the same runs on the wall clock (processes pinned as on two machines). The
    relay starts the link's trace again at the client's tick 0, so half a second of nothing at
    1.5 s stalls the frames shown at 1.5 s, not during the seconds the server and client calibrate
    after the Hello (where it fell before)."""
    link = tmp_path / "gap.csv"
    link.write_text("t,kbps\n0,20000\n1.5,0\n2,20000\n60,20000\n")
    r = run_network_bench(str(tmp_path), links=(str(link),), static_kbps=(2400.0,), adapt_kbps=2400.0,
                          method="rotation", duration_s=4.0, size=(96, 64), view_size=(192, 192), segment_s=1.0,
                          clock="real", progress=False, plot=False)
    assert r["settings"]["clock"] == "real" and r["settings"]["placement"] == "split"
    for name, run in r["links"][str(link)]["runs"].items():
        ages = run["series"]["age_ms_max"]            # the oldest frame shown every 0.25 s
        assert run["frames"] > 0 and run["longest_stall_ms"] >= 400.0
        # on the wall clock the server's rate control chooses each frame's level, and it is recorded
        assert run["server_level_mean"] is not None and run["server_level_mean"] >= 0.0
        oldest = max(range(len(ages)), key=lambda k: ages[k] or 0.0)
        assert 6 <= oldest <= 10                      # at 1.5-2.5 s
        if name.startswith("static"):
            # not before (the adapting stream's first second is its slow start from a frame every
            # 4 ticks: older frames there whatever the link does)
            assert max(ages[:5]) < 0.6 * ages[oldest]
    with pytest.raises(ValueError, match="clock"):
        run_network_bench(str(tmp_path), links=(str(link),), clock="wall", progress=False)


def test_a_link_given_as_a_file_runs_under_the_output_folder(tmp_path):
    """A link named by its path once made an absolute folder name, so its runs were written beside
    the trace file, outside ``out_dir/network``."""
    import os

    root = str(tmp_path / "network")
    for link in ("/data/links/lte.csv", "links/lte.csv", "lte.csv", "/data/links/lte.csv/"):
        out = os.path.join(root, run_label(link, "static 4000"))
        assert os.path.dirname(out) == root and os.path.basename(out) == "lte.csv-static-4000"
    assert run_label("cellular", "adapt 16000") == "cellular-adapt-16000"

