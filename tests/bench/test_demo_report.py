"""``pibr demo``'s report on the real clock: what the wall clock allowed."""
import json

import pytest

from pibr.bench.demo import print_report, real_clock_summary


def _metrics(missed: int, methods=("none", "proxy")) -> dict:
    per = {"psnr_mean": 20.0, "ssim_mean": 0.8, "dssim_mean": 0.1, "flip_mean": 0.2, "geometric_holes_mean": 0.03,
           "hole_fraction_mean": 0.01, "client_ms_median": 40.0, "age_ms_mean": 500.0, "frames": 60,
           "missed_deadlines": missed}
    return {"scene": "room", "trace": {"name": "pred6dof-1", "duration_s": 2.0}, "clock": "real",
            "output": {"width": 160, "height": 90, "rate_hz": 30.0}, "flip_every": 4, "latency_ms": 128.0,
            "methods": {m: dict(per) for m in methods}}


def test_real_clock_summary_counts_frames_on_the_clock_and_fresh_ticks(tmp_path):
    # arrivals before tick 0 (the warm-up) and after the run do not count
    session = {"session": {}, "result": {"frame_arrivals_s": [-0.4, -0.1, 0.05, 0.5, 1.0, 1.5, 1.99, 2.3]}}
    (tmp_path / "session.json").write_text(json.dumps(session))
    summary = real_clock_summary(str(tmp_path), _metrics(missed=45), 2.0)
    assert summary["frames_received"] == 5
    assert summary["server_fps"] == pytest.approx(2.5)
    assert summary["methods"]["proxy"]["output_hz"] == pytest.approx(7.5)
    assert summary["methods"]["none"]["missed_fraction"] == pytest.approx(0.75)


@pytest.mark.parametrize("methods, advice", [(("none", "proxy"), True), (("proxy",), False)])
def test_report_says_what_the_real_clock_allowed(tmp_path, capsys, methods, advice):
    (tmp_path / "session.json").write_text(json.dumps({"session": {}, "result": {"frame_arrivals_s": [0.1, 1.1]}}))
    metrics = _metrics(missed=15, methods=methods)
    metrics["real_clock"] = real_clock_summary(str(tmp_path), metrics, 2.0)
    print_report(metrics, str(tmp_path))
    out = capsys.readouterr().out
    assert "Real clock: the server delivered 1.0 frames/s; the client showed 22.5 fresh images/s of 30 " \
           "(25 % of ticks missed" in out
    assert ("time one at a time with --method proxy" in out) == advice


def test_report_on_the_virtual_clock_has_no_real_clock_line(tmp_path, capsys):
    metrics = _metrics(missed=0)
    metrics["clock"] = "virtual"
    print_report(metrics, str(tmp_path))
    assert "Real clock" not in capsys.readouterr().out
