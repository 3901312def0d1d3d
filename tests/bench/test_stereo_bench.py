"""``pibr bench stereo`` on a tiny run: what its table claims holds."""
import json
import os

import numpy as np
import pytest

from pibr.bench.stereo_bench import RESTING_M_S, WALKING_M_S, rest_window, run_stereo_bench
from pibr.client.recorder import anaglyph
from pibr.bench.windows import Window
from pibr.common.traces.loading import load_trace
from pibr.protocol.errors import ConfigError


def test_the_rest_window_walks_then_rests():
    w = rest_window()
    trace = load_trace(w.trace)
    linear, _ = trace.speeds()
    t = trace.t[1:]
    first = linear[(t >= w.start_s) & (t < w.start_s + 0.5)]
    last = linear[(t >= w.end_s - 1.5) & (t <= w.end_s)]
    assert first.mean() > WALKING_M_S and last.max() < RESTING_M_S
    with pytest.raises(ConfigError, match="comes to rest"):
        rest_window("synth-turns")


def test_anaglyph_takes_red_from_the_left_eye():
    left = np.full((2, 3, 3), 10, np.uint8)
    right = np.full((2, 3, 3), 200, np.uint8)
    assert anaglyph(left, right)[0, 0].tolist() == [10, 200, 200]


@pytest.mark.gl
def test_a_tiny_run(tmp_path):
    r = run_stereo_bench(windows=(Window("synth-walk", 5.0, 1.0),), methods=("proxy", "rotation"), scenes=("room",),
                         view_size=(256, 256), out_size=(240, 136), stride=3, flip_every=2, out_dir=str(tmp_path),
                         progress=False)
    assert {"stereo.json", "stereo.png", "stereo-pair.png", "stereo-anaglyph.png"} <= set(os.listdir(tmp_path))
    assert json.load(open(tmp_path / "stereo.json"))["goals"] == r["goals"]
    v, server = r["scenes"]["room"]["variants"], r["scenes"]["room"]["server"]
    # rotation ignores where the eye is, so both eyes get one image: exactly the mono image's mismatch
    assert v["rotation cyclops"]["inconsistent_mean"] == pytest.approx(v["rotation mono"]["inconsistent_mean"])
    # proxy re-projects each eye: far fewer mismatched pairs than one image shown to both eyes
    # (measured 0.029 against 0.137), at the mono view's quality per eye (1.04x)
    assert v["proxy cyclops"]["inconsistent_mean"] < 0.5 * v["proxy mono"]["inconsistent_mean"]
    assert v["proxy cyclops"]["dssim_vs_mono"] < 1.1
    assert v["proxy per-eye"]["dssim_mean"] < v["rotation per-eye"]["dssim_mean"]
    # the per-eye server makes two frames a tick at about twice the bits; the others one
    assert server["per-eye"]["frames_per_tick"] == 2.0 and server["alternate"]["frames_per_tick"] == 1.0
    assert 1.5 < server["per-eye"]["bits_per_second"] / server["centre"]["bits_per_second"] < 2.6
    # a pair is two views: dearer than one, eye by eye (the default) and at once (render_pair, timed
    # beside it on the same frames); rotation has no pair path, nor a per-eye server's pair
    assert v["proxy cyclops"]["cpu_ms_vs_mono"] > 1.2 and v["proxy cyclops"]["cpu_ms_pair_at_once_vs_mono"] > 1.2
    assert "cpu_ms_pair_at_once_median" not in v["rotation cyclops"]
    assert "cpu_ms_pair_at_once_median" not in v["proxy per-eye"]
    assert r["goals"]["room"]["ms_per_pair"]["pair_at_once_ratio"] > 1.2 and r["blas_threads"] == 1
    assert set(r["goals"]["room"]) == {"dssim", "ms_per_pair", "consistency"}


def test_the_client_is_timed_with_blas_on_one_thread():
    """OpenBLAS's idle workers spin between calls and were charged to the display timed next
    (bench/simulation.py blas_on_one_thread): within the bench BLAS runs on one thread."""
    from threadpoolctl import threadpool_info

    from pibr.bench.simulation import blas_on_one_thread

    np.ones((64, 64)) @ np.ones((64, 64))   # numpy's BLAS loaded
    before = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
    assert before
    if (os.cpu_count() or 1) > 1:   # (a pool of one already on one core)
        assert max(before) > 1
    with blas_on_one_thread():
        assert all(i["num_threads"] == 1 for i in threadpool_info() if i["user_api"] == "blas")
    assert [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"] == before


def test_modes_without_the_baseline_are_refused(tmp_path):
    with pytest.raises(ConfigError, match="mono"):
        run_stereo_bench(modes=("cyclops",), out_dir=str(tmp_path), progress=False)
    with pytest.raises(ConfigError, match="interpupillary"):
        run_stereo_bench(ipd_mm=0, out_dir=str(tmp_path), progress=False)
