"""Recording what the client displays: per method, a viewable MP4, a lossless copy for
metrics, and one CSV row per output tick.

Files in the output directory, for method M::

    M.mp4            H.264 yuv420p, for people
    M.lossless.avi   Ut Video RGB with median prediction (lossless), for metrics against
                     ground truth (recordings before 2026-12-03: M.lossless.mkv, H.264 4:4:4 at
                     qp 0; :func:`lossless_recording` finds either)
    M.records.csv    one row per output tick (columns: RECORD_FIELDS)

A client showing two eyes (``--stereo``) records each eye as a method of its own, ``M.left``
and ``M.right`` (their records hold that eye's pose), and per method ``M.stereo.mp4`` (both eyes
side by side, :func:`side_by_side`) and with ``--anaglyph`` ``M.anaglyph.mp4`` (:func:`anaglyph`)
to watch.

The videos hold one frame per tick displayed afresh, stamped with its tick; a missed tick
(``missed`` = 1 in its record) kept the previous image and adds none. ``level`` is the quality
level the tick was drawn at (client/deadline.py; 0 the method's best), ``level_reason`` why
(:data:`pibr.common.quality.REASONS`), with the tick's budget (its interval without a
controller) and the level's predicted cost (0: no prediction); ``server_level`` the level the
shown frame was made at by the server's rate control (an index in ``server_levels`` of the
session's options; -1: none); ``stream_kbps`` the colour's bitrate the server's stream
adaptation chose for the shown frame and ``stream_view`` its primary view's size there (rendered at
1/``stream_view`` of its side; -1 for both: no adaptation).

Writing runs on a worker thread per method; at most ``max_pending`` frames wait, so a slow
disk slows the client (and, on the real clock, shows up as missed deadlines) rather than
filling memory. ``defer`` (the wall clock's way) writes the images as they are, uncompressed,
and encodes the videos when the recorder closes, after the run: measuring what the client shows
then costs its clock a copy per tick, not two video encodes.
"""
from __future__ import annotations

import csv
import fractions
import os
from collections import deque

import numpy as np

from pibr.common.priority import background_executor
from pibr.common.quality import OFF

POSE_FIELDS = ("px", "py", "pz", "qw", "qx", "qy", "qz")
#: frame_*: the server frame shown (NaN before the first): its scene time and its primary
#: view's pose, from which the benchmarks re-render what was transmitted (geometric holes).
RECORD_FIELDS = (
    "tick", "t", "scene_t", *POSE_FIELDS,
    "frame_id", "frame_render_t", "frame_pose_t", "frame_arrival_t", "age_ms",
    "client_ms", "hole_fraction", "missed", "frame_scene_t", *(f"frame_{k}" for k in POSE_FIELDS),
    "level", "level_reason", "budget_ms", "predicted_ms", "server_level", "stream_kbps",
    "stream_view",
)
#: The columns of a recording made before they existed: the top level, no controller, no adaptation.
_LEVEL_DEFAULTS = {"level": 0, "level_reason": OFF, "budget_ms": 0.0, "predicted_ms": 0.0, "server_level": -1,
                   "stream_kbps": -1, "stream_view": -1}
#: The lossless copy's file suffix and (codec, pixel format, options). Ut Video's median
#: prediction, measured on the demo's recordings (960x540 room, one thread): 311 KiB a frame,
#: 5.8 ms to encode and 5.6 to decode to RGB, against 359 KiB, 8.4 and 11.7 ms for x264's lossless
#: 4:4:4 at its fastest (the metrics decode every frame of every method). AVI, as Matroska's muxer
#: takes Ut Video only below normal compliance.
LOSSLESS_SUFFIX = ".lossless.avi"
LOSSLESS_CODEC = ("utvideo", "gbrp", {"pred": "median"})
#: The lossless copy of recordings made before Ut Video (H.264 4:4:4, qp 0).
LEGACY_LOSSLESS_SUFFIX = ".lossless.mkv"


def lossless_recording(out_dir: str, method: str) -> str:
    """The path of ``method``'s lossless recording in ``out_dir``: the Ut Video file, or a legacy
    H.264 one when only that exists (the Ut Video path when neither does, for the error)."""
    path = os.path.join(out_dir, method + LOSSLESS_SUFFIX)
    legacy = os.path.join(out_dir, method + LEGACY_LOSSLESS_SUFFIX)
    return legacy if not os.path.exists(path) and os.path.exists(legacy) else path


#: Columns read as integers (the rest are numbers).
_INTEGER_FIELDS = ("tick", "frame_id", "missed", "level", "level_reason", "server_level", "stream_kbps",
                   "stream_view")


class MethodRecorder:
    def __init__(self, out_dir: str, method: str, width: int, height: int, rate_hz: float,
                 lossless: bool = True, max_pending: int = 4, video: bool = True, defer: bool = False,
                 records: bool = True):
        """video=False writes the records only: the least work per tick, for timing runs;
        defer: encode the videos after the run (see the module docstring); records=False: the
        videos only (a pair's side-by-side video)."""
        import av

        self._av = av
        os.makedirs(out_dir, exist_ok=True)
        self._raw = None     # defer: (file of (h, w, 3) uint8 images, [pts]) until close()
        if defer and video:
            self._raw = (open(os.path.join(out_dir, f".{method}.frames.raw"), "w+b"), [])
        self.method, self.width, self.height = method, width, height
        rate = fractions.Fraction(rate_hz).limit_denominator(1000)
        self._containers = []
        self._streams = []
        # (file, codec, pixel format, options): for watching, and lossless for the metrics
        outputs = [(f"{method}.mp4", "libx264", "yuv420p", {"preset": "ultrafast", "crf": "18"})] if video else []
        if lossless and video:
            outputs.append((method + LOSSLESS_SUFFIX, *LOSSLESS_CODEC))
        for name, codec, pix_fmt, options in outputs:
            container = av.open(os.path.join(out_dir, name), "w")
            s = container.add_stream(codec, rate=rate)
            s.width, s.height, s.pix_fmt = width, height, pix_fmt
            s.options = options
            self._containers.append(container)
            self._streams.append(s)
        self._csv_file = self._csv = None
        if records:
            self._csv_file = open(os.path.join(out_dir, f"{method}.records.csv"), "w", newline="")
            self._csv = csv.DictWriter(self._csv_file, fieldnames=RECORD_FIELDS)
            self._csv.writeheader()
        self._pool = background_executor(f"rec-{method}")
        self._pending: deque = deque()
        self.max_pending = max_pending
        self.frames = 0

    def _write(self, rgb: np.ndarray | None, pts: int, record: dict) -> None:
        if rgb is not None:
            if self._raw is not None:
                self._raw[0].write(rgb.data)
                self._raw[1].append(pts)
            else:
                self._encode(rgb, pts)
        if self._csv is not None:
            self._csv.writerow(record)

    def _encode(self, rgb: np.ndarray, pts: int) -> None:
        frame = self._av.VideoFrame.from_ndarray(rgb, format="rgb24")
        for container, stream in zip(self._containers, self._streams):
            frame.pts = pts
            for packet in stream.encode(frame):
                container.mux(packet)

    def _encode_deferred(self) -> None:
        """The images written during the run, encoded now, in order; the raw file is removed."""
        f, stamps = self._raw
        size = self.height * self.width * 3
        f.flush()
        f.seek(0)
        for pts in stamps:
            data = f.read(size)
            self._encode(np.frombuffer(data, np.uint8).reshape(self.height, self.width, 3), pts)
        f.close()
        os.unlink(f.name)
        self._raw = None

    def submit(self, rgb: np.ndarray, record: dict) -> None:
        """Queue one displayed image (H, W, 3) uint8 and its record; blocks while too many wait.
        The image's timestamp is its tick, so ticks recorded with :meth:`repeat` in between are
        held on screen by players."""
        if rgb.shape != (self.height, self.width, 3):
            raise ValueError(f"expected a ({self.height}, {self.width}, 3) image, got {rgb.shape}")
        self._queue(np.ascontiguousarray(rgb), record)

    def submit_pair(self, left: np.ndarray, right: np.ndarray, record: dict, compose) -> None:
        """Queue the image ``compose(left, right)`` (e.g. :func:`side_by_side`), composed on the
        recorder's thread rather than the client's tick."""
        while len(self._pending) >= self.max_pending:
            self._pending.popleft().result()
        pts = int(record.get("tick", self.frames))
        self._pending.append(self._pool.submit(lambda: self._write(compose(left, right), pts, record)))
        self.frames += 1

    def repeat(self, record: dict) -> None:
        """A tick whose display kept the previous image (a missed deadline): its record only. The
        videos hold the previous frame (blank before the first); nothing is encoded, so a client
        that falls behind does not also fall behind on its recording."""
        self._queue(None, record)

    def _queue(self, rgb, record: dict) -> None:
        while len(self._pending) >= self.max_pending:
            self._pending.popleft().result()
        self._pending.append(self._pool.submit(self._write, rgb, int(record.get("tick", self.frames)), record))
        self.frames += rgb is not None

    def close(self) -> None:
        while self._pending:
            self._pending.popleft().result()

        def finish():
            if self._raw is not None:
                self._encode_deferred()
            for container, stream in zip(self._containers, self._streams):
                for packet in stream.encode():
                    container.mux(packet)
                container.close()
            if self._csv_file is not None:
                self._csv_file.close()

        self._pool.submit(finish).result()
        self._pool.shutdown()


#: Black columns between the eyes of a side-by-side image.
PAIR_GAP = 8


def side_by_side_size(width: int, height: int) -> tuple[int, int]:
    """(width, height) of :func:`side_by_side` of two ``width`` x ``height`` images."""
    return 2 * width + PAIR_GAP, height


def side_by_side(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """(h, 2 w + PAIR_GAP, 3) uint8: the left eye's image, a black gap, the right eye's."""
    if left.shape != right.shape or left.ndim != 3 or left.shape[2] != 3:
        raise ValueError(f"need two (h, w, 3) images of one shape, got {left.shape} and {right.shape}")
    gap = np.zeros((left.shape[0], PAIR_GAP, 3), np.uint8)
    return np.concatenate([left, gap, right], axis=1)


def anaglyph(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """(h, w, 3) uint8 red-cyan anaglyph: red from the left eye, green and blue from the right."""
    if left.shape != right.shape or left.ndim != 3 or left.shape[2] != 3:
        raise ValueError(f"need two (h, w, 3) images of one shape, got {left.shape} and {right.shape}")
    out = right.copy()
    out[:, :, 0] = left[:, :, 0]
    return out


def read_records(path: str) -> list[dict]:
    """Rows of a ``M.records.csv`` with numbers converted."""
    from pibr.protocol.errors import ConfigError

    rows = []
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        missing = [k for k in RECORD_FIELDS if k not in (reader.fieldnames or []) and k not in _LEVEL_DEFAULTS]
        if missing:
            raise ConfigError(f"{path}: not a pibr records file (missing columns {', '.join(missing)})")
        for line, row in enumerate(reader, start=2):
            try:
                rows.append({**_LEVEL_DEFAULTS,
                             **{k: (int(v) if k in _INTEGER_FIELDS else float(v)) for k, v in row.items()}})
            except (TypeError, ValueError):
                raise ConfigError(f"{path}:{line}: a value does not parse as a number") from None
    return rows
