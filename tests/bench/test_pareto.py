"""The pareto benchmark's parts: windows, the front, uniform frames, geometric holes, and a tiny run."""
import json

import numpy as np
import pytest

from pibr.bench.metrics import nearly_uniform
from pibr.bench.pareto import default_variants, run_pareto_bench
from pibr.bench.variants import ORACLE, pareto_front
from pibr.bench.windows import EVALUATION_WINDOWS, TUNING_WINDOWS, Window, overlapping_tuning, parse_windows
from pibr.protocol.errors import ConfigError
from pibr.common.traces.loading import load_trace


def test_evaluation_windows_are_disjoint_from_tuning_and_inside_their_traces():
    assert overlapping_tuning(EVALUATION_WINDOWS) == []
    assert overlapping_tuning(TUNING_WINDOWS) == list(TUNING_WINDOWS)
    kinds = {w.trace for w in EVALUATION_WINDOWS}
    assert {"pred6dof-1", "pred6dof-2", "synth-walk", "synth-look", "synth-turns"} <= kinds
    for w in EVALUATION_WINDOWS:
        start, end = load_trace(w.trace).window(w.start_s, w.duration_s)
        assert end - start == pytest.approx(w.duration_s)     # the whole window lies inside the trace


def test_window_overlap_and_parsing():
    a = Window("pred6dof-1", 10.0, 8.0)
    assert a.overlaps(Window("pred6dof-1", 17.9, 1.0)) and not a.overlaps(Window("pred6dof-1", 18.0, 1.0))
    assert not a.overlaps(Window("pred6dof-2", 10.0, 8.0))
    assert parse_windows("tuning") == TUNING_WINDOWS
    assert parse_windows("pred6dof-2@30+4, synth-walk@1.5+2") == (Window("pred6dof-2", 30.0, 4.0),
                                                                  Window("synth-walk", 1.5, 2.0))
    for bad in ("pred6dof-1", "x@1", "x@-1+2", "@1+2", "x@1+0"):
        with pytest.raises(ConfigError):
            parse_windows(bad)


def test_synthetic_traces_by_name_are_deterministic():
    a, b = load_trace("synth-turns"), load_trace("synth-turns")
    np.testing.assert_array_equal(a.orientations, b.orientations)
    c = load_trace("synth-turns-seed7")
    assert not np.array_equal(a.orientations, c.orientations)
    assert a.duration == pytest.approx(60.0)


def test_pareto_front():
    points = {"fast bad": (1.0, 0.2), "slow good": (50.0, 0.02), "dominated": (60.0, 0.05),
              "middle": (10.0, 0.05), "tie slower": (10.0, 0.06)}
    assert pareto_front(points) == ["fast bad", "middle", "slow good"]


def test_nearly_uniform():
    sky = np.zeros((90, 160, 3), np.uint8) + np.array([120, 160, 220], np.uint8)
    assert nearly_uniform(sky)
    varied = sky.copy()
    varied[:, :20] = 0                       # 12.5 % of the image differs
    assert not nearly_uniform(varied)
    noisy = np.clip(sky.astype(int) + np.random.default_rng(0).integers(-1, 2, sky.shape), 0, 255).astype(np.uint8)
    assert nearly_uniform(noisy)             # codec noise of a level does not count


def test_unknown_methods_are_named():
    with pytest.raises(ConfigError, match="unknown method"):
        default_variants(["warp9"])
    assert {v.method for v in default_variants(["proxy"])} == {"proxy"}


def test_motion_variants_only_where_things_move():
    from pibr.bench.pareto import motion_variants
    from pibr.scenes.registry import load_scene

    everything = default_variants()
    assert motion_variants(everything, load_scene("sphere")) == []
    moving = {v.label: v.options for v in motion_variants(everything, load_scene("dynamic"))}
    # proxy's bounds, and every competitor that can warp the primary view along its motion flow,
    # once, at its default knobs (homography's default plane is 4 m, coarse-meshwarp's step 4)
    assert moving == {"proxy, static motion": {"motion": "static"}, "proxy, oracle motion": {"motion": "oracle"},
                      "rotation, flow": {"motion": "flow"},
                      "homography 4 m, flow": {"plane_distance": 4.0, "motion": "flow"},
                      "splat, flow": {"motion": "flow"}, "meshwarp, flow": {"motion": "flow"},
                      "coarse-meshwarp s=4, flow": {"step": 4, "motion": "flow"},
                      "gridwarp, flow": {"motion": "flow"}}
    assert motion_variants(default_variants(["none"]), load_scene("dynamic")) == []
    assert motion_variants(default_variants(["quadtree", "iterative"]), load_scene("dynamic")) == []


@pytest.mark.gl
def test_tiny_pareto_run(tmp_path):
    r = run_pareto_bench(scenes=("room",), methods=("none", "rotation", "coarse-meshwarp", "proxy"),
                         windows=(Window("pred6dof-1", 30.0, 0.7),), stride=10, view_size=(256, 256),
                         out_size=(160, 90), speed_sizes=((160, 90),), speed_frames=2, flip_every=2,
                         out_dir=str(tmp_path), progress=False)
    with open(tmp_path / "pareto.json") as f:
        assert json.load(f)["windows"]["disjoint_from_tuning"] is True
    assert (tmp_path / "pareto.png").stat().st_size > 10_000
    room = r["scenes"]["room"]
    v = room["variants"]
    assert set(v) == {"none", "rotation", "coarse-meshwarp s=2", "coarse-meshwarp s=4", "coarse-meshwarp s=8",
                      "coarse-meshwarp s=16", "proxy", "proxy lod 2px", "proxy lod 16px", "proxy tau 0.05",
                      "proxy tau 0.2", "proxy, no extra view", "proxy, no carving", "proxy, no inpainting", "proxy, no culling",
                      "proxy, static motion", "proxy, oracle motion", "rotation, flow",
                      "coarse-meshwarp s=4, flow", ORACLE}
    assert v["proxy, oracle motion"]["options"] == {"motion": "oracle"}
    # the competitors' flow variants get frames with their motion flow decoded, as a client does
    assert room["flow_frames"] is True
    assert all(x["quality"]["frames"] == 3 and x["quality"]["flip_frames"] == 2 for x in v.values())
    # One geometric definition: methods drawing from the same views share it; the extra view
    # only ever removes holes.
    geo = {k: x["quality"]["geometric_holes_mean"] for k, x in v.items()}
    assert geo["none"] == geo["rotation"] == geo["coarse-meshwarp s=4"] == geo["proxy, no extra view"]
    assert v["proxy"]["uses_extra_view"] and not v["none"]["uses_extra_view"]
    assert geo["proxy"] < geo["none"]
    assert geo[ORACLE] == 0.0
    # Primitives: a coarse grid with a vertex every 4th pixel has 1/16 of the quads, 2 triangles each.
    per_px = v["coarse-meshwarp s=4"]["quality"]["primitives_per_view_pixel"]
    assert per_px == pytest.approx(2 * (255 / 4) ** 2 / 256 ** 2, rel=0.05)
    assert v["none"]["quality"]["primitives_mean"] == 0
    for x in v.values():
        assert x["speed"]["160x90"]["frames"] == 4 and x["speed"]["160x90"]["ms_median"] > 0
    # Quality in order (measured DSSIM on this part of an evaluation window: zero latency 0.039,
    # proxy 0.051, its best competitor coarse-meshwarp s=2 0.070, ... rotation 0.132, none 0.184):
    # proxy beats the best competitor clearly, a coarser grid is worse, the extra view helps.
    d = {k: x["quality"]["dssim_mean"] for k, x in v.items()}
    competitors = [k for k in d if not k.startswith("proxy") and k != ORACLE]
    assert d[ORACLE] < d["proxy"] < 0.85 * min(d[k] for k in competitors), d
    grids = [d[f"coarse-meshwarp s={s}"] for s in (2, 4, 8, 16)]
    assert grids == sorted(grids) and d["rotation"] < 0.85 * d["none"], d
    assert d["proxy"] < d["proxy, no extra view"], d
    # The per-window record names what won each window (one window here: its means are the totals).
    (label, row), = room["per_window"].items()
    assert label == "pred6dof-1 30-30.7 s"
    assert row["best_competitor"] == min(competitors, key=d.get)
    assert row["best_competitor_dssim"] == pytest.approx(d[row["best_competitor"]])
    assert v[row["winner"]]["method"] == "proxy" and row["winner"] == row["best_proxy"]
    assert ORACLE not in row["dssim"] and row["dssim"]["proxy"] == pytest.approx(d["proxy"])


def test_window_winners_leave_out_the_bounds():
    """Oracle motion (the scene's animation) and the zero-latency oracle are bounds: recorded per
    window, never the winner, the best proxy variant or the best competitor."""
    from pibr.bench.pareto import window_winners

    def record(method, dssim, **options):
        return {"method": method, "options": options, "quality": {"per_window": {"w": {"dssim_mean": dssim}}}}

    variants = {"proxy": record("proxy", 0.05), "proxy, oracle motion": record("proxy", 0.03, motion="oracle"),
                "gridwarp": record("gridwarp", 0.06), "gridwarp, flow": record("gridwarp", 0.055, motion="flow"),
                ORACLE: record("none", 0.01)}
    row = window_winners(variants, ["w"])["w"]
    assert row["winner"] == row["best_proxy"] == "proxy" and row["winner_dssim"] == 0.05
    assert row["best_competitor"] == "gridwarp, flow"
    assert row["dssim"]["proxy, oracle motion"] == 0.03 and ORACLE not in row["dssim"]
