"""Holding the server's frame rate on the wall clock: each frame made at the best level whose
predicted cost fits one frame interval (pibr.common.quality).

A session's frame costs its render on the shared GL thread, its readback and packing, and its
encoders. The levels make less of it, best first (:func:`server_levels`): the extra view
rendered on every other frame, then every fourth or eighth (the atlas keeps the last one, with
its pose, so a client warps it as it was seen), longer straight edges in the wide-angle
projection (fewer pre-tessellated triangles: 9 to 24 degrees instead of 6), and the primary view
rendered at 1/2 or 1/3 of its side and upsampled into the atlas (server/producer.py). Chosen by
measurement (room, 1088^2 dual view, one core, 10 frames each): 283, 267, 197, 175, 137, 126 and
99 ms a frame; 3/4 of the view at 12 degrees (190 ms) was not cheaper than the whole view at 12
degrees (175 ms): on one core the vertex stage, not the pixels, is most of a frame. Since a
smaller primary is read back small and brought to size on the CPU (view_upsample.py), a session's
calibration in ``pibr bench realtime --placement split`` gave 314, 196, 189, 141, 110, 96 and
74 ms. The x264 preset is not a level: ``ultrafast`` is already its cheapest.

The costs are calibrated when the session starts (every kind of frame of every level made twice,
the first not timed: it builds the level's tessellation and loads the CPU upsampling's compiled
kernels; plus one H.264 encode on an encoder of its own, so the session's stream is untouched)
and followed online from what each frame takes, its wait for the shared GL thread and encoder
pool included: sessions share them in fair turns (fair_queue.py), so a session that would take
more than its share waits longer and moves down by itself, and
never starves another to hold its own rate. Each frame's level travels with it (a FRAME_LEVEL
payload: its index in ``SessionConfig.options["server_levels"]``) and the session's log says how
many frames each level made.
"""
from __future__ import annotations

import time

from pibr.common.quality import DeadlineController, Level

from .producer import FrameLevel

#: Frames made at each level before the session's first (the first of each not timed).
CALIBRATION_FRAMES = 2


_WITH_EXTRA = (
    Level("full", "server"),
    Level("extra every 2nd", "server", 1.0, {"extra_every": 2}),
    Level("extra every 2nd, 9 deg", "server", 1.0, {"extra_every": 2, "edge_deg": 9.0}),
    Level("extra every 4th, 12 deg", "server", 1.0, {"extra_every": 4, "edge_deg": 12.0}),
    Level("1/2 view, extra every 4th, 12 deg", "server", 0.5, {"extra_every": 4, "edge_deg": 12.0}),
    Level("1/2 view, extra every 4th, 18 deg", "server", 0.5, {"extra_every": 4, "edge_deg": 18.0}),
    Level("1/3 view, extra every 8th, 24 deg", "server", 1 / 3, {"extra_every": 8, "edge_deg": 24.0}),
)
_PRIMARY_ONLY = (
    Level("full", "server"),
    Level("9 deg", "server", 1.0, {"edge_deg": 9.0}),
    Level("12 deg", "server", 1.0, {"edge_deg": 12.0}),
    Level("1/2 view, 12 deg", "server", 0.5, {"edge_deg": 12.0}),
    Level("1/2 view, 18 deg", "server", 0.5, {"edge_deg": 18.0}),
    Level("1/3 view, 24 deg", "server", 1 / 3, {"edge_deg": 24.0}),
)


def server_levels(extra_view: bool) -> tuple[Level, ...]:
    """The levels of a session's frames, best first (``options``: ``extra_every``, the frames the
    extra view is rendered on; ``edge_deg``, the primary's longest straight edge; ``scale``: the
    primary's render scale). Without an extra view, the levels that thin it out are left out."""
    return _WITH_EXTRA if extra_view else _PRIMARY_ONLY


class RateControl:
    """One session's frame levels on the wall clock (module docstring)."""

    def __init__(self, levels, fps: float, margin: float = 0.05):
        """margin: the share of the frame interval kept free (scheduling, the event loop)."""
        self.levels = tuple(levels)
        self.controller = DeadlineController({"frame": self.levels}, 1e3 / fps, margin_ms=margin * 1e3 / fps)
        self.frames = 0
        self.calibration_ms: list = []
        #: level -> (ms of a frame that renders the extra view, ms of one that keeps it): the
        #: controller's base is their mean over the level's cycle, and each frame is measured
        #: against its own kind, so the alternation is no noise to the controller
        self._kinds: dict = {}

    @property
    def names(self) -> list[str]:
        return [lv.name for lv in self.levels]

    def frame_level(self, index: int, frame_number: int) -> FrameLevel:
        """What level ``index`` makes of the session's ``frame_number``-th frame."""
        lv = self.levels[index]
        every = int(lv.options.get("extra_every", 1))
        return FrameLevel(extra=frame_number % every == 0, edge_deg=lv.options.get("edge_deg"), scale=lv.scale)

    def choose(self) -> tuple[int, int, FrameLevel]:
        """-> (level index, reason, what to make) of the next frame."""
        index, reason = self.controller.choose()["frame"]
        level = self.frame_level(index, self.frames)
        self.frames += 1
        return index, reason, level

    def observe(self, index: int, ms: float, with_extra: bool = True) -> None:
        """The frame made at level ``index`` (rendering the extra view or keeping it) took ``ms``
        of wall time, waits included."""
        kinds = self._kinds.get(index)
        if kinds is not None:
            fresh, kept = kinds
            every = int(self.levels[index].options.get("extra_every", 1))
            ms *= ((fresh + (every - 1) * kept) / every) / (fresh if with_extra else kept)
        self.controller.observe("frame", index, ms)

    def calibrate(self, pipeline, pose, t: float) -> list[float]:
        """Make every level's frames on this (the GL) thread and time them -> ms per level, each
        the level's base cost. The H.264 encode is timed on an encoder of its own."""
        encoder = pipeline.new_video_encoder()

        def timed(level: FrameLevel) -> float:
            t0 = time.perf_counter()
            produced = pipeline.produce(pose, t, level)
            encoder.encode(produced.yuv)
            return (time.perf_counter() - t0) * 1e3

        try:
            out = []
            for index in range(len(self.levels)):
                every = int(self.levels[index].options.get("extra_every", 1))
                with_extra, keeping = self.frame_level(index, 0), self.frame_level(index, 1)
                for _ in range(CALIBRATION_FRAMES - 1):
                    timed(with_extra)        # builds the level's tessellation, compiles
                    if every > 1:
                        timed(keeping)       # a smaller view kept on the CPU: its kernels load
                fresh = timed(with_extra)
                kept = timed(keeping) if every > 1 else fresh
                mean = (fresh + (every - 1) * kept) / every
                self._kinds[index] = (fresh, kept)
                self.controller.calibrate("frame", index, mean)
                out.append(round(mean, 3))
        finally:
            encoder.close()
        self.calibration_ms = out
        return out

    def summary(self) -> dict:
        s = self.controller.summary()["methods"]["frame"]
        return {"levels": self.names, "frames_at_level": s["ticks_at_level"], "calibration_ms": self.calibration_ms,
                "costs_ms": self.controller.cost_table()["frame"], "reasons": s["reasons"]}
