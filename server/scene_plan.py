"""What the server models for a scene and a client, and why: decisions from measurements.

Each :class:`Decision` holds the value, the reason in words and the numbers it was made from.
:class:`ScenePlan` gathers them; ``pibr scenes --plan NAME`` prints it, and every session sends
it in ``SessionConfig.options["plan"]`` (so the client's ``session.json`` records it), and
session_plan.py builds the session from it:

- **extra view**: on when it measurably cuts the display pixels no view covers. From
  deterministic viewpoints (a synthetic head trace placed at the scene's viewer origin, never
  a shared trace's tuning or evaluation window), the coverage test of :mod:`.coverage` counts
  the geometry pixels the primary view leaves uncovered, with and without the extra view; on
  when the extra view covers more than :data:`EXTRA_VIEW_MIN_GAIN` of them. The measurement is
  cached on disk by the scene's content hash (next to the LoD cache, scenes/lod_cache.py).
- **motion**: only when some object moves (named in the plan).
- **proxies**: an object whose encaging proxy is not tighter than its box by a margin
  (:data:`BOX_VOLUME_RATIO`), or whose LoD generation fell back to the box, is sent its box as
  its proxy level.
- **view size**: the primary view sized for the client's output (Reinert et al. 2016, Sec. 7).
- **depth codec**: from the bandwidth the client states (or the server's cap): the transport
  that leaves the colour the most bits at equal total bitrate.

Explicit settings (server options, the client's depth codec) always win; the plan says so.
"""
from __future__ import annotations

import hashlib
import json
import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np

from pibr.protocol.atlas import ALIGN, MAX_VIEW_PIXELS
from pibr.protocol.depth_codecs import DEPTH_CODECS
from pibr.protocol.errors import ConfigError
from pibr.protocol.pose import Pose

from .coverage import COVERAGE_TOLERANCE

log = logging.getLogger(__name__)

#: The extra view is on when it covers more than this share of the display's geometry pixels that
#: the primary alone leaves uncovered (absolute: 0.5 %, about 2 600 pixels of a 960x540 output in
#: every frame). It always costs a quarter more pixels to render, encode and send; a gain below this
#: is a few scattered pixels per frame, which the client's inpainting fills anyway. Measured gains
#: (CoverageSettings, 23 viewpoints): sphere 0.09 %, dynamic 0.27 %, courtyard 0.70 %, room 2.07 %.
EXTRA_VIEW_MIN_GAIN = 0.005
#: A proxy holding at least this share of its box's volume is not worth its triangles: it is then
#: within the coverage test's 3 % distance tolerance of the box along each axis on average
#: ((1 - 0.03)^3 = 0.91), closer than depth carving tells surfaces apart.
BOX_VOLUME_RATIO = (1.0 - COVERAGE_TOLERANCE) ** 3
#: Reinert et al. size the primary view 1.6 x the output's width for a 70-degree output (2048^2 for
#: 1280x720): a sample density at the view's centre 1.6 x tan(35 deg) = 1.12 x the output's.
PAPER_SIZE_FACTOR, PAPER_OUTPUT_FOV_DEG = 1.6, 70.0
VIEW_DENSITY_RATIO = PAPER_SIZE_FACTOR * math.tan(math.radians(PAPER_OUTPUT_FOV_DEG / 2))
#: The primary view's side is a multiple of this: the extra view (half of it) stays on the atlas grid.
VIEW_STEP = 2 * ALIGN
#: Measured shares of the depth stream (README, "Depth codec", room at 1024^2): 8-bit disparity
#: took 1.7 of 16 Mbit/s in the H.264 atlas (colour 14.3); the edge codec at its default
#: threshold 2083 kbit/s. The edge stream is scaled by the primary view's side (edges are curves:
#: their samples grow with the side, not the area). NOT FITTED on the tuning windows: both were
#: measured on the evaluation windows and have not been re-measured on tuning data; every plan's
#: JSON says so (DEPTH_RATES_FITTED_ON).
H264_DEPTH_SHARE = (16.0 - 14.3) / 16.0
EDGE_KBPS_AT_1024 = 2083.0
DEPTH_RATES_FITTED_ON = "not fitted: measured on the room's evaluation windows, not re-measured on tuning windows"
#: The lowest H.264 bitrate the server accepts (config.py).
MIN_VIDEO_KBPS = 16.0
#: The coverage probe's measurement format: bump when what it measures changes (old cache files are ignored).
COVERAGE_FORMAT = 1


@dataclass(frozen=True)
class Decision:
    """One decision: ``value`` (JSON-able), ``reason`` in words and the ``measured`` numbers."""

    value: object
    reason: str
    measured: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"value": self.value, "reason": self.reason, "measured": self.measured}


@dataclass(frozen=True)
class ScenePlan:
    """What the server will model for ``scene``: one :class:`Decision` per aspect (see the module docstring)."""

    scene: str
    extra_view: Decision
    motion: Decision
    proxies: Decision
    view_size: Decision
    depth_codec: Decision

    ASPECTS = ("extra_view", "motion", "proxies", "view_size", "depth_codec")

    def to_json(self) -> dict:
        return {"scene": self.scene, **{a: getattr(self, a).to_json() for a in self.ASPECTS}}


# ----------------------------------------------------------------------------- extra view

@dataclass(frozen=True)
class CoverageSettings:
    """Where and how the extra view's coverage is measured: a synthetic trace of every motion kind
    (walking, looking around, quick turns; pibr.common.traces.synthesis) placed at the viewer origin, the
    system's default latency, small views (coverage is a share of pixels, not a detail measure)."""

    trace_kind: str = "mixed"
    seed: int = 0
    duration_s: float = 12.0
    sample_every_s: float = 0.5
    round_trip_ms: float = 128.0
    server_fps: float = 10.0
    view_size: tuple = (256, 256)
    out_size: tuple = (160, 90)
    fov_deg: float = 90.0

    def to_json(self) -> dict:
        return {"trace": f"synth-{self.trace_kind}-seed{self.seed}", "duration_s": self.duration_s,
                "sample_every_s": self.sample_every_s, "round_trip_ms": self.round_trip_ms,
                "server_fps": self.server_fps, "view_size": list(self.view_size), "out_size": list(self.out_size),
                "fov_deg": self.fov_deg}


def scene_digest(scene) -> str:
    """sha256 of what a scene's views show: every object's mesh, placement and motion, the viewer
    origin and the clip spheres (not materials or lights: coverage is geometry)."""
    h = hashlib.sha256()
    h.update(json.dumps([scene.near, scene.far, list(map(float, scene.viewer_origin.as_array()))]).encode())
    for obj in scene.objects:
        h.update(obj.name.encode() + b"\0" + obj.mesh.digest().encode())
        h.update(np.ascontiguousarray(obj.transform, np.float64).tobytes())
        h.update(repr(obj.animation).encode())
    return h.hexdigest()


def coverage_samples(scene, settings: CoverageSettings):
    """[(display time, display pose, render time, render pose)]: the synthetic trace's viewpoints."""
    from pibr.common.link import SessionSchedule
    from pibr.common.replay import trace_samples
    from pibr.common.traces.synthesis import synthesize

    trace = synthesize(settings.trace_kind, settings.duration_s, seed=settings.seed)
    rate_hz = 30.0
    schedule = SessionSchedule.round_trip(rate_hz, settings.round_trip_ms, settings.server_fps)
    stride = max(1, int(round(settings.sample_every_s * rate_hz)))
    # from one frame interval on: the first frames would show the viewer origin's pose itself
    return [s for s in trace_samples(scene, trace, 0.0, settings.duration_s, schedule, stride) if s[2] > 0]


def measure_extra_view(ctx, scene, offset: Pose, projection: str = "vertex",
                       settings: CoverageSettings = CoverageSettings(), renderer=None) -> dict:
    """Mean shares of the display's geometry pixels no view covers, with the primary alone and with
    the extra view at ``offset`` (depth-peeled, peeled pixels marked: the server's defaults), over
    :func:`coverage_samples`. GL work: call on the thread that owns ``ctx``."""
    from .coverage import CoverageProbe

    t0 = time.perf_counter()
    samples = coverage_samples(scene, settings)
    probe = CoverageProbe(scene, settings.view_size, settings.out_size, settings.fov_deg, projection, ctx=ctx,
                          renderer=renderer)
    primary_only, with_extra, sky = [], [], []
    try:
        for t_disp, display, t_render, rendered in samples:
            points, sky_mask, dirs = probe.display_points(display, t_disp)
            sky.append(float(sky_mask.mean()))
            primary = probe.render_primary(rendered, t_render)
            base = [(rendered, primary, False)]
            primary_only.append(probe.missing(points, sky_mask, dirs, base)[1])
            extra = probe.render_extra(rendered, offset, t_render, peel=True)
            with_extra.append(probe.missing(points, sky_mask, dirs, base + [(rendered.compose(offset), extra, True)])[1])
    finally:
        probe.close()
    return {"uncovered_primary": float(np.mean(primary_only)) if samples else 0.0,
            "uncovered_with_extra": float(np.mean(with_extra)) if samples else 0.0,
            "sky_share": float(np.mean(sky)) if samples else 1.0, "samples": len(samples),
            "offset": [round(float(x), 6) for x in offset.as_array()], "projection": projection,
            "settings": settings.to_json(), "seconds": round(time.perf_counter() - t0, 3)}


def coverage_key(scene, offset: Pose, projection: str, settings: CoverageSettings) -> str:
    blob = json.dumps({"format": COVERAGE_FORMAT, "scene": scene_digest(scene),
                       "offset": [float(x) for x in offset.as_array()], "projection": projection,
                       "settings": settings.to_json(), "tolerance": COVERAGE_TOLERANCE}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()


def cached_extra_view(ctx, scene, offset: Pose, projection: str = "vertex",
                      settings: CoverageSettings = CoverageSettings(), renderer=None, directory=None) -> dict:
    """:func:`measure_extra_view` through an on-disk cache keyed by the scene's content hash
    (``directory``: default the LoD cache's, scenes/lod_cache.py). ``measured["cached"]`` says which."""
    from pathlib import Path

    from pibr.protocol import bounded_json
    from pibr.protocol.errors import JSONError
    from pibr.scenes.lod_cache import cache_dir, write_atomic

    key = coverage_key(scene, offset, projection, settings)
    path = (Path(directory).expanduser() if directory is not None else cache_dir()) / f"coverage-{key}.json"
    if path.is_file():
        try:
            stored = bounded_json.loads(path.read_bytes(), what=str(path))
            if isinstance(stored, dict) and stored.get("key") == key and isinstance(stored.get("measured"), dict):
                return stored["measured"] | {"cached": True}
            raise JSONError("not a coverage measurement for this key")
        except (OSError, JSONError) as exc:
            log.warning("coverage cache file %s is unusable (%s): measuring again", path, exc)
    measured = measure_extra_view(ctx, scene, offset, projection, settings, renderer)
    try:
        write_atomic(path, json.dumps({"key": key, "measured": measured}).encode())
    except OSError as exc:
        log.warning("cannot write coverage cache file %s: %s", path, exc)
    return measured | {"cached": False}


def decide_extra_view(mode: str, measured: dict | None, scene=None) -> Decision:
    """``mode`` on / off (the server's explicit choice) or auto (``measured`` from :func:`cached_extra_view`).

    auto without a measurement (sessions planned without GL, e.g. by benchmarks) falls back to the
    scene's own ``extra_view`` flag, and says so; the server always measures."""
    if mode in ("on", "off"):
        return Decision(mode == "on", f"server setting --extra-view {mode}", measured or {})
    if measured is None:
        if scene is None:
            raise ConfigError("extra view 'auto' needs the coverage measurement or the scene")
        return Decision(bool(scene.extra_view), f"not measured here: the scene's own setting "
                                                f"(extra_view = {str(bool(scene.extra_view)).lower()})", {})
    gain = measured["uncovered_primary"] - measured["uncovered_with_extra"]
    numbers = (f"primary alone leaves {100 * measured['uncovered_primary']:.2f} % of geometry pixels "
               f"uncovered, with the extra view {100 * measured['uncovered_with_extra']:.2f} %")
    on = gain > EXTRA_VIEW_MIN_GAIN
    verdict = (f"it covers {100 * gain:.2f} % more, over the {100 * EXTRA_VIEW_MIN_GAIN:g} % threshold" if on else
               f"it covers {100 * gain:.2f} % more, not over the {100 * EXTRA_VIEW_MIN_GAIN:g} % threshold")
    return Decision(on, f"{numbers}: {verdict}", measured | {"gain": gain, "threshold": EXTRA_VIEW_MIN_GAIN})


# ----------------------------------------------------------------------------- motion, proxies

def decide_motion(scene) -> Decision:
    moving = {o.name: o.animation.kind for o in scene.objects if o.is_dynamic}
    if not moving:
        return Decision(False, "nothing moves: frames carry no object poses and no motion flow",
                        {"moving_objects": {}})
    names = ", ".join(f"{n} ({k})" for n, k in moving.items())
    return Decision(True, f"{len(moving)} object(s) move: {names}; every frame carries their poses and motion flow",
                    {"moving_objects": moving})


def proxy_level(lod) -> tuple[str, str, dict]:
    """-> ("proxy" or "box", why, numbers) for one object's :class:`~pibr.scenes.lod.LodResult`."""
    numbers = {"triangles_original": lod.triangles_original, "triangles_proxy": lod.triangles_proxy,
               "lod_kind": lod.kind}
    if lod.kind == "empty":
        return "box", "no faces", numbers
    if lod.kind == "box":
        return "box", f"LoD fell back to the box: {lod.note}", numbers
    ratio = float(lod.params["volume_ratio_to_box"])
    numbers["volume_ratio_to_box"] = round(ratio, 4)
    if ratio >= BOX_VOLUME_RATIO:
        return "box", f"proxy holds {ratio:.2f} of the box's volume (>= {BOX_VOLUME_RATIO:.2f})", numbers
    return "proxy", f"proxy holds {ratio:.2f} of the box's volume", numbers


def decide_proxies(scene, lods: dict | None) -> Decision:
    """Per object proxy or box, from its LoD (``lods``: name -> LodResult; None: no proxies sent)."""
    if lods is None:
        return Decision(None, "the client asked for no proxies", {})
    objects, proxy, box = {}, [], []
    for obj in scene.objects:
        level, why, numbers = proxy_level(lods[obj.name])
        objects[obj.name] = {"level": level, "why": why, **numbers}
        (proxy if level == "proxy" else box).append(obj.name)
    tri_proxy = sum(objects[n]["triangles_proxy"] for n in proxy)
    reason = (f"{len(proxy)} object(s) get their encaging proxy ({tri_proxy} triangles), {len(box)} their box "
              f"(its proxy holds {BOX_VOLUME_RATIO:.2f} of the box's volume or more, or the LoD made none)")
    return Decision({"proxy": proxy, "box": box}, reason, {"objects": objects, "box_volume_ratio": BOX_VOLUME_RATIO})


# ----------------------------------------------------------------------------- view size, depth codec

def view_side_for(output_width: int, fov_deg: float) -> int:
    """Primary view side whose centre density (side / 2 pixels per radian in the wide-angle projection)
    is :data:`VIEW_DENSITY_RATIO` x the output's (width / (2 tan(fov / 2))), on the atlas grid."""
    density = output_width / (2.0 * math.tan(math.radians(fov_deg) / 2))
    side = 2.0 * VIEW_DENSITY_RATIO * density
    largest = VIEW_STEP * (math.isqrt(MAX_VIEW_PIXELS) // VIEW_STEP)
    return int(min(largest, max(VIEW_STEP, VIEW_STEP * round(side / VIEW_STEP))))


def decide_view_size(output, explicit: tuple | None) -> Decision:
    """``output``: the Hello's OutputConfig; ``explicit``: the server's --view-size, which wins."""
    density = output.width / (2.0 * math.tan(math.radians(output.fov_deg) / 2))
    measured = {"output": [output.width, output.height], "output_fov_deg": output.fov_deg,
                "output_px_per_rad": round(density, 2), "density_ratio": round(VIEW_DENSITY_RATIO, 4)}
    if explicit is not None:
        w, h = explicit
        return Decision([w, h], f"server setting --view-size {w}x{h}",
                        measured | {"view_px_per_rad": round(w / 2, 2)})
    side = view_side_for(output.width, output.fov_deg)
    return Decision([side, side], f"{VIEW_DENSITY_RATIO:.2f} x the output's {density:.0f} px/rad at the centre "
                                  f"(Reinert et al.: 1.6 x the width at 70 degrees), rounded to {VIEW_STEP} px",
                    measured | {"view_px_per_rad": side / 2})


def edge_kbps_estimate(primary_side: int, configured_kbps: float) -> float:
    """The edge stream's bitrate: its rate target when set, else the measured figure scaled by the side."""
    return configured_kbps if configured_kbps > 0 else EDGE_KBPS_AT_1024 * primary_side / 1024


def decide_depth_codec(asked: str, server: str, bandwidth_kbps: float | None, video_kbps: float,
                       primary_side: int, edge_kbps: float) -> Decision:
    """``asked``: the client's choice ("" for none); ``server``: h264, edge or auto; ``bandwidth_kbps``:
    the smaller of the client's and the server's caps (None: none stated); ``video_kbps``: the H.264
    bitrate; ``edge_kbps``: the edge codec's rate target (0: fixed threshold).

    Value: {"codec", "video_kbps"}: the H.264 bitrate fitted into the bandwidth. When the configured
    video fits, H.264 depth (no second stream, cheap to decode). When it does not, at a total of B
    depth in the atlas takes :data:`H264_DEPTH_SHARE` of the bits and the colour the rest, while the
    edge codec takes its own stream E beside a colour-only video of B - E: edge when that leaves the
    colour more bits (H.264 depth's share of B is more than the edge stream costs)."""
    e = edge_kbps_estimate(primary_side, edge_kbps)
    measured = {"h264_depth_share": round(H264_DEPTH_SHARE, 4), "edge_kbps": round(e, 1),
                "configured_video_kbps": video_kbps, "depth_rates_fitted_on": DEPTH_RATES_FITTED_ON}
    if bandwidth_kbps is not None:
        measured["bandwidth_kbps"] = bandwidth_kbps
    if asked or server != "auto":
        codec = asked or server
        video = video_kbps if bandwidth_kbps is None else min(video_kbps, _fit(bandwidth_kbps, codec, e))
        who = f"the client asked for {asked}" if asked else f"server setting --depth-codec {server}"
        return Decision({"codec": codec, "video_kbps": video}, who, measured)
    if bandwidth_kbps is None:
        return Decision({"codec": "h264", "video_kbps": video_kbps},
                        "no bandwidth stated: 8-bit depth in the H.264 atlas, no second stream", measured)
    if video_kbps <= bandwidth_kbps:
        # both fit: the atlas needs no second stream, and the client decodes it far faster (README's
        # depth codec table: 8 ms against the edge codec's 165 ms per frame)
        return Decision({"codec": "h264", "video_kbps": video_kbps},
                        f"the {video_kbps:g} kbit/s atlas with depth fits in {bandwidth_kbps:g} kbit/s", measured)
    colour_h264 = bandwidth_kbps * (1 - H264_DEPTH_SHARE)
    colour_edge = bandwidth_kbps - e
    measured |= {"colour_kbps_h264": round(colour_h264, 1), "colour_kbps_edge": round(colour_edge, 1)}
    if colour_edge > colour_h264:
        return Decision({"codec": "edge", "video_kbps": round(colour_edge, 1)},
                        f"the {video_kbps:g} kbit/s atlas does not fit in {bandwidth_kbps:g}: beside the edge stream "
                        f"({e:.0f}) the colour keeps {colour_edge:.0f} kbit/s, with depth in the atlas "
                        f"{colour_h264:.0f}", measured)
    return Decision({"codec": "h264", "video_kbps": max(MIN_VIDEO_KBPS, bandwidth_kbps)},
                    f"the {video_kbps:g} kbit/s atlas does not fit in {bandwidth_kbps:g}: with depth in the atlas "
                    f"the colour keeps {colour_h264:.0f} kbit/s, beside the edge stream ({e:.0f}) "
                    f"{max(colour_edge, 0):.0f}", measured)


def _fit(bandwidth_kbps: float, codec: str, edge_kbps: float) -> float:
    return max(MIN_VIDEO_KBPS, bandwidth_kbps - (0.0 if DEPTH_CODECS[codec].in_atlas else edge_kbps))


# ----------------------------------------------------------------------------- the whole plan

def make_plan(scene, *, extra_view_mode: str, coverage: dict | None, proxies: Decision, output,
              view_size: tuple | None, asked_codec: str, server_codec: str, bandwidth_kbps: float | None,
              video_kbps: float, edge_kbps: float) -> ScenePlan:
    """Every decision for ``scene`` and one client (``output``: its OutputConfig; ``proxies``: from
    :func:`decide_proxies`)."""
    size = decide_view_size(output, view_size)
    return ScenePlan(scene.name, decide_extra_view(extra_view_mode, coverage, scene), decide_motion(scene),
                     proxies, size,
                     decide_depth_codec(asked_codec, server_codec, bandwidth_kbps, video_kbps, size.value[0],
                                        edge_kbps))


def format_plan(plan: dict) -> str:
    """A plan's JSON (:meth:`ScenePlan.to_json`) as a readable table."""
    lines = [f"plan for scene {plan['scene']}", f"{'aspect':<12} {'value':<26} reason"]
    for aspect in ScenePlan.ASPECTS:
        d = plan[aspect]
        value = d["value"]
        if aspect == "proxies" and isinstance(value, dict):
            shown = f"{len(value['proxy'])} proxy, {len(value['box'])} box"
        elif aspect == "view_size":
            shown = f"{value[0]}x{value[1]}"
        elif aspect == "depth_codec":
            shown = f"{value['codec']} ({value['video_kbps']:g} kbit/s video)"
        elif isinstance(value, bool):
            shown = "on" if value else "off"
        elif value is None:
            shown = "none"
        else:
            shown = str(value)
        lines.append(f"{aspect:<12} {shown:<26} {d['reason']}")
    objects = plan["proxies"]["measured"].get("objects", {})
    lod = plan.get("lod") or {}
    if lod:
        lines.append(f"{'lod':<12} {str(lod['target_px']) + ' px':<26} {lod['reason']}")
    if objects:
        lines.append("")
        width = max(len(n) for n in objects)
        near = lod.get("objects", {})
        head = "original <  level <  " if near else ""
        lines.append(f"{'object':<{width}}  level  tris orig  tris proxy  vol/box  {head}why")
        for name, o in objects.items():
            ratio = o.get("volume_ratio_to_box")
            dist = ""
            if name in near:
                dist = f"{near[name]['original_within_m']:>8.2f}m {near[name]['level_within_m']:>7.2f}m  "
            lines.append(f"{name:<{width}}  {o['level']:<5}  {o['triangles_original']:>9}  {o['triangles_proxy']:>10}  "
                         f"{'-' if ratio is None else f'{ratio:.3f}':>7}  {dist}{o['why']}")
    return "\n".join(lines)
