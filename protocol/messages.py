"""Protocol messages: dataclasses with ``serialize()`` (payload bytes) and ``parse(payload)``.

Handshake and rare messages (``Hello``, ``Welcome``, ``Stats``, ``Bye``) carry UTF-8 JSON
objects whose fields are validated here, so both ends see the same typed values. Hot-path
messages (``Pose``, ``Frame``, ``Clock``, ``ProxyChunk``) are fixed binary layouts,
little-endian. Every parse error is a :class:`MalformedMessage` naming the message and field.

A session: client ``Hello`` -> server ``Welcome`` (or ``Error``) -> server ``ProxyChunk``s
(when asked for) -> client ``Pose``/``Clock`` and server ``Frame``/``Clock`` -> either side
``Bye``. ``Stats`` may flow either way at any time. Each end's order is checked by
:mod:`.sides`.
"""
from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass, field
from typing import ClassVar

from . import bounded_json
from . import frustum as frustum_tangents
from .errors import ConfigError, InvalidPose, JSONError, MalformedMessage
from .pose import Pose
from .stereo import EYES, MAX_IPD_MM, STEREO_REFERENCES, check_ipd_mm

PROTOCOL_VERSION = 1
CLOCKS = ("virtual", "real")
MAX_TEXT = 4096
#: Largest JSON body (Hello, Welcome, Stats, Bye); a real Welcome is a few kilobytes.
MAX_JSON_BODY = 1 << 20
#: Largest relative distance range a client may ask quadtree leaves to span (Hello.quadtree_threshold).
MAX_QUADTREE_THRESHOLD = 10.0
#: Longest access token a Hello may carry (see access.py).
MAX_TOKEN = 256
#: Largest bandwidth a Hello may state, kbit/s (10 Gbit/s).
MAX_BANDWIDTH_KBPS = 1e7


class Message:
    TYPE: ClassVar[int]
    NAME: ClassVar[str]

    def serialize(self) -> bytes:  # pragma: no cover - abstract
        raise NotImplementedError

    @classmethod
    def parse(cls, payload: bytes):  # pragma: no cover - abstract
        raise NotImplementedError


# ---------------------------------------------------------------- JSON helpers

def _load_json(name: str, payload: bytes) -> dict:
    """The JSON object of a message body, read by :mod:`.bounded_json` (depth, number and size limits)."""
    try:
        obj = bounded_json.loads(payload, what=name, max_bytes=MAX_JSON_BODY)
    except JSONError as exc:
        raise MalformedMessage(str(exc)) from None
    if not isinstance(obj, dict):
        raise MalformedMessage(f"{name}: payload must be a JSON object, got {type(obj).__name__}")
    return obj


def _dump_json(obj: dict) -> bytes:
    return json.dumps(obj, separators=(",", ":"), sort_keys=True, allow_nan=False).encode("utf-8")


_MISSING = object()


def _get(name: str, obj: dict, key: str, kind, default=_MISSING, lo=None, hi=None, choices=None):
    """Typed field of a JSON object, with a clear error naming message, field and problem."""
    if key not in obj:
        if default is _MISSING:
            raise MalformedMessage(f"{name}: missing field {key!r}")
        return default
    v = obj[key]
    if kind is float:
        ok = isinstance(v, (int, float)) and not isinstance(v, bool)
        if ok:
            try:
                v = float(v)   # an integer past 1.8e308 raises OverflowError
            except OverflowError:
                raise MalformedMessage(f"{name}: field {key!r} is an integer too large for a float") from None
            ok = math.isfinite(v)
    elif kind is int:
        ok = isinstance(v, int) and not isinstance(v, bool)
    elif kind is dict:
        ok = isinstance(v, dict)
    elif kind is list:
        ok = isinstance(v, list)
    else:
        ok = isinstance(v, kind)
    if not ok:
        raise MalformedMessage(f"{name}: field {key!r} must be {getattr(kind, '__name__', kind)}, got {v!r:.80}")
    if kind is str and len(v) > MAX_TEXT:
        raise MalformedMessage(f"{name}: field {key!r} is longer than {MAX_TEXT} characters")
    if lo is not None and v < lo or hi is not None and v > hi:
        raise MalformedMessage(f"{name}: field {key!r} = {v} is outside [{lo}, {hi}]")
    if choices is not None and v not in choices:
        raise MalformedMessage(f"{name}: field {key!r} = {v!r} is not one of {', '.join(map(str, choices))}")
    return v


# ---------------------------------------------------------------- handshake

@dataclass(frozen=True)
class OutputConfig:
    """The client's display: ``width`` x ``height`` pixels, horizontal field of view, output rate.

    ``frustum``: None for a camera through the image's centre (``fov_deg`` and square pixels),
    else the (left, right, down, up) tangents of an eye's asymmetric frustum (protocol/frustum.py),
    which then sets the view alone; left out of the JSON when None."""

    width: int = 960
    height: int = 540
    fov_deg: float = 90.0
    rate_hz: float = 60.0
    frustum: tuple | None = None

    def tangents(self) -> tuple[float, float, float, float]:
        """(left, right, down, up) tangents of the camera's frustum."""
        return frustum_tangents.symmetric(self.fov_deg, self.width, self.height) if self.frustum is None \
            else self.frustum

    def to_json(self) -> dict:
        out = {"width": self.width, "height": self.height, "fov_deg": self.fov_deg, "rate_hz": self.rate_hz}
        if self.frustum is not None:
            out["frustum"] = list(self.frustum)
        return out

    @classmethod
    def from_json(cls, name: str, o: dict) -> "OutputConfig":
        frustum = _get(name, o, "frustum", list, default=None)
        if frustum is not None:
            if len(frustum) != 4 or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in frustum):
                raise MalformedMessage(f"{name}: field 'frustum' must be four numbers, got {frustum!r:.80}")
            try:
                frustum = frustum_tangents.check_tangents(frustum)
            except (ConfigError, OverflowError) as e:
                raise MalformedMessage(f"{name}: field 'frustum': {e}") from None
        return cls(
            width=_get(name, o, "width", int, lo=16, hi=8192),
            height=_get(name, o, "height", int, lo=16, hi=8192),
            fov_deg=_get(name, o, "fov_deg", float, lo=1.0, hi=170.0),
            rate_hz=_get(name, o, "rate_hz", float, lo=1.0, hi=1000.0),
            frustum=frustum,
        )


@dataclass(frozen=True)
class Hello(Message):
    """Client -> server, first message. ``scene`` empty: the server's default.

    ``quadtree_threshold`` > 0 asks for a depth quadtree of every view in every ``Frame``
    (``PayloadKind.QUADTREE``, see :mod:`pibr.protocol.quadtree`) whose leaves span at most
    this relative distance range; 0 (the default, and then the field is left out of the
    JSON) asks for none. At most ``MAX_QUADTREE_THRESHOLD``.

    ``token`` is the shared secret of a server that requires one (see access.py); left out
    of the JSON when empty, at most ``MAX_TOKEN`` characters, and kept out of ``repr``.

    ``bandwidth_kbps`` > 0 is the bandwidth the client can receive (kbit/s); the server fits its
    streams into it and picks the depth codec for it (server/scene_plan.py). 0 (the default, left
    out of the JSON, so older peers read the same bytes): not stated. At most ``MAX_BANDWIDTH_KBPS``.

    ``stereo`` names where a two-eye client wants its frames rendered from (protocol/stereo.py:
    cyclops, alternate, per-eye) and ``ipd_mm`` its interpupillary distance; "" (the default, and
    both are then left out of the JSON): one view at the head's centre.
    """

    TYPE: ClassVar[int] = 1
    NAME: ClassVar[str] = "Hello"
    client: str = "pibr-client"
    scene: str = ""
    clock: str = "virtual"
    output: OutputConfig = field(default_factory=OutputConfig)
    want_proxies: bool = False
    depth_codec: str = ""   # "" = the server's choice
    protocol: int = PROTOCOL_VERSION
    quadtree_threshold: float = 0.0   # 0 = no quadtree payload
    token: str = field(default="", repr=False)
    bandwidth_kbps: float = 0.0   # 0 = not stated
    stereo: str = ""              # "" = mono
    ipd_mm: float = 0.0           # with stereo: the eyes' distance

    def __post_init__(self):
        if self.stereo:
            if self.stereo not in STEREO_REFERENCES:
                raise MalformedMessage(f"Hello: stereo must be one of {', '.join(STEREO_REFERENCES)}, "
                                       f"got {self.stereo!r}")
            try:
                check_ipd_mm(self.ipd_mm)
            except ConfigError as exc:
                raise MalformedMessage(f"Hello: {exc}") from None
        elif self.ipd_mm:
            raise MalformedMessage("Hello: ipd_mm without stereo")

    def serialize(self) -> bytes:
        obj = {"protocol": self.protocol, "client": self.client, "scene": self.scene,
               "clock": self.clock, "output": self.output.to_json(),
               "want_proxies": self.want_proxies, "depth_codec": self.depth_codec}
        if self.quadtree_threshold:
            obj["quadtree_threshold"] = float(self.quadtree_threshold)
        if self.token:
            obj["token"] = self.token
        if self.bandwidth_kbps:
            obj["bandwidth_kbps"] = float(self.bandwidth_kbps)
        if self.stereo:
            obj["stereo"], obj["ipd_mm"] = self.stereo, float(self.ipd_mm)
        return _dump_json(obj)

    @classmethod
    def parse(cls, payload: bytes) -> "Hello":
        o = _load_json(cls.NAME, payload)
        return cls(
            protocol=_get(cls.NAME, o, "protocol", int, lo=0, hi=65535),
            client=_get(cls.NAME, o, "client", str, ""),
            scene=_get(cls.NAME, o, "scene", str, ""),
            clock=_get(cls.NAME, o, "clock", str, "virtual", choices=CLOCKS),
            output=OutputConfig.from_json(cls.NAME + ".output", _get(cls.NAME, o, "output", dict, {})
                                          or OutputConfig().to_json()),
            want_proxies=_get(cls.NAME, o, "want_proxies", bool, False),
            depth_codec=_get(cls.NAME, o, "depth_codec", str, ""),
            quadtree_threshold=_get(cls.NAME, o, "quadtree_threshold", float, 0.0, lo=0.0,
                                    hi=MAX_QUADTREE_THRESHOLD),
            token=_token(_get(cls.NAME, o, "token", str, "")),
            bandwidth_kbps=_get(cls.NAME, o, "bandwidth_kbps", float, 0.0, lo=0.0, hi=MAX_BANDWIDTH_KBPS),
            stereo=_get(cls.NAME, o, "stereo", str, "", choices=("",) + STEREO_REFERENCES),
            ipd_mm=_get(cls.NAME, o, "ipd_mm", float, 0.0, lo=0.0, hi=MAX_IPD_MM),
        )


def _token(token: str) -> str:
    # The error names the limit, never the value.
    if len(token) > MAX_TOKEN:
        raise MalformedMessage(f"Hello: field 'token' is longer than {MAX_TOKEN} characters")
    return token


@dataclass(frozen=True)
class Welcome(Message):
    """Server -> client: the session's fixed parameters.

    ``config`` holds everything the client needs to decode and re-render (scene info,
    views, projection, atlas layout, codecs, server rate and the virtual-time model); its
    keys are documented and validated by :class:`~pibr.protocol.session.SessionConfig`.
    ``setup_us`` is how long the server took between the Hello and this Welcome, so the
    client can tell network round trip from set-up time (real clock: clock offset estimate).
    """

    TYPE: ClassVar[int] = 2
    NAME: ClassVar[str] = "Welcome"
    server: str
    session: int
    config: dict
    setup_us: int = 0
    protocol: int = PROTOCOL_VERSION

    def serialize(self) -> bytes:
        return _dump_json({"protocol": self.protocol, "server": self.server, "session": self.session,
                           "config": self.config, "setup_us": self.setup_us})

    @classmethod
    def parse(cls, payload: bytes) -> "Welcome":
        o = _load_json(cls.NAME, payload)
        return cls(
            protocol=_get(cls.NAME, o, "protocol", int, lo=0, hi=65535),
            server=_get(cls.NAME, o, "server", str, ""),
            session=_get(cls.NAME, o, "session", int, lo=0),
            config=_get(cls.NAME, o, "config", dict),
            setup_us=_get(cls.NAME, o, "setup_us", int, 0, lo=0),
        )


# ---------------------------------------------------------------- poses and frames

_POSE = struct.Struct("<Iq7d")


def _pose_from(name: str, values) -> Pose:
    try:
        return Pose.make(values[:3], values[3:])
    except InvalidPose as exc:
        raise MalformedMessage(f"{name}: invalid pose: {exc}") from None


#: Sequence number of the poses a real-clock client sends while it warms up, before its clock
#: starts; its ticks' poses count from 0 (``t_us`` then from its tick 0, negative while it rolls in).
WARMUP_SEQ = (1 << 32) - 1


@dataclass(frozen=True)
class PoseMsg(Message):
    """Client -> server: the head pose sampled at client time ``t_us`` (sequence number ``seq``)."""

    TYPE: ClassVar[int] = 3
    NAME: ClassVar[str] = "Pose"
    seq: int
    t_us: int
    pose: Pose

    def serialize(self) -> bytes:
        return _POSE.pack(self.seq, self.t_us, *self.pose.position, *self.pose.orientation)

    @classmethod
    def parse(cls, payload: bytes) -> "PoseMsg":
        if len(payload) != _POSE.size:
            raise MalformedMessage(f"Pose: payload must be {_POSE.size} bytes, got {len(payload)}")
        seq, t_us, *v = _POSE.unpack(payload)
        return cls(seq, t_us, _pose_from(cls.NAME, v))


class PayloadKind:
    """What a ``Frame`` payload holds."""

    H264_ATLAS = 1        # one H.264 access unit of the colour (+ 8-bit disparity) atlas
    EDGE_DEPTH = 2        # edge-codec depth of the primary view
    EDGE_DEPTH_EXTRA = 3  # edge-codec depth of the extra view
    EDGE_MOTION = 4       # reserved: never sent (motion flow travels as MOTION_FLOW, with either depth codec)
    QUADTREE = 5          # depth quadtrees of every view (protocol/quadtree.py), when the Hello asked
    OBJECT_POSES = 6      # moving objects' transforms at the frame's scene time (protocol/object_poses.py)
    MOTION_FLOW = 7       # motion flow of moving objects in the primary view (protocol/motion_flow.py)
    FRAME_LEVEL = 8       # the server's rate-control level the frame was made at (one byte: its index in
                          # SessionConfig.options["server_levels"]); frames without rate control carry none
    EYE = 9               # the eye a stereo session's frame was rendered for (one byte: 0 left, 1 right;
                          # protocol/stereo.py); frames from the head's centre carry none
    STREAM_RATE = 10      # what the server's stream adaptation chose for the frame (encode_stream_rate);
                          # frames of a session without adaptation carry none
    ALL = (H264_ATLAS, EDGE_DEPTH, EDGE_DEPTH_EXTRA, EDGE_MOTION, QUADTREE, OBJECT_POSES, MOTION_FLOW, FRAME_LEVEL,
           EYE, STREAM_RATE)
    NAMES = {1: "h264-atlas", 2: "edge-depth", 3: "edge-depth-extra", 4: "edge-motion", 5: "quadtree",
             6: "object-poses", 7: "motion-flow", 8: "frame-level", 9: "eye", 10: "stream-rate"}


_STREAM_RATE = struct.Struct("<IBBB")


def encode_stream_rate(video_kbps: float, every: int, reason: int, view: int = 1) -> bytes:
    """The STREAM_RATE payload: the colour's target (whole kbit/s), the frames made (one every
    ``every`` ticks, 1..255), the reason code of the choice (server/stream_adaptation.py) and the
    primary view's size (rendered at 1/``view`` of its side, 1..255)."""
    if not (0 <= video_kbps < 2 ** 32 and 1 <= every <= 255 and 0 <= reason <= 255 and 1 <= view <= 255):
        raise ValueError(f"a stream rate is kbps in 0..2^32, every in 1..255, a reason in 0..255 and a view "
                         f"divisor in 1..255; got {video_kbps}, {every}, {reason}, {view}")
    return _STREAM_RATE.pack(int(round(video_kbps)), every, reason, view)


def decode_stream_rate(payload) -> tuple[int, int, int, int]:
    """A STREAM_RATE payload -> (video kbps, every, reason, view); MalformedMessage unless 7 bytes,
    every >= 1 and view >= 1."""
    if len(payload) != _STREAM_RATE.size:
        raise MalformedMessage(f"Frame: a stream-rate payload is {_STREAM_RATE.size} bytes, got {len(payload)}")
    kbps, every, reason, view = _STREAM_RATE.unpack(bytes(payload))
    if every < 1:
        raise MalformedMessage("Frame: a stream-rate payload says a frame every 0 ticks")
    if view < 1:
        raise MalformedMessage("Frame: a stream-rate payload says a view at 1/0 of its side")
    return kbps, every, reason, view


def encode_frame_level(level: int) -> bytes:
    """The FRAME_LEVEL payload of a level index in 0..255."""
    if not 0 <= level <= 255:
        raise ValueError(f"a frame level is an index in 0..255, got {level}")
    return bytes([level])


def encode_eye(eye: str) -> bytes:
    """The EYE payload of ``eye`` (left or right)."""
    if eye not in EYES:
        raise ValueError(f"an EYE payload names the left or right eye, got {eye!r}")
    return bytes([EYES.index(eye)])


def decode_eye(payload) -> str:
    """An EYE payload -> "left" or "right"; MalformedMessage unless it is one byte, 0 or 1."""
    if len(payload) != 1 or payload[0] >= len(EYES):
        raise MalformedMessage(f"Frame: an eye payload is one byte, 0 (left) or 1 (right), got {bytes(payload)!r}")
    return EYES[payload[0]]


def decode_frame_level(payload) -> int:
    """A FRAME_LEVEL payload -> its level index; MalformedMessage unless it is one byte."""
    if len(payload) != 1:
        raise MalformedMessage(f"Frame: a frame-level payload is one byte, got {len(payload)}")
    return payload[0]


_FRAME_HEAD = struct.Struct("<IqqIqI7d7ddd4fB")
_PAYLOAD_HEAD = struct.Struct("<BI")
FRAME_HAS_EXTRA = 1
FRAME_KEYFRAME = 2


@dataclass(frozen=True)
class Frame(Message):
    """Server -> client: one rendered server frame.

    frame_id      : counts the session's frames from 0
    render_t_us   : server time of the render (virtual clock: the frame's tick; also the
                    scene-animation time); the header's vtime says when it is usable
    pose_t_us     : client time of the pose it was rendered for; pose_seq its sequence number
    scene_t_us    : scene (animation) time the frame shows
    primary_pose  : camera-to-world pose of the primary view
    extra_pose    : of the extra view (None when the frame has none)
    near, far     : clip spheres of both views
    timings_ms    : server stage times (render, read back, pack, encode)
    payloads      : tuple of (PayloadKind, bytes)
    """

    TYPE: ClassVar[int] = 4
    NAME: ClassVar[str] = "Frame"
    frame_id: int
    render_t_us: int
    pose_t_us: int
    pose_seq: int
    scene_t_us: int
    primary_pose: Pose
    extra_pose: Pose | None
    near: float
    far: float
    timings_ms: tuple = (0.0, 0.0, 0.0, 0.0)
    payloads: tuple = ()
    keyframe: bool = False

    MAX_PAYLOADS: ClassVar[int] = 8

    def payload(self, kind: int) -> bytes | None:
        for k, data in self.payloads:
            if k == kind:
                return data
        return None

    def serialize(self) -> bytes:
        flags = (FRAME_HAS_EXTRA if self.extra_pose is not None else 0) | (FRAME_KEYFRAME if self.keyframe else 0)
        extra = self.extra_pose if self.extra_pose is not None else Pose.identity()
        parts = [_FRAME_HEAD.pack(self.frame_id, self.render_t_us, self.pose_t_us, self.pose_seq,
                                  self.scene_t_us, flags, *self.primary_pose.position,
                                  *self.primary_pose.orientation, *extra.position, *extra.orientation,
                                  self.near, self.far, *self.timings_ms, len(self.payloads))]
        for kind, data in self.payloads:
            parts.append(_PAYLOAD_HEAD.pack(kind, len(data)))
            parts.append(bytes(data))
        return b"".join(parts)

    @classmethod
    def parse(cls, payload: bytes) -> "Frame":
        n = cls.NAME
        if len(payload) < _FRAME_HEAD.size:
            raise MalformedMessage(f"{n}: payload of {len(payload)} bytes is shorter than its {_FRAME_HEAD.size}-byte header")
        v = _FRAME_HEAD.unpack_from(payload, 0)
        frame_id, render_t, pose_t, pose_seq, scene_t, flags = v[:6]
        if flags & ~(FRAME_HAS_EXTRA | FRAME_KEYFRAME):
            raise MalformedMessage(f"{n}: unknown flags {flags:#x}")
        primary = _pose_from(n + ".primary_pose", v[6:13])
        extra = _pose_from(n + ".extra_pose", v[13:20]) if flags & FRAME_HAS_EXTRA else None
        near, far = v[20], v[21]
        if not (math.isfinite(near) and math.isfinite(far) and 0 < near < far):
            raise MalformedMessage(f"{n}: need 0 < near < far, got near={near}, far={far}")
        timings = tuple(v[22:26])
        count = v[26]
        if count > cls.MAX_PAYLOADS:
            raise MalformedMessage(f"{n}: {count} payloads exceed the limit of {cls.MAX_PAYLOADS}")
        pos = _FRAME_HEAD.size
        payloads = []
        for i in range(count):
            if len(payload) - pos < _PAYLOAD_HEAD.size:
                raise MalformedMessage(f"{n}: payload {i} header is truncated")
            kind, length = _PAYLOAD_HEAD.unpack_from(payload, pos)
            pos += _PAYLOAD_HEAD.size
            if kind not in PayloadKind.ALL:
                raise MalformedMessage(f"{n}: payload {i} has unknown kind {kind}")
            if length > len(payload) - pos:
                raise MalformedMessage(f"{n}: payload {i} claims {length} bytes but only {len(payload) - pos} remain")
            payloads.append((kind, payload[pos:pos + length]))
            pos += length
        if pos != len(payload):
            raise MalformedMessage(f"{n}: {len(payload) - pos} trailing bytes after the last payload")
        kinds = [k for k, _ in payloads]
        if len(set(kinds)) != len(kinds):
            raise MalformedMessage(f"{n}: a payload kind appears twice")
        return cls(frame_id, render_t, pose_t, pose_seq, scene_t, primary, extra, near, far, timings,
                   tuple(payloads), bool(flags & FRAME_KEYFRAME))


@dataclass(frozen=True)
class Clock(Message):
    """Either way: a promise that no later message from this sender has an earlier virtual time.

    It has no payload; the frame header's ``vtime_us`` carries the promise. On the virtual
    clock this is what lets each end advance without waiting for a message that never comes
    (conservative discrete-event simulation's null message).
    """

    TYPE: ClassVar[int] = 8
    NAME: ClassVar[str] = "Clock"

    def serialize(self) -> bytes:
        return b""

    @classmethod
    def parse(cls, payload: bytes) -> "Clock":
        if payload:
            raise MalformedMessage(f"Clock: payload must be empty, got {len(payload)} bytes")
        return cls()


# ---------------------------------------------------------------- proxies (issue 4)

_PROXY = struct.Struct("<III")


@dataclass(frozen=True)
class ProxyChunk(Message):
    """Server -> client: chunk ``index`` of ``count`` of the zstd-compressed proxy bundle."""

    TYPE: ClassVar[int] = 9
    NAME: ClassVar[str] = "ProxyChunk"
    index: int
    count: int
    total_size: int
    data: bytes = b""

    def serialize(self) -> bytes:
        return _PROXY.pack(self.index, self.count, self.total_size) + self.data

    @classmethod
    def parse(cls, payload: bytes) -> "ProxyChunk":
        if len(payload) < _PROXY.size:
            raise MalformedMessage(f"ProxyChunk: payload of {len(payload)} bytes is shorter than its header")
        index, count, total = _PROXY.unpack_from(payload, 0)
        if count == 0 or index >= count:
            raise MalformedMessage(f"ProxyChunk: chunk index {index} is not below the count {count}")
        return cls(index, count, total, payload[_PROXY.size:])


# ---------------------------------------------------------------- control

#: Stats key a real-clock client sends whenever it takes the frames that arrived to decode them
#: (all, showing the newest): how many it has taken. The server keeps at most a few frames ahead
#: of it, so a slow client gets fresh frames, not a queue of stale ones.
FRAMES_DECODED = "frames_decoded"
#: ``Stats`` key: the median age (ms) of the frames a client showed over its last ticks (from the
#: pose a frame was rendered for to its display): a server predicting the head's pose
#: (SessionConfig.options["predict"]) predicts that far ahead.
DISPLAY_AGE_MS = "display_age_ms"
#: ``Stats`` keys of a session whose stream adapts to the link (SessionConfig.options["adapt"]),
#: sent every STREAM_REPORT_MS of the client's clock: the median age (ms) at arrival of the frames
#: that arrived since the last report (arrival less render time, on the wall clock less the
#: server's stage times too, client/app.py stream_left_us; if none arrived, the newest
#: frame's age now: how old the next one will be at least), and the bits of those frames over the
#: report's interval (kbit/s). The server compares ages with their least over the last seconds,
#: so an offset between the two clocks cancels.
ARRIVAL_AGE_MS = "arrival_age_ms"
DELIVERED_KBPS = "delivered_kbps"
STREAM_REPORT_MS = 200.0
#: The frames' queueing is their age at arrival less its least over the last STREAM_BASELINE_S
#: seconds (both ends compute it so). Above STREAM_QUEUE_HIGH_MS the link carries less than the
#: stream: the server lowers its rate, and the client reports at once instead of at the next
#: STREAM_REPORT_MS (at most one report every STREAM_URGENT_GAP_MS).
STREAM_BASELINE_S = 10.0
STREAM_QUEUE_HIGH_MS = 100.0
STREAM_URGENT_GAP_MS = 50.0
#: ``Stats`` keys sent with ARRIVAL_AGE_MS and DELIVERED_KBPS (a server reading reports without
#: them assumes STREAM_REPORT_MS and no estimate): the report's interval (ms); the link's rate
#: (kbit/s) measured from the frames that arrived while the link was busy with them, each one's
#: bits over the time since the frame before it arrived (packet-pair dispersion, a frame a pair;
#: absent when none did); and the newest frame id arrived so far (the server counts what it sent
#: after it as still on its way).
REPORT_SPAN_MS = "report_span_ms"
LINK_KBPS = "link_kbps"
NEWEST_FRAME = "newest_frame"
#: ``Stats`` key a client of an adapting session sends once, before its first pose: the link's
#: rate (kbit/s) measured on the proxy bundle sent ahead of the stream (its bits over the time from
#: the Welcome's arrival to its last chunk's), where the stream may start instead of at its
#: slowest (server/stream_adaptation.py).
PROBE_KBPS = "probe_kbps"


@dataclass(frozen=True)
class Stats(Message):
    """Either way: named numbers (e.g. the client's missed deadlines, the server's drops, and
    ``FRAMES_DECODED``)."""

    TYPE: ClassVar[int] = 5
    NAME: ClassVar[str] = "Stats"
    values: dict = field(default_factory=dict)

    MAX_ENTRIES: ClassVar[int] = 256

    def serialize(self) -> bytes:
        return _dump_json({"values": {str(k): float(v) for k, v in self.values.items()}})

    @classmethod
    def parse(cls, payload: bytes) -> "Stats":
        o = _load_json(cls.NAME, payload)
        vals = _get(cls.NAME, o, "values", dict)
        if len(vals) > cls.MAX_ENTRIES:
            raise MalformedMessage(f"Stats: {len(vals)} entries exceed the limit of {cls.MAX_ENTRIES}")
        out = {}
        for k, v in vals.items():
            out[k] = _get(cls.NAME, vals, k, float)
        return cls(out)


@dataclass(frozen=True)
class Bye(Message):
    """Either way: orderly end of the session."""

    TYPE: ClassVar[int] = 6
    NAME: ClassVar[str] = "Bye"
    reason: str = ""

    def serialize(self) -> bytes:
        return _dump_json({"reason": self.reason[:MAX_TEXT]})

    @classmethod
    def parse(cls, payload: bytes) -> "Bye":
        return cls(_get(cls.NAME, _load_json(cls.NAME, payload), "reason", str, ""))


_ERROR = struct.Struct("<H")


@dataclass(frozen=True)
class Error(Message):
    """Either way: the sender is closing the connection because of ``text`` (wire ``code``, see errors.py)."""

    TYPE: ClassVar[int] = 7
    NAME: ClassVar[str] = "Error"
    code: int
    text: str

    def serialize(self) -> bytes:
        return _ERROR.pack(self.code) + self.text.encode("utf-8")[:MAX_TEXT]

    @classmethod
    def parse(cls, payload: bytes) -> "Error":
        if len(payload) < _ERROR.size:
            raise MalformedMessage("Error: payload shorter than its 2-byte code")
        if len(payload) - _ERROR.size > MAX_TEXT:
            raise MalformedMessage(f"Error: text longer than {MAX_TEXT} bytes")
        (code,) = _ERROR.unpack_from(payload, 0)
        try:
            text = payload[_ERROR.size:].decode("utf-8")
        except UnicodeDecodeError:
            raise MalformedMessage("Error: text is not UTF-8") from None
        return cls(code, text)


MESSAGE_TYPES: dict[int, type[Message]] = {
    m.TYPE: m for m in (Hello, Welcome, PoseMsg, Frame, Stats, Bye, Error, Clock, ProxyChunk)
}


def parse_message(msg_type: int, payload: bytes) -> Message:
    """Payload bytes of a frame of type ``msg_type`` -> message. Raises UnknownMessageType / MalformedMessage."""
    from .errors import UnknownMessageType

    cls = MESSAGE_TYPES.get(msg_type)
    if cls is None:
        raise UnknownMessageType(f"unknown message type {msg_type}")
    try:
        return cls.parse(payload)
    except MalformedMessage:
        raise
    except (struct.error, ValueError, TypeError, KeyError) as exc:  # any other parse failure names the message
        raise MalformedMessage(f"{cls.NAME}: {exc}") from None
