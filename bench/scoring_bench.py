"""``pibr bench scoring``: is scoring a run as fast as streaming it, and where does its time go?

Streams the demo's session (server, relay and client processes on loopback, the virtual clock),
then scores it as ``pibr demo`` does (``evaluate_run``: ground truth, SSIM, PSNR, FLIP every
``flip_every`` ticks, geometric holes, the side-by-side video), and reports the wall and CPU
seconds of both phases, measured in one invocation.

Then, in this process, the first ``profile_ticks`` ticks once more stage by stage, in CPU
milliseconds per tick (one stage at a time, on one thread; the time of the threads a stage starts,
llvmpipe's, is included): pibr's compiled metrics beside the
libraries whose numbers they reproduce (scikit-image's SSIM, numpy's PSNR, NVIDIA flip-evaluator's
FLIP when it is installed, as with ``pip install 'pibr[test]'``), timed in the same run, and
whether every value is the library's to the bit.
"""
from __future__ import annotations

import math
import os
import resource
import tempfile
import time

import numpy as np

from .results import write_result


def _cpu(who) -> float:
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


def run_scoring_bench(out_dir: str = "out/bench", scene: str = "room", trace: str = "pred6dof-1",
                      start_s: float = 30.0, duration_s: float = 6.0, size=(960, 540), latency_ms: float = 128.0,
                      methods=("none", "rotation", "proxy"), flip_every: int = 4, profile_ticks: int = 24) -> dict:
    """Stream, score and profile one demo session; write ``scoring.json``."""
    from .demo import check_inputs, stream
    from .evaluate import evaluate_run

    check_inputs(scene, trace, start_s, duration_s)
    with tempfile.TemporaryDirectory(prefix="pibr-scoring-") as run_dir:
        t0, c0 = time.perf_counter(), _cpu(resource.RUSAGE_CHILDREN)
        stream(run_dir, scene, trace, start_s, duration_s, 30.0, size, latency_ms, methods, "virtual")
        t1, c1, s1 = time.perf_counter(), _cpu(resource.RUSAGE_CHILDREN), _cpu(resource.RUSAGE_SELF)
        metrics = evaluate_run(run_dir, scene_spec=scene, flip_every=flip_every, progress=False, plot=False)
        t2, c2, s2 = time.perf_counter(), _cpu(resource.RUSAGE_CHILDREN), _cpu(resource.RUSAGE_SELF)
        stages, identical, compared = profile_stages(run_dir, scene, min(profile_ticks, metrics["methods"][
            methods[0]]["frames"]), flip_every)
    result = {
        "session": {"scene": scene, "trace": trace, "start_s": start_s, "duration_s": duration_s,
                    "output": list(size), "rate_hz": 30.0, "latency_ms": latency_ms, "methods": list(methods),
                    "clock": "virtual", "flip_every": flip_every,
                    "window": "an evaluation window (bench/windows.py); nothing here is fitted"},
        "streaming": {"seconds": t1 - t0, "cpu_seconds": c1 - c0},
        "scoring": {"seconds": t2 - t1, "cpu_seconds": (c2 - c1) + (s2 - s1), "workers": 2},
        "scoring_over_streaming": (t2 - t1) / (t1 - t0),
        "profile_ticks": compared["ticks"], "stages": stages,
        "identical_to_libraries": identical, "compared": compared, "cpus": os.cpu_count(),
        "note": "seconds are wall time of each phase in one invocation; cpu_seconds include every process and "
                "thread the phase ran (streaming: server, relay, client; scoring: this process and its workers). "
                "Stage times are CPU ms per tick of a second pass over the first ticks, in this process.",
    }
    write_result(out_dir, "scoring.json", result)
    return result


def profile_stages(run_dir: str, scene_spec: str, ticks: int, flip_every: int):
    """CPU ms per tick of each scoring stage over the first ``ticks`` ticks of the run in ``run_dir``,
    pibr's metrics beside the libraries' (same run); -> (stages, every value equal, what was compared)."""
    from skimage.metrics import structural_similarity

    from pibr.client.recorder import read_records
    from pibr.protocol.pose import Pose
    from pibr.scenes.registry import load_scene

    from .evaluate import TransmittedViews, _shown_images, _side_by_side, read_session
    from .flip_metric import FlipReference
    from .groundtruth import GroundTruth
    from .metrics import SsimReference, pixels_per_degree, psnr
    from .video_writer import VideoWriter

    try:
        import flip_evaluator
    except ImportError:   # the test extra's; without it, no library FLIP to time or compare
        flip_evaluator = None
    info = read_session(run_dir)
    client = info["client"]
    methods = list(client["methods"])
    width, height, fov = int(client["width"]), int(client["height"]), float(client["fov_deg"])
    ppd = pixels_per_degree(width, fov)
    records = {m: read_records(os.path.join(run_dir, f"{m}.records.csv")) for m in methods}
    scene = load_scene(scene_spec)
    spent = dict.fromkeys(["ground truth", "decoding", "geometric holes", "ssim", "ssim library", "psnr",
                           "psnr library", "flip", "flip library", "video"], 0.0)
    equal = {"ssim": True, "psnr": True, "flip": True}
    counted = {"ssim": 0, "flip": 0}
    gt = GroundTruth(scene, width, height, fov)
    views = TransmittedViews(scene, info["session"], (width, height), fov)
    shown = _shown_images(run_dir, methods, records, ticks)   # on this thread: CPU time is the process's
    writer_path = os.path.join(run_dir, "profile.mp4")
    writer = VideoWriter(writer_path, client["rate_hz"], threads=1)

    def timed(stage, fn, *args, **kwargs):
        c = time.process_time()
        out = fn(*args, **kwargs)
        spent[stage] += time.process_time() - c
        return out

    try:
        for i in range(ticks):
            rec = records[methods[0]][i]
            pose = Pose.make([rec["px"], rec["py"], rec["pz"]], [rec["qw"], rec["qx"], rec["qy"], rec["qz"]])
            truth = timed("ground truth", gt.render, pose, rec["scene_t"])
            timed("geometric holes", views.holes, pose, rec)
            images = timed("decoding", next, shown)
            images = [images[m] if images[m] is not None else np.zeros_like(truth) for m in methods]
            reference = timed("ssim", SsimReference, truth)
            for img in images:
                ours = timed("ssim", reference.ssim, img)
                theirs = float(timed("ssim library", structural_similarity, truth, img, channel_axis=2,
                                     data_range=255))
                equal["ssim"] &= ours == theirs
                mse = timed("psnr library", lambda a, b: np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2),
                            truth, img)
                equal["psnr"] &= timed("psnr", psnr, truth, img) == (
                    100.0 if mse <= 0 else min(100.0, 10.0 * math.log10(255.0 ** 2 / mse)))
                counted["ssim"] += 1
            if flip_every > 0 and i % flip_every == 0:
                flip_reference = timed("flip", FlipReference, truth, ppd)
                for img in images:
                    ours = timed("flip", flip_reference.mean, img)
                    counted["flip"] += 1
                    if flip_evaluator is not None:
                        _, theirs, _ = timed("flip library", flip_evaluator.evaluate, truth.astype(np.float32) / 255.0,
                                             img.astype(np.float32) / 255.0, "LDR", True, False, True,
                                             {"ppd": float(ppd)})
                        equal["flip"] &= ours == float(theirs)
            frame = timed("video", _side_by_side, list(zip(images, [truth] * len(images))), 2)
            timed("video", writer.write, frame)
        timed("video", writer.close)
    finally:
        shown.close()
        gt.close()
        views.close()
    per_tick = {k: 1000.0 * v / ticks for k, v in spent.items()}
    if flip_evaluator is None:
        per_tick["flip library"] = None
    stages = [
        {"stage": "ground truth render (GL)", "ms_per_tick": per_tick["ground truth"], "library_ms_per_tick": None},
        {"stage": "decoding the lossless recordings", "ms_per_tick": per_tick["decoding"],
         "library_ms_per_tick": None},
        {"stage": "geometric holes (GL + coverage test)", "ms_per_tick": per_tick["geometric holes"],
         "library_ms_per_tick": None},
        {"stage": "SSIM (scikit-image's)", "ms_per_tick": per_tick["ssim"], "library_ms_per_tick": per_tick["ssim library"]},
        {"stage": "PSNR (numpy's)", "ms_per_tick": per_tick["psnr"], "library_ms_per_tick": per_tick["psnr library"]},
        {"stage": f"FLIP (flip-evaluator's), every {flip_every}th tick", "ms_per_tick": per_tick["flip"],
         "library_ms_per_tick": per_tick["flip library"]},
        {"stage": "side-by-side video (mosaic + x264)", "ms_per_tick": per_tick["video"], "library_ms_per_tick": None},
    ]
    compared = {"ticks": ticks, "images_per_tick": len(methods), "ssim_psnr_values": counted["ssim"],
                "flip_values": counted["flip"], "flip_compared": flip_evaluator is not None,
                "equal": equal}
    identical = equal["ssim"] and equal["psnr"] and (equal["flip"] or flip_evaluator is None)
    return stages, identical, compared


def print_scoring_table(r: dict) -> None:
    s, e = r["streaming"], r["scoring"]
    print(f"streaming {s['seconds']:.1f} s ({s['cpu_seconds']:.0f} CPU-s), scoring {e['seconds']:.1f} s "
          f"({e['cpu_seconds']:.0f} CPU-s): scoring / streaming = {r['scoring_over_streaming']:.2f}")
    print(f"\nstage, CPU ms per tick over the first {r['profile_ticks']} ticks      pibr   library")
    for st in r["stages"]:
        lib = st["library_ms_per_tick"]
        print(f"  {st['stage']:<52} {st['ms_per_tick']:7.1f}  {'' if lib is None else f'{lib:7.1f}'}")
    print("every SSIM, PSNR and FLIP value equal to the library's: " + ("yes" if r["identical_to_libraries"] else
                                                                        "NO " + str(r["compared"]["equal"])))
