"""pibr bench scoring on a tiny session: both phases timed, every stage timed, and pibr's metrics
equal to the libraries' on real images."""
import json
import os

import pytest

from pibr.bench.scoring_bench import run_scoring_bench

pytestmark = [pytest.mark.integration, pytest.mark.gl]


def test_a_tiny_session_is_streamed_scored_and_profiled(tmp_path):
    r = run_scoring_bench(out_dir=str(tmp_path), duration_s=1.0, size=(320, 180), profile_ticks=6, flip_every=2)
    with open(os.path.join(tmp_path, "scoring.json")) as f:
        assert json.load(f)["stages"] == r["stages"]
    assert r["streaming"]["seconds"] > 0 and r["scoring"]["seconds"] > 0
    assert r["streaming"]["cpu_seconds"] > 0 and r["scoring"]["cpu_seconds"] > 0
    assert r["scoring_over_streaming"] == r["scoring"]["seconds"] / r["streaming"]["seconds"]
    c = r["compared"]
    # 6 ticks x 3 methods; FLIP on ticks 0, 2, 4, compared with flip-evaluator (the test extra)
    assert (c["ticks"], c["ssim_psnr_values"], c["flip_values"], c["flip_compared"]) == (6, 18, 9, True)
    assert r["identical_to_libraries"] and all(c["equal"].values())
    stages = {s["stage"].split(" (")[0]: s for s in r["stages"]}
    assert set(stages) == {"ground truth render", "decoding the lossless recordings", "geometric holes", "SSIM",
                           "PSNR", "FLIP", "side-by-side video"}
    assert all(s["ms_per_tick"] > 0 for s in r["stages"])
    assert all(stages[k]["library_ms_per_tick"] > 0 for k in ("SSIM", "PSNR", "FLIP"))


def test_the_readme_tables_render_from_its_result(tmp_path):
    from pibr.bench.readme_tables import RENDERERS

    r = {"streaming": {"seconds": 30.0, "cpu_seconds": 60.0}, "scoring": {"seconds": 27.0, "cpu_seconds": 50.0},
         "scoring_over_streaming": 0.9,
         "stages": [{"stage": "SSIM (scikit-image's)", "ms_per_tick": 50.0, "library_ms_per_tick": 260.0},
                    {"stage": "ground truth render (GL)", "ms_per_tick": 40.0, "library_ms_per_tick": None}]}
    phases = "\n".join(RENDERERS["scoring"](r))
    assert "| scoring / streaming | 0.90 |" in phases.replace("  ", " ")
    stages = "\n".join(RENDERERS["scoring-stages"](r))
    assert "SSIM (scikit-image's) | 50.0 | 260.0" in stages and "| 40.0 | — |" in stages
