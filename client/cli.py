"""``pibr client``."""
from __future__ import annotations

import argparse
import asyncio
import sys

from pibr.common import arguments
from pibr.common.address import parse_host_port
from pibr.protocol.depth_codecs import DEPTH_CODECS
from pibr.protocol.errors import ConfigError
from pibr.protocol.messages import CLOCKS
from pibr.protocol.stereo import DEFAULT_IPD_MM, STEREO_REFERENCES

from .deadline import DEADLINE_MODES


def parse_methods(text: str) -> tuple:
    """argparse type: comma-separated method names, each one the client knows."""
    from .methods import method_names

    names = tuple(m.strip() for m in text.split(",") if m.strip())
    unknown = [m for m in names if m not in method_names()]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"unknown method {', '.join(unknown) or text!r}; "
                                         f"choose from {', '.join(method_names())} (comma-separated)")
    return names


def register(sub) -> None:
    p = sub.add_parser("client", help="replay a head trace against a server and record what is displayed",
                       description="Connect to a pibr server (or relay), replay a head trace at a fixed output "
                                   "rate, re-render every tick with one or more methods and record the results.")
    p.add_argument("--connect", default="127.0.0.1:7451", help="HOST:PORT of the server or relay (default :7451)")
    p.add_argument("--trace", default="pred6dof-1",
                   help="head trace: a file (canonical CSV or pred6dof) or a built-in name (see 'pibr trace list')")
    p.add_argument("--rate", dest="rate_hz", type=float, default=60.0, help="output rate in Hz (default 60)")
    p.add_argument("--clock", choices=CLOCKS, default="virtual",
                   help="virtual: simulated, deterministic time; real: the wall clock (default virtual)")
    p.add_argument("--method", dest="methods", type=parse_methods, default=("rotation",),
                   help="re-rendering method(s), comma-separated: none, rotation, ... (default rotation)")
    p.add_argument("--out", dest="out_dir", default="out", help="output directory (default out)")
    p.add_argument("--size", type=arguments.size, default=(960, 540), metavar="WxH", help="output size (default 960x540)")
    p.add_argument("--fov", dest="fov_deg", type=float, default=None,
                   help="horizontal field of view in degrees (default 90; see --eye-fov-deg)")
    p.add_argument("--start", dest="start_s", type=float, default=0.0, help="start this many seconds into the trace")
    p.add_argument("--duration", dest="duration_s", type=float, default=None, help="seconds of trace to replay (default: all)")
    p.add_argument("--anchor", choices=("start", "origin", "none"), default="start",
                   help="place the trace in the scene: its pose at --start at the scene's viewer origin and "
                        "heading (start, default), its own origin at the viewer origin (origin), or as recorded in "
                        "the scene's coordinates (none)")
    p.add_argument("--preroll", dest="preroll_s", type=float, default=0.5,
                   help="seconds of poses sent before the first displayed tick (default 0.5)")
    p.add_argument("--scene", default="", help="ask the server for this scene (default: the server's)")
    p.add_argument("--depth-codec", choices=tuple(DEPTH_CODECS), default=None, help="ask for this depth transport")
    p.add_argument("--bandwidth-kbps", type=float, default=0.0, metavar="KBPS",
                   help="tell the server the bandwidth this client receives: it fits its streams into it and "
                        "picks the depth codec for it (default 0: not stated)")
    p.add_argument("--stereo", choices=STEREO_REFERENCES, default="",
                   help="show two eyes, half --ipd-mm either side of the head, from frames the server renders "
                        "from the head's centre (cyclops), from each eye on alternate frames (alternate) or from "
                        "both eyes every frame (per-eye, twice the server's work); recordings per eye "
                        "(METHOD.left.*, METHOD.right.*) and a side-by-side METHOD.stereo.mp4 (default: one view)")
    p.add_argument("--ipd-mm", type=arguments.positive, default=DEFAULT_IPD_MM,
                   help=f"with --stereo: interpupillary distance in mm (default {DEFAULT_IPD_MM:g})")
    p.add_argument("--anaglyph", action="store_true",
                   help="with --stereo: also a red-cyan anaglyph video per method (METHOD.anaglyph.mp4)")
    p.add_argument("--eye-fov-deg", type=arguments.eye_fov, default=None, metavar="OUTER,INNER,UP,DOWN",
                   help="with --stereo: each eye's own asymmetric frustum, as a headset's (OpenXR's four angles): "
                        "the left eye's degrees from its axis to its outer (left), inner, top and bottom edges, "
                        "the right eye mirrored, over the --size pixels, instead of --fov (default: both eyes see "
                        "--fov symmetrically)")
    p.add_argument("--live", dest="live_port", type=int, default=None, metavar="PORT",
                   help="while the session runs, show it on a page at http://127.0.0.1:PORT/ (0: any free port, "
                        "printed): frame age, missed ticks, server frames/s, bitrate, decode and render ms over "
                        "the last seconds, and the current image")
    p.add_argument("--no-lossless", action="store_true", help="skip the lossless recording used for metrics")
    p.add_argument("--no-video", action="store_true",
                   help="write the per-tick records only, no video: the least work per tick (timing runs)")
    p.add_argument("--tau", type=float, default=0.1,
                   help="proxy: relative depth error still taken as the same surface (default 0.1)")
    p.add_argument("--lod-pixels", type=float, default=6.0,
                   help="proxy: finest LoD whose edges cover at least this many pixels of a 960-pixel-wide "
                        "90-degree output (an angle, the same at every output size; default 6)")
    p.add_argument("--lod-level", choices=("original", "proxy", "box"), default=None,
                   help="proxy: draw this level for every object instead of choosing by distance")
    p.add_argument("--deadline", choices=DEADLINE_MODES, default="auto",
                   help="keep the output rate by drawing each method at the best quality level whose predicted "
                        "cost fits the tick (render scale, no inpainting, coarser proxies, at last rotation): auto "
                        "(default) on the wall clock, and on the virtual clock when --cost-table gives the costs; "
                        "on; off (always the best level)")
    p.add_argument("--cost-table", default=None, metavar="FILE",
                   help="each level's cost in ms (JSON: method -> level -> ms, or a session.json of an earlier "
                        "wall-clock run, which records what it measured): on the virtual clock the levels are "
                        "then chosen from it alone, the same on every machine")
    p.add_argument("--progress", choices=("bar", "lines", "none"), default="bar")
    p.add_argument("--receive-timeout-s", type=arguments.positive, default=30.0, metavar="S",
                   help="give up when no whole message from the server arrives within S seconds while the "
                        "client waits for one, however it trickles in (default 30; the Welcome may take 4x as "
                        "long, while the server loads a scene)")
    p.add_argument("--session-timeout-s", type=arguments.non_negative, default=0.0, metavar="S",
                   help="give up when the whole session runs past S seconds (default 0: 10 minutes plus 30 s per "
                        "second of trace)")
    g = p.add_argument_group("access (a server or relay with a token or TLS)")
    g.add_argument("--token-file", metavar="FILE",
                   help="send the access token on the first line of FILE (default: $PIBR_TOKEN, if set)")
    g.add_argument("--token", metavar="TEXT",
                   help="send this access token: prefer --token-file or PIBR_TOKEN, since a command line is "
                        "visible to other users in ps")
    g.add_argument("--tls-ca", metavar="FILE",
                   help="connect with TLS, verifying the server's certificate and host name against this PEM CA file")
    g.add_argument("--tls-pin", metavar="SHA256",
                   help="connect with TLS, accepting only the certificate with this SHA-256 fingerprint "
                        "(as 'pibr serve' prints it; for a self-signed certificate)")
    add_method_knobs(p)
    p.set_defaults(func=cmd_client)


# The competitors' knobs: flag, the option it sets, its type, help. Each method takes the
# options it knows (see make_method); an option no chosen method takes is ignored.
METHOD_KNOBS = (
    ("--plane-distance", "plane_distance", arguments.positive,
     "homography: metres from the primary camera to the plane every pixel is taken to lie on"),
    ("--point-size", "point_size", arguments.positive, "splat: point size in output pixels"),
    ("--split", "split", arguments.positive,
     "meshwarp, quadtree, iterative: relative depth range that splits a triangle at a discontinuity"),
    ("--coarse-step", "step", arguments.positive_int, "coarse-meshwarp: pixels between grid vertices"),
    ("--quadtree-threshold", "threshold", arguments.positive,
     "quadtree, iterative: the server merges pixels into a quad while its relative depth range stays below this"),
    ("--iterations", "iterations", arguments.positive_int, "iterative: fixed-point iterations per pixel"),
    ("--damping", "damping", arguments.positive, "iterative: damping of each correction"),
    ("--grid-tile", "tile", arguments.positive_int, "gridwarp: tile size of the surface-estimation quadtree, pixels"),
    ("--grid-epsilon", "epsilon", arguments.positive, "gridwarp: relative collinearity tolerance"),
)


def add_method_knobs(parser) -> None:
    """The competitors' knobs as options of ``parser``; defaults come from the methods."""
    import inspect

    from .methods import METHODS

    defaults = {}
    for cls in METHODS.values():
        for name, param in inspect.signature(cls.__init__).parameters.items():
            if param.default is not inspect.Parameter.empty:
                defaults.setdefault(name, param.default)
    group = parser.add_argument_group("method knobs (each method takes its own)")
    for flag, option, kind, text in METHOD_KNOBS:
        if option in defaults:
            group.add_argument(flag, dest=f"knob_{option}", type=kind, default=None,
                               metavar=option.upper(), help=f"{text} (default {defaults[option]:g})")
    if "fill" in defaults:
        group.add_argument("--no-grid-fill", dest="knob_fill", action="store_const", const=False, default=None,
                           help="gridwarp: no depth-aware hole filling")
    group.add_argument("--no-extra-view", dest="knob_extra_view", action="store_const", const=False, default=None,
                       help="proxy: ignore the transmitted extra view")
    from .object_motion import CLIENT_MOTION_MODES, DEFAULT_MOTION

    group.add_argument("--motion", dest="knob_motion", choices=CLIENT_MOTION_MODES, default=None,
                       help=f"how moving objects are brought to the display time. proxy, from the transforms the "
                            f"frames carried: static (where the newest frame saw them), velocity (constant linear "
                            f"and angular velocity), accel (second order), default {DEFAULT_MOTION}; flow, for proxy and "
                            f"every method that re-projects the primary view (none, rotation, homography, splat, "
                            f"meshwarp, coarse-meshwarp): the moving pixels warped along the frames' motion flow "
                            f"(Pajak et al.), default static")
    group.add_argument("--no-carve", dest="knob_carve", action="store_const", const=False, default=None,
                       help="proxy: test only the nearest proxy fragment of each pixel (one cheaper pass; proxy "
                            "surfaces no view confirms then hide what lies behind them)")
    group.add_argument("--pair-at-once", dest="knob_pair_at_once", action="store_const", const=True, default=None,
                       help="proxy with --stereo cyclops: draw both eyes in one pass (one LoD selection, each proxy "
                            "drawn once per pass for both); off, each eye alone, which costs slightly less CPU on a "
                            "software rasteriser")
    group.add_argument("--no-inpaint", dest="knob_inpaint", action="store_const", const=False, default=None,
                       help="proxy: where no view confirms any proxy fragment, show the background along the ray "
                            "(sky, or the primary view rotated) instead of the nearest fragment coloured from the "
                            "view with the lower error: one geometry pass fewer")


def method_knobs(args) -> dict:
    """The knobs given on the command line: option -> value."""
    return {k[len("knob_"):]: v for k, v in vars(args).items() if k.startswith("knob_") and v is not None}


async def _until_signalled(run):
    """Run the coroutine ``run``; SIGTERM stops it as Ctrl-C does (the task is cancelled, so the
    recordings are closed and session.json says how far it got)."""
    import signal

    loop = asyncio.get_running_loop()
    task = asyncio.current_task()
    try:
        loop.add_signal_handler(signal.SIGTERM, task.cancel)
    except (NotImplementedError, RuntimeError):   # no signal handlers here (not the main thread, Windows)
        pass
    try:
        return await run
    finally:
        try:
            loop.remove_signal_handler(signal.SIGTERM)
        except (NotImplementedError, RuntimeError):
            pass


def cmd_client(args) -> int:
    from pibr.protocol.access import resolve_token

    from .app import run_client
    from .config import ClientConfig

    host, port = parse_host_port(args.connect)
    tls = None
    if args.tls_ca is not None or args.tls_pin is not None:
        from pibr.common.tls import ClientTLS

        tls = ClientTLS(args.tls_ca, args.tls_pin)
    if args.fov_deg is not None and args.eye_fov_deg is not None:
        raise ConfigError("give --fov or --eye-fov-deg, not both: the eyes' frustums set the field of view")
    cfg = arguments.config_from_args(
        ClientConfig, args, host=host, port=port, width=args.size[0], height=args.size[1],
        fov_deg=90.0 if args.fov_deg is None else args.fov_deg,
        depth_codec=args.depth_codec or "", lossless=not args.no_lossless, video=not args.no_video,
        options=method_knobs(args), token=resolve_token(args.token, args.token_file), tls=tls)
    from .connection import ServerClosed

    try:
        result = asyncio.run(_until_signalled(run_client(cfg)))
    except (ConnectionError, ServerClosed) as exc:
        print(f"pibr client: error: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, asyncio.CancelledError):
        print(f"pibr client: interrupted; what was displayed up to then is recorded in {args.out_dir}/ "
              f"(session.json says how far; 'pibr evaluate' scores it)", file=sys.stderr)
        return 130
    print(f"pibr client: {result.ticks} ticks, {result.frames_received} frames received, "
          f"{result.missed_deadlines} missed deadlines; recordings in {args.out_dir}/")
    if result.summary.get("proxies"):
        p = result.summary["proxies"]
        print(f"pibr client: proxies {p['objects']} objects, {p['bytes'] / 1e6:.2f} MB, received in "
              f"{p['transfer_ms']:.0f} ms (decoded in {p['decode_ms']:.0f} ms)")
    return 0
