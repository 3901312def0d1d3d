"""The session's fixed parameters, sent by the server in ``Welcome.config``.

Everything the client needs to decode frames and re-render them, and nothing about the
scene's geometry (the client learns geometry only from proxies on the wire). Validated on
parse like every other wire input.

Virtual time (DESIGN.md, Time and latency). Both ends share one timeline in integer
microseconds; 0 is the client's first displayed tick. Server frame k is rendered at
``t_k = k * frame_interval_us`` with the newest pose whose *arrival* (send time + uplink,
stamped by the relay) is <= t_k, once the server knows no earlier-arriving pose can come
(a client message with a later virtual time has arrived). The frame is sent stamped
``t_k + server_delay_us`` (the model of render + encode time); the relay adds the downlink
(and bandwidth, jitter). The client may use a frame at every output tick at or after that
stamp. Each end follows its messages with a ``Clock`` promise so the other never waits for
a message that will not come.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from . import bounded_json
from .atlas import (ALIGN, COLOUR_SCALES, MAX_VIEW_PIXELS, MAX_VIEW_SIDE, AtlasLayout, build_layout, check_view_size,
                    colour_size)
from .depth_codecs import DEPTH_CODECS
from .errors import JSONError, MalformedMessage
from .pose import Pose
from .proxy import BundleInfo

#: Clip spheres a session may announce, metres (scene descriptions obey the same ranges).
NEAR_RANGE = (1e-9, 1e12)
FAR_RANGE = (1e-9, 1e15)
#: Most objects a scene may have (as the proxy bundle's limit).
MAX_SCENE_OBJECTS = 100_000


def _num(o, key, lo, hi, kind=float, path="Welcome.config"):
    if key not in o:
        raise MalformedMessage(f"{path}: missing field {key!r}")
    v = o[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or (kind is int and not isinstance(v, int)):
        raise MalformedMessage(f"{path}: field {key!r} must be a number, got {v!r:.60}")
    if not (lo <= v <= hi) or (isinstance(v, float) and not math.isfinite(v)):  # ints compare exactly, any size
        huge = isinstance(v, int) and v.bit_length() > 14_000   # repr() refuses past 4300 digits
        shown = f"<{v.bit_length()}-bit integer>" if huge else f"{v!r:.40}"
        raise MalformedMessage(f"{path}: field {key!r} = {shown} is outside [{lo}, {hi}]")
    return kind(v)


@dataclass(frozen=True)
class ViewConfig:
    width: int
    height: int

    def to_json(self):
        return {"width": self.width, "height": self.height}

    @classmethod
    def from_json(cls, o, path):
        if not isinstance(o, dict):
            raise MalformedMessage(f"{path}: must be an object")
        view = cls(_num(o, "width", 16, MAX_VIEW_SIDE, int, path), _num(o, "height", 16, MAX_VIEW_SIDE, int, path))
        if view.width % ALIGN or view.height % ALIGN or view.width * view.height > MAX_VIEW_PIXELS:
            raise MalformedMessage(f"{path}: view size {view.width}x{view.height} must be multiples of {ALIGN} of at "
                                   f"most {MAX_VIEW_PIXELS} pixels")
        return view


@dataclass(frozen=True)
class SessionConfig:
    """What ``Welcome.config`` holds (see the module docstring for the time model).

    scene            : scene info (name, near, far, viewer_origin, bounds, dynamic, ...)
    clock            : "virtual" or "real"
    server_fps       : server frame rate
    server_delay_us  : virtual time from a frame's render to its send (render + encode model)
    primary, extra   : view sizes (extra None when the session has no extra view)
    extra_offset     : the extra view's pose relative to the primary (pose ∘ offset)
    atlas            : where the views sit in the H.264 image
    video_bitrate_kbps, keyint : H.264 settings
    depth_codec      : a name of protocol/depth_codecs.py: "h264" (8-bit disparity in the atlas) or "edge"
    depth_bits, depth_min_code : quantization of the depth transport
    motion           : the scene has moving objects: every frame carries their transforms
                       (``PayloadKind.OBJECT_POSES``) and their motion flow in the primary view
                       (``MOTION_FLOW``, either depth codec); False: frames carry no motion of any kind
    proxies          : the proxy bundle's announcement (proxy.BundleInfo as JSON) or None when none are sent
    colour_scale     : the views' colour is sent at this scale of their size (atlas.COLOUR_SCALES): at 0.5
                       frame ``k`` sends the luma of one pixel of each 2x2 block and the chroma of one 2x2
                       block of each 4x4, those ``atlas.colour_jitter(k)`` names (atlas.COLOUR_JITTER),
                       and the client rebuilds the rest (client/colour_rebuild.py); depth stays whole
    """

    scene: dict
    clock: str
    server_fps: float
    server_delay_us: int
    primary: ViewConfig
    extra: ViewConfig | None
    extra_offset: Pose | None
    atlas: AtlasLayout
    video_bitrate_kbps: float
    keyint: int
    depth_codec: str = "h264"
    depth_bits: int = 8
    depth_min_code: int = 16
    motion: bool = False
    proxies: dict | None = None
    options: dict = field(default_factory=dict)
    colour_scale: float = 1.0

    @property
    def frame_interval_us(self) -> int:
        return int(round(1e6 / self.server_fps))

    @property
    def near(self) -> float:
        return float(self.scene["near"])

    @property
    def far(self) -> float:
        return float(self.scene["far"])

    @property
    def object_count(self) -> int:
        """How many objects the scene has (the range of object indices in frames' object poses)."""
        n = self.scene.get("objects", 0)
        if isinstance(n, bool) or not isinstance(n, int) or not 0 <= n <= MAX_SCENE_OBJECTS:
            raise MalformedMessage(f"Welcome.config.scene: field 'objects' must be a whole number in "
                                   f"[0, {MAX_SCENE_OBJECTS}], got {n!r:.40}")
        return n

    @property
    def viewer_origin(self) -> Pose:
        return Pose.from_array(self.scene["viewer_origin"])

    def to_json(self) -> dict:
        return {
            "scene": self.scene, "clock": self.clock, "server_fps": self.server_fps,
            "server_delay_us": self.server_delay_us, "primary": self.primary.to_json(),
            "extra": None if self.extra is None else self.extra.to_json(),
            "extra_offset": None if self.extra_offset is None else list(self.extra_offset.as_array()),
            "atlas": self.atlas.to_json(), "video_bitrate_kbps": self.video_bitrate_kbps,
            "keyint": self.keyint, "depth_codec": self.depth_codec, "depth_bits": self.depth_bits,
            "depth_min_code": self.depth_min_code, "motion": self.motion, "proxies": self.proxies,
            "options": self.options, "colour_scale": self.colour_scale,
        }

    @classmethod
    def from_json(cls, o: dict) -> "SessionConfig":
        p = "Welcome.config"
        if not isinstance(o, dict):
            raise MalformedMessage(f"{p}: must be an object")
        try:   # what is not validated field by field (scene info, options) is still finite and shallow
            bounded_json.check_tree(o, what=p)
        except JSONError as exc:
            raise MalformedMessage(str(exc)) from None
        scene = o.get("scene")
        if not isinstance(scene, dict):
            raise MalformedMessage(f"{p}: field 'scene' must be an object")
        near = _num(scene, "near", *NEAR_RANGE, path=p + ".scene")
        far = _num(scene, "far", *FAR_RANGE, path=p + ".scene")
        if not near < far:
            raise MalformedMessage(f"{p}.scene: need near < far, got {near} and {far}")
        if "objects" in scene:
            _num(scene, "objects", 0, MAX_SCENE_OBJECTS, int, path=p + ".scene")
        vo = scene.get("viewer_origin")
        try:
            Pose.from_array(vo)
        except Exception as exc:  # InvalidPose, shape or type problems all mean the same here
            raise MalformedMessage(f"{p}.scene: bad viewer_origin ({exc})") from None
        clock = o.get("clock")
        if clock not in ("virtual", "real"):
            raise MalformedMessage(f"{p}: field 'clock' must be 'virtual' or 'real', got {clock!r:.40}")
        extra = None if o.get("extra") is None else ViewConfig.from_json(o["extra"], p + ".extra")
        offset = None
        if o.get("extra_offset") is not None:
            try:
                offset = Pose.from_array(o["extra_offset"])
            except Exception as exc:
                raise MalformedMessage(f"{p}: bad extra_offset ({exc})") from None
        codec = o.get("depth_codec", "h264")
        if not isinstance(codec, str) or codec not in DEPTH_CODECS:
            raise MalformedMessage(f"{p}: depth_codec must be one of {', '.join(DEPTH_CODECS)}, got {codec!r:.40}")
        proxies = o.get("proxies")
        if proxies is not None:
            BundleInfo.from_json(proxies, p + ".proxies")   # the bounds the client assembles and inflates within
        options = o.get("options", {})
        if not isinstance(options, dict):
            raise MalformedMessage(f"{p}: field 'options' must be an object")
        primary = ViewConfig.from_json(o.get("primary"), p + ".primary")
        try:
            check_view_size(primary.width, primary.height, "primary view")
        except ValueError as exc:
            raise MalformedMessage(f"{p}.primary: {exc}") from None
        if (extra is None) != (offset is None):
            raise MalformedMessage(f"{p}: an extra view needs an extra_offset and an extra_offset an extra view")
        colour_scale = o.get("colour_scale", 1.0)
        if isinstance(colour_scale, bool) or colour_scale not in COLOUR_SCALES:
            raise MalformedMessage(f"{p}: colour_scale must be one of {', '.join(f'{s:g}' for s in COLOUR_SCALES)}, "
                                   f"got {colour_scale!r:.40}")
        colour_scale = float(colour_scale)
        atlas = AtlasLayout.from_json(o.get("atlas"))
        _check_atlas_views(atlas, primary, extra, codec, colour_scale)
        bits = _num(o, "depth_bits", 1, 16, int) if "depth_bits" in o else 8
        min_code = _num(o, "depth_min_code", 1, 65534, int) if "depth_min_code" in o else 16
        _check_depth_transport(near, far, bits, min_code, codec)
        return cls(
            scene=scene, clock=clock,
            server_fps=_num(o, "server_fps", 0.1, 1000.0),
            server_delay_us=_num(o, "server_delay_us", 0, 10_000_000, int),
            primary=primary,
            extra=extra, extra_offset=offset,
            atlas=atlas,
            video_bitrate_kbps=_num(o, "video_bitrate_kbps", 1, 1e7),
            keyint=_num(o, "keyint", 1, 100000, int),
            depth_codec=codec,
            depth_bits=bits,
            depth_min_code=min_code,
            motion=bool(o.get("motion", False)), proxies=proxies, options=options, colour_scale=colour_scale,
        )


def _check_depth_transport(near: float, far: float, bits: int, min_code: int, codec: str) -> None:
    """The client builds its quantizer (and, for the edge codec, its decoder) from these."""
    from .depth import DepthQuantizer

    try:
        DepthQuantizer(near, far, bits, min_code)
    except ValueError as exc:
        raise MalformedMessage(f"Welcome.config: depth quantization: {exc}") from None
    spec = DEPTH_CODECS[codec]
    lo, hi = spec.bits_range
    if not lo <= bits <= hi:
        raise MalformedMessage(f"Welcome.config: {spec.noun} carries {lo}..{hi} bits, depth_bits is {bits}")


def _check_atlas_views(atlas: AtlasLayout, primary: ViewConfig, extra: ViewConfig | None, codec: str,
                       colour_scale: float = 1.0) -> None:
    """The atlas holds exactly the rectangles the views and the depth transport need, each
    of its view's size, colour at ``colour_scale`` of it (as :func:`~pibr.protocol.atlas.build_layout`
    places them)."""
    views = {"primary": primary, "extra": extra}
    for name in ("primary.color", "primary.depth", "extra.color", "extra.depth"):
        view = views[name.split(".")[0]]
        wanted = view is not None and (name.endswith("color") or DEPTH_CODECS[codec].in_atlas)
        r = atlas.rect(name)
        if wanted and r is None:
            raise MalformedMessage(f"Welcome.config.atlas: rectangle {name} is missing")
        if not wanted and r is not None:
            raise MalformedMessage(f"Welcome.config.atlas: rectangle {name} has no view or depth to hold")
        if r is None:
            continue
        size = (view.width, view.height)
        if name.endswith("color"):
            try:
                size = colour_size(size, colour_scale)
            except ValueError as exc:
                raise MalformedMessage(f"Welcome.config: {exc}") from None
        if (r[2], r[3]) != size:
            what = f"its view's colour at scale {colour_scale:g}" if name.endswith("color") else "its view's depth"
            raise MalformedMessage(f"Welcome.config.atlas: rectangle {name} is {r[2]}x{r[3]}, not {size[0]}x{size[1]} "
                                   f"({what})")


def check_atlas_layout(session: SessionConfig) -> None:
    """Before anything is allocated at the atlas's size: it must be the protocol's layout of the
    announced views (:func:`~pibr.protocol.atlas.build_layout`), so a Welcome cannot make it bigger
    than they need."""
    extra = None if session.extra is None else (session.extra.width, session.extra.height)
    try:
        expected = build_layout((session.primary.width, session.primary.height), extra,
                                depth_in_atlas=DEPTH_CODECS[session.depth_codec].in_atlas,
                                colour_scale=session.colour_scale)
    except ValueError as exc:
        raise MalformedMessage(f"Welcome.config: the views have no atlas layout ({exc})") from None
    if session.atlas != expected:
        raise MalformedMessage(f"Welcome.config.atlas: {session.atlas.width}x{session.atlas.height} with "
                               f"{session.atlas.rects} is not the layout of its views ({expected.width}x"
                               f"{expected.height} with {expected.rects})")
