"""``pibr bench codec``: depth on the wire — the edge codec against the alternatives.

Along real traces on the built-in scene, per server frame (primary view) and averaged:

* ``edge``          edge codec, four interleaved passes, temporal context (the default);
* ``edge-intra``    the same without the temporal context;
* ``edge-raster``   a one-pass raster context coder (no interleaved passes);
* ``zstd-lossless`` the 12-bit quantized depth, zstd-compressed: lossless up to quantization;
* ``h264-8bit``     8-bit disparity in the H.264 atlas beside the colour, as the atlas path sends it.

For each: bits per frame (edge image / values / regular samples for the edge variants;
the depth rectangle's share of the atlas for H.264, estimated by coding the atlas with and
without it at the same bitrate), disparity PSNR and maximum error after reconstruction
against the true depth (edge variants: edge-aware diffusion; ``edge`` also with plain
push-pull), and encode / decode ms. At equal *total* bitrate, the colour quality of the
atlas with depth inside against the colour-only atlas beside the edge stream.
"""
from __future__ import annotations

import math
import os
import sys
import time

import numpy as np

from .results import write_result


def disparity_error(r_true: np.ndarray, r_test: np.ndarray, near: float) -> dict:
    """PSNR (peak 1) and max / mean absolute error of disparity near / r (sky = 0) over all pixels,
    and the shares of geometry pixels whose distance is off by more than 1 % and 5 % (12-bit
    quantization alone is 1 % off beyond about 4 m, 5 % beyond about 20 m, with near = 0.1 m)."""
    d_true = np.where(r_true > 0, near / np.maximum(r_true, near), 0.0)
    d_test = np.where(r_test > 0, near / np.maximum(r_test, near), 0.0)
    err = np.abs(d_true - d_test)
    mse = float(np.mean(err ** 2))
    geo = r_true > 0
    rel = np.abs(r_test[geo] - r_true[geo]) / r_true[geo] if geo.any() else np.zeros(0)
    return {"psnr_db": 100.0 if mse == 0 else min(100.0, 10 * math.log10(1.0 / mse)),
            "max_error": float(err.max()), "mean_error": float(err.mean()),
            "outliers_1pct": float(np.mean(rel > 0.01)) if rel.size else 0.0,
            "outliers_5pct": float(np.mean(rel > 0.05)) if rel.size else 0.0}


def _colour_psnr(decoded_rgb: np.ndarray, true_rgb: np.ndarray) -> float:
    from .metrics import psnr

    return psnr(true_rgb, decoded_rgb)


def run_codec_bench(scene_spec="room", windows=None, window_s=4.0, fps=10.0, view_size=(1024, 1024),
                    bitrate_kbps=16000.0, out_dir="out/bench", progress=True, with_end_to_end=True,
                    out_size=(960, 540)) -> dict:
    import zstandard

    from pibr.client.diffusion import codes_to_distance, diffuse, diffuse_plain
    from pibr.client.video import H264Decoder
    from pibr.protocol.atlas import build_layout
    from pibr.protocol.depth import h264_quantizer
    from pibr.protocol.edgecodec.codec import EdgeDecoder, EdgeEncoder, warp_samples
    from pibr.protocol.gl import create_context
    from pibr.protocol.trace import load_trace, placement
    from pibr.scenes.registry import load_scene
    from pibr.server.depth_stream import EDGE_BITS, edge_quantizer
    from pibr.server.edge_extract import extract_edge_samples
    from pibr.server.packer import AtlasPacker
    from pibr.server.pipeline import FrameProducer, ProducerSpec
    from pibr.server.renderer import Renderer
    from pibr.server.video import H264Encoder

    from pibr.protocol.errors import ConfigError

    from .windows import EVALUATION_WINDOWS, Window, windows_json

    # The first window_s seconds of each window (default: the evaluation windows).
    windows = tuple(Window(w.trace, w.start_s, min(w.duration_s, window_s)) for w in (windows or EVALUATION_WINDOWS))
    if min(int(w.duration_s * fps) for w in windows) < 1:
        raise ConfigError(f"{min(w.duration_s for w in windows)} s at {fps:g} fps is not a single frame")
    scene = load_scene(scene_spec)
    for w in windows:
        load_trace(w.trace).window(w.start_s, w.duration_s)  # a start outside a trace is refused before any work
    w, h = view_size
    q8 = h264_quantizer(scene.near, scene.far)
    q12 = edge_quantizer(scene.near, scene.far, EDGE_BITS)
    with_depth = build_layout((w, h), None, depth_in_atlas=True)
    colour_only = build_layout((w, h), None, depth_in_atlas=False)
    ctx = create_context()
    renderer = Renderer(ctx, scene)
    producer = FrameProducer(ctx, renderer, ProducerSpec((w, h), with_depth, q8, keep_distance=True))
    colour_packer = AtlasPacker(ctx, colour_only, None)
    variants = {"edge": dict(temporal=True, passes=4), "edge-intra": dict(temporal=False, passes=4),
                "edge-raster": dict(temporal=True, passes=1)}
    per_frame = []
    frames_colour, frames_true_rgb = [], []
    bar = None
    n_frames = sum(int(w.duration_s * fps) for w in windows)
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=2 * n_frames, unit="frame", desc="bench codec", file=sys.stderr, leave=False, disable=None)
    zc = zstandard.ZstdCompressor(level=3)
    zd = zstandard.ZstdDecompressor()
    try:
        for win in windows:
            trace, start_s = load_trace(win.trace), win.start_s
            origin = placement(trace, start_s, scene.viewer_origin)
            enc_h264 = H264Encoder(with_depth.width, with_depth.height, fps, bitrate_kbps, 30, deterministic=True)
            dec_h264 = H264Decoder(with_depth.width, with_depth.height)
            coders = {name: (EdgeEncoder(w, h, EDGE_BITS, q12, temporal=v["temporal"], passes=v["passes"]),
                             EdgeDecoder(w, h, EDGE_BITS, q12), {"enc": None, "dec": None}) for name, v in variants.items()}
            for k in range(int(win.duration_s * fps)):
                t = k / fps
                pose = origin.compose(trace.pose_at(min(start_s + t, trace.duration)))
                p = producer.produce(pose, t)
                r_true = p.distances["primary"]
                row = {"window": win.label, "frame": k}
                # (a) 8-bit disparity inside the H.264 atlas
                t0 = time.perf_counter()
                data, _ = enc_h264.encode(p.yuv)
                t1 = time.perf_counter()
                img = dec_h264.decode(data)
                t2 = time.perf_counter()
                x, y, rw, rh = with_depth.rect("primary.depth")
                r8 = q8.dequantize(img.y[y:y + rh, x:x + rw])
                row["h264-8bit"] = {"atlas_bytes": len(data), "encode_ms": (t1 - t0) * 1e3,
                                    "decode_ms": (t2 - t1) * 1e3, **disparity_error(r_true, r8, scene.near)}
                cx, cy, cw, ch = with_depth.rect("primary.color")
                true_rgb = producer.primary.read_color().copy()
                row["h264-8bit"]["colour_psnr_db"] = _colour_psnr(img.to_rgb()[cy:cy + ch, cx:cx + cw], true_rgb)
                # colour-only atlas for the equal-total-bitrate comparison (second pass below)
                colour_packer.pack({"primary.color": producer.primary.color})
                frames_colour.append(colour_packer.read().copy())
                frames_true_rgb.append(true_rgb)
                # (b) lossless 12-bit codes with zstd
                codes = q12.quantize(r_true)
                t0 = time.perf_counter()
                z = zc.compress(codes.astype("<u2").tobytes())
                t1 = time.perf_counter()
                back = np.frombuffer(zd.decompress(z), "<u2").reshape(h, w)
                t2 = time.perf_counter()
                row["zstd-lossless"] = {"bytes": len(z), "encode_ms": (t1 - t0) * 1e3, "decode_ms": (t2 - t1) * 1e3,
                                        **disparity_error(r_true, q12.dequantize(back), scene.near)}
                # (c), (d) edge codec variants
                for name, (enc, dec, state) in coders.items():
                    t0 = time.perf_counter()
                    warped = warp_samples(state["enc"][0], state["enc"][1], pose, q12) if state["enc"] else None
                    found = extract_edge_samples(r_true, q12)
                    e = enc.encode(r_true, None if warped is None else warped.edges,
                                   None if warped is None else warped.values, edges=found.edges, signs=found.signs,
                                   codes=found.codes)
                    t1 = time.perf_counter()
                    warped_d = warp_samples(state["dec"][0], state["dec"][1], pose, q12) if state["dec"] else None
                    samples = dec.decode(e.payload, None if warped_d is None else warped_d.edges,
                                         None if warped_d is None else warped_d.values)
                    t2 = time.perf_counter()
                    dense = diffuse(samples)
                    t3 = time.perf_counter()
                    state["enc"], state["dec"] = (e.samples, pose), (samples, pose)
                    bits = e.stats.bits()
                    row[name] = {"bytes": e.stats.total_bytes, "bits_edges": bits["edges"], "bits_values": bits["values"],
                                 "bits_regular": bits["regular"], "bits_header": bits["header"],
                                 "edge_fraction": float(samples.edges.mean()), "encode_ms": (t1 - t0) * 1e3,
                                 "decode_ms": (t2 - t1) * 1e3, "diffusion_ms": (t3 - t2) * 1e3,
                                 **disparity_error(r_true, codes_to_distance(dense, q12), scene.near)}
                    if name == "edge":
                        t4 = time.perf_counter()
                        plain = diffuse_plain(samples)
                        row[name]["plain_diffusion_ms"] = (time.perf_counter() - t4) * 1e3
                        row[name]["plain"] = disparity_error(r_true, codes_to_distance(plain, q12), scene.near)
                per_frame.append(row)
                if bar is not None:
                    bar.update(1)
        # Equal total bitrate: colour-only atlas at (bitrate - the edge stream's mean rate).
        edge_kbps = float(np.mean([r["edge"]["bytes"] for r in per_frame]) * 8 * fps / 1000)
        colour_kbps = max(16.0, bitrate_kbps - edge_kbps)
        enc_c = dec_c = None
        for i, (yuv, true_rgb) in enumerate(zip(frames_colour, frames_true_rgb)):
            if i == 0 or per_frame[i]["frame"] == 0:
                enc_c = H264Encoder(colour_only.width, colour_only.height, fps, colour_kbps, 30, deterministic=True)
                dec_c = H264Decoder(colour_only.width, colour_only.height)
            data, _ = enc_c.encode(yuv)
            img = dec_c.decode(data)
            per_frame[i]["edge"]["colour_atlas_bytes"] = len(data)
            per_frame[i]["edge"]["colour_psnr_db"] = _colour_psnr(img.to_rgb()[:h, :w], true_rgb)
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
        producer.release()
        colour_packer.release()
        renderer.release()
        ctx.release()

    def mean(name, key):
        vals = [r[name][key] for r in per_frame if key in r[name]]
        return float(np.mean(vals)) if vals else None

    summary = {}
    for name in ("h264-8bit", "zstd-lossless", *variants):
        keys = sorted({k for r in per_frame for k, v in r[name].items() if not isinstance(v, dict)})
        summary[name] = {k: mean(name, k) for k in keys}
        if name == "edge":
            summary[name]["plain"] = {k: float(np.mean([r[name]["plain"][k] for r in per_frame]))
                                      for k in per_frame[0][name]["plain"]}
    for name in ("zstd-lossless", *variants):
        summary[name]["kbps"] = summary[name]["bytes"] * 8 * fps / 1000
    summary["h264-8bit"]["atlas_kbps"] = summary["h264-8bit"]["atlas_bytes"] * 8 * fps / 1000
    result = {"scene": scene.name, "windows": windows_json(windows, "reporting"), "fps": fps,
              "view_size": list(view_size),
              "total_bitrate_kbps": bitrate_kbps, "edge_kbps": edge_kbps, "colour_only_kbps": colour_kbps,
              "summary": summary, "frames": per_frame}
    if with_end_to_end:
        w0 = windows[0]
        result["end_to_end"] = end_to_end(scene_spec, w0.trace, w0.start_s, w0.duration_s, total_kbps=bitrate_kbps,
                                          view_size=view_size, out_size=out_size, progress=progress)
    write_result(out_dir, "codec.json", result)
    from .plots import plot_codec

    plot_codec(result, os.path.join(out_dir, "codec.png"))
    return result


def end_to_end(scene_spec="room", trace="pred6dof-1", start_s=10.0, duration_s=4.0, rate_hz=30.0,
               latency_ms=128.0, total_kbps=16000.0, view_size=(1024, 1024), out_size=(960, 540), stride=3,
               progress=True) -> dict:
    """Client DSSIM of ``proxy`` with 8-bit depth in the H.264 atlas against edge-coded depth,
    at the same total bitrate: the edge session's colour gets what its depth streams leave."""
    from pibr.scenes.registry import load_scene

    from .coverage import LatencyModel, display_samples
    from .ibr_bench import Simulation, evaluate_methods, load_proxies, summarize

    scene = load_scene(scene_spec)
    proxies, _ = load_proxies(scene, progress)
    latency = LatencyModel(rate_hz=rate_hz, up_ms=latency_ms / 2, down_ms=latency_ms / 2)
    samples = display_samples(scene, trace, start_s, duration_s, rate_hz, latency)[::stride]
    out = {}
    edge_kbps = None
    for codec in ("edge", "h264"):
        if codec == "edge":  # a first pass learns the depth streams' rate, then colour gets the rest
            probe = Simulation(scene, view_size, out_size, proxies=proxies, depth_codec="edge",
                               bitrate_kbps=total_kbps)
            try:
                for s in samples:
                    probe.frame_at(s[2], s[3])
                edge_kbps = float(np.mean(probe.depth_bytes) * 8 * probe.fps / 1000)
            finally:
                probe.close()
                probe.ctx.release()
            colour_kbps = max(16.0, total_kbps - edge_kbps)
        else:
            colour_kbps = total_kbps
        sim = Simulation(scene, view_size, out_size, proxies=proxies, depth_codec=codec, bitrate_kbps=colour_kbps)
        try:
            res = evaluate_methods(sim, samples, {"proxy": ("proxy", {})})
            out[codec] = summarize(res["proxy"]) | {
                "video_kbps": float(np.mean(sim.bytes) * 8 * sim.fps / 1000),
                "depth_kbps": float(np.mean(sim.depth_bytes) * 8 * sim.fps / 1000) if sim.depth_bytes else 0.0}
        finally:
            sim.close()
            sim.ctx.release()
    return {"trace": trace, "total_kbps": total_kbps, "edge_kbps": edge_kbps, "results": out}


def print_codec_table(r: dict) -> None:
    s = r["summary"]
    print(f"pibr bench codec: scene {r['scene']}, primary view {r['view_size'][0]}x{r['view_size'][1]}, "
          f"{r['fps']:g} fps, {len(r['frames'])} frames")
    head = f"{'variant':<15}{'kbit/s':>9}{'edges b':>10}{'values b':>10}{'regular b':>10}{'PSNR dB':>9}" \
           f"{'max err':>9}{'>1% off':>9}{'>5% off':>9}{'enc ms':>8}{'dec ms':>8}"
    print(head)
    print("-" * len(head))
    for name in ("edge", "edge-intra", "edge-raster", "zstd-lossless"):
        v = s[name]
        print(f"{name:<15}{v['kbps']:>9.0f}{v.get('bits_edges') or 0:>10.0f}{v.get('bits_values') or 0:>10.0f}"
              f"{v.get('bits_regular') or 0:>10.0f}{v['psnr_db']:>9.2f}{v['max_error']:>9.4f}"
              f"{100 * v['outliers_1pct']:>8.2f}%{100 * v['outliers_5pct']:>8.2f}%{v['encode_ms']:>8.1f}"
              f"{v['decode_ms'] + v.get('diffusion_ms', 0):>8.1f}")
    v = s["h264-8bit"]
    print(f"{'h264-8bit':<15}{'(atlas)':>9}{'':>30}{v['psnr_db']:>9.2f}{v['max_error']:>9.4f}"
          f"{100 * v['outliers_1pct']:>8.2f}%{100 * v['outliers_5pct']:>8.2f}%{v['encode_ms']:>8.1f}"
          f"{v['decode_ms']:>8.1f}")
    p = s["edge"]["plain"]
    print(f"\ndiffusion: edge-aware {s['edge']['psnr_db']:.2f} dB (max err {s['edge']['max_error']:.4f}) vs plain "
          f"push-pull {p['psnr_db']:.2f} dB (max err {p['max_error']:.4f}); decode ms above include diffusion")
    print(f"equal total bitrate {r['total_bitrate_kbps']:g} kbit/s: colour PSNR with 8-bit depth in the atlas "
          f"{s['h264-8bit']['colour_psnr_db']:.2f} dB; colour-only atlas at {r['colour_only_kbps']:.0f} kbit/s + "
          f"edge depth at {r['edge_kbps']:.0f} kbit/s: {s['edge']['colour_psnr_db']:.2f} dB")
    e2e = r.get("end_to_end")
    if e2e:
        print(f"end to end ({e2e['trace']}, proxy IBR, {e2e['total_kbps']:g} kbit/s in total):")
        for codec, v in e2e["results"].items():
            print(f"  {codec:>5} depth: DSSIM {v['dssim_mean']:.4f}, PSNR {v['psnr_mean']:.2f} dB, holes "
                  f"{100 * v['hole_fraction_mean']:.2f} %, colour {v['video_kbps']:.0f} + depth "
                  f"{v['depth_kbps']:.0f} kbit/s")
