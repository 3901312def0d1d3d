"""A scored run made up for the report's tests: real videos (bench/video_writer.py) whose every
panel is one flat colour that encodes the method's row, the panel and the tick, so a test can
tell from the pixels which tick the page shows."""
from __future__ import annotations

import csv
import json
import os

import numpy as np

from pibr.bench.video_writer import VideoWriter

METHODS = ("none", "rotation", "proxy")
TICKS = 60
RATE_HZ = 30.0
PANEL = (64, 48)   # width, height of one panel of side_by_side.mp4 (the method videos are twice that)


def panel_colour(row: int, panel: int, tick: int) -> tuple[int, int, int]:
    """The flat colour of ``panel`` (0 shown, 1 ground truth, 2 error) of method ``row`` at ``tick``."""
    return 40 + 60 * row, 50 + 70 * panel, 20 + 3 * tick


def make_run(out_dir: str, ticks: int = TICKS, methods=METHODS) -> dict:
    """Write metrics.json, metrics_frames.csv, <method>.records.csv, <method>.mp4, side_by_side.mp4
    and session.json into ``out_dir``; -> the metrics.json content."""
    os.makedirs(out_dir, exist_ok=True)
    w, h = PANEL
    sbs = VideoWriter(os.path.join(out_dir, "side_by_side.mp4"), RATE_HZ)
    own = {m: VideoWriter(os.path.join(out_dir, f"{m}.mp4"), RATE_HZ) for m in methods}
    for i in range(ticks):
        frame = np.zeros((h * len(methods), 3 * w, 3), np.uint8)
        for r, m in enumerate(methods):
            for p in range(3):
                frame[r * h:(r + 1) * h, p * w:(p + 1) * w] = panel_colour(r, p, i)
            own[m].write(np.full((2 * h, 2 * w, 3), panel_colour(r, 0, i), np.uint8))
        sbs.write(frame)
    sbs.close()
    for v in own.values():
        v.close()
    rng = np.random.default_rng(7)
    summary, frame_rows = {}, []
    for r, m in enumerate(methods):
        dssim = 0.02 + 0.05 * r + 0.01 * rng.random(ticks)
        age = 166.0 + (np.arange(ticks) % 3) * 33.3
        client = 10.0 + 20 * r + rng.random(ticks)
        with open(os.path.join(out_dir, f"{m}.records.csv"), "w", newline="") as f:
            wr = csv.writer(f)
            wr.writerow(["tick", "t", "age_ms", "client_ms", "level", "missed"])
            for i in range(ticks):
                wr.writerow([i, round(i / RATE_HZ, 6), age[i], client[i], i % 2 * r, 0])
        for i in range(ticks):
            frame_rows.append({"method": m, "tick": i, "t": round(i / RATE_HZ, 6), "psnr": 30 - 100 * dssim[i],
                               "ssim": 1 - 2 * dssim[i], "dssim": dssim[i], "flip": "" if i % 4 else 0.1 + 0.05 * r})
        summary[m] = {"psnr_mean": float(np.mean(30 - 100 * dssim)), "ssim_mean": float(np.mean(1 - 2 * dssim)),
                      "dssim_mean": float(np.mean(dssim)), "flip_mean": 0.1 + 0.05 * r,
                      "geometric_holes_mean": 0.0123 * (r + 1), "hole_fraction_mean": 0.00456 * r,
                      "client_ms_median": float(np.median(client)), "frames": ticks, "flip_frames": ticks // 4,
                      "age_ms_mean": float(np.mean(age)), "missed_deadlines": r}
    with open(os.path.join(out_dir, "stream.csv"), "w", newline="") as f:   # a batch of one frame every 0.1 s
        wr = csv.writer(f)
        wr.writerow(["t", "frames", "wire_bytes", "decode_ms", "server_fps", "kbps"])
        for k in range(int(ticks / RATE_HZ * 10)):
            wr.writerow([round(k / 10 + 0.05, 6), 1, 20000 + k, 3.0 + k, 10.0, 160.0 + k])
    with open(os.path.join(out_dir, "metrics_frames.csv"), "w", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=list(frame_rows[0]))
        wr.writeheader()
        wr.writerows(frame_rows)
    metrics = {"run": out_dir, "scene": "room", "trace": {"name": "pred6dof-1", "start_s": 30.0, "duration_s": 2.0},
               "clock": "virtual", "output": {"width": 2 * w, "height": 2 * h, "fov_deg": 90.0, "rate_hz": RATE_HZ,
                                              "pixels_per_degree": 1.4},
               "flip_every": 4, "nearly_uniform_frames": 0, "methods": summary, "complete": True}
    with open(os.path.join(out_dir, "metrics.json"), "w") as f:
        json.dump(metrics, f)
    session = {"client": {"methods": list(methods), "trace": "pred6dof-1", "start_s": 30.0, "duration_s": 2.0,
                          "deadline": "auto", "stereo": ""},
               "session": {"server_fps": 10.0, "primary": {"width": 1088, "height": 1088},
                           "extra": {"width": 544, "height": 544}, "video_bitrate_kbps": 16000.0,
                           "depth_codec": "h264", "depth_bits": 8},
               "complete": True, "stopped": None}
    with open(os.path.join(out_dir, "session.json"), "w") as f:
        json.dump(session, f)
    return metrics
