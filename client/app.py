"""The client process: replay a head trace against a server and re-render every output tick.

Per output tick the client samples the trace, sends the pose, takes the newest usable
server frame, re-renders the current view with each requested method and records the
result. Two clocks (DESIGN.md, Time and latency):

* **virtual**: ticks are simulated. At tick t the client sends its pose stamped t and a
  ``Clock`` promise for its next tick, then reads until the server's messages pass t, so it
  has every frame usable at t (stamped <= t). Nothing depends on the wall clock: the same
  inputs give bit-identical recordings on any machine.
* **real**: ticks follow the wall clock at the output rate, from when the first frame has
  been decoded and drawn once by every method (the warm-up compiles shaders). Frames are
  taken off the socket as they arrive and decoded whenever the decoder is free, all that have
  arrived at once with only the newest converted for display; what was decoded is reported to
  the server, which keeps only a few frames ahead. A tick whose work ends after the next
  deadline makes the display skip ticks, each counted as a missed deadline and recorded as a
  repeat of the last image.

The client knows the scene only from the wire (``Welcome``; proxies when a method asks).
"""
from __future__ import annotations

import asyncio
import json
import logging
import math
import os
import sys
import time
from collections import deque
from dataclasses import asdict, dataclass, field

import numpy as np

from pibr.common.gl import GLThread, wait_idle
from pibr.common.priority import background_executor
from pibr.common.quality import OFF, DeadlineController, read_cost_table
from pibr.protocol.age_baseline import AgeBaseline
from pibr.protocol.errors import ConfigError, MalformedMessage, UnexpectedMessage
from pibr.protocol.frustum import eyes_tangents
from pibr.protocol.messages import (ARRIVAL_AGE_MS, DELIVERED_KBPS, DISPLAY_AGE_MS, FRAMES_DECODED, LINK_KBPS,
                                    MAX_BANDWIDTH_KBPS, NEWEST_FRAME, PROBE_KBPS, REPORT_SPAN_MS, STREAM_BASELINE_S,
                                    STREAM_QUEUE_HIGH_MS, STREAM_REPORT_MS, STREAM_URGENT_GAP_MS, WARMUP_SEQ,
                                    Clock, Frame, Hello, OutputConfig, PayloadKind, PoseMsg, Stats, decode_eye,
                                    decode_frame_level, decode_stream_rate)
from pibr.protocol.pose import Pose
from pibr.protocol.stereo import CENTRE, EYES, eye_pose

from .config import ClientConfig
from .connection import ClientConnection
from .deadline import levels_for
from .depth_decoders import make_depth_decoder
from .frame_textures import FrameTextures
from .live import LiveSeries, LiveServer
from .methods import needs_proxies, quadtree_threshold
from .recorder import POSE_FIELDS, MethodRecorder, anaglyph, side_by_side, side_by_side_size
from .video import H264Decoder

log = logging.getLogger(__name__)

#: Timed renders of every quality level before the wall clock starts (after one that compiles it).
CALIBRATION_RENDERS = 5
#: A server that predicts the head's pose hears the median age of the frames shown over this many
#: ticks, every this many ticks (Stats DISPLAY_AGE_MS).
AGE_REPORT_TICKS = 15
#: The interpreter's thread switch interval on the wall clock (see _run_real).
SWITCH_INTERVAL_S = 0.001


@dataclass
class _Decoded:
    frame: Frame
    arrival_us: int
    image: object
    distances: dict | None = None   # edge codec: view -> dense distance (h, w) float32
    flow: object = None             # the primary view's FlowFrame (client/flow_warp.py), when a method uses flow


@dataclass
class ClientResult:
    ticks: int
    frames_received: int
    missed_deadlines: int
    bytes_received: int
    handshake_ms: float
    summary: dict = field(default_factory=dict)
    #: client time (s) each frame was decoded at; the real clock's warm-up ones are negative
    frame_arrivals_s: list = field(default_factory=list)
    #: bytes each of those frames took on the wire (header included), in the same order
    frame_bytes: list = field(default_factory=list)


class _Progress:
    def __init__(self, mode: str, total: int):
        self.mode, self.total, self.done = mode, total, 0
        self._bar = None
        if mode == "bar":
            from tqdm import tqdm

            self._bar = tqdm(total=total, unit="tick", desc="client", file=sys.stderr, leave=False,
                       disable=None)  # None: no bar when stderr is not a terminal

    def step(self) -> None:
        self.done += 1
        if self._bar is not None:
            self._bar.update(1)
        elif self.mode == "lines" and (self.done % 10 == 0 or self.done == self.total):
            print(f"PROGRESS {self.done} {self.total}", flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


#: The longest server stage time stream_left_us believes (ms).
MAX_STAGE_MS = 10_000.0


def stream_left_us(frame: Frame, wall_clock: bool) -> int:
    """When a frame left the server, as the stream's reports count its age (issue 28): its render
    time, plus on the wall clock the server's own stages (its ``timings_ms``: render, read back,
    pack, encode), so that a busy server is not read as a full link (its frames leave late, but
    no lower rate would make them younger). A stage time that is not a number from 0 to
    :data:`MAX_STAGE_MS` counts as 0. On the virtual clock the stages take a fixed virtual time,
    which the least age cancels."""
    if not wall_clock:
        return frame.render_t_us
    stages_ms = sum(float(ms) if 0.0 <= ms <= MAX_STAGE_MS else 0.0 for ms in frame.timings_ms)
    return frame.render_t_us + int(round(1e3 * stages_ms))


def live_image(per_eye: list) -> np.ndarray | None:
    """What the live page shows of one method's tick, ``per_eye`` [(rgb (h, w, 3) or None, hole
    fraction, ms) per eye]: its one view, or both eyes side by side (as ``M.stereo.mp4``); None
    before a frame."""
    images = [rgb for rgb, _, _ in per_eye]
    if any(rgb is None for rgb in images):
        return None
    return images[0] if len(images) == 1 else side_by_side(*images)


def _read_back(rgba, ms: float) -> tuple:
    """(rgb or None, hole fraction, ms) of one eye's image read back, (h, w, 4) or None (not read)."""
    if rgba is None:
        return None, float("nan"), ms
    hole = float(np.count_nonzero(rgba[:, :, 3] == 0)) / (rgba.shape[0] * rgba.shape[1])
    return rgba[:, :, :3], hole, ms


class Client:
    def __init__(self, config: ClientConfig):
        self.cfg = config
        self.conn: ClientConnection | None = None
        self.session = None
        self.gl: GLThread | None = None
        # decoding uses the CPU the ticks leave (common/priority.py): the newest frame wins, and it
        # must never slow the tick that shows the one before
        self._decode_pool = background_executor("pibr-decode")
        self.recorders: dict[str, MethodRecorder] = {}   # recording name (method, or method.eye) -> recorder
        self._recorded: dict[str, tuple[str, str]] = {}  # recording name -> (method, eye)
        self.pair_recorders: dict[str, list] = {}        # method -> videos of both eyes (side by side, anaglyph)
        #: the eyes shown (the head's centre, or left and right) and the frames' slots (the centre's
        #: frames serve both eyes, except with alternate and per-eye references: one slot per eye)
        self._eyes: tuple = EYES if config.stereo else (CENTRE,)
        self._slots: tuple = EYES if config.stereo in ("alternate", "per-eye") else (CENTRE,)
        #: eye -> the (left, right, down, up) tangents it sees through (--eye-fov-deg), None: symmetric
        self._frustums: dict = eyes_tangents(self._eyes, config.eye_fov_deg)
        self._shown: dict[str, _Decoded] = {}            # slot -> the newest decoded frame for it
        self.frames_received = 0
        self.missed = 0
        self._newest: _Decoded | None = None
        self._gl_state = None
        self._method_info: dict = {}
        self._placement: Pose | None = None   # trace -> scene (pibr.common.traces.placement)
        self._last_shown: dict = {}
        self.proxies = None
        self.proxy_stats: dict = {}
        self._depth_decoder = None
        self._motion_decoder = None     # the frames' MOTION_FLOW (scenes that move)
        #: moving objects' transforms from every frame received (scenes that move)
        self.poses = None
        #: server time = client time + this (0 on the virtual clock, estimated on the real one)
        self._server_offset_us = 0
        #: real clock: client time 0 (tick 0) in microseconds after the receiver started; arrivals
        #: and warm-up poses are stamped from that start, ticks' poses in client time
        self._time_base_us = 0
        #: a server adapting its stream (options["adapt"]): frames arrived since the last report
        #: as (arrival less render us, wire bytes), the newest render time, when the last report went
        self._adapting = False
        self._stream_arrived: list = []
        #: ages at arrival (us) of the last STREAM_BASELINE_S, by arrival: the least is the age of
        #: a frame that did not queue; the newest arrival, for the dispersion
        self._stream_ages = AgeBaseline(STREAM_BASELINE_S * 1e6)
        self._stream_urgent = False       # a frame arrived queued since the last report
        self._link_bits_us = [0.0, 0.0]   # bits of the frames that arrived behind another, and their gaps (us)
        self._newest_frame_id = -1
        self._newest_left_us: int | None = None
        self._stream_reported_us: int | None = None
        self._arrivals_us: list[int] = []
        self._frame_bytes: list[int] = []
        #: frame id -> wire size of the frames received and not decoded yet
        self._wire_sizes: dict[int, int] = {}
        #: the quality levels' controller (client/deadline.py), None with --deadline off
        self.deadline: DeadlineController | None = None
        self._levels: dict = {}          # method -> its levels, best first (one with --deadline off)
        self._chosen: dict = {}          # method -> (level, reason) of the tick being drawn
        self._record_ms: list[float] = []   # per tick: reading the images back for the recorders
        self._calibration: dict = {}        # method -> median ms of each level before the clock started
        self._stopped: str | None = None    # why the run ended before its last tick (interrupted, failed)
        self.ticks_shown = 0                # ticks displayed (afresh or repeated) so far
        self._ages: deque = deque(maxlen=AGE_REPORT_TICKS)   # ms, of the frames the last ticks showed
        #: the last seconds' ticks and frame batches (client/live.py): the live page's series, and
        #: the server's frame rate and bitrate written to stream.csv
        self.series = LiveSeries(config.methods, config.rate_hz)
        self.live: LiveServer | None = None     # --live PORT: the page that shows them
        self._stream_log = None                 # stream.csv, one row per batch of frames decoded

    # ------------------------------------------------------------------ set-up

    def _trace_poses(self):
        from pibr.common.traces.loading import load_trace

        trace = load_trace(self.cfg.trace)
        start, end = trace.window(self.cfg.start_s, self.cfg.duration_s)
        if end <= start:
            raise ConfigError(f"--start {start} s leaves nothing of trace {trace.name!r} ({trace.duration:.2f} s)")
        return trace, end - start

    def _set_up_deadline(self) -> None:
        """The quality levels of every method and, unless --deadline says off, their controller:
        on by default on the wall clock (fitted to what the ticks take); on the virtual clock only
        with a cost table (its choices then depend on the table alone, not on this machine)."""
        cfg = self.cfg
        costs = read_cost_table(cfg.cost_table) if cfg.cost_table else None
        if costs is not None and len(self._eyes) > 1:   # a table's costs are one view's; a tick draws each eye
            costs = _scale_costs(costs, len(self._eyes))
        on = cfg.deadline == "on" or (cfg.deadline == "auto" and (cfg.clock == "real" or costs is not None))
        if on and cfg.clock == "virtual" and costs is None:
            raise ConfigError("--deadline on with the virtual clock needs --cost-table: its choices must not "
                              "depend on how fast this machine is")
        if not on:
            self._levels = {m: levels_for(m)[:1] for m in cfg.methods}
            return
        self._levels = {m: levels_for(m) for m in cfg.methods}
        self.deadline = DeadlineController(self._levels, 1e3 / cfg.rate_hz, costs=costs,
                                           adapt=cfg.clock == "real")

    def _choose_levels(self) -> dict:
        """The levels of this tick: the controller's, or the top ones (--deadline off)."""
        if self.deadline is None:
            return {m: (0, OFF) for m in self.cfg.methods}
        return self.deadline.choose()

    def _pose_at(self, trace, t_s: float) -> Pose:
        local = trace.pose_at(self.cfg.start_s + min(max(t_s, 0.0), self._duration))
        if self._placement is None:
            from pibr.common.traces.placement import placement

            self._placement = placement(trace, self.cfg.start_s, self.session.viewer_origin, self.cfg.anchor)
        return self._placement.compose(local)

    def _gl_setup(self, ctx):
        """Per slot (the head's centre, or each eye: :attr:`_slots`) the frame textures and every
        method at each of its quality levels (one level each with --deadline off); the output target."""
        from .output_target import OutputTarget
        from .render_scale import make_level

        out = OutputConfig(self.cfg.width, self.cfg.height, self.cfg.fov_deg, self.cfg.rate_hz)
        textures = {slot: FrameTextures(ctx, self.session) for slot in self._slots}
        options = {"tau": self.cfg.tau, "lod_target_px": self.cfg.lod_pixels, "lod_level": self.cfg.lod_level,
                   "poses": self.poses, **self.cfg.options}
        methods = {slot: {name: [make_level(ctx, lv, out, self.session, self.proxies, **options)
                                 for lv in self._levels[name]] for name in self.cfg.methods}
                   for slot in self._slots}
        target = OutputTarget(ctx, self.cfg.width, self.cfg.height)
        # both eyes side by side, for the methods that draw a pair at once from one slot's frame
        # (through one symmetric frustum: a pair drawn at once shares its projection)
        pair_target = OutputTarget(ctx, 2 * self.cfg.width, self.cfg.height) if len(self._eyes) == 2 \
            and len(self._slots) == 1 and self.cfg.eye_fov_deg is None else None
        self._gl_state = (textures, methods, target, pair_target)
        first = methods[self._slots[0]]
        self._method_info = {name: {"uses_extra_view": bool(ms[0].uses_extra_view)} for name, ms in first.items()}
        if pair_target is not None:   # whether each eye of a pair is drawn alone, or both at once
            head = Pose.identity()
            eyes = {eye: eye_pose(head, eye, self.cfg.ipd_mm) for eye in EYES}
            for name, ms in first.items():
                shares = getattr(ms[0], "shares_pair", None)
                self._method_info[name]["pair_drawn_at_once"] = bool(shares and shares(eyes["left"], eyes["right"]))
        elif len(self._eyes) == 2 and len(self._slots) == 1:   # eyes with frustums of their own: one by one
            for info in self._method_info.values():
                info["pair_drawn_at_once"] = False

    def _slot(self, eye: str) -> str:
        return eye if eye in self._slots else CENTRE

    def _eye_poses(self, head: Pose) -> dict:
        """eye -> its pose, for every eye shown (the head's own pose for one view)."""
        return {eye: head if eye == CENTRE else eye_pose(head, eye, self.cfg.ipd_mm) for eye in self._eyes}

    def _gl_render(self, ctx, poses: dict, shown: dict, scene_t: float, chosen: dict | None = None,
                   read: bool = True):
        """Upload each slot's newest frame if new, render every method at its chosen level
        (``chosen``: method -> (level, reason); None: the top levels) for every eye of ``poses``
        (eye -> Pose) from its slot's frame (``shown``: slot -> _Decoded) -> per method
        [(rgb or None, hole fraction, ms) per eye], with the wall ms of reading the images back in
        ``self._record_ms`` (``read``: for the recorders)."""
        self._upload_newest(shown)
        out, read_ms = [], 0.0
        for name in self.cfg.methods:
            drawn, ms = self._draw_eyes(ctx, name, chosen[name][0] if chosen else 0, poses, shown, scene_t, read)
            out.append([_read_back(rgba, eye_ms) for rgba, eye_ms in drawn])
            read_ms += ms
        if read:
            self._record_ms.append(read_ms)
        return out

    def _upload_newest(self, shown: dict) -> None:
        """Upload each slot's newest frame (``shown``: slot -> _Decoded) where it is new."""
        textures = self._gl_state[0]
        for slot, decoded in shown.items():
            if textures[slot].frame_id != decoded.frame.frame_id:
                textures[slot].upload(decoded.image, decoded.frame, decoded.distances, decoded.flow)

    def _draw_eyes(self, ctx, name: str, level: int, poses: dict, shown: dict, scene_t: float,
                   read: bool) -> tuple[list, float]:
        """Draw method ``name`` at ``level`` for every eye of ``poses`` from its slot's frame: both at
        once where the method shares the pair (proxy's render_pair, the pair's ms shared out evenly),
        else one at a time -> ([(rgba (h, w, 4) or None (``read`` false), wall ms) per eye], wall ms
        of reading them back)."""
        textures, methods, target, pair_target = self._gl_state
        pair = self._pair_method(methods, name, level, poses, shown)
        if pair is not None:
            pair_target.begin()
            t0 = time.perf_counter()
            pair.render_pair(poses["left"], poses["right"], shown[CENTRE].frame, textures[CENTRE], scene_t)
            wait_idle(ctx)
            t1 = time.perf_counter()
            rgba = pair_target.read() if read else None
            w, ms = self.cfg.width, (t1 - t0) * 0.5e3
            halves = [None if rgba is None else rgba[:, half] for half in (slice(0, w), slice(w, 2 * w))]
            return [(half, ms) for half in halves], (time.perf_counter() - t1) * 1e3 if read else 0.0
        drawn, read_ms = [], 0.0
        for eye, pose in poses.items():
            slot = self._slot(eye)
            decoded = shown.get(slot)
            target.begin()
            t0 = time.perf_counter()
            if decoded is not None:
                method = methods[slot][name][level]
                method.look_through(self._frustums[eye])
                method.render(pose, decoded.frame, textures[slot], scene_t)
            wait_idle(ctx)   # the GIL released: frames arriving meanwhile are read on time
            t1 = time.perf_counter()
            drawn.append((target.read() if read else None, (t1 - t0) * 1e3))
            read_ms += (time.perf_counter() - t1) * 1e3 if read else 0.0
        return drawn, read_ms

    def _pair_method(self, methods, name: str, level: int, poses: dict, shown: dict):
        """The method instance that draws both eyes of ``poses`` at once (one slot's frame, and a
        method that shares the pair: proxy's render_pair), else None: one eye at a time."""
        if set(poses) != set(EYES) or self._gl_state[3] is None or CENTRE not in shown:
            return None
        inst = methods[CENTRE][name][level]
        shares = getattr(inst, "shares_pair", None)
        return inst if shares is not None and shares(poses["left"], poses["right"]) else None

    def _gl_calibrate(self, ctx, poses: dict, shown: dict, renders: int) -> dict:
        """Draw every level of every method for every eye ``renders`` times, untimed the first (it
        compiles shader variants) -> method -> [ms per level, all eyes]: the wall clock's first cost
        estimates."""
        self._upload_newest(shown)
        costs = {name: [[] for _ in self._levels[name]] for name in self.cfg.methods}
        # Round after round of every level, not every draw of one level and then the next: what
        # else runs meanwhile (a server sharing the cores, a frame decoding) then slows every
        # level alike instead of making one look costlier than the level above it.
        for k in range(renders + 1):
            for name in self.cfg.methods:
                for level in range(len(self._levels[name])):
                    drawn, _ = self._draw_eyes(ctx, name, level, poses, shown, 0.0, read=False)
                    if k:
                        costs[name][level].append(sum(ms for _, ms in drawn))
        return costs

    def _gl_release(self, ctx):
        if self._gl_state is None:
            return
        textures, methods, target, pair_target = self._gl_state
        for per_slot in methods.values():
            for instances in per_slot.values():
                for m in instances:
                    m.release()
        for t in textures.values():
            t.release()
        for t in (target, pair_target):
            if t is not None:
                t.release()
        self._gl_state = None

    # ------------------------------------------------------------------ run

    async def run(self) -> ClientResult:
        cfg = self.cfg
        trace, self._duration = self._trace_poses()
        loop = asyncio.get_running_loop()
        self.conn = await ClientConnection.open(cfg.host, cfg.port, tls=cfg.tls,
                                                receive_timeout_s=cfg.receive_timeout_s,
                                                session_timeout_s=cfg.session_limit_s(self._duration))
        t_hello = time.monotonic()
        hello = Hello(client="pibr-client/0.1", scene=cfg.scene, clock=cfg.clock,
                      output=OutputConfig(cfg.width, cfg.height, cfg.fov_deg, cfg.rate_hz),
                      want_proxies=needs_proxies(cfg.methods), depth_codec=cfg.depth_codec,
                      bandwidth_kbps=cfg.bandwidth_kbps,
                      quadtree_threshold=quadtree_threshold(cfg.methods, cfg.options), token=cfg.token or "",
                      stereo=cfg.stereo, ipd_mm=cfg.ipd_mm if cfg.stereo else 0.0)
        try:
            # the Welcome is checked against the Hello (clock, atlas layout, proxies) when taken
            self.session = await self.conn.handshake(hello)
            t_welcome = time.monotonic()
            self._adapting = bool(self.session.options.get("adapt"))
            handshake_ms = (t_welcome - t_hello) * 1e3
            agreed = self.session.options.get("stereo")
            if cfg.stereo and (not isinstance(agreed, dict) or agreed.get("reference") != cfg.stereo):
                raise UnexpectedMessage(f"asked for stereo {cfg.stereo}, the server's session has {agreed!r}")
            if hello.want_proxies:
                await self._receive_proxies(t_welcome)
            self._decoder = H264Decoder(self.session.atlas.width, self.session.atlas.height)
            self._depth_decoder = make_depth_decoder(self.session)
            if self.session.motion:
                self.poses = self._pose_history()
                if cfg.options.get("motion") == "flow" and self.session.colour_scale != 1.0:
                    raise ConfigError(f"--motion flow extrapolates the frame's whole colour; this server sends "
                                      f"colour at scale {self.session.colour_scale:g} (serve with --colour-scale 1)")
                if cfg.options.get("motion") == "flow":
                    from .motion_flow import MotionFlowDecoder

                    self._motion_decoder = MotionFlowDecoder(self.session.primary.width, self.session.primary.height)
            self._set_up_deadline()
            self.gl = await loop.run_in_executor(None, GLThread, "pibr-client-gl")
            await self.gl.run(self._gl_setup)
            if cfg.live_port is not None:
                self.live = LiveServer(self.series, cfg.live_port)
                await self.live.start()
                print(f"pibr client: live view at {self.live.url}", file=sys.stderr, flush=True)
            if cfg.record:
                self._open_recorders()
                # written first (what evaluate needs is known now) and again when the run ends, so an
                # interrupted recording is still evaluable up to its last tick
                self._write_session(None, trace)
            interval_us = int(round(1e6 / cfg.rate_hz))
            n_ticks = max(1, int(math.floor(self._duration * cfg.rate_hz + 1e-9)))
            preroll = int(math.ceil(cfg.preroll_s * cfg.rate_hz))
            progress = _Progress(cfg.progress, n_ticks)
            try:
                if cfg.clock == "virtual":
                    await self._run_virtual(trace, interval_us, n_ticks, preroll, progress)
                else:
                    await self._run_real(trace, interval_us, n_ticks, preroll, progress, t_hello, t_welcome)
            finally:
                progress.close()
            await self.conn.send(Stats({"ticks": n_ticks, "missed_deadlines": self.missed,
                                        "frames_received": self.frames_received}))
            result = ClientResult(n_ticks, self.frames_received, self.missed, self.conn.bytes_received,
                                  handshake_ms, {"proxies": self.proxy_stats or None},
                                  [(a - self._time_base_us) / 1e6 for a in self._arrivals_us], self._frame_bytes)
            self._write_session(result, trace)
            return result
        except BaseException as exc:   # interrupted (Ctrl-C, SIGTERM) or failed: keep what was recorded
            self._stopped = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
            raise
        finally:
            await self._shutdown()
            if self._stopped is not None and self.recorders:
                self._write_session(None, trace)   # the recorders are closed: everything up to the last tick
            if self.live is not None:
                await self.live.close()

    def _open_recorders(self) -> None:
        """A recorder per method and eye shown (on the wall clock the videos are encoded after the
        run); with two eyes, per method a side-by-side video to watch (and an anaglyph if asked)."""
        cfg = self.cfg
        defer = cfg.clock == "real"
        os.makedirs(cfg.out_dir, exist_ok=True)
        self._stream_log = open(os.path.join(cfg.out_dir, "stream.csv"), "w", buffering=1 << 16)
        self._stream_log.write("t,frames,wire_bytes,decode_ms,server_fps,kbps\n")
        for m in cfg.methods:
            for eye in self._eyes:
                name = m if eye == CENTRE else f"{m}.{eye}"
                self._recorded[name] = (m, eye)
                self.recorders[name] = MethodRecorder(cfg.out_dir, name, cfg.width, cfg.height, cfg.rate_hz,
                                                      lossless=cfg.lossless, video=cfg.video, defer=defer)
            if cfg.stereo and cfg.video:
                pair = [MethodRecorder(cfg.out_dir, f"{m}.stereo", *side_by_side_size(cfg.width, cfg.height),
                                       cfg.rate_hz, lossless=False, defer=defer, records=False)]
                if cfg.anaglyph:
                    pair.append(MethodRecorder(cfg.out_dir, f"{m}.anaglyph", cfg.width, cfg.height, cfg.rate_hz,
                                               lossless=False, defer=defer, records=False))
                self.pair_recorders[m] = pair

    async def _shutdown(self) -> None:
        if self._stream_log is not None:
            self._stream_log.close()
        if self.conn is not None:
            await self.conn.close()
        for rec in [*self.recorders.values(), *(r for pair in self.pair_recorders.values() for r in pair)]:
            rec.close()
        if self.gl is not None:
            await self.gl.run(self._gl_release)
            self.gl.close()
        self._decode_pool.shutdown(wait=True)
        if self._depth_decoder is not None:
            self._depth_decoder.close()

    async def _receive_proxies(self, t_welcome: float) -> None:
        """The proxy bundle follows the Welcome: collect, decompress and parse it (off the loop). The
        connection's side takes nothing but the announced chunks meanwhile, and collects them."""
        from pibr.protocol.proxy import decode_bundle, decompress_bundle

        assembler = self.conn.side.proxies
        info = assembler.info
        last = None
        while not assembler.complete:
            env = await self.conn.recv()
            last = (env.vtime_us, asyncio.get_running_loop().time())
        t_received = time.monotonic()
        chunks = assembler.chunks()
        assembler.release()
        compressed = sum(len(c) for c in chunks)
        loop = asyncio.get_running_loop()

        def decode(chunks):   # the chunks go once decompressed; the meshes are views of the raw bundle
            raw = decompress_bundle(chunks, info.raw_bytes, info.objects)
            chunks.clear()
            return decode_bundle(raw)

        self.proxies = await loop.run_in_executor(None, decode, chunks)
        self.proxy_stats = {"bytes": compressed, "chunks": assembler.count, "objects": len(self.proxies),
                            "transfer_ms": (t_received - t_welcome) * 1e3,
                            "decode_ms": (time.monotonic() - t_received) * 1e3,
                            "probe_kbps": self._probe_kbps(compressed, last)}
        log.info("proxies: %d objects, %.2f MB in %d chunks, received in %.0f ms, decoded in %.0f ms",
                 len(self.proxies), compressed / 1e6, assembler.count, self.proxy_stats["transfer_ms"],
                 self.proxy_stats["decode_ms"])

    def _probe_kbps(self, nbytes: int, last) -> float | None:
        """The link's rate (kbit/s) the proxy bundle measured: its ``nbytes`` over the time from the
        Welcome's arrival to its last chunk's (``last``: (virtual us, loop s)), on the session's
        clock (the virtual one as a relay stamps it). On the virtual clock a bundle that took no
        time crossed no modelled link (no relay, or a relay with no bandwidth trace): it has room
        for any stream, MAX_BANDWIDTH_KBPS. None without a time to measure."""
        if last is None or self.conn.welcome_arrival is None:
            return None
        if self.cfg.clock == "virtual":
            seconds = (last[0] - self.conn.welcome_arrival[0]) / 1e6
            if seconds <= 0 and nbytes > 0:
                return MAX_BANDWIDTH_KBPS
        else:
            seconds = last[1] - self.conn.welcome_arrival[1]
        return min(MAX_BANDWIDTH_KBPS, 8.0 * nbytes / seconds / 1e3) if seconds > 0 else None

    def _pose_history(self):
        """Where the frames' object transforms are kept (the proxies' rest transforms and boxes
        give each object the point whose path is extrapolated)."""
        from .object_motion import PoseHistory

        if not self.proxies:
            return PoseHistory()
        return PoseHistory(np.stack([o.transform for o in self.proxies]), np.stack([o.bounds for o in self.proxies]))

    def _object_poses(self, frame: Frame):
        """The frame's moving-object transforms (None when it carries none), checked against the session."""
        from pibr.protocol.object_poses import decode_object_poses

        payload = frame.payload(PayloadKind.OBJECT_POSES)
        if payload is None:
            return None
        if not self.session.motion:
            raise MalformedMessage(f"frame {frame.frame_id} carries object poses, but the session has no moving objects")
        count = len(self.proxies) if self.proxies else self.session.object_count
        return decode_object_poses(payload, count)

    async def _decode(self, frames: list) -> None:
        """Decode ``frames`` [(Frame, arrival us)], oldest first, and make the last the newest.

        Every frame's streams are decoded (each refers to the one before), but only the last is
        converted and its depth reconstructed: a frame that is already stale when it is decoded
        is never shown. (Skipping stale frames instead would need a keyframe each time: 4.5x the
        bytes of a P-frame at 1024x1024, where decoding one costs 3 ms.)"""
        for frame, _ in frames:
            if frame.payload(PayloadKind.H264_ATLAS) is None:
                raise UnexpectedMessage(f"frame {frame.frame_id} carries no H.264 atlas")
        slots = [self._frame_slot(frame) for frame, _ in frames]
        last = {slot: i for i, slot in enumerate(slots)}   # each slot's newest frame of the batch
        poses = [(frame, self._object_poses(frame)) for frame, _ in frames]
        loop = asyncio.get_running_loop()

        def decode():  # every frame, in order: both decoders keep state from the previous frame
            t0 = time.perf_counter()
            out = {}
            for i, (frame, _) in enumerate(frames):
                newest = last[slots[i]] == i
                image = self._decoder.decode(frame.payload(PayloadKind.H264_ATLAS), convert=newest)
                depth = self._depth_decoder.decode(frame, reconstruct=newest)
                if newest:   # the flow (its decoder keeps no state) only for frames that will be shown
                    out[slots[i]] = (image, depth, self._flow_frame(frame, image, depth))
            return out, (time.perf_counter() - t0) * 1e3

        decoded, decode_ms = await loop.run_in_executor(self._decode_pool, decode)
        if self.poses is not None:   # every frame's transforms: the history sees each frame's time
            for frame, p in poses:
                if p is not None and (self.poses.newest_time is None
                                      or frame.scene_t_us / 1e6 > self.poses.newest_time):
                    self.poses.add(frame.scene_t_us / 1e6, p)
        for slot, i in sorted(last.items(), key=lambda item: item[1]):
            frame, arrival_us = frames[i]
            self._shown[slot] = _Decoded(frame, arrival_us, *decoded[slot])
        self._newest = self._shown[slots[-1]]
        self.frames_received += len(frames)
        self._arrivals_us.extend(arrival for _, arrival in frames)
        # 0 only for a frame id the server sent twice (the second copy's size was taken with the first)
        sizes = [self._wire_sizes.pop(f.frame_id, 0) for f, _ in frames]
        self._frame_bytes.extend(sizes)
        t_s = (frames[-1][1] - self._time_base_us) / 1e6
        fps, kbps = self.series.frames(t_s, len(frames), sum(sizes), decode_ms)
        if self._stream_log is not None:
            self._stream_log.write(f"{t_s:.6f},{len(frames)},{sum(sizes)},{decode_ms:.3f},{fps:.3f},{kbps:.3f}\n")
        if self._adapting:   # what the next stream report tells the server (_report_stream)
            wall, newest_left = self.cfg.clock == "real", None
            for (f, arrival), size in sorted(zip(frames, sizes), key=lambda item: item[0][1]):
                left = stream_left_us(f, wall)
                self._stream_arrival(arrival, arrival - left, size)
                self._newest_frame_id = max(self._newest_frame_id, f.frame_id)
                newest_left = left if newest_left is None else max(newest_left, left)
            self._newest_left_us = newest_left

    def _stream_arrival(self, arrival_us: int, age_us: int, size: int) -> None:
        """One frame of an adapting stream arrived (``size`` wire bytes, ``age_us`` after it was
        rendered), kept for the next report. If the frame before it arrived later than this one
        could have unqueued (its render time plus the least age), the link was busy with this one
        from then on: its bits over that gap measure the link. Past STREAM_QUEUE_HIGH_MS of
        queueing the report goes at once (_report_stream)."""
        ages = self._stream_ages
        previous = ages.newest_t
        queued_us = ages.add(arrival_us, age_us)
        if previous is not None and arrival_us > previous > arrival_us - age_us + ages.least:
            self._link_bits_us[0] += 8.0 * size
            self._link_bits_us[1] += arrival_us - previous
        if queued_us / 1e3 > STREAM_QUEUE_HIGH_MS:
            self._stream_urgent = True
        self._stream_arrived.append((age_us, size))

    def _frame_slot(self, frame: Frame) -> str:
        """The slot a frame fills: its eye in a session with a slot per eye, else the centre's;
        a frame whose eye tag does not fit the session is malformed."""
        payload = frame.payload(PayloadKind.EYE)
        if self._slots == EYES:
            if payload is None:
                raise MalformedMessage(f"frame {frame.frame_id} of a {self.cfg.stereo} stereo session names no eye")
            return decode_eye(payload)
        if payload is not None:
            raise MalformedMessage(f"frame {frame.frame_id} names an eye, but this session's frames are rendered "
                                   f"from the head's centre")
        return CENTRE

    def _flow_frame(self, frame: Frame, image, distances):
        """The frame's primary view ready for ``flow`` extrapolation (decode pool), or None when no
        method uses flow or the frame carries no motion flow."""
        if self._motion_decoder is None:
            return None
        from .frame_textures import primary_flow_frame

        payload = frame.payload(PayloadKind.MOTION_FLOW)
        if payload is None:
            raise MalformedMessage(f"frame {frame.frame_id} of a moving scene carries no motion flow")
        flow, moving = self._motion_decoder.decode(payload)
        return primary_flow_frame(self.session, image, distances, flow, moving, frame.scene_t_us / 1e6)

    async def _display(self, tick: int, t_us: int, pose: Pose) -> float:
        """Render all methods for the tick (every eye) and record them. Recorded times are in
        client time; ``scene_t`` is the scene-animation (server) time the ground truth must show."""
        offset = self._server_offset_us
        shown = dict(self._shown)
        poses = self._eye_poses(pose)
        chosen = self._chosen = self._choose_levels()
        # without a controller the tick's budget is still its interval, and nothing is predicted (0)
        budget = self.deadline.budget_ms if self.deadline is not None else 1e3 / self.cfg.rate_hz
        predicted = {m: (self.deadline.predicted(m, k) if self.deadline is not None else None)
                     for m, (k, _) in chosen.items()}
        watched = self.live is not None and self.live.wants_image()
        results = await self.gl.run(self._gl_render, poses, shown, (t_us + offset) / 1e6, chosen,
                                    bool(self.recorders) or watched)
        drawn = sum(ms for per_eye in results for _, _, ms in per_eye)
        for name, per_eye in zip(self.cfg.methods, results):
            level, reason = chosen[name]
            if self.deadline is not None and len(shown) == len(self._slots):   # every eye drew from a frame
                self.deadline.observe(name, level, sum(ms for _, _, ms in per_eye))
            for eye, (rgb, hole, ms) in zip(poses, per_eye):
                recording = name if eye == CENTRE else f"{name}.{eye}"
                rec = self.recorders.get(recording)
                if rec is None:
                    continue
                record = self._record(tick, t_us, poses[eye], shown.get(self._slot(eye)), ms, hole, missed=0)
                record.update(level=level, level_reason=reason, budget_ms=budget,
                              predicted_ms=0.0 if predicted[name] is None else predicted[name])
                rec.submit(rgb, record)
                self._last_shown[recording] = record
            pair = self.pair_recorders.get(name)
            if pair:
                left, right = per_eye[0][0], per_eye[1][0]
                for rec, compose in zip(pair, (side_by_side, anaglyph)):   # composed off the tick
                    rec.submit_pair(left, right, {"tick": tick}, compose)
        self.ticks_shown += 1
        age = float("nan")
        if shown:   # the age of what the head-centre (or left eye) slot showed: pose sent -> now
            f = shown[self._slot(self._eyes[0])].frame if self._slot(self._eyes[0]) in shown else None
            if f is not None:
                pose_t_us = f.pose_t_us - (self._time_base_us if f.pose_seq == WARMUP_SEQ else 0)
                age = (t_us - pose_t_us) / 1e3
                self._ages.append(age)
        t0 = time.thread_time()
        self.series.tick(t_us / 1e6, age, False, {m: sum(ms for _, _, ms in per_eye)
                                                  for m, per_eye in zip(self.cfg.methods, results)},
                         {m: level for m, (level, _) in chosen.items()})
        if watched:
            image = live_image(results[0])
            if image is not None:
                self.live.set_image(image)
        if self.live is not None:
            self.live.account((time.thread_time() - t0) * 1e3)
        return drawn

    async def _report_stream(self, t_us: int, vtime_us: int) -> None:
        """Tell a server whose stream adapts to the link (options["adapt"]) what arrived, every
        STREAM_REPORT_MS of the client's clock: the frames' median age at arrival (since they left
        the server, stream_left_us; none arrived: the newest one's age now) and their bits over
        the interval (protocol/messages.py)."""
        if not self._adapting or self._newest_left_us is None:
            return
        last = self._stream_reported_us
        if last is not None and t_us - last < (STREAM_URGENT_GAP_MS if self._stream_urgent else STREAM_REPORT_MS) * 1e3:
            return
        now = self._time_base_us + t_us     # the arrival times' clock
        arrived, self._stream_arrived = self._stream_arrived, []
        if arrived:
            age_ms = float(np.median([a for a, _ in arrived])) / 1e3
        else:
            age_ms = (now - self._newest_left_us) / 1e3
        span_ms = STREAM_REPORT_MS if last is None else (t_us - last) / 1e3
        kbps = 8.0 * sum(n for _, n in arrived) / span_ms
        values = {ARRIVAL_AGE_MS: age_ms, DELIVERED_KBPS: kbps, REPORT_SPAN_MS: span_ms,
                  NEWEST_FRAME: float(self._newest_frame_id)}
        bits, gaps_us = self._link_bits_us
        if gaps_us > 0:
            values[LINK_KBPS] = 1e3 * bits / gaps_us
        self._link_bits_us = [0.0, 0.0]
        self._stream_urgent = False
        self._stream_reported_us = t_us
        await self.conn.send(Stats(values), vtime_us=vtime_us, flush=False)

    async def _report_age(self, tick: int, vtime_us: int) -> None:
        """Tell a server that predicts the head's pose how old the frames shown are (every
        AGE_REPORT_TICKS ticks, the median of the last ones)."""
        if self.session.options.get("predict") and self._ages and tick % AGE_REPORT_TICKS == AGE_REPORT_TICKS - 1:
            await self.conn.send(Stats({DISPLAY_AGE_MS: float(np.median(self._ages))}), vtime_us=vtime_us,
                                 flush=False)

    def _record(self, tick: int, t_us: int, pose: Pose, decoded, client_ms: float, hole: float, missed: int) -> dict:
        """One row of ``<method>.records.csv``: the tick, its pose, and the frame shown (if any)."""
        offset = self._server_offset_us
        f = decoded.frame if decoded is not None else None
        if f is not None:
            pose_t_us = f.pose_t_us - (self._time_base_us if f.pose_seq == WARMUP_SEQ else 0)
            arrival_us = decoded.arrival_us - self._time_base_us
        return {
            "tick": tick, "t": t_us / 1e6, "scene_t": (t_us + offset) / 1e6,
            **dict(zip(POSE_FIELDS, pose.as_array())),
            "frame_id": -1 if f is None else f.frame_id,
            "frame_render_t": float("nan") if f is None else (f.render_t_us - offset) / 1e6,
            "frame_pose_t": float("nan") if f is None else pose_t_us / 1e6,
            "frame_arrival_t": float("nan") if f is None else arrival_us / 1e6,
            "age_ms": float("nan") if f is None else (t_us - pose_t_us) / 1e3,
            "client_ms": client_ms, "hole_fraction": hole, "missed": missed,
            "level": 0, "level_reason": OFF, "budget_ms": 1e3 / self.cfg.rate_hz, "predicted_ms": 0.0,
            "server_level": self._server_level(f),
            **dict(zip(("stream_kbps", "stream_view"), self._stream_rate(f))),
            "frame_scene_t": float("nan") if f is None else f.scene_t_us / 1e6,
            **dict(zip((f"frame_{k}" for k in POSE_FIELDS),
                       [float("nan")] * 7 if f is None else f.primary_pose.as_array())),
        }

    @staticmethod
    def _stream_rate(frame) -> tuple[int, int]:
        """The colour's target the stream adaptation chose for ``frame`` (kbit/s) and its primary
        view's divisor (rendered at 1/view of its side); -1, -1 for none."""
        payload = None if frame is None else frame.payload(PayloadKind.STREAM_RATE)
        if payload is None:
            return -1, -1
        kbps, _, _, view = decode_stream_rate(payload)
        return kbps, view

    def _server_level(self, frame) -> int:
        """The server's rate-control level ``frame`` was made at (an index in the session's
        ``server_levels``), -1 for none (no frame yet, or no rate control)."""
        payload = None if frame is None else frame.payload(PayloadKind.FRAME_LEVEL)
        if payload is None:
            return -1
        level, count = decode_frame_level(payload), len(self.session.options.get("server_levels", ()))
        if level >= count:
            raise MalformedMessage(f"frame {frame.frame_id} names server level {level}, but the session has {count}")
        return level

    async def _send_probe(self, vtime_us: int) -> None:
        """An adapting session's link measured on the proxies (PROBE_KBPS), where its stream may
        start, sent before the first pose (on the virtual clock stamped as the first tick is: a
        link's messages arrive in order, so a later stamp would hold the first poses back)."""
        probe = (self.proxy_stats or {}).get("probe_kbps")
        if self._adapting and probe is not None:
            await self.conn.send(Stats({PROBE_KBPS: probe}), vtime_us=vtime_us)

    async def _run_virtual(self, trace, interval_us, n_ticks, preroll, progress) -> None:
        side = self.conn.side   # side.horizon_us: every later server message has a virtual time >= this
        inbox: deque = deque()
        await self._send_probe(-preroll * interval_us)
        for tick in range(-preroll, n_ticks):
            t_us = tick * interval_us
            pose = self._pose_at(trace, t_us / 1e6)
            # before the clock's promise, so the server sees it by the frames after t_us whatever the timing
            await self._report_stream(t_us, t_us)
            await self.conn.send(PoseMsg(tick + preroll, t_us, pose), vtime_us=t_us, flush=False)
            await self.conn.send(Clock(), vtime_us=t_us + interval_us)
            while side.horizon_us is None or side.horizon_us <= t_us:
                env = await self.conn.recv()    # a frame, clock or stats, its time checked by the side
                if isinstance(env.message, Frame):
                    self._wire_sizes[env.message.frame_id] = env.wire_size
                    inbox.append(env)
            usable = []
            while inbox and inbox[0].vtime_us <= t_us:
                env = inbox.popleft()
                usable.append((env.message, env.vtime_us))
            if usable:
                await self._decode(usable)
            if tick >= 0:
                await self._display(tick, t_us, pose)
                await self._report_age(tick, t_us)
                progress.step()

    async def _run_real(self, trace, interval_us, n_ticks, preroll, progress, t_hello, t_welcome) -> None:
        # The GL thread draws in many short Python steps between GL calls; while the decoder's
        # thread holds the GIL it waits for it, up to the switch interval (5 ms by default) each
        # time. A shorter one gives it back sooner (measured: the cheapest proxy level 34 -> 22 ms
        # on one core beside a decoding thread).
        switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        loop = asyncio.get_running_loop()
        await self._send_probe(0)
        origin = loop.time()
        receiver = asyncio.create_task(self._receive_real(origin), name="client-receiver")
        try:
            await self._warm_up(trace, interval_us, receiver, origin)
            zero = loop.time() + preroll * interval_us / 1e6   # tick 0's deadline: client time 0
            self._time_base_us = int(round((zero - origin) * 1e6))
            # The server's clock starts when it sends Welcome, estimated half a network round
            # trip (the handshake minus the server's set-up time) before we received it.
            one_way = max(0.0, t_welcome - t_hello - self.conn.welcome.setup_us / 1e6) / 2
            self._server_offset_us = int(round((zero - (t_welcome - one_way)) * 1e6))
            await self._tick_real(trace, interval_us, n_ticks, preroll, progress, receiver, zero)
        finally:
            sys.setswitchinterval(switch_interval)
            receiver.cancel()
            try:
                await receiver
            except (asyncio.CancelledError, Exception):  # its outcome was already reported
                pass

    async def _warm_up(self, trace, interval_us, receiver, origin) -> None:
        """Before the clock starts: ask for frames at the first pose until one is decoded, then
        draw every method with it once, untimed. The first draw compiles shader variants and
        fills caches (seconds on a software rasteriser); on the clock it would miss deadlines
        and leave a queue of frames behind it."""
        loop = asyncio.get_running_loop()
        pose = self._pose_at(trace, 0.0)
        give_up = loop.time() + self.cfg.warmup_s
        await self._frame_since(0, pose, interval_us, receiver, origin, give_up)
        poses = self._eye_poses(pose)
        if self.deadline is None:
            await self.gl.run(self._gl_render, poses, dict(self._shown), 0.0, None, False)
        else:
            # every level drawn once to compile it, then timed: the controller's first estimates
            costs = await self.gl.run(self._gl_calibrate, poses, dict(self._shown), CALIBRATION_RENDERS)
            self._calibration = {name: [round(float(np.median(t)), 3) for t in per_level]
                                 for name, per_level in costs.items()}
            for name, medians in self._calibration.items():
                for level, ms in enumerate(medians):
                    self.deadline.calibrate(name, level, ms)
        # The clock starts from a frame of a pose sent now: one rendered before the warm-up ended
        # would show its age (seconds, on a slow machine) on the first ticks.
        await self._frame_since(int((loop.time() - origin) * 1e6), pose, interval_us, receiver, origin, give_up)

    async def _frame_since(self, since_us: int, pose: Pose, interval_us: int, receiver, origin: float,
                           give_up: float) -> None:
        """Send warm-up poses until every slot's newest decoded frame was rendered from one sent at
        or after ``since_us`` (from ``origin``)."""
        loop = asyncio.get_running_loop()
        while len(self._shown) < len(self._slots) or min(d.frame.pose_t_us for d in self._shown.values()) < since_us:
            if loop.time() > give_up:
                raise UnexpectedMessage(f"no frame from the server within {self.cfg.warmup_s:g} s")
            await self.conn.send(PoseMsg(WARMUP_SEQ, int((loop.time() - origin) * 1e6), pose))
            await asyncio.wait({receiver}, timeout=interval_us / 1e6)
            if receiver.done():
                receiver.result()
                raise UnexpectedMessage("server stopped sending before the first frame")

    async def _tick_real(self, trace, interval_us, n_ticks, preroll, progress, receiver, zero) -> None:
        loop = asyncio.get_running_loop()
        tick = -preroll
        while tick < n_ticks:
            deadline = zero + tick * interval_us / 1e6
            wait = deadline - loop.time()
            if wait > 0:
                await asyncio.wait({receiver}, timeout=wait)
            if receiver.done():
                receiver.result()
                raise UnexpectedMessage("server stopped sending before the trace ended")
            t_us = tick * interval_us
            pose = self._pose_at(trace, t_us / 1e6)
            started = loop.time()
            await self._report_stream(t_us, t_us)
            await self.conn.send(PoseMsg(tick + preroll, int((loop.time() - zero) * 1e6), pose), vtime_us=t_us)
            if tick >= 0:
                drawn = await self._display(tick, t_us, pose)
                await self._report_age(tick, t_us)
                progress.step()
                if self.deadline is not None:   # the tick's work besides drawing: the controller's margin
                    self.deadline.observe_overhead((loop.time() - started) * 1e3 - drawn)
            # Ticks whose deadline passed while we worked (the pre-roll's too, which may
            # run into the first displayed ticks) are not displayed afresh.
            next_tick = max(tick + 1, math.floor((loop.time() - zero) * 1e6 / interval_us) + 1)
            for missed_tick in range(max(tick + 1, 0), min(next_tick, n_ticks)):
                self.missed += 1
                self._repeat_last(missed_tick, missed_tick * interval_us, trace)
                progress.step()
            tick = next_tick

    def _repeat_last(self, tick: int, t_us: int, trace) -> None:
        """Record a missed tick: the display kept showing the previous image."""
        self.ticks_shown += 1
        last = self.series.ticks[-1] if self.series.ticks else None
        self.series.tick(t_us / 1e6, float("nan") if last is None else last[1] + (t_us / 1e6 - last[0]) * 1e3,
                         True, {}, {})
        poses = self._eye_poses(self._pose_at(trace, t_us / 1e6))
        for name, rec in self.recorders.items():
            pose = poses[self._recorded[name][1]]
            if name not in self._last_shown:  # nothing displayed yet: the screen stays blank
                rec.repeat(self._record(tick, t_us, pose, None, 0.0, 1.0, missed=1))
                continue
            record = self._last_shown[name]
            age = record["age_ms"] + (t_us / 1e6 - record["t"]) * 1e3  # NaN stays NaN: no frame yet
            rec.repeat(dict(record, tick=tick, t=t_us / 1e6, scene_t=(t_us + self._server_offset_us) / 1e6,
                            missed=1, age_ms=age, **dict(zip(POSE_FIELDS, pose.as_array()))))

    async def _receive_real(self, origin: float) -> None:
        """Two tasks: one takes every message off the socket as it comes (arrival stamped from
        ``origin``, the receiver's start), never waiting on decoding; the other, whenever it is
        free, takes all frames that have arrived, tells the server how many it has taken
        (FRAMES_DECODED, so the server never runs far ahead) and decodes them, showing the newest
        (see :meth:`_decode`). A slow client thus shows the newest frame, not the oldest of a backlog."""
        inbox = FrameInbox()
        reader = asyncio.create_task(self._read_frames(inbox, origin), name="client-reader")
        decoder = asyncio.create_task(self._decode_frames(inbox), name="client-decoder")
        try:
            done, _ = await asyncio.wait({reader, decoder}, return_when=asyncio.FIRST_COMPLETED)
            for task in done:
                task.result()   # re-raises what ended it
        finally:
            for task in (reader, decoder):
                task.cancel()
            await asyncio.gather(reader, decoder, return_exceptions=True)

    async def _read_frames(self, inbox: "FrameInbox", origin: float) -> None:
        loop = asyncio.get_running_loop()
        while True:
            env = await self.conn.recv()    # a frame, clock or stats (the side refuses anything else)
            if isinstance(env.message, Frame):
                self._wire_sizes[env.message.frame_id] = env.wire_size
                await inbox.put(env.message, int((loop.time() - origin) * 1e6), env.wire_size)

    async def _decode_frames(self, inbox: "FrameInbox") -> None:
        taken = 0
        while True:
            frames = await inbox.take_all()
            taken += len(frames)
            # Reported before decoding: the server may render the next frames meanwhile, so the
            # next batch's newest is fresh (reported after, it would be a batch old).
            await self.conn.send(Stats({FRAMES_DECODED: taken}))
            await self._decode(frames)

    def _deadline_summary(self) -> dict:
        """The controller's summary for session.json, its cost table per view whatever the eyes (so a
        later run, with one eye or two, reads it as ``--cost-table``; the calibration is per tick)."""
        out = {**self.deadline.summary(), "calibration_ms": self._calibration}
        if len(self._eyes) > 1:
            out["costs_ms"] = _scale_costs(out["costs_ms"], 1.0 / len(self._eyes))
            out["eyes_per_tick"] = len(self._eyes)
        return out

    def _write_session(self, result: ClientResult | None, trace) -> None:
        """session.json: the client's settings, the negotiated session and what each recording shows;
        ``result`` None while the run goes on (``complete`` false, ``stopped`` why it ended early)."""
        os.makedirs(self.cfg.out_dir, exist_ok=True)
        info = {
            "client": asdict(self.cfg) | {"methods": list(self.cfg.methods), "token": self.cfg.token and "(given)"},
            "session": self.session.to_json(),
            "trace": {"name": trace.name, "start_s": self.cfg.start_s, "duration_s": self._duration,
                      "anchor": self.cfg.anchor, "assumptions": trace.assumptions},
            "result": None if result is None else asdict(result),
            "complete": result is not None,
            "stopped": self._stopped,
            "ticks_recorded": self.ticks_shown,
            "proxies": self.proxy_stats or None,
            "methods": {**self._method_info,
                        **{name: self._method_info[m] for name, (m, eye) in self._recorded.items() if eye != CENTRE}},
            # what each recording shows: recording name -> method and eye (pibr evaluate scores each
            # against the ground truth at the pose its records hold)
            "recordings": {name: {"method": m, "eye": eye} for name, (m, eye) in self._recorded.items()},
            "stereo": None if not self.cfg.stereo else {"reference": self.cfg.stereo, "ipd_mm": self.cfg.ipd_mm,
                                                        "slots": list(self._slots),
                                                        # eye -> its frustum's tangents; None: symmetric
                                                        "frustums": {e: None if f is None else list(f)
                                                                     for e, f in self._frustums.items()}},
            # the quality levels chosen and why (client/deadline.py); None with --deadline off
            "deadline": None if self.deadline is None else self._deadline_summary(),
            # what recording cost each tick on the client's clock (reading the images back and
            # handing them over; on the wall clock the videos are encoded after the run)
            "record_ms": _percentiles(self._record_ms),
            # --live: what the live page cost the client (client/live.py)
            "live": None if self.live is None else {
                "url": self.live.url, **self.live.cost(self.ticks_shown, 1e3 / self.cfg.rate_hz)},
        }
        path = os.path.join(self.cfg.out_dir, "session.json")
        with open(path + ".tmp", "w") as f:   # replaced whole: never a half-written file
            json.dump(info, f, indent=2, default=str)
        os.replace(path + ".tmp", path)


def _scale_costs(costs: dict, factor: float) -> dict:
    """A cost table (method -> level name -> ms) with every number times ``factor``; anything else
    is left for the controller to refuse by name."""
    def scale(v):
        return v * factor if isinstance(v, (int, float)) and not isinstance(v, bool) else v

    return {m: ({k: scale(v) for k, v in t.items()} if isinstance(t, dict) else t) for m, t in costs.items()}


def _percentiles(values) -> dict | None:
    if not values:
        return None
    v = np.asarray(values, float)
    return {"median": float(np.median(v)), "p95": float(np.percentile(v, 95)), "ticks": len(v)}


class FrameInbox:
    """Frames received and not yet decoded, bounded in bytes: :meth:`put` waits while it holds
    ``max_bytes`` (the server keeps only a few frames ahead, so a full inbox means the server
    ignores FRAMES_DECODED); :meth:`take_all` waits for at least one and takes them all."""

    def __init__(self, max_bytes: int = 64 << 20):
        self.max_bytes = max_bytes
        self._frames: list = []
        self._bytes = 0
        self._changed = asyncio.Event()

    async def put(self, frame: Frame, arrival_us: int, size: int) -> None:
        while self._frames and self._bytes + size > self.max_bytes:
            self._changed.clear()
            await self._changed.wait()
        self._frames.append((frame, arrival_us))
        self._bytes += size
        self._changed.set()

    async def take_all(self) -> list:
        while not self._frames:
            self._changed.clear()
            await self._changed.wait()
        frames, self._frames, self._bytes = self._frames, [], 0
        self._changed.set()
        return frames


async def run_client(config: ClientConfig) -> ClientResult:
    return await Client(config).run()
