"""How much of each displayed view the transmitted views cover (Reinert et al., Fig. 4).

For a displayed pose the ground-truth renderer gives, per output pixel, the surface point
the viewer sees (or sky). A pixel is *covered* when some transmitted view shows that same
point: its back-projection into the view lands on a texel (any of the four around it)
whose stored distance matches the point's distance within a relative tolerance — the same
test depth peeling uses. Sky is covered where a view shows sky in that direction; a peeled
view vouches for sky only when it marks what it peeled away apart from sky (protocol/depth.py;
the server's default).
Everything else is a hole an ideal, depth-exact warp of the transmitted views could not fill.

Variants (``VARIANTS``): the primary view alone; plus an extra view at zero offset with
peeling (a second depth layer); at the offset without peeling; at the offset with peeling.
``floor`` is the primary view rendered at the displayed pose itself (no latency): what the
test misses with nothing to disocclude (grazing surfaces, sub-texel leaves), the noise floor
the other numbers sit on.

Frames follow the system's virtual-clock schedule (protocol/session.py): at display time t
the client shows the newest server frame usable by then, rendered from the newest pose
that had reached the server.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from pibr.protocol.pose import Pose
from pibr.protocol.projection import FORWARD
from .results import write_result

VARIANTS = ("primary", "peel_no_offset", "offset_no_peel", "offset_peel")
VARIANT_LABELS = {"primary": "primary only", "peel_no_offset": "extra: peeling, no offset",
                  "offset_no_peel": "extra: offset, no peeling", "offset_peel": "extra: offset + peeling",
                  "floor": "primary, no latency (floor)"}
#: Relative distance tolerance of the coverage test (as depth peeling's, see renderer.py).
COVERAGE_TOLERANCE = 0.03


@dataclass(frozen=True)
class LatencyModel:
    """The virtual clock's schedule without a network in between (integer microseconds)."""

    rate_hz: float = 60.0
    server_fps: float = 10.0
    up_ms: float = 64.0
    down_ms: float = 64.0
    server_delay_ms: float = 20.0

    def frame_for(self, t_us: int) -> tuple[int, int]:
        """-> (render time, client time of the pose used) of the frame shown at display time t."""
        interval = int(round(1e6 / self.server_fps))
        tick = int(round(1e6 / self.rate_hz))
        up, down, delay = (int(round(x * 1000)) for x in (self.up_ms, self.down_ms, self.server_delay_ms))
        render = ((t_us - delay - down) // interval) * interval
        pose_t = ((render - up) // tick) * tick
        return render, pose_t


def project_to_view(points: np.ndarray, view_pose: Pose):
    """World points (n, 3) -> (t' (n, 2), distance (n,), in front (n,) bool) in a wide-angle view."""
    local = (points - view_pose.p) @ view_pose.rotation()
    tx, ty, r = FORWARD.numpy(px=local[:, 0], py=local[:, 1], pz=local[:, 2])
    return np.stack([tx, ty], axis=1), r, local[:, 2] <= 0.0


def matches_view(points, view_pose: Pose, distance: np.ndarray, tolerance: float) -> np.ndarray:
    """(n,) True where the view's distance map (h, w), row 0 on top, shows the point."""
    h, w = distance.shape
    t, r, front = project_to_view(points, view_pose)
    tx = (t[:, 0] + 1.0) * 0.5 * w - 0.5
    ty = (1.0 - t[:, 1]) * 0.5 * h - 0.5
    x0, y0 = np.floor(tx).astype(np.int64), np.floor(ty).astype(np.int64)
    hit = np.zeros(len(points), bool)
    for dx, dy in ((0, 0), (1, 0), (0, 1), (1, 1)):
        d = distance[np.clip(y0 + dy, 0, h - 1), np.clip(x0 + dx, 0, w - 1)]
        hit |= (d > 0) & (np.abs(d - r) < tolerance * r)
    return hit & front


def sky_in_view(directions: np.ndarray, view_pose: Pose, distance: np.ndarray) -> np.ndarray:
    """(n,) True where the view shows sky along world directions (n, 3)."""
    h, w = distance.shape
    local = directions @ view_pose.rotation()
    tx, ty, _ = FORWARD.numpy(px=local[:, 0], py=local[:, 1], pz=local[:, 2])
    x = np.clip(((tx + 1.0) * 0.5 * w).astype(np.int64), 0, w - 1)
    y = np.clip(((1.0 - ty) * 0.5 * h).astype(np.int64), 0, h - 1)
    return (local[:, 2] <= 0.0) & (distance[y, x] == 0)


def camera_rays(width: int, height: int, fov_deg: float) -> np.ndarray:
    """Unit directions (width * height, 3) of a perspective camera's pixel centres, row 0 on top,
    in camera space (looking along -Z); ``fov_deg`` is horizontal."""
    tan_x = math.tan(math.radians(fov_deg) / 2)
    tan_y = tan_x * height / width
    xs = ((np.arange(width) + 0.5) / width * 2 - 1) * tan_x
    ys = (1 - (np.arange(height) + 0.5) / height * 2) * tan_y
    gx, gy = np.meshgrid(xs, ys)
    d = np.stack([gx, gy, -np.ones_like(gx)], axis=-1).reshape(-1, 3)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def displayed_points(rays: np.ndarray, pose: Pose, distance: np.ndarray):
    """What a perspective view at ``pose`` shows: world points (n, 3), sky (n,), world directions
    (n, 3), from its camera rays (n, 3) and ground-truth radial distance (h, w), 0 = sky."""
    r = distance.reshape(-1).astype(np.float64)
    dirs = rays @ pose.rotation().T
    return pose.p + dirs * r[:, None], r == 0, dirs


def uncovered(points, sky, dirs, views, tolerance: float = COVERAGE_TOLERANCE,
              peeled_marked: bool = True) -> np.ndarray:
    """(n,) True where no transmitted view saw what the displayed pixel shows: the one
    geometric definition of a hole, the same for every method.

    points, dirs : (n, 3) world points and directions of the displayed pixels (ground truth);
    sky : (n,) the pixel shows sky; views : [(pose, distance map (h, w), peeled)]. A view
    vouches for sky where it stores sky (distance 0); a depth-peeled view only if it marks the
    pixels it peeled away apart (``peeled_marked``: a negative distance, protocol/depth.py
    PEELED), else its 0 may be a surface the primary shows."""
    covered = np.zeros(len(points), bool)
    geo = ~sky
    for pose, dist, peeled in views:
        todo = geo & ~covered
        covered[todo] = matches_view(points[todo], pose, dist, tolerance)
        if not peeled or peeled_marked:
            s = sky & ~covered
            covered[s] = sky_in_view(dirs[s], pose, dist)
    return ~covered


class CoverageProbe:
    """Renders ground truth and wide-angle views of one scene at small sizes, on this thread."""

    def __init__(self, scene, view_size=(512, 512), out_size=(320, 180), fov_deg=90.0, projection="vertex",
                 tolerance=COVERAGE_TOLERANCE, ctx=None, mark_peeled: bool = True):
        from pibr.protocol.gl import create_context
        from pibr.server.renderer import PEEL_TOLERANCE, RenderTarget, Renderer

        self._own = ctx is None
        self.ctx = create_context() if ctx is None else ctx
        self.scene, self.fov_deg, self.projection, self.tolerance = scene, fov_deg, projection, tolerance
        self.mark_peeled = mark_peeled   # peeled views mark what they peeled (as the server does by default)
        self.peel_tolerance = PEEL_TOLERANCE
        self.renderer = Renderer(self.ctx, scene, projection)
        self.primary = RenderTarget(self.ctx, *view_size)
        self.extra = RenderTarget(self.ctx, view_size[0] // 2, view_size[1] // 2)
        self.gt = RenderTarget(self.ctx, *out_size)
        self._dirs = camera_rays(*out_size, fov_deg)

    # Every GL entry point makes this probe's context current first (``with self.ctx``):
    # another context created on the same thread since would otherwise receive the calls.

    def display_points(self, pose: Pose, t: float):
        """Ground truth at the displayed pose: world points (n, 3), sky mask (n,), world directions (n, 3)."""
        with self.ctx:
            self.renderer.render_perspective(self.gt, pose, t, self.fov_deg)
            distance = self.gt.read_distance()
        return displayed_points(self._dirs, pose, distance)

    def render_primary(self, pose: Pose, t: float) -> np.ndarray:
        with self.ctx:
            self.renderer.render_wide(self.primary, pose, t, self.projection)
            return self.primary.read_distance().copy()

    def load_primary(self, distance: np.ndarray) -> None:
        """Put a primary distance map rendered earlier back where peeling reads it."""
        with self.ctx:
            self.primary.distance.write(np.ascontiguousarray(distance, np.float32).tobytes())

    def render_extra(self, primary_pose: Pose, offset: Pose, t: float, peel: bool) -> np.ndarray:
        """The extra view's distance map; the primary must be the last one rendered."""
        peel_arg = (self.primary, primary_pose, self.peel_tolerance) if peel else None
        with self.ctx:
            self.renderer.render_wide(self.extra, primary_pose.compose(offset), t, self.projection, peel=peel_arg,
                                      mark_peeled=self.mark_peeled)
            return self.extra.read_distance().copy()

    def missing(self, points, sky, dirs, views) -> tuple[float, float]:
        """(fraction of all pixels, fraction of pixels showing geometry) no view covers.

        views: [(pose, distance map, peeled)]."""
        holes = uncovered(points, sky, dirs, views, self.tolerance, self.mark_peeled)
        geo = ~sky
        n_geo = int(geo.sum())
        geo_missing = float((geo & holes).sum() / n_geo) if n_geo else 0.0
        return float(holes.mean()), geo_missing

    def close(self) -> None:
        with self.ctx:
            self.renderer.release()
            for t in (self.primary, self.extra, self.gt):
                t.release()
        if self._own:
            self.ctx.release()


def trace_poses(scene, trace_spec: str, start_s: float, duration_s: float | None, rate_hz: float,
                anchor: str = "start"):
    """-> (tick us, pose_at): the display ticks of a trace window and the viewer's pose at a
    client time (us from the window's start; earlier times clamp to its start), placed in the
    scene as the client places it (``protocol.trace.placement``)."""
    from pibr.protocol.trace import load_trace, placement

    trace = load_trace(trace_spec)
    _, end = trace.window(start_s, duration_s)
    n = max(1, int(math.floor((end - start_s) * rate_hz + 1e-9)))
    tick_us = int(round(1e6 / rate_hz))
    origin = placement(trace, start_s, scene.viewer_origin, anchor)

    def pose_at(t_us: int) -> Pose:
        return origin.compose(trace.pose_at(start_s + max(t_us, 0) / 1e6))

    return [i * tick_us for i in range(n)], pose_at


def display_samples(scene, trace_spec: str, start_s: float, duration_s: float | None, rate_hz: float,
                    latency: LatencyModel, stride: int = 1, anchor: str = "start"):
    """[(display time s, display pose, render time s, render pose)] along a trace window,
    placed in the scene as the client places it (``protocol.trace.placement``)."""
    ticks, pose_at = trace_poses(scene, trace_spec, start_s, duration_s, rate_hz, anchor)
    out = []
    for t_us in ticks[::stride]:
        render_us, pose_us = latency.frame_for(t_us)
        out.append((t_us / 1e6, pose_at(t_us), render_us / 1e6, pose_at(pose_us)))
    return out


class LinkSchedule:
    """The schedule of one session through a modelled network, frame by frame.

    Each direction is a :class:`~pibr.protocol.link.LinkModel`, the relay's own model: a delay,
    a jitter drawn from a seeded generator, and a bandwidth cap under which messages queue
    behind each other (a frame of B bits holds the link B / cap seconds). The client sends its
    pose every display tick; the server renders every ``1 / server_fps`` from the newest pose
    that has reached it and sends the frame ``server_delay_ms`` later, unless ``max_in_flight``
    frames it sent are not known to be received (the real clock's rule, server/session.py: the
    client reports what it decoded, the report travelling the uplink); the client shows the
    newest frame that has arrived. Without jitter, cap or skipped frames this is
    :class:`LatencyModel`'s arithmetic. Sizes of frames come from the stream as it is made, so
    the schedule advances with it: :meth:`due`, then :meth:`sent` for each frame made.
    """

    POSE_BYTES = 80   # a Pose message on the wire (framing header included)

    def __init__(self, rate_hz: float, server_fps: float, up, down, server_delay_ms: float = 20.0,
                 seed: int = 0, max_in_flight: int | None = 3):
        """up, down: ``protocol.link.LinkParams``; max_in_flight None: never skip a frame."""
        from pibr.protocol.link import LinkModel

        self.tick_us = int(round(1e6 / rate_hz))
        self.interval_us = int(round(1e6 / server_fps))
        self.delay_us = int(round(server_delay_ms * 1000))
        self.up, self.down = LinkModel(up, seed=2 * seed), LinkModel(down, seed=2 * seed + 1)
        self.max_in_flight = max_in_flight
        self._pose_arrivals: list[int] = []    # per display tick, in order
        self._sent: list[tuple[int, int]] = []  # (render us, arrival us) of every frame sent
        # Pre-roll: the first frames are rendered before the window starts (from its first pose),
        # so that the first display tick has a frame whatever the latency.
        lead = self.delay_us + self.down._delay_us + self.down._jitter_us + 2 * self.interval_us
        self._next_render = -(-lead // self.interval_us) * -self.interval_us
        self._pose_i = 0
        self.skipped = 0

    def _pose_arrival(self, i: int) -> int:
        while len(self._pose_arrivals) <= i:
            k = len(self._pose_arrivals)
            self._pose_arrivals.append(self.up.arrival_us(k * self.tick_us, self.POSE_BYTES))
        return self._pose_arrivals[i]

    def _pose_tick(self, render_us: int) -> int:
        """Client time of the newest pose that reached the server by ``render_us`` (0 if none);
        render times only grow, and so do arrivals (the link is FIFO)."""
        while self._pose_arrival(self._pose_i + 1) <= render_us:
            self._pose_i += 1
        return self._pose_i * self.tick_us

    def next_due(self, t_us: int):
        """The next server frame to render whose send time is at or before display time ``t_us``:
        (render us, client us of its pose), or None; frames skipped on the way are counted in
        ``skipped``. Report each with :meth:`sent` before asking for the next."""
        while self._next_render + self.delay_us <= t_us:
            r = self._next_render
            self._next_render += self.interval_us
            if self.max_in_flight is not None:
                known = sum(1 for _, a in self._sent if a + self.up.min_delay_us <= r)
                if len(self._sent) - known >= self.max_in_flight:
                    self.skipped += 1
                    continue
            return r, self._pose_tick(r)
        return None

    def sent(self, render_us: int, nbytes: int) -> int:
        """Record the frame rendered at ``render_us`` of ``nbytes`` on the wire -> its arrival us."""
        arrival = self.down.arrival_us(render_us + self.delay_us, nbytes)
        self._sent.append((render_us, arrival))
        return arrival


def measure_coverage(probe: CoverageProbe, samples, offset: Pose, variants=VARIANTS + ("floor",)) -> dict:
    """Per variant, the missing fraction of every sample -> {variant: [fraction, ...]}, and
    under ``variant + ":geometry"`` the same over pixels that show geometry (no sky)."""
    zero = Pose.identity()
    out = {v: [] for v in variants}
    out.update({v + ":geometry": [] for v in variants})
    out["sky_share"] = []
    for t_disp, display, t_render, rendered in samples:
        points, sky, dirs = probe.display_points(display, t_disp)
        out["sky_share"].append(float(sky.mean()))
        if "floor" in variants:
            here = probe.render_primary(display, t_disp)
            everything, geometry = probe.missing(points, sky, dirs, [(display, here, False)])
            out["floor"].append(everything)
            out["floor:geometry"].append(geometry)
        primary = probe.render_primary(rendered, t_render)
        base = [(rendered, primary, False)]
        for v in variants:
            if v == "floor":
                continue
            if v == "primary":
                views = base
            else:
                off = zero if v == "peel_no_offset" else offset
                peel = v != "offset_no_peel"
                extra = probe.render_extra(rendered, off, t_render, peel)
                views = base + [(rendered.compose(off), extra, peel)]
            everything, geometry = probe.missing(points, sky, dirs, views)
            out[v].append(everything)
            out[v + ":geometry"].append(geometry)
    return out


def run_coverage_bench(scene_spec="room", windows=None, latency_ms=128.0, rate_hz=30.0, view_size=(1024, 1024),
                       out_size=(320, 180), offset=None, stride=2, out_dir="out/bench", progress=True) -> dict:
    """``pibr bench coverage``: JSON and plot of the four variants' missing-pixel fractions,
    per window (default: the evaluation windows of bench/windows.py)."""
    from pibr.scenes.registry import load_scene
    from pibr.server.config import PAPER_EXTRA_OFFSET, extra_offset_pose

    from .windows import EVALUATION_WINDOWS, windows_json

    windows = tuple(windows or EVALUATION_WINDOWS)
    scene = load_scene(scene_spec)
    if offset is None:
        offset_pose = scene.extra_view_offset or extra_offset_pose(*PAPER_EXTRA_OFFSET)
    else:
        offset_pose = extra_offset_pose(*offset)
    latency = LatencyModel(rate_hz=rate_hz, up_ms=latency_ms / 2, down_ms=latency_ms / 2)
    all_samples = {w.label: display_samples(scene, w.trace, w.start_s, w.duration_s, rate_hz, latency)[::stride]
                   for w in windows}
    probe = CoverageProbe(scene, view_size, out_size)
    per_window = {}
    bar = None
    try:
        if progress:
            import sys

            from tqdm import tqdm

            bar = tqdm(total=sum(len(s) for s in all_samples.values()), unit="frame", desc="coverage",
                       file=sys.stderr, leave=False,
                       disable=None)  # None: no bar when stderr is not a terminal
        for label, samples in all_samples.items():
            series = {}
            for s in samples:
                for k, vals in measure_coverage(probe, [s], offset_pose).items():
                    series.setdefault(k, []).extend(vals)
                if bar is not None:
                    bar.update(1)
            sky_share = series.pop("sky_share")
            per_window[label] = {"times": [s[0] for s in samples], "missing": series,
                                 "means": {k: float(np.mean(v)) for k, v in series.items()},
                                 "nearly_all_sky_frames": int(sum(x > 0.95 for x in sky_share))}
    finally:
        if bar is not None:
            bar.close()
        probe.close()
    labels = list(per_window)
    overall = {k: float(np.mean(np.concatenate([per_window[w]["missing"][k] for w in labels])))
               for k in per_window[labels[0]]["missing"]}
    result = {"scene": scene.name, "windows": windows_json(windows, "reporting"), "latency_ms": latency_ms,
              "rate_hz": rate_hz, "stride": stride, "view_size": list(view_size), "output_size": list(out_size),
              "offset": list(offset_pose.as_array()), "tolerance": COVERAGE_TOLERANCE, "means": overall,
              "per_window": per_window}
    write_result(out_dir, "coverage.json", result)
    from .plots import plot_coverage

    plot_coverage(result, os.path.join(out_dir, "coverage.png"))
    return result


def print_coverage_table(result: dict) -> None:
    print(f"pibr bench coverage: scene {result['scene']}, {result['latency_ms']:g} ms round trip, "
          f"missing-pixel fraction % (lower is better)")
    w = result["windows"]
    if not w["disjoint_from_tuning"]:
        print("note: some windows overlap the tuning windows (bench/windows.py)")
    variants = VARIANTS + ("floor",)
    short = {"primary": "primary", "peel_no_offset": "peel, no off", "offset_no_peel": "offset, no peel",
             "offset_peel": "offset+peel", "floor": "floor"}
    head = f"{'window':<26}" + "".join(f"{short[v]:>16}" for v in variants)
    print(head)
    print("-" * len(head))
    sky = sum(d["nearly_all_sky_frames"] for d in result["per_window"].values())
    for label, d in result["per_window"].items():
        print(f"{label:<26}" + "".join(f"{100 * d['means'][v]:>16.2f}" for v in variants))
    print(f"{'all':<26}" + "".join(f"{100 * result['means'][v]:>16.2f}" for v in variants))
    print(f"{'all, geometry only':<26}" + "".join(f"{100 * result['means'][v + ':geometry']:>16.2f}" for v in variants))
    print("'geometry only' leaves out pixels showing sky.")
    if sky:
        print(f"warning: {sky} displayed frames are more than 95 % sky; there is little to cover on them")
