"""Score a client recording against ground truth (``pibr evaluate RUN_DIR``).

For every displayed tick: render the ground truth at the tick's pose and scene time, read
each method's lossless recording, and compute PSNR, SSIM, DSSIM, FLIP and the hole fraction.
Writes into the run directory:

    metrics.json         per method: psnr_mean, ssim_mean, dssim_mean, flip_mean,
                         geometric_holes_mean (pixels no transmitted view saw, one definition
                         for every method), hole_fraction_mean (own holes: pixels where
                         the method accepted no transmitted sample, whatever it shows there), client_ms_median, frames (+ more, see below)
    metrics_frames.csv   one row per method and tick

A recording of two eyes (``pibr client --stereo``) holds each eye as a recording of its own,
``M.left`` and ``M.right``, each scored against the ground truth at its eye's pose; metrics.json
then also has ``stereo``: per method, the binocular consistency of the shown pairs
(bench/stereo_metrics.py: the share of surface points both eyes see on which the two images
disagree beyond what the ground truth's two eyes do).
    quality.png          quality and frame age over time
    side_by_side.mp4     per method one row: method | ground truth | error image

Metrics run in worker processes while this process renders ground truth and decodes, and the
geometric holes of each eye in a process of their own.
"""
from __future__ import annotations

import concurrent.futures
import contextlib
import csv
import logging
import math
import multiprocessing
import os
import sys
from collections import deque

import numpy as np

from pibr.protocol import bounded_json
from pibr.protocol.errors import ConfigError, JSONError
from pibr.protocol.pose import Pose

from .metrics import nearly_uniform, pixels_per_degree, tick_metrics
from .results import write_result

log = logging.getLogger(__name__)


def _shown_images(run_dir: str, methods: list, records: dict, n: int):
    """Per tick, each method's image on screen ({method: (H, W, 3) uint8, or None before its
    first}), decoded from its lossless recording: a tick missed keeps the previous image."""
    from pibr.client.recorder import lossless_recording

    paths = {m: lossless_recording(run_dir, m) for m in methods}
    streams = {m: _frames(paths[m]) for m in methods}
    shown = dict.fromkeys(methods)
    try:
        for i in range(n):
            for m in methods:
                if records[m][i]["missed"]:
                    continue
                try:
                    shown[m] = next(streams[m])
                except StopIteration:
                    fresh = sum(1 for r in records[m] if not r["missed"])
                    raise ConfigError(f"{os.path.basename(paths[m])} ends at tick {i}, but {m}.records.csv has {fresh} "
                                      f"ticks displayed afresh (one frame each)") from None
            yield dict(shown)
    finally:
        for stream in streams.values():
            stream.close()


class _Ahead:
    """Iterate a generator in a thread of its own, at most ``depth`` items ahead; its error is
    raised where the item would have been."""

    _END = object()

    def __init__(self, items, depth: int):
        import queue
        import threading

        self._items, self._queue, self._stop = items, queue.Queue(depth), threading.Event()
        self._thread = threading.Thread(target=self._run, name="evaluate-decode", daemon=True)
        self._thread.start()

    def _put(self, item) -> bool:
        """Queue ``item`` unless the consumer has stopped; whether it was queued."""
        import queue

        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=0.2)
                return True
            except queue.Full:
                continue
        return False

    def _run(self):
        try:
            for item in self._items:
                if not self._put(item):
                    return
            self._put(self._END)
        except BaseException as exc:   # handed to the consumer, never lost
            self._put(exc)
        finally:
            self._items.close()

    def __iter__(self):
        return self

    def __next__(self):
        item = self._queue.get()
        if item is self._END:
            raise StopIteration
        if isinstance(item, BaseException):
            raise item
        return item

    def close(self) -> None:
        self._stop.set()
        self._thread.join()


class _Behind:
    """A video writer fed through a queue of at most ``depth`` frames and a thread of its own;
    an encoding error is raised by the next write or by close."""

    def __init__(self, writer, depth: int):
        import queue
        import threading

        self._writer, self._queue, self._error, self._reported = writer, queue.Queue(depth), None, False
        self._thread = threading.Thread(target=self._run, name="evaluate-encode", daemon=True)
        self._thread.start()

    def _run(self):
        while True:
            frame = self._queue.get()
            if frame is None:
                return
            if self._error is None:
                try:
                    self._writer.write(frame)
                except BaseException as exc:   # raised in the caller's thread
                    self._error = exc

    def write(self, frame: np.ndarray) -> None:
        if self._error is not None:
            self._reported = True
            raise self._error
        self._queue.put(frame)

    def close(self) -> None:
        """Finish the frames queued and close the writer (also after an error); raises an
        encoding error that no write has raised yet."""
        self._queue.put(None)
        self._thread.join()
        self._writer.close()
        if self._error is not None and not self._reported:
            self._reported = True
            raise self._error


def read_session(run_dir: str) -> dict:
    """The client's ``session.json`` in ``run_dir`` (a clear error when missing or broken)."""
    path = os.path.join(run_dir, "session.json")
    try:
        with open(path, "rb") as f:
            data = f.read(bounded_json.MAX_TEXT_BYTES + 1)
    except FileNotFoundError:
        raise ConfigError(f"{run_dir} holds no client recording (no session.json); run 'pibr client --out DIR' first") \
            from None
    try:
        info = bounded_json.loads(data, what=path)
    except JSONError as exc:
        raise ConfigError(f"{exc}; is it a client's session.json?") from None
    if not isinstance(info, dict) or not isinstance(info.get("session"), dict):
        raise ConfigError(f"{path}: not a client's session.json (no 'session' object)")
    return info


def _frames(path: str):
    import av

    try:
        container = av.open(path)
    except (OSError, av.error.FFmpegError) as exc:
        raise ConfigError(f"cannot open recording {path}: {exc}") from None
    with container:
        # One decoding thread: the recordings are decoded beside other work on every core, and
        # slice threads cost 15 % more CPU time per frame here.
        container.streams.video[0].thread_count = 1
        decoded = 0
        try:
            for frame in container.decode(video=0):
                yield frame.to_ndarray(format="rgb24")
                decoded += 1
        except av.error.FFmpegError as exc:   # e.g. a file cut short by a killed client
            raise ConfigError(f"recording {path}: cannot decode past frame {decoded}: {exc}") from None


def _side_by_side(pairs, scale: int) -> np.ndarray:
    """One video frame: per (shown (H, W, 3), ground truth (H, W, 3)) uint8 pair a row
    ``shown | ground truth | error image``, every ``scale``-th pixel of every ``scale``-th row of
    that mosaic, cropped to even sides. Only the pixels kept are read (and their error colours
    computed): a 1/scale² share."""
    from .metric_kernels import mosaic_rows
    from .metrics import _error_colours

    h, w = pairs[0][1].shape[:2]
    height, width = -(-len(pairs) * h // scale), -(-3 * w // scale)
    out = np.empty((height - height % 2, width - width % 2, 3), np.uint8)
    colours = _error_colours(4.0)
    for r, (shown, ref) in enumerate(pairs):
        if shown.shape != ref.shape or ref.shape[:2] != (h, w) or shown.dtype != np.uint8 or ref.dtype != np.uint8:
            raise ValueError(f"need (H, W, 3) uint8 pairs of one size, got {shown.shape} and {ref.shape}")
        mosaic_rows(out, r * h, shown, ref, scale, colours)
    return out


def evaluate_run(run_dir: str, scene_spec: str | None = None, flip_every: int = 1, workers: int = 2,
                 side_by_side: bool = True, plot: bool = True, progress: bool = True,
                 max_frames: int | None = None) -> dict:
    """Score every method of the recording in ``run_dir``; returns the metrics.json content."""
    from pibr.client.recorder import read_records
    from pibr.scenes.registry import load_scene

    from .groundtruth import GroundTruth

    if flip_every < 0:
        raise ConfigError("flip_every must be >= 0 (0: no FLIP)")
    info = read_session(run_dir)
    client = info["client"]
    recordings = info.get("recordings") or {m: {"method": m, "eye": "centre"} for m in client["methods"]}
    if not isinstance(recordings, dict) or not all(isinstance(r, dict) and "eye" in r for r in recordings.values()):
        raise ConfigError(f"{run_dir}/session.json: 'recordings' must map each recording to its method and eye")
    methods = list(recordings)
    eyes = list(dict.fromkeys(r["eye"] for r in recordings.values()))   # the eyes' ground truths, in order
    first_of = {eye: next(m for m in methods if recordings[m]["eye"] == eye) for eye in eyes}
    width, height, fov = int(client["width"]), int(client["height"]), float(client["fov_deg"])
    frustums = _eye_frustums(client, eyes)   # eye -> its tangents, None: symmetric in fov
    scene = load_scene(scene_spec or info["session"]["scene"]["name"])
    records = {m: read_records(os.path.join(run_dir, f"{m}.records.csv")) for m in methods}
    n = min(len(r) for r in records.values())
    if max_frames is not None:
        n = min(n, max_frames)
    if n == 0:
        raise ConfigError(f"{run_dir}: the recording has no displayed frames")
    ppd = pixels_per_degree(width, fov)
    # Decoding the recordings (PyAV lets go of the GIL) runs ahead in a thread of its own.
    shown_images = _Ahead(_shown_images(run_dir, methods, records, n), depth=3)
    gt = GroundTruth(scene, width, height, fov)
    transmitted = ({eye: TransmittedViews(scene, info["session"], (width, height), fov, frustum=frustums[eye])
                    for eye in eyes}
                   if workers == 0 else {})
    pairs_of = _stereo_pairs(recordings)   # method -> (left recording, right recording)
    consistency = {m: [] for m in pairs_of}
    rays = None
    if pairs_of:
        from pibr.server.coverage import camera_rays

        rays = camera_rays(width, height, fov, frustums.get("left"))
    uses_extra = {m: bool((info.get("methods") or {}).get(m, {}).get("uses_extra_view", False)) for m in methods}
    geometric = {eye: [] for eye in eyes}   # per eye, per tick: {"primary": fraction, "both": fraction}
    uniform = 0      # ticks whose ground truth is nearly one colour
    # 'spawn', not fork: this process runs threads (decoding, encoding, llvmpipe's) that a forked
    # child could find holding locks forever.
    pool = (concurrent.futures.ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                                                   initializer=keep_freed_memory)
            if workers > 0 else None)
    # The geometric holes need only the records: per eye one task, in a process of its own (with
    # its own GL context) while this one renders ground truth and the pool scores.
    # (multiprocessing's Pool: on an error it can be stopped at once, not waited for.)
    holes_pool = None
    if workers > 0:
        with _environment(OPENBLAS_NUM_THREADS="1"):   # see geometric_holes
            holes_pool = multiprocessing.get_context("spawn").Pool(len(eyes), initializer=keep_freed_memory)
    holes_of = {}
    if holes_pool is not None:
        spec = scene_spec or info["session"]["scene"]["name"]
        for eye in eyes:
            holes_of[eye] = holes_pool.apply_async(geometric_holes, (spec, info["session"], records[first_of[eye]][:n],
                                                                     (width, height), fov, frustums[eye]))
    writer = None
    if side_by_side:
        from .video_writer import VideoWriter

        # encoded in a thread of its own (PyAV lets go of the GIL while x264 works)
        writer = _Behind(VideoWriter(os.path.join(run_dir, "side_by_side.mp4"), client["rate_hz"], threads=1), depth=3)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n, unit="frame", desc="ground truth + metrics", file=sys.stderr, leave=False,
                       disable=None)  # None: no bar when stderr is not a terminal
    results = {m: [None] * n for m in methods}
    pending: deque = deque()

    def settle(block: bool):
        while pending and (block or pool is None or pending[0][2].done() or len(pending) > 2 * max(1, workers)):
            names, i, fut = pending.popleft()
            for m, r in zip(names, fut.result() if pool is not None else fut):
                results[m][i] = r
    try:
        for i in range(n):
            truth, truth_pose, truth_distance = {}, {}, {}
            for eye in eyes:
                rec = records[first_of[eye]][i]
                pose = truth_pose[eye] = Pose.make([rec["px"], rec["py"], rec["pz"]],
                                                   [rec["qw"], rec["qx"], rec["qy"], rec["qz"]])
                truth[eye] = gt.render(pose, rec["scene_t"], frustums[eye])
                if pairs_of:
                    truth_distance[eye] = gt.distance()
                if holes_pool is None:
                    geometric[eye].append(transmitted[eye].holes(pose, rec))
            uniform += nearly_uniform(truth[eyes[0]])
            rows = []
            displayed = {}
            with_flip = flip_every > 0 and i % flip_every == 0
            images_now = next(shown_images)
            for m in methods:
                ref = truth[recordings[m]["eye"]]
                img = images_now[m] if images_now[m] is not None else np.zeros_like(ref)   # blank before any
                if img.shape != ref.shape:
                    raise ConfigError(f"{m}'s lossless recording has {img.shape} frames, expected {ref.shape}")
                displayed[m] = img
                if writer is not None:
                    rows.append((img, ref))
            # one task per eye and tick: its ground truth's share of SSIM is computed once for every method
            for eye in eyes:
                names = [m for m in methods if recordings[m]["eye"] == eye]
                images = [displayed[m] for m in names]
                pending.append((names, i, pool.submit(tick_metrics, truth[eye], images, ppd, with_flip)
                                if pool is not None else tick_metrics(truth[eye], images, ppd, with_flip)))
            if pairs_of:
                from .stereo_metrics import binocular_pairs, stereo_consistency

                pairs = binocular_pairs(rays, (width, height), fov, truth_pose["left"], truth_pose["right"],
                                        truth_distance["left"], truth_distance["right"],
                                        right_frustum=frustums.get("right"))
                for m, (left, right) in pairs_of.items():
                    consistency[m].append(stereo_consistency(displayed[left], displayed[right], truth["left"],
                                                             truth["right"], pairs))
            if writer is not None:
                writer.write(_side_by_side(rows, 2))
            settle(block=False)
            if bar is not None:
                bar.update(1)
        settle(block=True)
        for eye, task in holes_of.items():
            geometric[eye] = task.get()
        if holes_pool is not None:
            holes_pool.close()
    finally:
        shown_images.close()
        if bar is not None:
            bar.close()
        gt.close()
        for t in transmitted.values():
            t.close()
        if pool is not None:
            pool.shutdown(cancel_futures=True)
        if holes_pool is not None:
            holes_pool.terminate()   # after close(): the finished workers; after an error: stop them
            holes_pool.join()
        if writer is not None:
            writer.close()

    summary = {}
    rows_out = []
    for m in methods:
        per = results[m]
        recs = records[m][:n]
        flips = [p["flip"] for p in per if not math.isnan(p["flip"])]
        ages = [r["age_ms"] for r in recs if not math.isnan(r["age_ms"])]
        geo = [g["both" if uses_extra[m] else "primary"] for g in geometric[recordings[m]["eye"]]]
        summary[m] = {
            "geometric_holes_mean": float(np.mean(geo)),
            "psnr_mean": float(np.mean([p["psnr"] for p in per])),
            "ssim_mean": float(np.mean([p["ssim"] for p in per])),
            "dssim_mean": float(np.mean([p["dssim"] for p in per])),
            "flip_mean": float(np.mean(flips)) if flips else None,
            "hole_fraction_mean": float(np.mean([r["hole_fraction"] for r in recs])),
            "client_ms_median": float(np.median([r["client_ms"] for r in recs])),
            "frames": n,
            "flip_frames": len(flips),
            "age_ms_mean": float(np.mean(ages)) if ages else None,
            "missed_deadlines": int(sum(r["missed"] for r in recs)),
        }
        for r, p, g in zip(recs, per, geo):
            rows_out.append({"method": m, "tick": r["tick"], "t": r["t"], **p, "geometric_holes": g,
                             "hole_fraction": r["hole_fraction"],
                             "age_ms": r["age_ms"], "client_ms": r["client_ms"], "frame_id": r["frame_id"]})
    out = {"run": os.path.abspath(run_dir), "scene": scene.name, "trace": info.get("trace"),
           "clock": client["clock"], "output": {"width": width, "height": height, "fov_deg": fov,
                                                "rate_hz": client["rate_hz"], "pixels_per_degree": ppd},
           "flip_every": flip_every, "nearly_uniform_frames": uniform, "methods": summary}
    if pairs_of:
        out["stereo"] = {"reference": (info.get("stereo") or {}).get("reference"),
                         "ipd_mm": (info.get("stereo") or {}).get("ipd_mm"),
                         "eye_fov_deg": client.get("eye_fov_deg"), "methods": {}}
        for m, values in consistency.items():
            scored = [c for c in values if c["inconsistent"] is not None]
            out["stereo"]["methods"][m] = {
                "inconsistent_mean": float(np.mean([c["inconsistent"] for c in scored])) if scored else None,
                "excess_mean": float(np.mean([c["excess_mean"] for c in scored])) if scored else None,
                "pairs_mean": float(np.mean([c["pairs"] for c in values])), "frames": len(values)}
    out["complete"] = info.get("complete", True) is not False
    if not out["complete"]:
        log.warning("%s: the client's run ended early (%s): scored the %d ticks it recorded", run_dir,
                    info.get("stopped") or "unknown", n)
    if uniform:
        log.warning("%s: %d of %d ground-truth frames are nearly one colour (sky or a wall filling the view); "
                    "every method scores well on them", run_dir, uniform, n)
    write_result(run_dir, "metrics.json", out)
    with open(os.path.join(run_dir, "metrics_frames.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows_out[0].keys()))
        w.writeheader()
        # A metric not computed on a frame (FLIP on every Nth) is an empty cell, not "nan".
        w.writerows({k: ("" if isinstance(v, float) and math.isnan(v) else v) for k, v in row.items()}
                    for row in rows_out)
    if plot:
        from .plots import plot_quality_over_time

        plot_quality_over_time(rows_out, os.path.join(run_dir, "quality.png"))
    return out


def _eye_frustums(client: dict, eyes) -> dict:
    """eye -> the (left, right, down, up) tangents the client showed it through (its
    ``eye_fov_deg``, protocol/frustum.py), None for a symmetric one of its ``fov_deg``."""
    from pibr.protocol.frustum import eyes_tangents

    try:
        return eyes_tangents(eyes, client.get("eye_fov_deg"))
    except ConfigError as exc:
        raise ConfigError(f"session.json: client.eye_fov_deg: {exc}") from None


def _stereo_pairs(recordings: dict) -> dict:
    """method -> (its left eye's recording, its right eye's) for every method recorded with both."""
    eyes = {}
    for name, r in recordings.items():
        eyes.setdefault(r.get("method", name), {})[r["eye"]] = name
    return {m: (e["left"], e["right"]) for m, e in eyes.items() if "left" in e and "right" in e}


def keep_freed_memory() -> None:
    """Let this process reuse the memory it frees instead of handing it back to the system (glibc;
    elsewhere nothing): the metric kernels allocate and free tens of MB per image, and memory
    mapped afresh is paid for again in page faults."""
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return
    M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
    mallopt(M_MMAP_THRESHOLD, 1 << 30)    # large blocks from the heap, not fresh mappings
    mallopt(M_TRIM_THRESHOLD, 1 << 30)    # and the heap not trimmed after each


@contextlib.contextmanager
def _environment(**values):
    """Environment variables set for the processes started inside (spawned children read them)."""
    old = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def geometric_holes(scene_spec: str, session: dict, records: list, out_size, fov_deg: float,
                    frustum=None) -> list[dict]:
    """:meth:`TransmittedViews.holes` of every tick of one eye's ``records`` (its poses and frames),
    in this process: a task for a worker of its own. Its worker runs with one BLAS thread: the
    (n, 3) @ (3, 3) products of the coverage test gain nothing from more, and idle BLAS threads
    spin, taking CPU from the other workers (measured: half of this test's CPU time)."""
    from pibr.scenes.registry import load_scene

    views = TransmittedViews(load_scene(scene_spec), session, out_size, fov_deg, frustum=frustum)
    try:
        return [views.holes(Pose.make([r["px"], r["py"], r["pz"]], [r["qw"], r["qx"], r["qy"], r["qz"]]), r)
                for r in records]
    finally:
        views.close()


class TransmittedViews:
    """Re-renders the views the server sent for the frame each tick showed, to count the
    geometric holes: the displayed pixels whose surface no transmitted view saw
    (``coverage.uncovered``; the same definition for every method, against the primary view for
    methods that use only it, both views otherwise). Counted on every second pixel of every
    second row (a quarter of the pixels) to keep evaluation quick."""

    def __init__(self, scene, session: dict, out_size, fov_deg: float, subsample: int = 2, frustum=None):
        from pibr.protocol.session import SessionConfig

        from pibr.server.coverage import CoverageProbe

        config = SessionConfig.from_json(session)
        self.offset = config.extra_offset if config.extra is not None else None
        size = (max(1, out_size[0] // subsample), max(1, out_size[1] // subsample))
        self.probe = CoverageProbe(scene, (config.primary.width, config.primary.height), size, fov_deg,
                                   projection=config.options.get("projection", "vertex"),
                                   mark_peeled=bool(config.options.get("peel_marker")), frustum=frustum)
        self._frame = None     # (frame_id, views)

    def holes(self, pose: Pose, rec: dict) -> dict:
        """{"primary": fraction, "both": fraction} for one tick's record (1.0 before any frame)."""
        from pibr.server.coverage import uncovered_by_views

        if rec["frame_id"] < 0:
            return {"primary": 1.0, "both": 1.0}
        if self._frame is None or self._frame[0] != rec["frame_id"]:
            frame_pose = Pose.make([rec[f"frame_{k}"] for k in ("px", "py", "pz")],
                                   [rec[f"frame_{k}"] for k in ("qw", "qx", "qy", "qz")])
            t = rec["frame_scene_t"]
            views = [(frame_pose, self.probe.render_primary(frame_pose, t), False)]
            if self.offset is not None:
                views.append((frame_pose.compose(self.offset),
                              self.probe.render_extra(frame_pose, self.offset, t, peel=True), True))
            self._frame = (rec["frame_id"], views)
        views = self._frame[1]
        points, sky, dirs = self.probe.display_points(pose, rec["scene_t"])
        # the primary's mask is where testing both views starts: it is tested once
        masks = uncovered_by_views(points, sky, dirs, views, peeled_marked=self.probe.mark_peeled)
        return {"primary": float(masks[0].mean()), "both": float(masks[-1].mean())}

    def close(self) -> None:
        self.probe.close()


def summary_table(metrics: dict) -> str:
    """Plain-text table of metrics.json's per-method means."""
    cols = [("method", "{}"), ("PSNR dB", "{:.2f}"), ("SSIM", "{:.4f}"), ("DSSIM", "{:.4f}"), ("FLIP", "{:.4f}"),
            ("geo holes %", "{:.2f}"), ("own holes %", "{:.2f}"), ("client ms", "{:.1f}"), ("age ms", "{:.0f}"),
            ("frames", "{}")]
    rows = []
    for m, s in metrics["methods"].items():
        vals = [m, s["psnr_mean"], s["ssim_mean"], s["dssim_mean"], s["flip_mean"],
                100 * s["geometric_holes_mean"], 100 * s["hole_fraction_mean"], s["client_ms_median"],
                s["age_ms_mean"], s["frames"]]
        rows.append(["-" if v is None else fmt.format(v) for (_, fmt), v in zip(cols, vals)])
    widths = [max(len(c[0]), *(len(r[i]) for r in rows)) for i, c in enumerate(cols)]
    line = "  ".join(c[0].rjust(w) for c, w in zip(cols, widths))
    body = ["  ".join(v.rjust(w) for v, w in zip(r, widths)) for r in rows]
    uniform = metrics.get("nearly_uniform_frames", 0)
    if uniform:
        frames = next(iter(metrics["methods"].values()))["frames"]
        body.append(f"warning: {uniform} of {frames} ground-truth frames are nearly one colour (sky or a wall "
                    "filling the view); every method scores well on them")
    stereo = metrics.get("stereo")
    if stereo:
        for m, c in stereo["methods"].items():
            share = "-" if c["inconsistent_mean"] is None else f"{100 * c['inconsistent_mean']:.2f} %"
            eyes = "" if not stereo.get("eye_fov_deg") else \
                ", eyes " + "/".join(f"{a:g}" for a in stereo["eye_fov_deg"]) + " degrees out/in/up/down"
            body.append(f"stereo {m} ({stereo['reference']}, {stereo['ipd_mm']:g} mm{eyes}): {share} of the points "
                        f"both eyes see shown inconsistently")
    return "\n".join([line, "-" * len(line), *body])
