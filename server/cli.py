"""``pibr serve`` and ``pibr relay``."""
from __future__ import annotations

import asyncio
import sys

from pibr.common import arguments
from pibr.common.address import parse_host_port
from pibr.protocol.atlas import COLOUR_SCALES
from pibr.protocol.depth_codecs import AUTO, DEPTH_CODECS
from pibr.protocol.motion_flow import DEFAULT_FLOW_CODER, FLOW_CODERS

from .config import DEFAULT_PORT, RATE_CONTROL_MODES
from .relay import DEFAULT_BUFFER_BYTES, DEFAULT_MAX_CONNECTIONS
from .stream_adaptation import STARTS


def _announce(what: str):
    def ready(host, port):
        print(f"pibr {what}: listening on {host}:{port}", flush=True)
    return ready


TOKEN_HELP = ("access token every client must send: prefer --token-file or the PIBR_TOKEN environment variable, "
              "since a command line is visible to other users in ps")


def _add_access_options(p, what: str) -> None:
    """--token/--token-file and --tls-cert/--tls-key of a listening process."""
    g = p.add_argument_group("access (needed to listen on anything but loopback)")
    g.add_argument("--token-file", metavar="FILE",
                   help="read the access token from the first line of FILE; with a token (this, $PIBR_TOKEN or "
                        "--token) every client must send it, also on loopback. Listening on any other address "
                        "needs one")
    g.add_argument("--token", metavar="TEXT", help=TOKEN_HELP)
    g.add_argument("--tls-cert", metavar="FILE",
                   help=f"serve TLS (1.2 or newer) with this PEM certificate chain; clients then connect with "
                        f"--tls-ca or --tls-pin (the {what} prints its certificate's SHA-256 fingerprint)")
    g.add_argument("--tls-key", metavar="FILE", help="the certificate's PEM private key (unencrypted)")


def _token(args):
    from pibr.protocol.access import resolve_token

    return resolve_token(args.token, args.token_file)


def _print_fingerprint(command: str, cert_file: str | None) -> None:
    if cert_file is not None:
        from pibr.common.tls import certificate_fingerprint

        fp = certificate_fingerprint(cert_file)
        print(f"pibr {command}: TLS certificate sha256 {fp} (clients may pin it: --tls-pin {fp})", flush=True)


def register(sub) -> None:
    from .renderer import DEFAULT_PROJECTION, MAX_EDGE_ANGLE_DEG, PROJECTIONS

    p = sub.add_parser("serve", help="run the rendering server",
                       description="Serve wide-angle views of a scene to pibr clients over TCP.")
    p.add_argument("--scene", default="room", help="default scene: a built-in name (see 'pibr scenes'), "
                   "a scene description (.toml/.json) or an asset file (default: room)")
    p.add_argument("--up", choices=("y", "z", "auto"), default=None,
                   help="an asset file's up axis (default auto: decided from its geometry; see 'pibr scenes --show')")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default 127.0.0.1, this machine only; any other needs a token)")
    p.add_argument("--port", type=int, default=DEFAULT_PORT, help=f"TCP port, 0 for any free one (default {DEFAULT_PORT})")
    p.add_argument("--fps", type=float, default=10.0, help="server frame rate (default 10)")
    p.add_argument("--view-size", type=arguments.size, default=None, metavar="WxH",
                   help="primary wide-angle view size; the extra view is half (default: sized for each client's "
                        "output, 1.12 x its angular density, as Reinert et al.; 'pibr scenes --plan')")
    p.add_argument("--extra-view", choices=("auto", "on", "off"), default="auto",
                   help="render the dual view's extra view: when it measurably adds coverage (auto, see "
                        "'pibr scenes --plan'), always, never")
    p.add_argument("--extra-scale", type=float, default=0.5, metavar="S",
                   help="the extra view's side over the primary view's, 0.125..1 (default 0.5; "
                        "'pibr bench trade --knobs extra' measures it)")
    p.add_argument("--no-peel-marker", action="store_true",
                   help="the extra view leaves peeled pixels empty like sky instead of marking them (saves the "
                        "early depth test: about a quarter of the extra view's render time; clients then cannot "
                        "take sky from it)")
    p.add_argument("--extra-offset", type=arguments.offset, default=None, metavar="F,U,TILT",
                   help="extra view offset: metres forward, metres up, degrees tilted down (default: the "
                        "scene's, else Reinert et al.'s 1.5,1.8,15)")
    p.add_argument("--bitrate-kbps", type=float, default=16000.0, help="H.264 bitrate (default 16000)")
    p.add_argument("--keyint", type=int, default=30, help="H.264 keyframe interval in frames (default 30)")
    p.add_argument("--preset", default="ultrafast", help="x264 preset (default ultrafast)")
    p.add_argument("--projection", choices=PROJECTIONS, default=DEFAULT_PROJECTION,
                   help=f"wide-angle rasterisation: pre-tessellated vertex projection, tessellation shader or "
                        f"cube faces resampled (the primary view only) "
                        f"(default {DEFAULT_PROJECTION}; 'pibr bench server' measures them)")
    p.add_argument("--max-edge-deg", type=float, default=MAX_EDGE_ANGLE_DEG, metavar="DEG",
                   help=f"longest triangle edge, as a view angle, drawn straight in the wide-angle projection: "
                        f"smaller follows its curves more closely and costs more triangles (default "
                        f"{MAX_EDGE_ANGLE_DEG:g}; 'pibr bench server --max-edge-deg 3,6,12' measures the trade)")
    p.add_argument("--server-delay-ms", type=float, default=20.0,
                   help="virtual clock: modelled render + encode time of a frame (default 20)")
    p.add_argument("--depth-codec", choices=(AUTO, *DEPTH_CODECS), default=AUTO,
                   help="depth transport: 8-bit disparity in the H.264 atlas, the edge codec, or auto (default: "
                        "H.264 unless a stated bandwidth favours the edge codec; 'pibr scenes --plan')")
    p.add_argument("--bandwidth-kbps", type=float, default=None, metavar="KBPS",
                   help="the most a session may send; streams are fitted into it (default: no cap)")
    p.add_argument("--edge-kbps", type=float, default=0.0,
                   help="edge codec: target bitrate of the depth streams, reached by scaling the edge threshold "
                        "(default 0: a fixed threshold)")
    p.add_argument("--edge-perceptual", action="store_true",
                   help="edge codec: weight edges by their visibility in the colour (contrast transducer)")
    p.add_argument("--edge-no-temporal", action="store_true", help="edge codec: no temporal context")
    p.add_argument("--flow-coder", choices=tuple(FLOW_CODERS), default=DEFAULT_FLOW_CODER,
                   help="motion flow of scenes that move: the moving mask and 8x8 block means (blocks), or "
                        "Pajak et al.'s edge samples diffused on the client (edges) ('pibr bench dynamic' "
                        f"measures both; default {DEFAULT_FLOW_CODER})")
    p.add_argument("--rate-control", choices=RATE_CONTROL_MODES, default="on",
                   help="on the real clock, hold --fps by making each frame at the best level whose predicted cost "
                        "fits its interval (the extra view on every 2nd, 4th or 8th frame, longer straight edges, the "
                        "primary view rendered at 1/2 or 1/3 and upsampled); each frame's level goes to the client "
                        "and the log (default on; the virtual clock has no deadline and makes every frame whole)")
    p.add_argument("--colour-scale", type=float, choices=COLOUR_SCALES, default=1.0,
                   help="send the views' colour at this scale of their size: 0.5 sends the colour of a quarter of "
                        "the pixels, a different one of each 2x2 block every frame, and the client rebuilds the rest "
                        "from its previous views reprojected with depth (Pajak et al. 2011; depth stays whole; "
                        "'pibr bench upsampling' measures it; default 1)")
    p.add_argument("--max-sessions", type=int, default=8,
                   help="sessions served at once, counted from a valid Hello (default 8)")
    p.add_argument("--admit-wait-s", type=float, default=5.0, metavar="S",
                   help="a Hello that finds every session slot taken waits up to S seconds for one to free, "
                        "first come first served, before 'server full' (default 5; 0: refuse at once)")
    p.add_argument("--max-pending", type=int, default=64, metavar="N",
                   help="connections still to send their Hello; beyond N the oldest is dropped (default 64)")
    p.add_argument("--predict", choices=("none", "velocity", "accel", "kalman"), default="kalman",
                   help="render each frame for the head pose predicted as far ahead as the client reports its "
                        "frames are seen (server/pose_prediction.py; 'pibr bench predict' measures each: the "
                        "Kalman filter cut proxy's DSSIM by a third at 128 ms; default kalman, none renders for "
                        "the pose as it came)")
    p.add_argument("--adapt", choices=("on", "off"), default="off",
                   help="adapt the stream to the link the client reports: the colour's bitrate, the edge codec's "
                        "rate, and under the floor the frame rate and the primary view's size, for frames that stay "
                        "young (server/stream_adaptation.py; default off: 'pibr bench network' finds it far ahead of "
                        "a static 16 Mbit/s on changing links but behind the best static rate in hindsight, and "
                        "short of its goals on the wall clock)")
    p.add_argument("--adapt-start", choices=STARTS, default="foot",
                   help="with --adapt on, where the stream starts: foot (a frame every 4 ticks, the primary view at "
                        "half its side, the default) or probe (half the link's rate the client measured on the "
                        "proxy bundle, when it asked for proxies; on the virtual clock with no modelled link, "
                        "the session's bitrate; 'pibr bench network --adapt-start foot,probe' compares them: "
                        "better first seconds, older frames when a link halves soon after)")
    p.add_argument("--silent-slot-s", type=float, default=2.0, metavar="S",
                   help="a session that has sent no pose S seconds after its Welcome gives its slot to a Hello "
                        "waiting for one (default 2; a running client sends a pose every tick)")
    p.add_argument("--hello-timeout-s", type=float, default=10.0, metavar="S",
                   help="a connection must send its whole Hello within S seconds (default 10)")
    p.add_argument("--idle-timeout-s", type=float, default=15.0, metavar="S",
                   help="real clock: close a session whose client sends no pose for S seconds, or reads nothing "
                        "for as long (default 15; a client sends a pose every output tick)")
    p.add_argument("--idle-timeout-virtual-s", type=float, default=30.0, metavar="S",
                   help="virtual clock: the same; longer because a client may work long on each tick (default 30; "
                        "the longest wait measured, every method at 960x540 on a loaded 2-core machine, was 5.4 s)")
    p.add_argument("--max-clock-lead-s", type=float, default=10.0, metavar="S",
                   help="virtual clock: a client's clock may run at most S seconds (plus one frame interval and "
                        "the server delay) ahead of the next frame (default 10)")
    p.add_argument("--max-in-flight", type=int, default=3, metavar="N",
                   help="real clock: render a new frame only while fewer than N sent frames wait to be decoded "
                        "by the client (default 3: enough for a 200 ms round trip at 10 fps)")
    _add_access_options(p, "server")
    p.set_defaults(func=cmd_serve)

    r = sub.add_parser("relay", help="inject latency between clients and a server",
                       description="Relay pibr connections, adding delay, jitter and a bandwidth cap or a bandwidth trace "
                                   "per direction.")
    r.add_argument("--listen", default="127.0.0.1:7451", help="HOST:PORT to accept clients on (port 0: any)")
    r.add_argument("--upstream", default=f"127.0.0.1:{DEFAULT_PORT}", help="HOST:PORT of the server")
    r.add_argument("--up-ms", type=float, default=64.0, help="client -> server one-way delay (default 64)")
    r.add_argument("--down-ms", type=float, default=64.0, help="server -> client one-way delay (default 64)")
    r.add_argument("--jitter-ms", type=float, default=0.0, help="uniform +- jitter on each direction (default 0)")
    r.add_argument("--kbps", type=float, default=0.0, help="bandwidth cap per direction, 0 = none (default 0)")
    r.add_argument("--down-trace", metavar="TRACE",
                   help="server -> client bandwidth replayed from a trace, looping from each session's start: a "
                        "built-in (pibr link list) or a file of Mahimahi delivery opportunities or t,kbps rows "
                        "(instead of --kbps on that direction)")
    r.add_argument("--up-trace", metavar="TRACE", help="client -> server bandwidth from a trace (as --down-trace)")
    r.add_argument("--seed", type=int, default=0,
                   help="jitter seed; each session's jitter follows from it and the client's Hello, so a replay "
                        "through any relay with the same seed is identical (default 0)")
    r.add_argument("--max-connections", type=int, default=DEFAULT_MAX_CONNECTIONS, metavar="N",
                   help=f"clients relayed at once, counted from their Hello; one more gets an error (default "
                        f"{DEFAULT_MAX_CONNECTIONS})")
    r.add_argument("--max-pending", type=int, default=64, metavar="N",
                   help="connections still to send their Hello; beyond N the oldest is dropped (default 64)")
    r.add_argument("--buffer-mib", type=int, default=DEFAULT_BUFFER_BYTES >> 20, metavar="MIB",
                   help=f"most bytes held per direction of each connection, in MiB: when full, the relay stops "
                        f"reading that direction's sender (default {DEFAULT_BUFFER_BYTES >> 20}, at least one "
                        f"message: 17)")
    _add_access_options(r, "relay")
    u = r.add_argument_group("TLS towards the server")
    u.add_argument("--upstream-tls-ca", metavar="FILE",
                   help="connect to the server with TLS, verifying its certificate against this PEM CA file")
    u.add_argument("--upstream-tls-pin", metavar="SHA256",
                   help="connect to the server with TLS, accepting only the certificate with this SHA-256 "
                        "fingerprint (as 'pibr serve' prints it)")
    r.set_defaults(func=cmd_relay)


def cmd_serve(args) -> int:
    from pibr.scenes.registry import with_up

    from .app import run_server
    from .config import EdgeSettings, ServerConfig

    config = arguments.config_from_args(
        ServerConfig, args, scene=with_up(args.scene, args.up), peel_marker=not args.no_peel_marker,
        edge=EdgeSettings(kbps=args.edge_kbps, temporal=not args.edge_no_temporal, perceptual=args.edge_perceptual),
        token=_token(args))
    _print_fingerprint("serve", config.tls_cert)
    try:
        asyncio.run(run_server(config, _announce("serve")))
    except KeyboardInterrupt:
        print("pibr serve: stopped", file=sys.stderr)
    return 0


def cmd_relay(args) -> int:
    from pibr.protocol.errors import ConfigError
    from pibr.common.link import LinkParams

    from .relay import RelayConfig, run_relay

    from pibr.common.bandwidth import load_bandwidth_trace

    up_trace = load_bandwidth_trace(args.up_trace) if args.up_trace else None
    down_trace = load_bandwidth_trace(args.down_trace) if args.down_trace else None
    try:
        up = LinkParams(args.up_ms, args.jitter_ms, 0.0 if up_trace else args.kbps, up_trace)
        down = LinkParams(args.down_ms, args.jitter_ms, 0.0 if down_trace else args.kbps, down_trace)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    upstream_tls = None
    if args.upstream_tls_ca is not None or args.upstream_tls_pin is not None:
        from pibr.common.tls import ClientTLS

        upstream_tls = ClientTLS(args.upstream_tls_ca, args.upstream_tls_pin)
    if not 1 <= args.buffer_mib <= 1 << 20:
        raise ConfigError(f"--buffer-mib must be in 1..{1 << 20}, got {args.buffer_mib}")
    config = RelayConfig(parse_host_port(args.listen), parse_host_port(args.upstream), up, down, args.seed,
                         buffer_bytes=args.buffer_mib << 20, max_connections=args.max_connections,
                         max_pending=args.max_pending,
                         token=_token(args), tls_cert=args.tls_cert, tls_key=args.tls_key,
                         upstream_tls=upstream_tls)
    _print_fingerprint("relay", config.tls_cert)
    try:
        asyncio.run(run_relay(config, _announce("relay")))
    except KeyboardInterrupt:
        print("pibr relay: stopped", file=sys.stderr)
    return 0
