"""The benchmarks run end to end at tiny sizes and write what they promise (JSON, plots, tables)."""
import json
import math

import pytest

from pibr.bench.windows import Window

pytestmark = pytest.mark.gl

TINY_VIEW = (128, 128)
TINY_OUT = (96, 54)


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and math.isfinite(x)


def test_bench_server_and_client(tmp_path, capsys):
    from pibr.bench.pipeline_bench import bench_client, bench_server, print_client_table, print_server_table

    server = bench_server(frames=3, view_size=TINY_VIEW, projections=("vertex",), extra_view="both",
                          edge_angles=(6.0, 12.0), out_dir=str(tmp_path))
    rows = server["rows"]
    assert [(r["max_edge_deg"], r["extra_view"]) for r in rows] == [(6.0, False), (6.0, True), (12.0, False),
                                                                     (12.0, True)]
    assert rows[1]["atlas"][0] > rows[0]["atlas"][0]                    # the extra view widens the atlas
    assert all(_finite(r[k]) and r[k] > 0 for r in rows for k in ("render_ms", "encode_ms", "kbps"))
    # coarser edges: fewer triangles; each compared with the 2-degree reference
    assert rows[0]["rasterised_triangles"] > rows[2]["rasterised_triangles"]
    for r in (rows[0], rows[2]):
        assert r["psnr_vs_reference_db"] > 20 and 0 <= r["distance_off_fraction"] < 0.05
    client = bench_client(frames=3, view_size=TINY_VIEW, out_size=TINY_OUT, methods=("none", "proxy"),
                          out_dir=str(tmp_path))
    assert set(client["display_ms"]) == {"none", "proxy"}
    assert all(_finite(v) and v > 0 for v in client["display_ms"].values())
    saved = json.loads((tmp_path / "bench_client.json").read_text())
    assert saved["display_ms"] == client["display_ms"]
    print_server_table(server)
    print_client_table(client)
    out = capsys.readouterr().out
    assert "proxy" in out and "vertex" in out


def test_bench_ibr(tmp_path, capsys):
    from pibr.bench.ibr_bench import print_ibr_tables, run_ibr_bench

    r = run_ibr_bench(windows=(Window("pred6dof-1", 30.0, 0.4),), view_size=TINY_VIEW, out_size=TINY_OUT, stride=4,
                      lod_targets=(6.0,), speed_sizes=(TINY_OUT,), speed_frames=2, out_dir=str(tmp_path),
                      progress=False)
    assert r["windows"]["disjoint_from_tuning"]
    quality = r["quality"]["pred6dof-1 30-30.4 s"]
    assert {"none", "rotation", "proxy"} <= set(quality)
    for m in ("none", "rotation", "proxy"):
        assert 0.0 <= quality[m]["dssim_mean"] <= 0.5 and quality[m]["frames"] > 0
    # The methods' order on this part of an evaluation window (measured DSSIM: none 0.279,
    # rotation 0.120, proxy 0.081): each is clearly better than the one before.
    d = {m: quality[m]["dssim_mean"] for m in ("none", "rotation", "proxy")}
    assert d["proxy"] < 0.85 * d["rotation"] and d["rotation"] < 0.7 * d["none"], d
    speed = r["speed"][f"{TINY_OUT[0]}x{TINY_OUT[1]}"]
    assert speed["proxy_ms"] > 0 and speed["floor_ms"] > 0
    assert json.loads((tmp_path / "ibr.json").read_text())["quality"] == r["quality"]
    print_ibr_tables(r)
    assert "floor" in capsys.readouterr().out


def test_bench_codec(tmp_path, capsys):
    """Rate-distortion curves at a tiny size: more bits never lower a codec's PSNR, H.264 depth is
    coded at the edge codec's rates, the lossless codecs decode exactly their quantisation, the
    end-to-end split gives colour what depth leaves."""
    from pibr.bench.codec_bench import MIN_COLOUR_KBPS, print_codec_table, run_codec_bench

    r = run_codec_bench(windows=(Window("pred6dof-1", 30.0, 8.0),), window_s=0.3, view_size=TINY_VIEW,
                        out_size=TINY_OUT, out_dir=str(tmp_path), progress=False, thresholds=(2.0, 16.0, 128.0),
                        log_bits=(16, 8), totals_kbps=(600.0, 2000.0), e2e_windows=1,
                        plot_path=str(tmp_path / "depth_rd.png"))
    assert r["windows"]["used"] == [{"trace": "pred6dof-1", "start_s": 30.0, "duration_s": 0.3}]
    assert r["windows"]["disjoint_from_tuning"] and r["frames"] == 3
    curves = r["curves"]
    h264 = ["h264-8bit", "h264-10bit"] if r["h264_10bit"]["available"] else ["h264-8bit"]
    assert set(curves) == {"edge", "edge-8bit", "edge-10bit", *h264, "log-zstd", "zstd-lossless"}
    assert {p["setting"]["bits"] for p in curves["edge-8bit"]} == {8}
    assert [p["setting"]["threshold"] for p in curves["edge"]] == [128.0, 16.0, 2.0]   # sorted by bits
    for name, pts in curves.items():
        bits = [p["bits_per_frame"] for p in pts]
        assert bits == sorted(bits) and all(b > 0 for b in bits), name
        psnr = [p["psnr_db"] for p in pts]
        assert psnr == sorted(psnr), name                     # more bits: PSNR not lower
        assert all(p["frames"] == 3 for p in pts)
    for name in h264:   # rate control targets the edge codec's bits of the same threshold and precision
        matched = "edge-8bit" if name == "h264-8bit" else "edge-10bit"
        for p in curves[name]:
            edge = next(e for e in curves[matched] if e["setting"]["threshold"] == p["setting"]["matched_to_edge_threshold"])
            assert 0.5 < p["bits_per_frame"] / edge["bits_per_frame"] < 2.0
    assert curves["zstd-lossless"][0]["exact_codes"] == 1.0
    assert all(p["exact_codes"] == 1.0 for p in curves["log-zstd"])
    assert curves["log-zstd"][-1]["outliers_1pct"] == 0.0 and curves["log-zstd"][-1]["psnr_db"] > 90
    assert set(r["edge_variants"]) == {"edge-intra", "edge-raster", "edge-plain-diffusion"}
    default = next(p for p in curves["edge"] if p["setting"]["threshold"] == 2.0)
    assert all(default[f"bits_{k}"] > 0 for k in ("edges", "values", "regular", "header"))
    assert sum(default[f"bits_{k}"] for k in ("edges", "values", "regular", "header")) == \
        pytest.approx(default["bits_per_frame"])
    assert [m["threshold"] for m in r["matched"]] == [128.0, 16.0, 2.0] and all(
        {*h264, "edge", "edge-8bit", "edge-10bit"} <= set(m) for m in r["matched"])
    # precision: at the finest threshold, more code bits leave fewer pixels more than 1 % off
    finest = r["matched"][-1]
    print({k: (v["bits_per_frame"], v["outliers_1pct"]) for k, v in finest.items() if k != "threshold"})
    assert finest["edge"]["outliers_1pct"] < finest["edge-10bit"]["outliers_1pct"] < \
        finest["edge-8bit"]["outliers_1pct"]
    assert [p["setting"]["total_kbps"] for p in r["h264_8bit_atlas"]] == [600.0, 2000.0]
    assert all(p["bits_per_frame"] is None and p["atlas_kbps"] > 0 for p in r["h264_8bit_atlas"])
    for metric in ("psnr_db", "outliers_1pct"):
        assert {w["winner"] for w in r["wins"][metric]} <= set(curves)
    e2e = r["end_to_end"]
    assert {v["codec"] for v in e2e["results"].values()} == {"h264-8bit-atlas", "edge", "edge-rc", *h264,
                                                             "log-zstd", "zstd-lossless"}
    for v in e2e["results"].values():
        # the depth streams' rate is the same in the probe and the run; H.264 depth is targeted at the edge's
        depth = e2e["results"][f"{v['total_kbps']:g}/edge"]["depth_kbps"] if v["codec"] in h264 else \
            e2e["edge_share"] * v["total_kbps"] if v["codec"] == "edge-rc" else v["depth_kbps"]
        assert v["colour_kbps"] == pytest.approx(v["total_kbps"] - depth - v["motion_kbps"], rel=1e-9)
        assert v["feasible"] == (v["colour_kbps"] >= MIN_COLOUR_KBPS)
        if v["feasible"]:
            assert 0.0 <= v["dssim_mean"] <= 0.5
    atlas = e2e["results"]["2000/h264-8bit-atlas"]
    assert atlas["feasible"] and atlas["depth_kbps"] == 0 and atlas["colour_kbps"] == 2000.0 - atlas["motion_kbps"]
    assert e2e["results"]["2000/edge"]["depth_kbps"] > 0
    assert e2e["wins"]["2000"]["winner"] in {v["codec"] for v in e2e["results"].values() if v["feasible"]}
    assert set(r["extremes"]["quantizers"]) == {"8bit-disparity", "edge-12bit-disparity", "log16"}
    data = json.loads((tmp_path / "codec.json").read_text())
    assert data["curves"]["edge"][0]["bits_per_frame"] == curves["edge"][0]["bits_per_frame"]
    assert (tmp_path / "codec.png").stat().st_size > 0 and (tmp_path / "depth_rd.png").stat().st_size > 0
    # What the curves are for (measured at this size: outliers 87 -> 38 % for the edge codec from
    # 11 to 37 kbit a frame, 66 % for 8-bit H.264 at 30 kbit and 46 % at 10 bits, 3 % lossless):
    # more bits leave fewer pixels more than 1 % off, 10 bits fewer than 8, lossless fewest; end to
    # end every codec scores better with more total bits.
    for name, pts in curves.items():
        outliers = [p["outliers_1pct"] for p in pts]
        assert outliers == sorted(outliers, reverse=True), name
    if "h264-10bit" in curves:
        assert curves["h264-10bit"][-1]["outliers_1pct"] < 0.9 * curves["h264-8bit"][-1]["outliers_1pct"]
    assert curves["zstd-lossless"][0]["outliers_1pct"] < 0.25 * min(curves[n][-1]["outliers_1pct"]
                                                                  for n in ("edge", *h264))
    for codec in {v["codec"] for v in e2e["results"].values()}:
        low, high = e2e["results"][f"600/{codec}"], e2e["results"][f"2000/{codec}"]
        if low["feasible"]:
            assert high["dssim_mean"] < low["dssim_mean"], codec
    print_codec_table(r)
    out = capsys.readouterr().out
    assert "end to end" in out and "10-bit H.264" in out


def test_bench_codec_speed_against_a_checkout_of_itself(tmp_path, capsys):
    """The baseline worker imports pibr from the given source tree; against this very tree every
    payload and decoded sample set must come out identical, and every stage is timed."""
    import os

    from pibr.bench.codec_speed import print_codec_speed, run_codec_speed

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    r = run_codec_speed(windows=(Window("pred6dof-1", 30.0, 8.0),), window_s=0.3, view_size=TINY_VIEW,
                        baseline=root, out_dir=str(tmp_path), progress=False)
    assert r["frames"] == 3 and set(r["versions"]) == {"current", "baseline"}
    assert r["versions"]["baseline"]["pibr"].startswith(os.path.join(root, "protocol")) or \
        "pibr-checkout-" in r["versions"]["baseline"]["pibr"]
    c = r["comparison"]
    assert c["identical_payloads"] == 3 and c["identical_samples"] == 3 and c["bytes_ratio"] == 1.0
    for v in r["versions"].values():
        assert v["decoder_matches_encoder"]
        assert all(_finite(ms) and ms >= 0 for ms in v["median_ms"].values())
        assert v["median_encode_total_ms"] > 0 and v["mean_psnr_db"] > v["mean_plain_psnr_db"] - 1e-9
    assert json.loads((tmp_path / "codec_speed.json").read_text())["frames"] == 3
    print_codec_speed(r)
    assert "enc.encode" in capsys.readouterr().out


def test_bench_upsampling(tmp_path, capsys):
    """Three streams over a still and a moving sequence: the quarter's server colour costs less,
    its rebuild converges on the still view and beats bilinear upscaling of the same frames."""
    from pibr.bench.upsampling_bench import STREAMS, print_upsampling_table, run_upsampling_bench

    r = run_upsampling_bench(windows=(Window("pred6dof-1", 12.0, 1.0),), still_frames=5, moving_s=0.8,
                             view_size=TINY_VIEW, depth_codec="edge", out_dir=str(tmp_path), progress=False)
    assert list(r["streams"]) == [name for name, _, _ in STREAMS]
    whole, quarter = r["streams"]["whole"], r["streams"]["quarter"]
    assert whole["atlas"] == [192, 128] and quarter["atlas"] == [96, 64]
    assert whole["frames"] == quarter["frames"] == 5 + 8
    assert quarter["times_ms_median"]["rebuild_ms"] > 0 and whole["times_ms_median"]["rebuild_ms"] < 1.0
    curve = [x["psnr_mean"] for x in quarter["still_by_frame"]["primary"]]
    assert curve[3] > curve[0] + 3                      # four frames: every pixel sent once
    assert "bilinear" not in whole["moving"]["primary"]
    moving = quarter["moving"]["primary"]
    assert moving["rebuilt"]["psnr_mean"] > moving["bilinear"]["psnr_mean"]
    assert len(r["verdicts"]) == 3 and all(isinstance(v["met"], bool) for v in r["verdicts"])
    assert r["windows"]["disjoint_from_tuning"] is False          # 12 s of pred6dof-1 is a tuning window
    saved = json.loads((tmp_path / "upsampling.json").read_text())
    assert saved["streams"]["quarter"]["colour_scale"] == 0.5
    print_upsampling_table(r)
    assert "quarter-bits" in capsys.readouterr().out


def test_bench_predict_on_a_short_window(tmp_path):
    """Issue 28: the predictors on part of an evaluation window; the Kalman filter below no
    prediction at every look-ahead, velocity far below none at 100 ms (measured 1.4 deg against 4.3)."""
    from pibr.bench.predict_bench import run_predict_bench
    from pibr.bench.windows import Window

    r = run_predict_bench(windows=(Window("pred6dof-1", 30.0, 3.0),), look_aheads_ms=(20.0, 100.0),
                          out_dir=str(tmp_path), plot=False)
    assert (tmp_path / "predict.json").exists()
    overall = {name: p["overall"] for name, p in r["predictors"].items()}
    assert r["kalman_beats_none_at_every_look_ahead"]
    assert overall["velocity"]["100"]["angle_deg_mean"] < 0.6 * overall["none"]["100"]["angle_deg_mean"]
    assert overall["none"]["20"]["angle_deg_mean"] < overall["none"]["100"]["angle_deg_mean"]
    assert r["windows"]["disjoint_from_tuning"]


@pytest.mark.gl
def test_rendering_for_the_predicted_pose_helps_rotation():
    """The server rendering each frame for the pose a predictor expects at its display: rotation,
    which cannot follow the head's translation, gains most (measured at 128 ms on this window:
    DSSIM 0.096 with velocity, 0.133 without)."""
    from pibr.bench.predict_bench import prediction_quality
    from pibr.bench.windows import Window

    q = prediction_quality((Window("pred6dof-1", 30.0, 1.0),), (128.0,), ("rotation",), stride=3,
                           view_size=(256, 256), out_size=(240, 136))["128"]
    assert q["velocity"]["rotation"]["dssim_mean"] < 0.85 * q["none"]["rotation"]["dssim_mean"]
    assert q["kalman"]["rotation"]["dssim_mean"] < 0.85 * q["none"]["rotation"]["dssim_mean"]
    assert q["none"]["rotation"]["frames"] == 10
