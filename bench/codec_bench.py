"""``pibr bench codec``: depth codecs on rate-distortion curves, at equal bitrate.

Along the evaluation windows (``bench/windows.py``) on a built-in scene, per server frame of
the primary view, each codec over its rate settings:

* ``edge``           the edge codec (Pajak et al. 2011) as the server and client run it
                     (12-bit codes, temporal context, rate-free threshold), over a sweep of
                     significance thresholds; at the default threshold also ``edge-intra`` (no
                     temporal context), ``edge-raster`` (one raster pass) and
                     ``edge-plain-diffusion`` (plain push-pull instead of edge-aware diffusion);
* ``edge-8bit``, ``edge-10bit``  the same sweep with 8- and 10-bit codes, so the coding and the
                     precision can be told apart (Pajak et al. compared at equal precision);
* ``h264-8bit``      8-bit disparity in its *own* monochrome libx264 stream, rate control
                     targeted at ``edge-8bit``'s measured bits per frame of each threshold (per
                     window): Pajak et al.'s comparison at equal bandwidth and equal precision
                     (their Table 2);
* ``h264-10bit``     the same at 10 bits (``gray10le``) against ``edge-10bit``, when PyAV's
                     libx264 offers it (``h264_10bit`` in the JSON says whether, and the error
                     if not); x264 codes at most 10 bits, so there is no 12-bit H.264 to set
                     beside the 12-bit ``edge``;
* ``log-zstd``       Koniaris et al. 2018: log-quantised distance (16 bits in the paper, fewer
                     as rate settings) with block-skip temporal coding and zstd
                     (``bench/depth_codecs.py``);
* ``zstd-lossless``  the edge codec's 12-bit codes, zstd-compressed;
* ``h264-8bit-atlas`` 8-bit disparity beside the colour in the atlas at each total bitrate
                     (its depth share is not separable: no bits per frame of its own).

Axes: bits per frame against disparity PSNR and against the share of pixels more than 1 %
off in distance; and end to end, ``proxy`` DSSIM at equal *total* bitrate (colour + depth +
the moving objects' poses and motion flow): the colour stream gets the total minus the depth
codec's and the motion streams' measured rates. ``wins`` says which codec is best at each bit
budget, ``matched`` sets the edge codec beside H.264 at its rate; ``extremes`` tabulates
each quantiser's error against distance from 1 cm to 10 km.
"""
from __future__ import annotations

import math
import os
import sys
import time

import numpy as np

from .results import write_result
from .simulation import BENCH_VIEW_SIZE

#: Edge codec significance thresholds of the rate sweep (code units; 3.5 is the default).
DEFAULT_THRESHOLDS = (2.0, 3.5, 8.0, 16.0, 32.0, 64.0, 128.0)
#: Bits of the log-depth codec's rate settings (16: Koniaris et al.).
DEFAULT_LOG_BITS = (16, 12, 10, 8)
#: Total bitrates of the end-to-end comparison.
DEFAULT_TOTALS_KBPS = (4000.0, 8000.0, 16000.0)
#: The end-to-end competitors (see :func:`end_to_end`).
E2E_CODECS = ("h264-8bit-atlas", "edge", "edge-rc", "h264-8bit", "h264-10bit", "log-zstd", "zstd-lossless")
#: A codec whose depth leaves the colour less than this is infeasible at a total.
MIN_COLOUR_KBPS = 250.0


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


class _Point:
    """One codec at one setting: per-frame measurements, by window."""

    KEYS = ("bits", "psnr_db", "max_error", "mean_error", "outliers_1pct", "outliers_5pct", "encode_ms",
            "decode_ms")

    def __init__(self, codec: str, setting: dict):
        self.codec, self.setting = codec, setting
        self.rows: list[dict] = []

    def add(self, window: str, bits, err: dict, encode_ms: float, decode_ms: float, **extra) -> None:
        self.rows.append({"window": window, "bits": bits, **err, "encode_ms": encode_ms, "decode_ms": decode_ms,
                          **extra})

    def window_bits(self, window: str) -> float:
        return float(np.mean([r["bits"] for r in self.rows if r["window"] == window]))

    def summary(self, fps: float) -> dict:
        out = {"codec": self.codec, "setting": self.setting, "frames": len(self.rows)}
        for k in self.KEYS:
            vals = [r[k] for r in self.rows if r.get(k) is not None]
            out[k if k != "bits" else "bits_per_frame"] = float(np.mean(vals)) if vals else None
        out["kbps"] = None if out["bits_per_frame"] is None else out["bits_per_frame"] * fps / 1000
        extra = sorted({k for r in self.rows for k in r} - set(self.KEYS) - {"window"})
        for k in extra:
            vals = [r[k] for r in self.rows if r.get(k) is not None]
            out[k] = float(np.mean(vals)) if vals else None
        windows = list(dict.fromkeys(r["window"] for r in self.rows))
        out["by_window"] = {}
        for w in windows:
            rows = [r for r in self.rows if r["window"] == w]
            out["by_window"][w] = {k: float(np.mean([r[k] for r in rows if r.get(k) is not None]))
                                   for k in ("bits", "psnr_db", "outliers_1pct")
                                   if any(r.get(k) is not None for r in rows)}
        return out


def _timed(fn, *args):
    t0 = time.perf_counter()
    out = fn(*args)
    return out, (time.perf_counter() - t0) * 1e3


def winners(curves: dict, metric: str, higher_is_better: bool) -> list[dict]:
    """At each bit budget (every operating point's bits per frame), the codec whose best point
    within the budget scores best on ``metric``. -> [{"bits_per_frame", "winner", "value", "by_codec"}]."""
    pts = [(c, p) for c, ps in curves.items() for p in ps if p.get("bits_per_frame") is not None]
    budgets = sorted({p["bits_per_frame"] for _, p in pts})
    out = []
    for b in budgets:
        best = {}
        for c, p in pts:
            if p["bits_per_frame"] <= b * (1 + 1e-9) and p.get(metric) is not None:
                v = p[metric]
                if c not in best or (v > best[c] if higher_is_better else v < best[c]):
                    best[c] = v
        if not best:
            continue
        win = (max if higher_is_better else min)(best, key=best.get)
        out.append({"bits_per_frame": b, "winner": win, "value": best[win], "by_codec": best})
    return out


#: H.264 depth alone is coded at the rate of the edge curve of its own precision.
MATCHED_EDGE_CURVE = {"h264-8bit": "edge-8bit", "h264-10bit": "edge-10bit"}
#: The edge curves by code bits (12: the codec's default, ``edge``).
EDGE_CURVE_BITS = {"edge-8bit": 8, "edge-10bit": 10, "edge": 12}


def matched_pairs(curves: dict) -> list[dict]:
    """Per edge threshold, the edge codec at 8, 10 and 12 bits, each H.264 depth stream beside
    the edge curve of its precision coded at its rate (Pajak et al.'s Table 2 comparison at equal
    precision): [{"threshold", codec: {"bits_per_frame", "psnr_db", "outliers_1pct",
    "outliers_5pct"}}]."""
    keys = ("bits_per_frame", "psnr_db", "outliers_1pct", "outliers_5pct")
    rows = []
    for e in curves["edge"]:
        t = e["setting"]["threshold"]
        row = {"threshold": t}
        for name in (*EDGE_CURVE_BITS, *MATCHED_EDGE_CURVE):
            m = [p for p in curves.get(name, []) if p["setting"].get("threshold",
                                                                     p["setting"].get("matched_to_edge_threshold")) == t]
            if m:
                row[name] = {k: m[0][k] for k in keys}
        rows.append(row)
    return rows


def run_codec_bench(scene_spec="room", windows=None, window_s=2.0, fps=10.0, view_size=BENCH_VIEW_SIZE,
                    thresholds=DEFAULT_THRESHOLDS, log_bits=DEFAULT_LOG_BITS, totals_kbps=DEFAULT_TOTALS_KBPS,
                    out_dir="out/bench", progress=True, with_end_to_end=True, out_size=(960, 540),
                    e2e_windows=2, e2e_log_bits=10, plot_path=None) -> dict:
    """The rate-distortion curves (module docstring) on the first ``window_s`` seconds of each
    window, the end-to-end comparison on the first ``e2e_windows`` of them, the extremes table.
    Writes ``codec.json`` and ``codec.png`` (and ``plot_path`` if given) under ``out_dir``."""
    from pibr.client.depth_decoders import EdgeDepthStreamDecoder
    from pibr.client.video import H264Decoder
    from pibr.protocol.depth_codecs import h264_quantizer
    from pibr.protocol.messages import Hello
    from pibr.protocol.errors import ConfigError
    from pibr.common.gl import create_context
    from pibr.common.traces.loading import load_trace
    from pibr.common.traces.placement import placement
    from pibr.scenes.registry import load_scene
    from pibr.protocol.depth_codecs import EDGE_BITS, edge_quantizer
    from pibr.server.depth_encoders import EdgeDepthStream
    from pibr.server.pipeline import SessionPipeline

    from .depth_codecs import make_pair, probe_h264_10bit
    from .simulation import bench_server_config
    from .windows import EVALUATION_WINDOWS, Window, windows_json

    windows = tuple(Window(w.trace, w.start_s, min(w.duration_s, window_s)) for w in (windows or EVALUATION_WINDOWS))
    if min(int(w.duration_s * fps) for w in windows) < 1:
        raise ConfigError(f"{min(w.duration_s for w in windows)} s at {fps:g} fps is not a single frame")
    if not thresholds or not log_bits:
        raise ConfigError("need at least one edge threshold and one log-depth bit depth")
    scene = load_scene(scene_spec)
    for w in windows:
        load_trace(w.trace).window(w.start_s, w.duration_s)  # a start outside a trace is refused before any work
    w, h = view_size
    near, far = scene.near, scene.far
    q8 = h264_quantizer(near, far)
    q12 = edge_quantizer(near, far, EDGE_BITS)
    q_edge = {name: edge_quantizer(near, far, bits) for name, bits in EDGE_CURVE_BITS.items()}
    ten_bit = probe_h264_10bit()
    h264_codecs = ("h264-8bit", "h264-10bit") if ten_bit["available"] else ("h264-8bit",)
    ctx = create_context()
    # the primary view alone, depth in the atlas beside the colour (h264-8bit-atlas), float distances kept
    pipeline = SessionPipeline(bench_server_config(view_size, extra_view="off", fps=fps), scene, Hello(),
                               deterministic=True, keep_distance=True).open(ctx)
    with_depth = pipeline.spec.layout
    edge_pts = {t: _Point("edge", {"threshold": t}) for t in thresholds}
    low_bit_pts = {(name, t): _Point(name, {"threshold": t, "bits": bits}) for name, bits in EDGE_CURVE_BITS.items()
                   if bits != EDGE_BITS for t in thresholds}
    variant_pts = {"edge-intra": _Point("edge-intra", {"threshold": 3.5, "temporal": False}),
                   "edge-raster": _Point("edge-raster", {"threshold": 3.5, "passes": 1}),
                   "edge-plain-diffusion": _Point("edge-plain-diffusion", {"threshold": 3.5, "edge_aware": False})}
    h264_pts = {(c, t): _Point(c, {"matched_to_edge_threshold": t}) for c in h264_codecs for t in thresholds}
    log_pts = {b: _Point("log-zstd", {"bits": b}) for b in log_bits}
    zstd_pt = _Point("zstd-lossless", {"bits": EDGE_BITS})
    atlas_pts = {T: _Point("h264-8bit-atlas", {"total_kbps": T}) for T in totals_kbps}
    n_frames = sum(int(win.duration_s * fps) for win in windows)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n_frames, unit="frame", desc="bench codec", file=sys.stderr, leave=False, disable=None)
    try:
        for win in windows:
            trace, start_s = load_trace(win.trace), win.start_s
            origin = placement(trace, start_s, scene.viewer_origin)
            frames = []
            for k in range(int(win.duration_s * fps)):
                pose = origin.compose(trace.pose_at(min(start_s + k / fps, trace.duration)))
                p = pipeline.produce(pose, k / fps)
                frames.append((pose, p.distances["primary"].copy(), p.yuv.copy()))
            label = win.label

            def run_edge(point, edge_aware=True, quantizer=q12, **opts):
                enc = EdgeDepthStream(w, h, quantizer, fps, **opts)
                dec = EdgeDepthStreamDecoder(w, h, quantizer, edge_aware=edge_aware)
                for pose, r, _ in frames:
                    (payload, stats), e_ms = _timed(enc.encode, r, pose)
                    (dense, _), d_ms = _timed(dec.decode, payload, pose)
                    parts = {f"bits_{k}": v for k, v in stats.bits().items()}
                    point.add(label, stats.total_bits, disparity_error(r, dense, near), e_ms, d_ms,
                              edge_fraction=stats.n_edges / (w * h), **parts)

            for t, pt in edge_pts.items():
                run_edge(pt, threshold=t)
            for (name, t), pt in low_bit_pts.items():
                run_edge(pt, threshold=t, quantizer=q_edge[name])
            run_edge(variant_pts["edge-intra"], temporal=False)
            run_edge(variant_pts["edge-raster"], passes=1)
            run_edge(variant_pts["edge-plain-diffusion"], edge_aware=False)
            # the other codecs' streams
            streams = [(zstd_pt, make_pair("zstd", w, h, near, far, fps))]
            streams += [(pt, make_pair("log", w, h, near, far, fps, bits=b)) for b, pt in log_pts.items()]
            streams += [(pt, make_pair(c, w, h, near, far, fps,
                                       low_bit_pts[MATCHED_EDGE_CURVE[c], t].window_bits(label) * fps / 1000))
                        for (c, t), pt in h264_pts.items()]
            for pt, (enc, dec) in streams:
                for _, r, _ in frames:
                    payload, e_ms = _timed(enc.encode, r)
                    back, d_ms = _timed(dec.decode, payload)
                    extra = {}
                    if pt is zstd_pt or pt.codec == "log-zstd":   # lossless relative to the quantisation
                        extra["exact_codes"] = float(np.array_equal(dec.quantizer.dequantize(
                            dec.quantizer.quantize(r)), back))
                    pt.add(label, 8 * len(payload), disparity_error(r, back, near), e_ms, d_ms, **extra)
            for T, pt in atlas_pts.items():
                enc = pipeline.new_video_encoder(kbps=T)
                dec = H264Decoder(with_depth.width, with_depth.height)
                x, y, rw, rh = with_depth.rect("primary.depth")
                for _, r, yuv in frames:
                    (data, _), e_ms = _timed(enc.encode, yuv)
                    img, d_ms = _timed(dec.decode, data)
                    pt.add(label, None, disparity_error(r, q8.dequantize(img.y[y:y + rh, x:x + rw]), near), e_ms,
                           d_ms, atlas_bits=8 * len(data))
            if bar is not None:
                bar.update(len(frames))
    finally:
        if bar is not None:
            bar.close()
        pipeline.release()
        ctx.release()

    def curve(points):
        return sorted((p.summary(fps) for p in points), key=lambda s: (s["bits_per_frame"] or 0.0))

    curves = {"edge": curve(edge_pts.values())}
    for name, bits in EDGE_CURVE_BITS.items():
        if bits != EDGE_BITS:
            curves[name] = curve(pt for (n, _), pt in low_bit_pts.items() if n == name)
    for c in h264_codecs:
        curves[c] = curve(pt for (cc, _), pt in h264_pts.items() if cc == c)
    curves["log-zstd"] = curve(log_pts.values())
    curves["zstd-lossless"] = curve([zstd_pt])
    atlas = [atlas_pts[T].summary(fps) | {"atlas_kbps": atlas_pts[T].summary(fps)["atlas_bits"] * fps / 1000}
             for T in totals_kbps]
    result = {"scene": scene.name, "windows": windows_json(windows, "reporting"), "fps": fps,
              "view_size": list(view_size), "frames": n_frames, "near": near, "far": far,
              "h264_10bit": ten_bit, "curves": curves,
              "edge_variants": {k: v.summary(fps) for k, v in variant_pts.items()},
              "h264_8bit_atlas": atlas,
              "matched": matched_pairs(curves),
              "wins": {"psnr_db": winners(curves, "psnr_db", True),
                       "outliers_1pct": winners(curves, "outliers_1pct", False)},
              "extremes": extremes_table()}
    if with_end_to_end:
        e2e_wins = windows[:max(1, e2e_windows)]
        result["end_to_end"] = end_to_end(scene_spec, e2e_wins, totals_kbps, view_size=view_size, out_size=out_size,
                                          log_bits=e2e_log_bits, with_10bit=ten_bit["available"],
                                          progress=progress)
    write_result(out_dir, "codec.json", result)
    from .plots import plot_depth_rd

    plot_depth_rd(result, os.path.join(out_dir, "codec.png"))
    if plot_path:
        plot_depth_rd(result, plot_path)
    return result


#: The ``edge-rc`` variant's share of the total bitrate (0.2) is a round figure, not fitted on any
#: windows; it is a benchmark variant, not a server default (``--edge-kbps`` is 0 by default).
EDGE_SHARE_FITTED_ON = "not fitted: a round 20 %, a benchmark variant only (the server's --edge-kbps defaults to 0)"


def end_to_end(scene_spec="room", windows=None, totals_kbps=DEFAULT_TOTALS_KBPS, rate_hz=30.0, latency_ms=128.0,
               view_size=BENCH_VIEW_SIZE, out_size=(960, 540), stride=3, log_bits=10, with_10bit=True,
               edge_share=0.2, codecs=None, progress=True) -> dict:
    """Client DSSIM of ``proxy`` at equal *total* bitrate, per depth codec and total: the 8-bit
    disparity in the atlas gets the whole total; every other codec's colour gets the total minus
    its depth streams' measured rate (both views), learnt in a first pass (depth bits do not depend
    on the colour's rate); a moving scene's object poses and motion flow are subtracted too.
    ``edge`` runs at the default threshold, ``edge-rc`` rate-controlled to ``edge_share`` of the
    total (its depth budget is that target); H.264 depth alone is targeted at ``edge``'s measured
    rate, log depth has ``log_bits``. ``codecs``: a subset of :data:`E2E_CODECS` (default all).
    A codec that leaves the colour less than :data:`MIN_COLOUR_KBPS` is marked infeasible."""
    from pibr.scenes.registry import load_scene

    from pibr.common.link import SessionSchedule
    from pibr.common.replay import display_samples

    from .depth_codecs import ViewDepthStreams
    from pibr.server.config import EdgeSettings

    from .simulation import Simulation, bench_server_config, evaluate_methods, load_proxies, summarize
    from .windows import EVALUATION_WINDOWS, Window, windows_json

    windows = tuple(windows or (Window(EVALUATION_WINDOWS[0].trace, EVALUATION_WINDOWS[0].start_s, 2.0),))
    scene = load_scene(scene_spec)
    proxies, _ = load_proxies(scene, progress)
    schedule = SessionSchedule.round_trip(rate_hz, latency_ms)

    def sim(colour_kbps, codec, depth_kbps=0.0):
        def server(depth_codec, **settings):
            return bench_server_config(view_size, depth_codec=depth_codec, bitrate_kbps=colour_kbps, **settings)

        if codec == "h264-8bit-atlas":
            return Simulation(scene, server("h264"), out_size, proxies=proxies)
        if codec in ("edge", "edge-rc"):
            edge = EdgeSettings(kbps=depth_kbps if codec == "edge-rc" else 0.0)
            return Simulation(scene, server("edge", edge=edge), out_size, proxies=proxies)
        name, opts = {"log-zstd": ("log", {"bits": log_bits}), "zstd-lossless": ("zstd", {}),
                      "h264-8bit": ("h264-8bit", {}), "h264-10bit": ("h264-10bit", {})}[codec]
        return Simulation(scene, server("edge"), out_size, proxies=proxies,
                          depth_streams=lambda session, fps: ViewDepthStreams(name, session, fps, depth_kbps, **opts))

    codecs = [c for c in (codecs or E2E_CODECS) if with_10bit or c != "h264-10bit"]
    unknown = set(codecs) - set(E2E_CODECS)
    if unknown:
        raise ValueError(f"unknown end-to-end codecs {sorted(unknown)}: expected some of {E2E_CODECS}")
    # what the colour budgets need measured first: edge for itself, H.264 alone and edge-rc's motion
    edge_first = "edge" in codecs or bool(set(codecs) & {"edge-rc", "h264-8bit", "h264-10bit"})
    probes = (["edge"] if edge_first else []) + [c for c in ("log-zstd", "zstd-lossless") if c in codecs]
    if scene.is_dynamic and "h264-8bit-atlas" in codecs:
        probes.append("h264-8bit-atlas")
    per_window = []
    for win in windows:
        samples = display_samples(scene, win.trace, win.start_s, win.duration_s, schedule)[::stride]
        depth_kbps, motion_kbps = {"h264-8bit-atlas": 0.0}, {}
        # the depth streams' rate (and a moving scene's object poses and motion flow), before colour
        for codec in probes:
            probe = sim(max(totals_kbps), codec)
            try:
                for s in samples:
                    probe.frame_at(s[2], s[3])
                kbps = 8 * probe.fps / 1000
                if probe.depth_bytes:
                    depth_kbps[codec] = float(np.mean(probe.depth_bytes) * kbps)
                motion_kbps[codec] = float((np.mean(probe.flow_bytes) if probe.flow_bytes else 0.0) * kbps
                                           + (np.mean(probe.pose_bytes) if probe.pose_bytes else 0.0) * kbps)
            finally:
                probe.close()
                probe.ctx.release()
        if "edge" in probes:
            for c in ("h264-8bit", "h264-10bit", "edge-rc"):
                depth_kbps[c], motion_kbps[c] = depth_kbps["edge"], motion_kbps["edge"]
        motion_kbps.setdefault("h264-8bit-atlas", 0.0)
        rows = {}
        for total in totals_kbps:
            depth_kbps["edge-rc"] = edge_share * total
            for codec in codecs:
                colour = total - depth_kbps[codec] - motion_kbps[codec]
                key = f"{total:g}/{codec}"
                if colour < MIN_COLOUR_KBPS:
                    rows[key] = {"total_kbps": total, "codec": codec, "feasible": False,
                                 "depth_kbps": depth_kbps[codec], "motion_kbps": motion_kbps[codec],
                                 "colour_kbps": colour}
                    continue
                s = sim(colour, codec, depth_kbps[codec])
                try:
                    res = evaluate_methods(s, samples, {"proxy": ("proxy", {})})
                    rows[key] = summarize(res["proxy"]) | {
                        "total_kbps": total, "codec": codec, "feasible": True, "colour_kbps": colour,
                        "video_kbps": float(np.mean(s.bytes) * 8 * s.fps / 1000),
                        "depth_kbps": float(np.mean(s.depth_bytes) * 8 * s.fps / 1000) if s.depth_bytes else 0.0,
                        "motion_kbps": motion_kbps[codec]}
                finally:
                    s.close()
                    s.ctx.release()
        per_window.append({"window": win.label, "samples": len(samples), "results": rows})
    # mean over windows, per total and codec
    results = {}
    for key in per_window[0]["results"]:
        rs = [pw["results"][key] for pw in per_window]
        first = rs[0]
        out = {"total_kbps": first["total_kbps"], "codec": first["codec"],
               "feasible": all(r["feasible"] for r in rs)}
        for k in ("dssim_mean", "psnr_mean", "hole_fraction_mean", "video_kbps", "depth_kbps", "motion_kbps",
                  "colour_kbps"):
            vals = [r[k] for r in rs if r.get(k) is not None]
            out[k] = float(np.mean(vals)) if vals and (out["feasible"] or k in ("depth_kbps", "motion_kbps",
                                                                               "colour_kbps")) \
                else None
        results[key] = out
    return {"windows": windows_json(windows, "reporting"), "rate_hz": rate_hz, "latency_ms": latency_ms,
            "stride": stride, "log_bits": log_bits, "edge_share": edge_share,
            "edge_share_fitted_on": EDGE_SHARE_FITTED_ON, "min_colour_kbps": MIN_COLOUR_KBPS,
            "totals_kbps": list(totals_kbps), "results": results, "wins": e2e_winners(results),
            "per_window": per_window}


def e2e_winners(results: dict) -> dict:
    """Per total bitrate, the feasible codec with the lowest proxy DSSIM: {total: {"winner", "dssim", "by_codec"}}."""
    best = {}
    for total in sorted({v["total_kbps"] for v in results.values()}):
        ok = {v["codec"]: v["dssim_mean"] for v in results.values() if v["total_kbps"] == total and v["feasible"]}
        if ok:
            win = min(ok, key=ok.get)
            best[f"{total:g}"] = {"winner": win, "dssim": ok[win], "by_codec": ok}
    return best


def extremes_table(near: float = 1e-2, far: float = 1e4, per_decade: int = 4) -> dict:
    """Error against distance of the depth quantisers from ``near`` to ``far`` (1 cm to 10 km):
    8-bit disparity (the H.264 atlas), the edge codec's 12-bit disparity, 16-bit log depth. Per
    distance: the decoded distance and its relative error; per quantiser its documented bound
    (half a code step: in disparity for the linear ones, in ln r for log depth) and whether
    decoding is monotone and finite over the whole range."""
    from pibr.protocol.depth_codecs import h264_quantizer
    from pibr.protocol.depth_codecs import EDGE_BITS, edge_quantizer

    from .depth_codecs import LogDepthQuantizer

    n = int(round(math.log10(far / near) * per_decade)) + 1
    r = np.geomspace(near, far, n)
    dense = np.geomspace(near, far, 20001)
    out = {"near": near, "far": far, "distances_m": r.tolist(), "quantizers": {}}
    for name, q in (("8bit-disparity", h264_quantizer(near, far)), ("edge-12bit-disparity",
                                                                     edge_quantizer(near, far, EDGE_BITS)),
                    ("log16", LogDepthQuantizer(near, far, 16))):
        back = q.dequantize(q.quantize(r)).astype(np.float64)
        dense_back = q.dequantize(q.quantize(dense)).astype(np.float64)
        rel = np.abs(back - r) / r
        if isinstance(q, LogDepthQuantizer):
            bound = {"relative_error_max": q.max_relative_error()}
        else:
            half = 0.5 / (q.max_code - q.min_code)
            bound = {"disparity_error_max": half,
                     # beyond near / half the disparity rounds to the lowest surface code: every farther
                     # distance decodes to near / half
                     "resolves_up_to_m": min(near / half, far)}
        out["quantizers"][name] = {
            "decoded_m": back.tolist(), "relative_error": rel.tolist(), "bound": bound,
            "max_relative_error": float(rel.max()),
            "monotone": bool(np.all(np.diff(dense_back) >= 0)), "finite": bool(np.all(np.isfinite(dense_back))),
            "farthest_decoded_m": float(dense_back.max())}
    return out


def print_codec_table(r: dict) -> None:
    print(f"pibr bench codec: scene {r['scene']}, primary view {r['view_size'][0]}x{r['view_size'][1]}, "
          f"{r['fps']:g} fps, {r['frames']} frames over {len(r['windows']['used'])} windows")
    t = r["h264_10bit"]
    status = "available" if t["available"] else f"NOT available: {t['error']}"
    print(f"10-bit H.264 (libx264 {t['pix_fmt']}): {status}")
    head = f"{'codec':<16}{'setting':<22}{'kbit/frame':>11}{'kbit/s':>9}{'PSNR dB':>9}{'>1% off':>9}" \
           f"{'>5% off':>9}{'enc ms':>8}{'dec ms':>8}"
    print(head)
    print("-" * len(head))

    def row(name, p):
        setting = ",".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in p["setting"].items())
        bits = p["bits_per_frame"]
        kbit = "" if bits is None else f"{bits / 1000:.1f}"
        kbps = "" if bits is None else f"{p['kbps']:.0f}"
        print(f"{name:<16}{setting[:21]:<22}{kbit:>11}{kbps:>9}{p['psnr_db']:>9.2f}{100 * p['outliers_1pct']:>8.2f}%"
              f"{100 * p['outliers_5pct']:>8.2f}%{p['encode_ms']:>8.1f}{p['decode_ms']:>8.1f}")

    for name, pts in r["curves"].items():
        for p in pts:
            row(name, p)
    for name, p in r["edge_variants"].items():
        row(name, p)
    for p in r["h264_8bit_atlas"]:
        row("h264-8bit-atlas", p)
    print("edge codec against H.264 depth alone at its rate (kbit/frame, PSNR dB, % > 1 % off):")
    for m in r["matched"]:
        print(f"  threshold {m['threshold']:>5g}: " + "; ".join(
            f"{name} {v['bits_per_frame'] / 1000:.0f} kbit {v['psnr_db']:.2f} dB {100 * v['outliers_1pct']:.1f} %"
            for name, v in m.items() if name != "threshold"))
    for metric in ("psnr_db", "outliers_1pct"):
        runs = []
        for w in r["wins"][metric]:
            if not runs or runs[-1][0] != w["winner"]:
                runs.append([w["winner"], w["bits_per_frame"], w["bits_per_frame"]])
            runs[-1][2] = w["bits_per_frame"]
        print(f"best {metric} within a bit budget: " + "; ".join(
            f"{a / 1000:.0f}-{b / 1000:.0f} kbit/frame: {name}" for name, a, b in runs))
    e2e = r.get("end_to_end")
    if e2e:
        print(f"end to end (proxy IBR, {e2e['latency_ms']:g} ms, {len(e2e['per_window'])} windows), DSSIM at equal "
              f"total bitrate (colour + depth):")
        for v in e2e["results"].values():
            if v["feasible"]:
                print(f"  {v['total_kbps']:>6.0f} kbit/s {v['codec']:<16} DSSIM {v['dssim_mean']:.4f}  PSNR "
                      f"{v['psnr_mean']:.2f} dB  colour {v['video_kbps']:.0f} + depth {v['depth_kbps']:.0f} kbit/s")
            else:
                print(f"  {v['total_kbps']:>6.0f} kbit/s {v['codec']:<16} infeasible: depth alone "
                      f"{v['depth_kbps']:.0f} kbit/s")
        for total, wv in e2e["wins"].items():
            print(f"  best at {total} kbit/s: {wv['winner']} (DSSIM {wv['dssim']:.4f})")
    x = r["extremes"]
    print(f"extremes {x['near']:g}-{x['far']:g} m: " + "; ".join(
        f"{k}: max rel err {v['max_relative_error']:.3g}, farthest decoded {v['farthest_decoded_m']:.4g} m, "
        f"monotone {v['monotone']}, finite {v['finite']}" for k, v in x["quantizers"].items()))
