"""Client settings (``pibr client`` options), validated once at start-up."""
from __future__ import annotations

import os
from dataclasses import dataclass, field

from pibr.common.tls import ClientTLS
from pibr.protocol.errors import ConfigError
from pibr.protocol.frustum import check_eye_fov_deg, equivalent_fov_deg, eye_tangents
from pibr.protocol.messages import MAX_BANDWIDTH_KBPS, OutputConfig
from pibr.protocol.stereo import DEFAULT_IPD_MM, STEREO_REFERENCES, check_ipd_mm

from .deadline import DEADLINE_MODES
from .methods import method_names


#: The session's time limit when not given: this much, plus this much per second of trace (a
#: 1024^2 virtual-clock session here takes about 3 s per second of trace; a wall-clock one 1 s).
SESSION_BASE_S, SESSION_PER_TRACE_S = 600.0, 30.0


@dataclass
class ClientConfig:
    host: str = "127.0.0.1"
    port: int = 7451
    trace: str = "pred6dof-1"
    rate_hz: float = 60.0
    clock: str = "virtual"
    methods: tuple = ("rotation",)
    out_dir: str = "out"
    width: int = 960
    height: int = 540
    fov_deg: float = 90.0
    start_s: float = 0.0
    duration_s: float | None = None
    anchor: str = "start"    # how the trace window is placed in the scene (pibr.common.traces.placement)
    preroll_s: float = 0.5
    scene: str = ""
    depth_codec: str = ""
    bandwidth_kbps: float = 0.0   # stated to the server in the Hello (0: not stated)
    record: bool = True
    lossless: bool = True
    video: bool = True       # False: records only (no MP4 / lossless copy), the least work per tick
    warmup_s: float = 60.0   # real clock: longest wait for the first frame before the clock starts
    receive_timeout_s: float = 30.0  # longest wait for one whole message from the server (the Welcome: 4x)
    session_timeout_s: float = 0.0   # the whole connection's limit (0: SESSION_BASE_S + SESSION_PER_TRACE_S per trace second)
    progress: str = "bar"    # bar, lines (machine-readable on stdout), none
    tau: float = 0.1         # proxy IBR: relative depth error accepted as the same surface
    lod_pixels: float = 6.0  # proxy IBR: edge length, in pixels of a 960-wide 90-degree output, that selects the LoD
    lod_level: str | None = None  # proxy IBR: force original, proxy or box for every object
    deadline: str = "auto"   # quality levels chosen to keep the output rate (client/deadline.py): auto, on, off
    cost_table: str | None = None  # JSON of each level's ms (or a session.json), for the virtual clock
    options: dict = field(default_factory=dict)  # other methods' knobs (client/cli.py METHOD_KNOBS)
    token: str | None = field(default=None, repr=False)  # the server's (or relay's) access token; never recorded
    tls: ClientTLS | None = None                 # connect with TLS, verifying the server this way
    stereo: str = ""         # two eyes from frames rendered this way (protocol/stereo.py); "": one view
    ipd_mm: float = DEFAULT_IPD_MM   # with stereo: the eyes' distance along the head's x axis
    anaglyph: bool = False   # with stereo: also a red-cyan anaglyph video per method
    #: with stereo: the left eye's (outer, inner, up, down) degrees from its axis to its frustum's
    #: edges, the right eye mirrored (protocol/frustum.py), over width x height pixels; fov_deg is
    #: then the symmetric one of the same pixels per radian. None: both eyes see fov_deg symmetrically
    eye_fov_deg: tuple | None = None
    live_port: int | None = None   # serve the live page on 127.0.0.1:PORT (0: any free port; None: no page)

    def __post_init__(self):
        if self.clock not in ("virtual", "real"):
            raise ConfigError(f"clock must be virtual or real, got {self.clock!r}")
        if not self.methods:
            raise ConfigError("name at least one method")
        for m in self.methods:
            if m not in method_names():
                raise ConfigError(f"unknown method {m!r}; choose from {', '.join(method_names())}")
        if len(set(self.methods)) != len(self.methods):
            raise ConfigError("a method is named twice")
        if not (1 <= self.rate_hz <= 1000):
            raise ConfigError(f"output rate must be in 1..1000 Hz, got {self.rate_hz}")
        if self.duration_s is not None and self.duration_s <= 0:
            raise ConfigError(f"duration must be positive, got {self.duration_s}")
        if not (0 <= self.bandwidth_kbps <= MAX_BANDWIDTH_KBPS):
            raise ConfigError(f"bandwidth must be in 0..{MAX_BANDWIDTH_KBPS:g} kbit/s (0: not stated), "
                              f"got {self.bandwidth_kbps}")
        from pibr.common.traces.placement import ANCHORS

        if self.anchor not in ANCHORS:
            raise ConfigError(f"anchor must be one of {', '.join(ANCHORS)}, got {self.anchor!r}")
        if not (0 < self.receive_timeout_s <= 86400):
            raise ConfigError(f"receive timeout must be in (0, 86400] s, got {self.receive_timeout_s}")
        if not (0 <= self.session_timeout_s <= 30 * 86400):
            raise ConfigError(f"session timeout must be in [0, {30 * 86400}] s (0: from the trace's length), "
                              f"got {self.session_timeout_s}")
        if self.preroll_s < 0:
            raise ConfigError("preroll must be >= 0")
        if not (0 < self.tau < 10):
            raise ConfigError(f"tau must be in (0, 10), got {self.tau}")
        if not (self.lod_pixels > 0):
            raise ConfigError(f"LoD pixel target must be positive, got {self.lod_pixels}")
        if self.lod_level not in (None, "original", "proxy", "box"):
            raise ConfigError(f"LoD level must be original, proxy or box, got {self.lod_level!r}")
        if self.deadline not in DEADLINE_MODES:
            raise ConfigError(f"deadline must be one of {', '.join(DEADLINE_MODES)}, got {self.deadline!r}")
        if self.cost_table is not None and not os.path.isfile(self.cost_table):
            raise ConfigError(f"cost table {self.cost_table!r}: no such file")
        if self.stereo and self.stereo not in STEREO_REFERENCES:
            raise ConfigError(f"stereo must be one of {', '.join(STEREO_REFERENCES)}, got {self.stereo!r}")
        check_ipd_mm(self.ipd_mm)
        if self.anaglyph and not self.stereo:
            raise ConfigError("an anaglyph needs two eyes: add --stereo cyclops, alternate or per-eye")
        if self.eye_fov_deg is not None:
            if not self.stereo:
                raise ConfigError("an eye's field of view needs two eyes: add --stereo cyclops, alternate or per-eye")
            self.eye_fov_deg = check_eye_fov_deg(self.eye_fov_deg)
            if self.options.get("pair_at_once"):
                raise ConfigError("--pair-at-once draws both eyes through one projection: it cannot with "
                                  "--eye-fov-deg, whose eyes each have their own")
            # the eyes' pixels per radian at their centres, for the server's views and FLIP
            self.fov_deg = equivalent_fov_deg(eye_tangents("left", self.eye_fov_deg))
        if self.live_port is not None and not (0 <= self.live_port <= 65535):
            raise ConfigError(f"--live takes a TCP port 0..65535 (0: any free one), got {self.live_port}")
        if self.progress not in ("bar", "lines", "none"):
            raise ConfigError(f"progress must be bar, lines or none, got {self.progress!r}")
        OutputConfig(self.width, self.height, self.fov_deg, self.rate_hz)
        if self.token is not None:
            from pibr.protocol.access import check_token_text

            check_token_text(self.token)
        if not (16 <= self.width <= 8192 and 16 <= self.height <= 8192 and 1 <= self.fov_deg <= 170):
            raise ConfigError(f"output {self.width}x{self.height} at {self.fov_deg} degrees is out of range")

    def session_limit_s(self, trace_seconds: float) -> float:
        """The session's time limit for a run of ``trace_seconds`` of trace."""
        return self.session_timeout_s or SESSION_BASE_S + SESSION_PER_TRACE_S * trace_seconds
