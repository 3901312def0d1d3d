"""Server settings (``pibr serve`` options), validated once at start-up."""
from __future__ import annotations

from dataclasses import dataclass, field

from pibr.protocol.access import check_listen_access
from pibr.protocol.atlas import COLOUR_SCALES, check_view_size
from pibr.protocol.depth_codecs import AUTO, DEPTH_CODECS
from pibr.protocol.errors import ConfigError
from pibr.protocol.framing import DEFAULT_MAX_MESSAGE_SIZE
from pibr.protocol.motion_flow import DEFAULT_FLOW_CODER, FLOW_CODERS
from pibr.protocol.pose import dual_view_offset

from .proxies import ProxySettings
from .renderer import DEFAULT_PROJECTION, MAX_EDGE_ANGLE_DEG, PROJECTIONS

DEFAULT_PORT = 7450
#: Range of --max-edge-deg: below 1 degree the pre-tessellated room has millions of triangles;
#: above 30 the straight edges miss the projection's curves by many pixels.
MIN_EDGE_DEG, MAX_EDGE_DEG = 1.0, 30.0


extra_offset_pose = dual_view_offset  # the server's name for it


#: --rate-control: the real clock's frames held to --fps by their levels (server/rate_control.py), or not.
RATE_CONTROL_MODES = ("on", "off")
#: Real clock: frames a session sends ahead of what its client reports decoded (server/session.py).
DEFAULT_MAX_IN_FLIGHT = 3

#: Reinert et al.'s offset: 1.5 m forward, 1.8 m up, tilted 15 degrees down.
PAPER_EXTRA_OFFSET = (1.5, 1.8, 15.0)


@dataclass
class EdgeSettings:
    """The edge codec's settings (server/depth_encoders.py)."""

    kbps: float = 0.0          # target for all depth streams together; 0: fixed threshold
    temporal: bool = True
    intra_every: int = 30
    perceptual: bool = False


@dataclass
class ServerConfig:
    host: str = "127.0.0.1"
    port: int = DEFAULT_PORT
    scene: str = "room"                 # default scene when a client asks for none
    fps: float = 10.0
    view_size: tuple | None = None      # primary view (the extra view is half of it); None: sized for the output
    extra_view: str = "auto"            # "auto" (on when it measurably buys coverage: scene_plan.py), "on", "off"
    extra_scale: float = 0.5            # the extra view's side over the primary's (rounded to the atlas alignment)
    peel_marker: bool = True            # the extra view marks peeled pixels apart from sky
    extra_offset: tuple | None = None   # (forward m, up m, tilt deg); None: the scene's or the paper's
    bitrate_kbps: float = 16000.0
    keyint: int = 30
    preset: str = "ultrafast"
    projection: str = DEFAULT_PROJECTION
    max_edge_deg: float = MAX_EDGE_ANGLE_DEG  # longest edge (view angle) the projection rasterises straight
    server_delay_ms: float = 20.0       # virtual clock: render + encode time model
    depth_codec: str = AUTO             # protocol/depth_codecs.py, or "auto": for the bandwidth (scene_plan.py)
    bandwidth_kbps: float | None = None  # the most any session may send (kbit/s); None: no cap
    max_message_size: int = DEFAULT_MAX_MESSAGE_SIZE
    max_sessions: int = 8               # sessions past their Hello
    admit_wait_s: float = 5.0           # a Hello at a full server waits this long for a slot
    max_pending: int = 64               # connections yet to send a Hello; beyond, the oldest is dropped
    predict: str = "kalman"             # render for the head pose predicted at display (server/pose_prediction.py; pibr bench predict)
    adapt: str = "off"                  # the stream follows the link the client reports (server/stream_adaptation.py)
    adapt_start: str = "foot"           # where it starts: its ladder's foot, or half the link its proxies measured
    silent_slot_s: float = 2.0          # a session without a pose this long after its Welcome yields its slot to a waiting client
    hello_timeout_s: float = 10.0       # from connecting to a whole Hello
    idle_timeout_s: float = 15.0        # real clock: longest wait for the client's next pose or clock
    idle_timeout_virtual_s: float = 30.0  # virtual clock: the same (a client may work long per tick)
    max_clock_lead_s: float = 10.0      # virtual clock: how far a client's clock may run ahead of the frames
    max_in_flight: int = DEFAULT_MAX_IN_FLIGHT  # real clock: frames sent ahead of what the client has decoded
    token: str | None = None            # every Hello must carry it; required to listen off loopback
    tls_cert: str | None = None         # PEM certificate chain: serve TLS (with tls_key)
    tls_key: str | None = None          # PEM key, unencrypted
    proxy_settings: ProxySettings = field(default_factory=ProxySettings)
    edge: EdgeSettings = field(default_factory=EdgeSettings)
    flow_coder: str = DEFAULT_FLOW_CODER    # MOTION_FLOW of scenes that move (protocol/motion_flow.py)
    rate_control: str = "on"            # the real clock's frame levels held to --fps (server/rate_control.py)
    colour_scale: float = 1.0           # the views' colour sent at this scale, jittered (protocol/atlas.py)

    def __post_init__(self):
        if not (0 < self.port < 65536) and self.port != 0:
            raise ConfigError(f"port must be in 1..65535 (or 0 for any free port), got {self.port}")
        if not (0.1 <= self.fps <= 240):
            raise ConfigError(f"server fps must be in 0.1..240, got {self.fps}")
        if self.view_size is not None:
            try:
                check_view_size(*self.view_size, what="server view")
            except ValueError as exc:
                raise ConfigError(str(exc)) from None
        if self.extra_view not in ("auto", "on", "off"):
            raise ConfigError(f"extra view must be auto, on or off, got {self.extra_view!r}")
        if not (0.125 <= self.extra_scale <= 1.0):
            raise ConfigError(f"extra view scale must be in 0.125..1 of the primary view, got {self.extra_scale}")
        if not (16 <= self.bitrate_kbps <= 1e6):
            raise ConfigError(f"bitrate must be in 16..1000000 kbit/s, got {self.bitrate_kbps}")
        if not (1 <= self.keyint <= 10000):
            raise ConfigError(f"keyframe interval must be in 1..10000 frames, got {self.keyint}")
        if self.projection not in PROJECTIONS:
            raise ConfigError(f"projection must be one of {', '.join(PROJECTIONS)}, got {self.projection!r}")
        if not (MIN_EDGE_DEG <= self.max_edge_deg <= MAX_EDGE_DEG):
            raise ConfigError(f"max edge angle must be in {MIN_EDGE_DEG:g}..{MAX_EDGE_DEG:g} degrees, "
                              f"got {self.max_edge_deg}")
        if not (0 <= self.server_delay_ms <= 10000):
            raise ConfigError(f"server delay must be in 0..10000 ms, got {self.server_delay_ms}")
        if self.depth_codec not in (AUTO, *DEPTH_CODECS):
            raise ConfigError(f"depth codec must be {', '.join((AUTO, *DEPTH_CODECS))}, got {self.depth_codec!r}")
        if self.bandwidth_kbps is not None and not (16 <= self.bandwidth_kbps <= 1e7):
            raise ConfigError(f"bandwidth cap must be in 16..10000000 kbit/s, got {self.bandwidth_kbps}")
        if self.flow_coder not in FLOW_CODERS:
            raise ConfigError(f"flow coder must be one of {', '.join(FLOW_CODERS)}, got {self.flow_coder!r}")
        if self.rate_control not in RATE_CONTROL_MODES:
            raise ConfigError(f"rate control must be on or off, got {self.rate_control!r}")
        if self.colour_scale not in COLOUR_SCALES:
            raise ConfigError(f"colour scale must be one of {', '.join(f'{c:g}' for c in COLOUR_SCALES)}, "
                              f"got {self.colour_scale!r}")
        if self.max_sessions < 1:
            raise ConfigError("max sessions must be at least 1")
        if self.max_pending < 1:
            raise ConfigError("max pending connections must be at least 1")
        from .pose_prediction import PREDICTORS

        if self.predict not in PREDICTORS:
            raise ConfigError(f"unknown pose predictor {self.predict!r}; choose from {', '.join(PREDICTORS)}")
        if self.adapt not in ("on", "off"):
            raise ConfigError(f"stream adaptation must be on or off, got {self.adapt!r}")
        from .stream_adaptation import STARTS

        if self.adapt_start not in STARTS:
            raise ConfigError(f"the adapting stream starts at {' or '.join(STARTS)}, got {self.adapt_start!r}")
        if not (0 < self.silent_slot_s <= 3600):
            raise ConfigError(f"--silent-slot-s must be in (0, 3600] s, got {self.silent_slot_s}")
        if not (0 <= self.admit_wait_s <= 3600):
            raise ConfigError(f"admission wait must be in 0..3600 s, got {self.admit_wait_s}")
        for value, what in ((self.hello_timeout_s, "hello timeout"), (self.idle_timeout_s, "idle timeout"),
                            (self.idle_timeout_virtual_s, "virtual-clock idle timeout"),
                            (self.max_clock_lead_s, "clock lead")):
            if not (0 < value <= 86400):
                raise ConfigError(f"{what} must be in (0, 86400] s, got {value}")
        if not (1 <= self.max_in_flight <= 1000):
            raise ConfigError(f"frames in flight must be in 1..1000, got {self.max_in_flight}")
        check_listen_access("server", self.host, self.token)
        from pibr.common.tls import check_server_files

        check_server_files(self.tls_cert, self.tls_key, "server")
        if not (0 <= self.edge.kbps <= 1e6):
            raise ConfigError(f"edge codec bitrate must be in 0..1000000 kbit/s (0: a fixed threshold), "
                              f"got {self.edge.kbps}")
