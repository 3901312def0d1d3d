"""``pibr bench codec-speed``: the edge codec's CPU time stage by stage, optionally against a baseline checkout.

Renders the primary view's distance along head-trace windows (default: the evaluation
windows, ``bench/windows.py``), then runs the edge codec's server and client path on every
frame — warp of the previous samples, edge extraction, encode; warp, decode, edge-aware
diffusion (and plain push-pull for reference) — in a worker process per code version
(:mod:`pibr.bench.codec_speed_worker`). With ``--baseline CHECKOUT`` (a pibr source tree, e.g.
``git worktree add --detach /tmp/pibr-main main``) the baseline's worker and the current one
take turns frame by frame, so both see the same machine load; timings are process CPU ms and
the table shows medians over frames and the ratio new / baseline. Also reported per version:
payload bytes (and the ratio), whether payloads and decoded samples are identical, and
disparity PSNR after reconstruction (edge-aware and plain).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile

import numpy as np

from .results import write_result
from .simulation import BENCH_VIEW_SIZE

_WORKER = os.path.join(os.path.dirname(os.path.abspath(__file__)), "codec_speed_worker.py")


def render_frames(path: str, scene_spec: str, windows, fps: float, view_size, progress: bool = True) -> int:
    """Render the primary view's distance (n, h, w) float32 and poses along ``windows`` into ``path`` (.npz)."""
    from pibr.common.gl import create_context
    from pibr.common.traces.loading import load_trace
    from pibr.common.traces.placement import placement
    from pibr.protocol.messages import Hello
    from pibr.scenes.registry import load_scene
    from pibr.server.pipeline import SessionPipeline

    from .simulation import bench_server_config

    scene = load_scene(scene_spec)
    ctx = create_context()
    # the primary view alone, its depth coded by the edge codec: the float distances are kept
    pipeline = SessionPipeline(bench_server_config(view_size, extra_view="off", depth_codec="edge", fps=fps), scene,
                               Hello(), deterministic=True).open(ctx)
    distance, position, orientation, start = [], [], [], []
    try:
        for win in windows:
            trace = load_trace(win.trace)
            origin = placement(trace, win.start_s, scene.viewer_origin)
            for k in range(max(1, int(win.duration_s * fps))):
                pose = origin.compose(trace.pose_at(min(win.start_s + k / fps, trace.duration)))
                p = pipeline.produce(pose, k / fps)
                distance.append(p.distances["primary"].astype(np.float32))
                position.append(pose.position)
                orientation.append(pose.orientation)
                start.append(k == 0)
            if progress:
                print(f"rendered {win.label}", file=sys.stderr)
    finally:
        pipeline.release()
        ctx.release()
    np.savez(path, distance=np.stack(distance), position=np.array(position), orientation=np.array(orientation),
             window_start=np.array(start), near=scene.near, far=scene.far)
    return len(distance)


class _Worker:
    def __init__(self, frames: str, root: str | None):
        cmd = [sys.executable, _WORKER, frames] + (["--root", root] if root else [])
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        self.info = self._read()

    def _read(self) -> dict:
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"codec-speed worker exited with {self.proc.wait()}")
        return json.loads(line)

    def frame(self, i: int) -> dict:
        self.proc.stdin.write(json.dumps({"frame": i}) + "\n")
        self.proc.stdin.flush()
        return self._read()

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.stdin.write(json.dumps({"quit": True}) + "\n")
            self.proc.stdin.close()
            self.proc.wait()


def _median(rows, key, sub="ms"):
    vals = [r[sub][key] for r in rows if key in r[sub]]
    return float(np.median(vals)) if vals else None


def summarize(rows: list[dict]) -> dict:
    stages = list(rows[0]["ms"])
    inner = sorted({k for r in rows for k in r["inner_ms"]})
    enc = [r["ms"]["enc.warp"] + r["ms"]["enc.extract"] + r["ms"]["enc.encode"] for r in rows]
    dec = [r["ms"]["dec.warp"] + r["ms"]["dec.decode"] + r["ms"]["dec.diffuse"] for r in rows]
    return {"median_ms": {k: _median(rows, k) for k in stages},
            "median_inner_ms": {k: _median(rows, k, "inner_ms") for k in inner},
            "median_encode_total_ms": float(np.median(enc)), "median_decode_total_ms": float(np.median(dec)),
            "mean_bytes": float(np.mean([r["bytes"] for r in rows])),
            "mean_edge_bytes": float(np.mean([r["edge_bytes"] for r in rows])),
            "mean_value_bytes": float(np.mean([r["value_bytes"] for r in rows])),
            "mean_psnr_db": float(np.mean([r["psnr_db"] for r in rows])),
            "mean_plain_psnr_db": float(np.mean([r["plain_psnr_db"] for r in rows])),
            "decoder_matches_encoder": all(r["encoder_view_matches"] for r in rows)}


def run_codec_speed(scene_spec="room", windows=None, window_s=1.0, fps=10.0, view_size=BENCH_VIEW_SIZE,
                    baseline: str | None = None, out_dir="out/bench", progress=True) -> dict:
    from .windows import EVALUATION_WINDOWS, Window, windows_json

    windows = tuple(Window(w.trace, w.start_s, min(w.duration_s, window_s)) for w in (windows or EVALUATION_WINDOWS))
    with tempfile.TemporaryDirectory(prefix="pibr-codec-speed-") as tmp:
        frames = os.path.join(tmp, "frames.npz")
        n = render_frames(frames, scene_spec, windows, fps, view_size, progress)
        workers = {"current": _Worker(frames, None)}
        if baseline:
            workers["baseline"] = _Worker(frames, os.path.abspath(baseline))
        rows = {name: [] for name in workers}
        try:
            for i in range(n):
                order = list(workers) if i % 2 == 0 else list(reversed(workers))  # alternate who goes first
                for name in order:
                    rows[name].append(workers[name].frame(i))
                if progress and (i + 1) % 10 == 0:
                    print(f"frame {i + 1}/{n}", file=sys.stderr)
        finally:
            for wk in workers.values():
                wk.close()
    result = {"scene": scene_spec, "windows": windows_json(windows, "reporting"), "fps": fps,
              "view_size": list(view_size), "frames": n, "timer": "process CPU ms, median over frames",
              "versions": {name: {"pibr": workers[name].info["pibr"], **summarize(r)} for name, r in rows.items()},
              "per_frame": rows}
    if baseline:
        cur, base = rows["current"], rows["baseline"]
        result["comparison"] = {
            "bytes_ratio": float(sum(r["bytes"] for r in cur) / sum(r["bytes"] for r in base)),
            "identical_payloads": sum(a["payload_digest"] == b["payload_digest"] for a, b in zip(cur, base)),
            "identical_samples": sum(a["samples_digest"] == b["samples_digest"] for a, b in zip(cur, base)),
            "psnr_delta_db": float(np.mean([a["psnr_db"] - b["psnr_db"] for a, b in zip(cur, base)])),
            "frames_psnr_lower": sum(a["psnr_db"] < b["psnr_db"] - 1e-9 for a, b in zip(cur, base))}
    write_result(out_dir, "codec_speed.json", result)
    return result


def print_codec_speed(r: dict) -> None:
    v = r["versions"]
    names = list(v)
    print(f"pibr bench codec-speed: scene {r['scene']}, {r['view_size'][0]}x{r['view_size'][1]}, {r['frames']} frames "
          f"({len(r['windows']['used'])} windows), {r['timer']}")
    head = f"{'stage':<34}" + "".join(f"{n:>12}" for n in names) + (f"{'ratio':>8}" if len(names) == 2 else "")
    print(head)
    print("-" * len(head))

    def line(label, vals):
        cells = "".join(f"{x:>12.2f}" if x is not None else f"{'-':>12}" for x in vals)
        ratio = ""
        if len(vals) == 2 and vals[0] is not None and vals[1]:
            ratio = f"{vals[0] / vals[1]:>8.2f}"
        print(f"{label:<34}{cells}{ratio}")

    for k in v[names[0]]["median_ms"]:
        line(k, [v[n]["median_ms"].get(k) for n in names])
    line("encode total (warp+extract+enc)", [v[n]["median_encode_total_ms"] for n in names])
    line("decode total (warp+dec+diffuse)", [v[n]["median_decode_total_ms"] for n in names])
    print("inner functions (inclusive):")
    inner = sorted({k for n in names for k in v[n]["median_inner_ms"]})
    for k in inner:
        line("  " + k, [v[n]["median_inner_ms"].get(k) for n in names])
    line("bytes / frame", [v[n]["mean_bytes"] for n in names])
    line("  edge image bytes", [v[n]["mean_edge_bytes"] for n in names])
    line("  value bytes", [v[n]["mean_value_bytes"] for n in names])
    line("disparity PSNR dB (edge-aware)", [v[n]["mean_psnr_db"] for n in names])
    line("disparity PSNR dB (plain)", [v[n]["mean_plain_psnr_db"] for n in names])
    c = r.get("comparison")
    if c:
        print(f"bytes current / baseline {c['bytes_ratio']:.4f}; identical payloads {c['identical_payloads']}/"
              f"{r['frames']}, identical decoded samples {c['identical_samples']}/{r['frames']}; PSNR delta "
              f"{c['psnr_delta_db']:+.3f} dB (lower on {c['frames_psnr_lower']} frames)")
    print("decoder matches the encoder's view of the samples: " +
          ", ".join(f"{n} {v[n]['decoder_matches_encoder']}" for n in names))
