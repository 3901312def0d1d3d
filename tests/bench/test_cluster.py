"""Sweeps spread over workers (bench/cluster.py): the same numbers in this process and on Ray.

The Ray tests need the optional extra (pip install '.[cluster]'); they skip without it unless
PIBR_REQUIRE_RAY=1 (as .ci/run sets)."""
import os
import sys

import pytest

from pibr.bench.cluster import Placement, Point, Worker, import_ray, run_points, same_numbers
from pibr.bench.windows import Window
from pibr.protocol.errors import ConfigError


def _square(worker, x, fail=False):
    if fail:
        raise ConfigError(f"point {x} refuses")
    return {"x": x, "square": x * x, "pid": os.getpid(), "same_worker_cache": len(worker.cache("seen"))}


def test_points_run_here_in_order_and_report_each():
    seen, ticks = [], []

    class Bar:
        def update(self, n):
            ticks.append(n)

    points = [Point(_square, {"x": x}, cost=x, ticks=x + 1) for x in (3, 1, 2)]
    out = run_points(points, bar=Bar(), on_result=lambda i, r: seen.append((i, r["square"])))
    assert [r["square"] for r in out] == [9, 1, 4] and seen == [(0, 9), (1, 1), (2, 4)] and ticks == [4, 2, 3]
    assert {r["pid"] for r in out} == {os.getpid()}
    assert run_points([]) == []


def test_a_worker_keeps_its_scene_and_caches_and_scores_inline_or_on_a_process():
    w = Worker(score_processes=0)
    try:
        assert w.scene("room") is w.scene("room")
        w.cache("a")["k"] = 1
        assert w.cache("a") == {"k": 1} and w.cache("b") == {}
        assert w.submit(pow, 2, 10).result() == 1024
    finally:
        w.close()
    w = Worker(score_processes=1)
    try:
        assert w.submit(pow, 3, 3).result() == 27
    finally:
        w.close()


def test_without_ray_the_error_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)
    with pytest.raises(ConfigError, match=r"pip install 'pibr\[cluster\]'"):
        import_ray()
    with pytest.raises(ConfigError, match="--workers and --ray-address"):
        run_points([Point(_square, {"x": 1})], Placement(workers=2))


def test_a_ray_address_where_nothing_listens_is_refused_at_once():
    pytest.importorskip("ray")
    from pibr.bench.processes import free_port

    for address in (f"127.0.0.1:{free_port()}", f"ray://127.0.0.1:{free_port()}"):
        with pytest.raises(ConfigError, match=f"--ray-address {address}: nothing answers at 127.0.0.1"):
            run_points([Point(_square, {"x": 1})], Placement(ray_address=address))


def test_workers_the_cluster_cannot_hold_are_refused_or_warned(caplog):
    from pibr.bench.cluster import _check_resources

    with pytest.raises(ConfigError, match=r"1 CPU and 1 GPU\(s\), and the cluster has 2 CPU\(s\) and 0 GPU"):
        _check_resources({"CPU": 2.0}, 2, 1.0)
    _check_resources({"CPU": 2.0}, 2, 0.0)
    assert not caplog.records
    _check_resources({"CPU": 2.0, "GPU": 1.0}, 2, 1.0)
    assert "some wait for room" in caplog.text


def test_cli_placement_options(monkeypatch, capsys):
    from pibr.cli import main

    with pytest.raises(SystemExit):
        main(["bench", "trade", "--workers", "0"])
    assert "--workers: must be at least 1" in capsys.readouterr().err
    assert main(["bench", "coverage", "--gpus-per-worker", "1"]) == 2
    assert "add --workers N or --ray-address" in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, "ray", None)
    assert main(["bench", "pareto", "--workers", "2"]) == 2
    assert "pip install 'pibr[cluster]'" in capsys.readouterr().err
    assert main(["bench", "dynamic", "--ray-address", "auto"]) == 2


def test_same_numbers_ignores_timings_only():
    a = {"seconds": 3.0, "rows": [{"dssim": 0.1, "client_cpu_ms": 5.0, "moving": float("nan")}]}
    assert same_numbers(a, {"seconds": 9.0, "rows": [{"dssim": 0.1, "client_cpu_ms": 7.0, "moving": float("nan")}]})
    assert not same_numbers(a, {"seconds": 3.0, "rows": [{"dssim": 0.1000001, "client_cpu_ms": 5.0,
                                                          "moving": float("nan")}]})
    assert not same_numbers(a, {"seconds": 3.0, "rows": [{"dssim": 0.1, "client_cpu_ms": 5.0, "moving": 0.0}]})


@pytest.fixture(scope="module")
def ray_two_cpus():
    """A local Ray with two CPUs for the module's tests (run_points leaves a Ray it did not start running)."""
    try:
        import ray
    except ImportError:
        if os.environ.get("PIBR_REQUIRE_RAY") == "1":
            raise
        pytest.skip("Ray is not installed (pip install '.[cluster]')")
    ray.init(num_cpus=2, include_dashboard=False, logging_level="ERROR")
    # this module's point functions go to the workers by value: they cannot import the tests
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    yield ray
    ray.shutdown()


def test_points_on_ray_come_back_in_order_from_two_workers(ray_two_cpus):
    points = [Point(_square, {"x": x}, cost=x) for x in range(8)]
    out = run_points(points, Placement(workers=2))
    assert [r["square"] for r in out] == [x * x for x in range(8)]
    pids = {r["pid"] for r in out}
    assert len(pids) == 2 and os.getpid() not in pids
    assert ray_two_cpus.is_initialized()      # not this call's to stop


def test_a_failing_point_on_ray_raises_its_own_error(ray_two_cpus):
    with pytest.raises(ConfigError, match="point 3 refuses"):
        run_points([Point(_square, {"x": x, "fail": x == 3}) for x in range(5)], Placement(workers=2))


@pytest.mark.gl
def test_trade_on_two_ray_workers_gives_the_serial_numbers(ray_two_cpus, tmp_path):
    from pibr.bench.trade import StreamPoint, run_trade_bench

    kw = dict(knobs=("bitrate", "tau"), windows=(Window("pred6dof-1", 30.0, 0.5), Window("synth-walk", 5.0, 0.5)),
              stride=3, out_size=(128, 72), flip_every=2, stream=StreamPoint(bitrate_kbps=2000.0, view_size=(128, 128)),
              values={"bitrate": (300.0,), "tau": (0.4,)}, progress=False)
    here = run_trade_bench(out_dir=str(tmp_path / "here"), **kw)
    ray = run_trade_bench(out_dir=str(tmp_path / "ray"), placement=Placement(workers=2), **kw)
    assert here["placement"]["mode"] == "in-process" and ray["placement"] == {**ray["placement"], "mode": "ray",
                                                                              "workers": 2}
    assert same_numbers(here, ray)
    # each says what it drew with: this process's context, and each of the two workers' own
    assert len(here["placement"]["gl_renderers"]) == 1 and ray["placement"]["gl_renderers"]
    rows = here["scenes"]["room"]["sweeps"]["bitrate"]
    assert len(rows) == 2 and rows[0]["methods"]["proxy"]["frames"] > 0


@pytest.mark.gl
def test_pareto_coverage_and_dynamic_on_ray_give_the_serial_numbers(ray_two_cpus, tmp_path):
    from pibr.bench.coverage import run_coverage_bench
    from pibr.bench.dynamic_bench import run_dynamic_bench
    from pibr.bench.pareto import run_pareto_bench

    windows = (Window("pred6dof-1", 30.0, 0.5), Window("synth-walk", 5.0, 0.5))
    for run, kw in (
            (run_pareto_bench, dict(methods=("rotation", "gridwarp"), windows=windows, stride=6, view_size=(128, 128),
                                    out_size=(96, 54), speed_sizes=((96, 54),), speed_frames=1, flip_every=2)),
            (run_coverage_bench, dict(windows=windows, stride=6, view_size=(128, 128), out_size=(64, 36))),
            (run_dynamic_bench, dict(scenes=("dynamic",), windows=(Window("synth-turns", 5.0, 0.3),),
                                     latencies=(64.0, 256.0), stride=4, view_size=(96, 96), out_size=(64, 48),
                                     event_stride=16))):
        here = run(out_dir=str(tmp_path / "here"), progress=False, **kw)
        ray = run(out_dir=str(tmp_path / "ray"), progress=False, placement=Placement(workers=2), **kw)
        assert same_numbers(here, ray), run.__name__
        assert ray["placement"]["mode"] == "ray"
