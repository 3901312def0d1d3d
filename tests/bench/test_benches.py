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
    speed = r["speed"][f"{TINY_OUT[0]}x{TINY_OUT[1]}"]
    assert speed["proxy_ms"] > 0 and speed["floor_ms"] > 0
    assert json.loads((tmp_path / "ibr.json").read_text())["quality"] == r["quality"]
    print_ibr_tables(r)
    assert "floor" in capsys.readouterr().out


def test_bench_codec(tmp_path, capsys):
    from pibr.bench.codec_bench import print_codec_table, run_codec_bench

    r = run_codec_bench(windows=(Window("pred6dof-1", 30.0, 8.0),), window_s=0.3, view_size=TINY_VIEW,
                        out_size=TINY_OUT, out_dir=str(tmp_path), progress=False)
    assert r["windows"]["used"] == [{"trace": "pred6dof-1", "start_s": 30.0, "duration_s": 0.3}]
    s = r["summary"]
    assert {"edge", "edge-intra", "edge-raster", "zstd-lossless", "h264-8bit"} <= set(s)
    for name in ("edge", "edge-intra", "edge-raster"):
        assert s[name]["bits_edges"] > 0 and s[name]["bits_values"] > 0
    # lossless codes are never worse than the edge codec's reconstruction
    assert s["zstd-lossless"]["psnr_db"] >= s["edge"]["psnr_db"]
    e2e = r["end_to_end"]["results"]
    assert set(e2e) == {"edge", "h264"}
    assert all(0.0 <= v["dssim_mean"] <= 0.5 for v in e2e.values())
    assert e2e["edge"]["depth_kbps"] > 0 and e2e["h264"]["depth_kbps"] == 0
    assert (tmp_path / "codec.json").exists() and (tmp_path / "codec.png").stat().st_size > 0
    print_codec_table(r)
    assert "end to end" in capsys.readouterr().out


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
