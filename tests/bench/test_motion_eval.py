"""The moving-object measurement of proxy's extrapolations (bench/motion_eval.py)."""
import numpy as np
import pytest

from pibr.bench.metrics import PSNR_CAP
from pibr.bench.motion_eval import measure_motion
from pibr.bench.windows import Window
from pibr.scenes.registry import load_scene

from .motion_quality import masked_quality


def test_masked_quality():
    rng = np.random.default_rng(3)
    a = rng.integers(0, 256, (40, 60, 3), dtype=np.uint8)
    mask = np.zeros((40, 60), bool)
    mask[10:20, 20:40] = True
    assert masked_quality(a, a, mask) == (0.0, PSNR_CAP)
    assert masked_quality(a, a, np.zeros_like(mask)) == (None, None)
    b = a.copy()
    b[~mask] = 255 - b[~mask]                 # wrong everywhere but in the mask
    assert masked_quality(a, b, mask)[1] == PSNR_CAP
    assert masked_quality(a, b, ~mask)[0] > 0.3


@pytest.mark.gl
def test_tiny_run_orders_the_modes():
    r = measure_motion(load_scene("dynamic"), [Window("synth-turns", 5.0, 1.0)], modes=("static", "oracle"),
                       stride=3, view_size=(256, 256), out_size=(160, 90))
    assert set(r["modes"]) == {"static", "oracle"} and r["windows"] == ["synth-turns 5-6 s"]
    for mode, s in r["modes"].items():
        assert s["frames"] == 10 and 0 < s["moving_frames"] <= 10 and s["ms_median"] > 0
        assert len(r["series"][mode]["synth-turns 5-6 s"]) == 10
    assert r["modes"]["oracle"]["moving_dssim_mean"] < r["modes"]["static"]["moving_dssim_mean"]
