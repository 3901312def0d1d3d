"""pibr report: the page's content from a run's and a benchmark's files, and its errors."""
from __future__ import annotations

import html
import json
import os
import re
import shutil

import pytest

from pibr.bench import readme_tables
from pibr.bench.report import METRIC_COLUMNS, build_report, write_report
from pibr.protocol.errors import ConfigError

from .report_run import METHODS, TICKS, make_run

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("run"))
    make_run(out)
    return out


def _data(page: str) -> dict:
    m = re.search(r'<script type="application/json" id="pibr-data">(.*?)</script>', page, re.S)
    return json.loads(m.group(1))


def test_metrics_table_shows_metrics_json_per_method_and_column(run_dir):
    page = build_report(run_dir)
    with open(os.path.join(run_dir, "metrics.json")) as f:
        metrics = json.load(f)
    for m in METHODS:
        row = re.search(rf'<tr data-method="{m}">(.*?)</tr>', page).group(1)
        cells = dict(re.findall(r'<td data-key="(\w+)" data-value="[^"]*">([^<]*)</td>', row))
        assert list(cells) == [k for k, *_ in METRIC_COLUMNS]
        for key, _, scale, fmt in METRIC_COLUMNS:
            expected = metrics["methods"][m][key] * scale
            assert float(cells[key]) == pytest.approx(expected, abs=0.51 * 10 ** -int(fmt[1] if fmt != "d" else 0))


def test_series_follow_the_csv_files_tick_by_tick(run_dir):
    series = _data(build_report(run_dir))["run"]["series"]
    assert list(series) == list(METHODS)
    for m in METHODS:
        assert len(series[m]["dssim"]) == len(series[m]["age_ms"]) == TICKS
        assert series[m]["t"][30] == pytest.approx(1.0)
    assert series["proxy"]["dssim"][5] > series["none"]["dssim"][5]       # 0.12+ against 0.03 at most
    assert series["proxy"]["level"][:4] == [0, 2, 0, 2]


def test_stream_series_show_the_newest_batch_at_each_tick(run_dir):
    run = _data(build_report(run_dir))["run"]
    stream = run["stream"]
    assert set(stream) == {"server_fps", "kbps", "decode_ms"} and len(stream["kbps"]) == TICKS
    # batches at 0.05, 0.15, ... s: tick 0 (0 s) has none yet, tick 3 (0.1 s) the first, tick 30 (1 s) the 10th
    assert stream["kbps"][0] is None and stream["kbps"][3] == 160.0 and stream["kbps"][30] == 169.0
    assert stream["decode_ms"][30] == 12.0


def test_the_page_needs_nothing_from_outside_the_folder(run_dir):
    page = write_report(run_dir)
    text = open(page).read()
    assert not re.search(r'(src|href)\s*=\s*"(https?:|//)', text)
    assert "<link" not in text and "<script src" not in text
    srcs = re.findall(r'<video[^>]* src="([^"]+)"', text)
    assert sorted(set(srcs)) == sorted({"side_by_side.mp4", *(f"{m}.mp4" for m in METHODS)})
    assert all(os.path.exists(os.path.join(run_dir, s)) for s in srcs)


def test_text_from_files_cannot_break_out_of_the_page(tmp_path):
    out = str(tmp_path / "run")
    make_run(out, ticks=4)
    with open(os.path.join(out, "metrics.json")) as f:
        metrics = json.load(f)
    metrics["scene"] = "</script><img src=x onerror=alert(1)>"
    with open(os.path.join(out, "metrics.json"), "w") as f:
        json.dump(metrics, f)
    page = build_report(out)
    assert "<img src=x" not in page
    assert html.escape(metrics["scene"]) in page


def test_benchmark_tables_are_the_readmes_renderers(tmp_path):
    for name in ("pareto.json", "network.json"):
        shutil.copy(os.path.join(ROOT, "docs", "results", name), tmp_path / name)
    page = build_report(str(tmp_path))
    pareto = json.load(open(tmp_path / "pareto.json"))
    for renderer in ("pareto", "pareto-windows", "network"):
        lines = readme_tables.RENDERERS[renderer](pareto if renderer.startswith("pareto") else
                                                  json.load(open(tmp_path / "network.json")))
        first_row = [c.strip().replace("**", "") for c in lines[2].strip().strip("|").split("|")]
        assert "".join(f"<td>{html.escape(c)}</td>" for c in first_row) in page
    points = _data(page)["pareto"]
    assert {p["variant"] for p in points} == set(pareto["scenes"]["room"]["variants"])


def test_every_readme_table_of_a_benchmarks_own_file_is_in_its_report(tmp_path):
    from pibr.bench.report import BENCH_TABLES

    shown = {r for renderers in BENCH_TABLES.values() for r in renderers}
    # tables of files no single bench run writes under that name: upsampling-edge/-h264.json (one run
    # per depth codec, renamed), lod-target.json (five runs merged), server-edges (bench_server.json
    # of another command line, whose own table is server-projection's), network-start.json (a network
    # run per head-trace window, merged by network_bench.compare_starts), network-real-repeats.json
    # (wall-clock network runs repeated, merged)
    assert set(readme_tables.RENDERERS) - shown == {"upsampling", "lod-target", "server-edges", "network-start",
                                                    "network-repeats"}
    shutil.copy(os.path.join(ROOT, "docs", "results", "cluster.json"), tmp_path / "cluster.json")
    assert "<td>Ray, 2 workers</td>" in build_report(str(tmp_path))


def test_a_benchmark_file_of_another_shape_gets_a_note_not_a_crash(tmp_path):
    (tmp_path / "pareto.json").write_text(json.dumps({"scenes": {"room": {"variants": {}}}}))
    page = build_report(str(tmp_path))
    assert "No pareto table: this run's file lacks" in page


@pytest.mark.parametrize("setup, message", [
    (None, "no such folder"),
    ({}, "holds nothing to report"),
    ({"session.json": "{}"}, "was not scored; run 'pibr evaluate"),
    ({"metrics.json": "{not json"}, "cannot read"),
    ({"metrics.json": '{"methods": {}}'}, "not the metrics of a scored run"),
])
def test_folders_with_nothing_to_show_say_why(tmp_path, setup, message):
    folder = tmp_path / "f"
    if setup is not None:
        folder.mkdir()
        for name, text in setup.items():
            (folder / name).write_text(text)
    with pytest.raises(ConfigError, match=re.escape(message)):
        build_report(str(folder))


def test_pibr_report_command(run_dir, capsys, tmp_path):
    from pibr.cli import main

    page = os.path.join(run_dir, "report.html")
    if os.path.exists(page):
        os.remove(page)
    assert main(["report", run_dir]) == 0
    assert os.path.exists(os.path.join(run_dir, "report.html"))
    assert main(["report", str(tmp_path / "missing")]) == 2
    assert "pibr report: error:" in capsys.readouterr().err


def test_benchmark_commands_end_with_the_report():
    from pibr.cli import build_parser

    parser = build_parser()
    for argv, folder in ((["bench", "pareto"], "out/bench"), (["bench", "network"], "out/bench"), (["demo"], "out"),
                         (["evaluate", "r"], "r")):
        args = parser.parse_args(argv)
        assert args.func.__wrapped__.__name__.startswith("cmd_"), argv
        assert getattr(args, args.func.folder_arg) == folder
