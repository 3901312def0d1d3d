"""``pibr demo``, ``pibr evaluate`` and ``pibr bench ...``."""
from __future__ import annotations

import argparse
import math

from pibr.client.cli import parse_methods


def _size(text: str) -> tuple[int, int]:
    from pibr.common.address import parse_size
    from pibr.protocol.errors import ConfigError

    try:
        return parse_size(text)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _number(text: str, kind=float) -> float:
    try:
        v = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {'an integer' if kind is int else 'a number'}, got {text!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return v


def _floats(text: str) -> tuple:
    return tuple(_positive(part) for part in text.split(",") if part.strip())


def _sizes(text: str) -> tuple:
    return tuple(_size(part) for part in text.split(",") if part.strip())


_WINDOWS_HELP = ("head-trace windows: 'evaluation' (default: disjoint from every window a default was fitted "
                 "on), 'tuning', or TRACE@START+DURATION,... in seconds (see bench/windows.py)")


def _windows(text: str) -> tuple:
    from pibr.protocol.errors import ConfigError

    from .windows import parse_windows

    try:
        return parse_windows(text)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _codecs(text: str) -> tuple:
    codecs = tuple(part.strip() for part in text.split(",") if part.strip())
    bad = [c for c in codecs if c not in ("h264", "edge")]
    if bad or not codecs:
        raise argparse.ArgumentTypeError(f"expected h264, edge or both, got {text!r}")
    return codecs


def _numbers(text: str) -> tuple:
    vals = tuple(_positive(part) for part in text.split(",") if part.strip())
    if not vals:
        raise argparse.ArgumentTypeError(f"expected positive numbers separated by commas, got {text!r}")
    return vals


def _counts(text: str) -> tuple:
    return tuple(_positive_int(part) for part in text.split(",") if part.strip())


def _positive(text: str) -> float:
    v = _number(text)
    if v <= 0:
        raise argparse.ArgumentTypeError(f"must be positive, got {text}")
    return v


def _non_negative(text: str) -> float:
    v = _number(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return v


def _positive_int(text: str) -> int:
    v = _number(text, int)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {text}")
    return v


def _non_negative_int(text: str) -> int:
    v = _number(text, int)
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return v


def _fraction(text: str) -> float:
    v = _number(text)
    if not 0 < v <= 1:
        raise argparse.ArgumentTypeError(f"must be in (0, 1], got {text}")
    return v


def _offset(text: str) -> tuple:
    try:
        parts = tuple(float(x) for x in text.split(","))
    except ValueError:
        parts = ()
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"expected FORWARD,UP,TILT_DEG, got {text!r}")
    return parts


def _range(text: str) -> list:
    from .offset_search import parse_range

    try:
        return parse_range(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _angles(text: str) -> tuple:
    from pibr.server.config import MAX_EDGE_DEG, MIN_EDGE_DEG

    angles = tuple(_number(x.strip()) for x in text.split(",") if x.strip())
    if not angles or not all(MIN_EDGE_DEG <= a <= MAX_EDGE_DEG for a in angles):
        raise argparse.ArgumentTypeError(f"expected angles in {MIN_EDGE_DEG:g}..{MAX_EDGE_DEG:g} degrees, got {text!r}")
    return angles


def _names(text: str) -> tuple:
    names = tuple(x.strip() for x in text.split(",") if x.strip())
    if not names:
        raise argparse.ArgumentTypeError("name at least one")
    return names


def register(sub) -> None:
    from pibr.client.object_motion import CLIENT_MOTION_MODES

    d = sub.add_parser("demo", help="run server, relay and client on loopback and score the result",
                       description="Start a server, a 128 ms relay and a client as separate processes, replay a "
                                   "real head trace, then compare the methods against ground truth.")
    d.add_argument("--out", default="out", help="output directory (default out)")
    d.add_argument("--scene", default="room",
                   help="a built-in name, a scene description or an asset file (FILE#up=z for a Z-up asset)")
    d.add_argument("--up", choices=("y", "z", "auto"), default=None, help="an asset file's up axis (default auto)")
    d.add_argument("--trace", default="pred6dof-1")
    d.add_argument("--start", type=_non_negative, default=30.0,
                   help="seconds into the trace (default 30: an evaluation window, away from where defaults were tuned)")
    d.add_argument("--anchor", choices=("start", "origin", "none"), default="start",
                   help="how the trace is placed in the scene (see 'pibr client --help'; default start)")
    d.add_argument("--duration", type=_positive, default=6.0, help="seconds to replay (default 6)")
    d.add_argument("--rate", type=_positive, default=30.0, help="output rate Hz (default 30)")
    d.add_argument("--size", type=_size, default=(960, 540), metavar="WxH")
    d.add_argument("--latency-ms", type=_non_negative, default=128.0, help="round trip, split evenly (default 128)")
    d.add_argument("--method", type=parse_methods, default=("none", "rotation", "proxy"),
                   help="methods to compare, comma-separated (default none,rotation,proxy)")
    d.add_argument("--depth-codec", choices=("h264", "edge"), default="h264", help="depth transport")

    d.add_argument("--clock", choices=("virtual", "real"), default="virtual")
    d.add_argument("--flip-every", type=_non_negative_int, default=4, help="FLIP on every Nth frame, 0: never (default 4)")
    d.add_argument("--motion", choices=CLIENT_MOTION_MODES, default=None,
                   help="how the client brings moving objects to the display time (see 'pibr client --help'; "
                        "try --scene dynamic --motion flow)")
    d.set_defaults(func=cmd_demo)

    e = sub.add_parser("evaluate", help="score a client recording against ground truth",
                       description="Render ground truth for every displayed tick of a 'pibr client' recording and "
                                   "compute PSNR, SSIM, DSSIM, FLIP and hole fraction per method.")
    e.add_argument("run", help="the client's --out directory")
    e.add_argument("--scene", default=None, help="scene spec if the recording's scene name is not a built-in")
    e.add_argument("--flip-every", type=_non_negative_int, default=1)
    e.add_argument("--workers", type=_positive_int, default=2, help="metric worker processes (default 2)")
    e.add_argument("--no-video", action="store_true", help="skip side_by_side.mp4")
    e.set_defaults(func=cmd_evaluate)

    b = sub.add_parser("bench", help="benchmarks: speed, size and quality trades",
                       description="Benchmarks print a table and write JSON (and plots) to --out.")
    bs = b.add_subparsers(dest="bench", metavar="BENCH")
    bs.required = True
    s = bs.add_parser("server", help="server ms per frame by stage, and bitrate")
    s.add_argument("--scene", default="room")
    s.add_argument("--trace", default="pred6dof-1")
    s.add_argument("--frames", type=_positive_int, default=40)
    s.add_argument("--view-size", type=_size, default=(1024, 1024), metavar="WxH")
    s.add_argument("--projection", type=_names, default=("vertex", "tess"),
                   help="which to measure: vertex, tess, cube (default vertex,tess)")
    s.add_argument("--cube-scale", type=_positive, default=0.75,
                   help="projection cube: face size as a fraction of the view width (default 0.75)")
    s.add_argument("--max-edge-deg", type=_angles, default=None, metavar="DEG[,DEG...]",
                   help="edge angles to measure (default: the server's); several, or one that is not the "
                        "default, also compare each with a finer reference render")
    s.add_argument("--extra-view", choices=("auto", "on", "off", "both"), default="auto")
    s.add_argument("--lod", choices=("on", "off", "both"), default="on",
                   help="pre-tessellated copies chosen by the eye's distance (on, the server's), one copy for "
                        "the whole viewing region (off), or both; both also compare with the reference")
    s.add_argument("--accuracy", action="store_true",
                   help="compare every variant's primary view with a 2-degree reference render")
    s.add_argument("--bitrate-kbps", type=_positive, default=16000.0)
    s.add_argument("--out", default="out/bench")
    s.set_defaults(func=cmd_bench_server)
    c = bs.add_parser("client", help="client ms per frame by stage")
    c.add_argument("--scene", default="room")
    c.add_argument("--trace", default="pred6dof-1")
    c.add_argument("--frames", type=_positive_int, default=40)
    c.add_argument("--view-size", type=_size, default=(1024, 1024), metavar="WxH")
    c.add_argument("--size", type=_size, default=(960, 540), metavar="WxH", help="client output size")
    c.add_argument("--method", type=parse_methods, default=("none", "rotation", "proxy"))
    c.add_argument("--out", default="out/bench")
    c.set_defaults(func=cmd_bench_client)

    cov = bs.add_parser("coverage", help="pixels no transmitted view covers: primary, peeling, offset, both",
                        description="Reproduces Reinert et al.'s Figure 4: the fraction of displayed pixels that no "
                                    "transmitted view covers, for four dual-view variants, along real traces.")
    cov.add_argument("--scene", default="room")
    cov.add_argument("--windows", type=_windows, default="evaluation", help=_WINDOWS_HELP)
    cov.add_argument("--stride", type=_positive_int, default=2, help="measure every Nth displayed tick (default 2)")
    cov.add_argument("--latency-ms", type=_non_negative, default=128.0)
    cov.add_argument("--rate", type=_positive, default=30.0)
    cov.add_argument("--view-size", type=_size, default=(1024, 1024), metavar="WxH")
    cov.add_argument("--size", type=_size, default=(320, 180), metavar="WxH", help="displayed view size")
    cov.add_argument("--offset", type=_offset, default=None, metavar="F,U,TILT",
                     help="extra view offset (default: the scene's, else Reinert et al.'s 1.5,1.8,15)")
    cov.add_argument("--out", default="out/bench")
    cov.set_defaults(func=cmd_bench_coverage)

    i = bs.add_parser("ibr", help="none / rotation / proxy against ground truth, proxy speed against a floor",
                      description="Quality of the client methods at the given latency on real traces (in one "
                                  "process, on the virtual clock's schedule), the LoD trade, and proxy IBR's ms per "
                                  "frame next to a full-screen pass with the same texture lookups.")
    i.add_argument("--scene", default="room", help="scene spec (default room)")
    i.add_argument("--windows", type=_windows, default="evaluation", help=_WINDOWS_HELP)
    i.add_argument("--latency-ms", type=_non_negative, default=128.0, help="round trip (default 128)")
    i.add_argument("--rate", type=_positive, default=30.0, help="display rate Hz (default 30)")
    i.add_argument("--stride", type=_positive_int, default=2, help="score every Nth displayed tick (default 2)")
    i.add_argument("--size", type=_size, default=(960, 540), metavar="WxH", help="output size (default 960x540)")
    i.add_argument("--view-size", type=_size, default=(1024, 1024), metavar="WxH",
                   help="primary view size (default 1024x1024)")
    i.add_argument("--lod-targets", type=_floats, default=(), metavar="PX,...",
                   help="also score proxy at these LoD pixel targets, e.g. 2,16 (default: none)")
    i.add_argument("--lod-levels", type=_names, default=(), metavar="LEVEL,...",
                   help="also score proxy with every object at this level: original, proxy, box (default: none)")
    i.add_argument("--speed-sizes", type=_sizes, default=((960, 540), (1280, 720)), metavar="WxH,...",
                   help="output sizes of the speed comparison with the floor (default 960x540,1280x720; '' for none)")
    i.add_argument("--speed-frames", type=_positive_int, default=20, help="frames timed per size (default 20)")
    i.add_argument("--out", default="out/bench", help="output directory (default out/bench)")
    i.set_defaults(func=cmd_bench_ibr)

    cd = bs.add_parser("codec", help="depth codecs on rate-distortion curves at equal bitrate",
                       description="Bits per frame against disparity PSNR and 1 % outliers of the edge codec over its "
                                   "thresholds, H.264 depth alone (8- and 10-bit) at the edge codec's rates, "
                                   "Koniaris-style log depth with temporal coding and zstd, lossless 12-bit zstd; proxy "
                                   "DSSIM at equal total bitrate; the quantisers' error from 1 cm to 10 km. Full run "
                                   "(defaults): 7 evaluation windows x 2 s at 1024^2, about 20-30 min on 2 cores.")
    cd.add_argument("--scene", default="room")
    cd.add_argument("--windows", type=_windows, default="evaluation", help=_WINDOWS_HELP)
    cd.add_argument("--duration", type=_positive, default=2.0, help="seconds of each window (default 2)")
    cd.add_argument("--view-size", type=_size, default=(1024, 1024), metavar="WxH")
    cd.add_argument("--thresholds", type=_numbers, default=None, metavar="T,...",
                    help="edge codec significance thresholds (default 2,3.5,8,16,32,64,128)")
    cd.add_argument("--log-bits", type=_counts, default=None, metavar="B,...",
                    help="bits of the log-depth codec's settings (default 16,12,10,8)")
    cd.add_argument("--totals-kbps", type=_numbers, default=None, metavar="KBPS,...",
                    help="total bitrates (colour + depth) of the end-to-end comparison (default 4000,8000,16000)")
    cd.add_argument("--e2e-windows", type=_positive_int, default=2,
                    help="how many of the windows the end-to-end comparison runs on (default 2)")
    cd.add_argument("--size", type=_size, default=(960, 540), metavar="WxH",
                    help="client output size of the end-to-end comparison")
    cd.add_argument("--quick", action="store_true",
                    help="small run: 256x256 view, 1 s of the first two windows, 3 thresholds, 1 end-to-end window")
    cd.add_argument("--plot", default=None, help="also write the chart here (e.g. docs/depth_rd.png)")
    cd.add_argument("--out", default="out/bench")
    cd.set_defaults(func=cmd_bench_codec)

    cs = bs.add_parser("codec-speed", help="the edge codec's CPU ms stage by stage, bytes and PSNR, vs a baseline",
                       description="Encode and decode (with diffusion) of the edge codec on rendered frames along "
                                   "real traces, process CPU ms per stage; with --baseline, another pibr checkout "
                                   "runs interleaved frame by frame in its own process and the table shows both, "
                                   "the ratio, the bytes ratio and whether payloads are identical.")
    cs.add_argument("--scene", default="room")
    cs.add_argument("--windows", type=_windows, default="evaluation", help=_WINDOWS_HELP)
    cs.add_argument("--duration", type=_positive, default=1.0, help="seconds of each window (default 1)")
    cs.add_argument("--fps", type=_positive, default=10.0, help="server frames per second (default 10)")
    cs.add_argument("--view-size", type=_size, default=(1024, 1024), metavar="WxH")
    cs.add_argument("--baseline", default=None, metavar="CHECKOUT",
                    help="a pibr source tree to compare against, e.g. a git worktree of main")
    cs.add_argument("--out", default="out/bench")
    cs.set_defaults(func=cmd_bench_codec_speed)

    ps = bs.add_parser("proxy-speed", help="proxy's CPU ms against the passes it replaced, --no-carve and the floor",
                       description="CPU ms of proxy's passes in one run: the default carving, carve_all (the passes "
                                   "it replaced: the same image), both without inpainting (--no-inpaint), carve=False, "
                                   "the default and carve=False drawing every back face (cull=False), and the floor "
                                   "of 'pibr bench ibr', interleaved frame by frame on room frames along the "
                                   "evaluation windows, and how far the default's images are from carve_all's and "
                                   "cull=False's (and the two without inpainting from each other). Writes "
                                   "proxy_speed.json.")
    ps.add_argument("--scene", default="room")
    ps.add_argument("--sizes", type=_sizes, default=((960, 540), (1280, 720)), metavar="WxH,...",
                    help="output sizes (default 960x540,1280x720)")
    ps.add_argument("--frames", type=_positive_int, default=12, help="display samples (default 12)")
    ps.add_argument("--repeats", type=_positive_int, default=3, help="renders of each sample (default 3)")
    ps.add_argument("--out", default="out/bench")
    ps.set_defaults(func=cmd_bench_proxy_speed)

    pa = bs.add_parser("pareto", help="every method and knob: client ms against DSSIM (Reinert et al.'s Figure 9)",
                       description="Runs every client method with each of its knobs (and a zero-latency oracle) on "
                                   "the scenes and head-trace windows, scores each against ground truth (DSSIM, "
                                   "PSNR, FLIP, geometric and own holes) and times it at each output size. Writes "
                                   "pareto.json and pareto.png.")
    pa.add_argument("--scene", type=_names, default=("room",),
                    help="comma-separated scenes (default room; the sphere scene's frames are mostly sky on the "
                         "shared traces)")
    pa.add_argument("--method", type=parse_methods, default=None, help="only these methods (default: all)")
    pa.add_argument("--windows", type=_windows, default="evaluation", help=_WINDOWS_HELP)
    pa.add_argument("--latency-ms", type=_non_negative, default=128.0)
    pa.add_argument("--rate", type=_positive, default=30.0, help="display rate Hz (default 30)")
    pa.add_argument("--stride", type=_positive_int, default=8, help="score every Nth displayed tick (default 8)")
    pa.add_argument("--view-size", type=_size, default=(1024, 1024), metavar="WxH")
    pa.add_argument("--size", type=_size, default=(960, 540), metavar="WxH",
                    help="output size scored (default 960x540)")
    pa.add_argument("--speed-sizes", type=_sizes, default=((960, 540), (1280, 720)), metavar="WxH,...",
                    help="output sizes timed (default 960x540,1280x720)")
    pa.add_argument("--speed-frames", type=_positive_int, default=12,
                    help="frames timed per size and scene (default 12)")
    pa.add_argument("--flip-every", type=_non_negative_int, default=4, help="FLIP on every Nth scored frame, 0: never")
    pa.add_argument("--depth-codec", choices=("h264", "edge"), default="h264")
    pa.add_argument("--out", default="out/bench")
    pa.set_defaults(func=cmd_bench_pareto)

    tr = bs.add_parser("trade", help="each knob swept with the others at their defaults: quality against bits and ms",
                       description="Sweeps colour bitrate, x264 preset, keyframe interval, primary and extra view "
                                   "size, server fps, latency, jitter, a bandwidth cap, proxy tau and depth slack "
                                   "and the LoD settings, one at a time, for rotation, proxy, gridwarp and "
                                   "coarse-meshwarp: DSSIM, PSNR, FLIP, geometric holes, client and server CPU ms, "
                                   "total bits per frame. Writes trade.json and trade_KNOB.png per knob.")
    tr.add_argument("--knobs", type=_trade_knobs, default=None, metavar="NAME,...",
                    help="only these knobs (default all: bitrate, preset, keyint, view, extra, fps, latency, "
                         "jitter, cap, tau, slack, lod_resolution, lod_fraction)")
    tr.add_argument("--scenes", type=_names, default=("room",), help="comma-separated scenes (default room)")
    tr.add_argument("--windows", type=_windows, default="evaluation", help=_WINDOWS_HELP)
    tr.add_argument("--window-seconds", type=_positive, default=2.0,
                    help="the first seconds of each window (default 2; every server frame in them is rendered and "
                         "encoded, ~0.5 CPU-s each at 1024^2 here)")
    tr.add_argument("--stride", type=_positive_int, default=4,
                    help="score every Nth displayed tick at 30 Hz (default 4)")
    tr.add_argument("--size", type=_size, default=(960, 540), metavar="WxH", help="output size (default 960x540)")
    tr.add_argument("--flip-every", type=_non_negative_int, default=4, help="FLIP on every Nth scored tick, 0: never")
    tr.add_argument("--seed", type=_non_negative_int, default=0, help="jitter seed (default 0)")
    tr.add_argument("--out", default="out/bench")
    tr.set_defaults(func=cmd_bench_trade)

    dy = bs.add_parser("dynamic", help="moving objects at the display time: static, velocity, accel, flow and the "
                                       "oracle per latency; both flow coders",
                       description="Every way the client brings moving objects to the display time (proxy with "
                                   "--motion static, velocity, accel, flow, oracle; rotation with and without flow), "
                                   "at several round trips, on scenes that move: DSSIM and PSNR over the frame and "
                                   "over the moving objects' pixels, client ms, motion bits per frame; the error "
                                   "over time around a reversal and a stop; the motion flow's bits and error with "
                                   "both flow coders. Writes dynamic.json and dynamic.png.")
    dy.add_argument("--scene", type=_names, default=("dynamic", "room"), help="scenes that move (default dynamic,room)")
    dy.add_argument("--windows", type=_windows, default=None,
                    help="head-trace windows (default: pred6dof-2@50+2,synth-turns@5+2, parts of the evaluation "
                         "windows where the dynamic scene's objects are in view; " + _WINDOWS_HELP + ")")
    dy.add_argument("--latency-ms", type=_floats, default=(64.0, 128.0, 256.0), metavar="MS,...",
                    help="round trips (default 64,128,256)")
    dy.add_argument("--event-latency-ms", type=_positive, default=128.0,
                    help="round trip of the reversal and stop probes (default 128)")
    dy.add_argument("--rate", type=_positive, default=30.0, help="display rate Hz (default 30)")
    dy.add_argument("--stride", type=_positive_int, default=3, help="score every Nth displayed tick (default 3)")
    dy.add_argument("--event-stride", type=_positive_int, default=2,
                    help="score every Nth tick around the reversals and stops (default 2)")
    dy.add_argument("--view-size", type=_size, default=(512, 512), metavar="WxH",
                    help="server view size (default 512x512: a few minutes on 2 cores; the server's is 1024x1024)")
    dy.add_argument("--size", type=_size, default=(480, 270), metavar="WxH", help="output size (default 480x270)")
    dy.add_argument("--depth-codec", choices=("h264", "edge"), default="h264")
    dy.add_argument("--flow-coder", choices=("blocks", "edges"), default=None,
                    help="the motion flow the flow methods receive (default: the server's); both are measured")
    dy.add_argument("--out", default="out/bench")
    dy.set_defaults(func=cmd_bench_dynamic)

    sp = bs.add_parser("split", help="a one-mesh level, whole against cut into pieces: LoD, client ms, DSSIM",
                       description="Generates a one-mesh atrium (167k triangles) and serves it whole and cut into "
                                   "pieces (scenes/split.py): LoD build time, proxy's client ms and quality on "
                                   "synthetic walks inside it. Writes split.json.")
    sp.add_argument("--duration", type=_positive, default=6.0, help="seconds of each synthetic trace (default 6)")
    sp.add_argument("--stride", type=_positive_int, default=6, help="score every Nth displayed tick (default 6)")
    sp.add_argument("--size", type=_size, default=(960, 540), metavar="WxH")
    sp.add_argument("--out", default="out/bench")
    sp.set_defaults(func=cmd_bench_split)

    lo = bs.add_parser("lod", help="encaging level-of-detail proxies: triangles, enclosure, time per object",
                       description="Generate (or read from the cache) every object's encaging proxy and report the "
                                   "triangle counts, the fraction of original vertices enclosed and the time taken.")
    lo.add_argument("--scene", type=_names, default=("room",), help="comma-separated scene specs")
    lo.add_argument("--asset", type=_names, default=None, help="asset files to measure as well (default: the shipped real asset)")
    lo.add_argument("--resolution", type=int, default=128, help="voxels along an object's longest side")
    lo.add_argument("--fraction", type=_fraction, default=0.005, help="proxy triangles / original triangles")
    lo.add_argument("--no-cache", action="store_true",
                    help="generate every proxy afresh (timing this machine) instead of reading the LoD cache")
    lo.add_argument("--out", default="out/bench")
    lo.set_defaults(func=cmd_bench_lod)

    rt = bs.add_parser("realtime", help="server, relay and client processes on the wall clock: fps, missed "
                                        "deadlines, frame age, CPU; and the cost per session",
                       description="Runs each method with each depth codec as separate server, relay and client "
                                   "processes on the real clock and reports the server's fps, the client's output "
                                   "rate and missed deadlines, frame age p50/p99 and each process's CPU share; then "
                                   "1, 2, 4 ... clients on one server: server CPU-ms per delivered frame (virtual "
                                   "clock) and fps per client (real clock). Writes realtime.json.")
    rt.add_argument("--method", type=parse_methods, default=("rotation", "proxy"))
    rt.add_argument("--depth-codec", type=_codecs, default=("h264", "edge"), metavar="CODEC,...",
                    help="h264, edge or both (default h264,edge)")
    rt.add_argument("--clients", type=_counts, default=(1, 2, 4), metavar="N,...",
                    help="session counts of the cost-per-session runs ('' for none; default 1,2,4)")
    rt.add_argument("--duration", type=_positive, default=20.0, help="seconds of trace per real-clock run (default 20)")
    rt.add_argument("--scaling-duration", type=_positive, default=6.0,
                    help="seconds of trace per client of the virtual-clock cost runs (default 6)")
    rt.add_argument("--scene", default="room")
    rt.add_argument("--trace", default="pred6dof-1")
    rt.add_argument("--start", type=_non_negative, default=30.0, help="seconds into the trace (default 30)")
    rt.add_argument("--rate", type=_positive, default=30.0, help="output rate Hz (default 30)")
    rt.add_argument("--size", type=_size, default=(960, 540), metavar="WxH", help="output size (default 960x540)")
    rt.add_argument("--latency-ms", type=_non_negative, default=128.0, help="round trip (default 128)")
    rt.add_argument("--server-fps", type=_positive, default=10.0, help="server frame rate asked for (default 10)")
    rt.add_argument("--view-size", type=_size, default=None, metavar="WxH",
                    help="the server's primary view size (default: the server's, sized for the output: "
                         "1088x1088 at 960x540)")
    rt.add_argument("--extra-view", choices=("auto", "on", "off"), default=None,
                    help="the server's extra view (default: the server's, auto)")
    rt.add_argument("--out", default="out/bench")
    rt.set_defaults(func=cmd_bench_realtime)

    from .hostile import KINDS

    so = bs.add_parser("soak", help="a server under legitimate clients and hostile peers: equal records, flat "
                                    "memory, no traceback",
                       description="Runs each legitimate client alone (virtual clock), then all of them again and "
                                   "again for --duration seconds beside hostile peers of every kind (malformed "
                                   "messages, slow and idle connections, a far-future clock, a non-reading client, "
                                   "connection floods). Passes when every soaked run equals its solo run, the "
                                   "server's memory and open files stay flat and its log has no traceback. "
                                   "Writes soak.json; exit code 1 when it fails.")
    so.add_argument("--duration", type=_positive, default=60.0, help="seconds of soak (default 60)")
    so.add_argument("--clients", type=int, default=8, help="legitimate clients (default 8)")
    so.add_argument("--kinds", default=",".join(KINDS), metavar="KIND,...",
                    help="hostile kinds (default all: " + ", ".join(KINDS) + ")")
    so.add_argument("--scene", default="room")
    so.add_argument("--trace", default="pred6dof-1")
    so.add_argument("--method", default="rotation", help="the legitimate clients' method (default rotation)")
    so.add_argument("--run-duration", type=_positive, default=1.0,
                    help="seconds of trace per legitimate run (default 1)")
    so.add_argument("--view-size", type=_size, default=(256, 256), metavar="WxH",
                    help="the server's primary view size (default 256x256: many sessions on two cores)")
    so.add_argument("--seed", type=int, default=0)
    so.add_argument("--out", default="out/bench")
    so.set_defaults(func=cmd_bench_soak)

    fz = bs.add_parser("fuzz", help="mutation fuzzing of every parser a peer or a file feeds: documented errors only",
                       description="Mutates valid inputs (bytes, text, JSON and TOML structure) of the wire decoder, "
                                   "the edge codec and quadtree decoders, the proxy bundle decoder, the head-trace "
                                   "importers and the scene loader, runs each in a worker process with a per-input "
                                   "deadline, and reports per parser the inputs, accepted inputs, documented errors "
                                   "by class, undocumented exceptions and hangs (both must be 0: the exit status is "
                                   "1 otherwise; failing inputs are saved), peak memory and inputs/s. Writes "
                                   "fuzz.json.")
    fz.add_argument("--inputs", type=_positive_int, default=100_000, help="inputs per parser (default 100000)")
    fz.add_argument("--seed", type=_non_negative_int, default=0, help="mutation seed (default 0)")
    fz.add_argument("--parsers", type=_names, default=None, metavar="NAME,...",
                    help="wire, edge, quadtree, proxy, trace, scene (default: all)")
    fz.add_argument("--timeout-s", type=_positive, default=10.0,
                    help="an input running longer than this is a hang (default 10)")
    fz.add_argument("--replay", default=None, metavar="FILE",
                    help="run one saved input (OUT/fuzz_inputs/PARSER-KIND-INDEX.*) again and show what it raises")
    fz.add_argument("--out", default="out/bench")
    fz.set_defaults(func=cmd_bench_fuzz)

    o = bs.add_parser("optimize-offset", help="search the extra view's offset for the fewest holes",
                      description="Exhaustive (or coarse-to-fine) search over forward offset, height and tilt of "
                                  "the extra view, minimising the mean missing-pixel fraction over traces.")
    o.add_argument("--scene", default="room")
    o.add_argument("--windows", type=_windows, default="tuning",
                   help="where to fit: 'tuning' (default), or TRACE@START+DURATION,... (a fit on the "
                        "evaluation windows would make them tuning data)")
    o.add_argument("--latency-ms", type=_non_negative, default=128.0)
    o.add_argument("--frames", type=_positive_int, default=12, help="displayed frames per window (default 12)")
    o.add_argument("--forward", type=_range, default="-1:2:0.5", help="metres, START:STOP:STEP or a,b,c")
    o.add_argument("--up", type=_range, default="0:1.8:0.3", help="metres")
    o.add_argument("--tilt", type=_range, default="-30:45:15", help="degrees down")
    o.add_argument("--method", choices=("exhaustive", "coarse-to-fine"), default="exhaustive")
    o.add_argument("--objective", choices=("all", "geometry"), default="all",
                   help="missing fraction over all pixels, or only over pixels showing geometry")
    o.add_argument("--view-size", type=_size, default=(512, 512), metavar="WxH")
    o.add_argument("--size", type=_size, default=(192, 108), metavar="WxH")
    o.add_argument("--out", default="out/bench")
    o.set_defaults(func=cmd_bench_offset)


def realtime_server_args(view_size, extra_view) -> tuple:
    """The server options ``pibr bench realtime`` passes on: only those the user set."""
    out = () if view_size is None else ("--view-size", "%dx%d" % tuple(view_size))
    return out + (() if extra_view is None else ("--extra-view", extra_view))


def cmd_bench_realtime(args) -> int:
    from .demo import check_inputs
    from .realtime import print_realtime, run_realtime_bench

    check_inputs(args.scene, args.trace, args.start, args.duration)
    r = run_realtime_bench(out_dir=args.out, methods=args.method, depth_codecs=args.depth_codec,
                           clients=args.clients, duration_s=args.duration, scaling_duration_s=args.scaling_duration,
                           scene=args.scene, trace=args.trace, start_s=args.start, rate_hz=args.rate,
                           size=args.size, latency_ms=args.latency_ms, server_fps=args.server_fps,
                           server_args=realtime_server_args(args.view_size, args.extra_view))
    print_realtime(r)
    print(f"written: {args.out}/realtime.json")
    return 0


def cmd_bench_soak(args) -> int:
    from pibr.protocol.errors import ConfigError

    from .demo import check_inputs
    from .hostile import KINDS
    from .soak import print_soak, run_soak

    kinds = tuple(k.strip() for k in args.kinds.split(",") if k.strip())
    unknown = [k for k in kinds if k not in KINDS]
    if unknown:
        raise ConfigError(f"unknown hostile kind(s) {', '.join(unknown)}; kinds: {', '.join(KINDS)}")
    if args.clients < 1:
        raise ConfigError(f"--clients must be at least 1, got {args.clients}")
    check_inputs(args.scene, args.trace, 0.0, args.clients * (args.run_duration + 1.0))
    r = run_soak(args.out, duration_s=args.duration, clients=args.clients, kinds=kinds, scene=args.scene,
                 trace=args.trace, method=args.method, run_s=args.run_duration,
                 view_size="%dx%d" % args.view_size, seed=args.seed)
    print_soak(r)
    print(f"written: {args.out}/soak.json")
    return 0 if r["passed"] else 1


def cmd_bench_fuzz(args) -> int:
    from .fuzz import print_fuzz_table, replay, run_fuzz_bench

    if args.replay is not None:
        return replay(args.replay)
    r = run_fuzz_bench(parsers=args.parsers, inputs=args.inputs, seed=args.seed, timeout_s=args.timeout_s,
                       out_dir=args.out)
    print_fuzz_table(r)
    print(f"written: {args.out}/fuzz.json")
    return 0 if r["ok"] else 1


def cmd_bench_dynamic(args) -> int:
    from .dynamic_bench import DEFAULT_WINDOWS, print_dynamic_tables, run_dynamic_bench

    r = run_dynamic_bench(scenes=args.scene, windows=args.windows or DEFAULT_WINDOWS, latencies=args.latency_ms,
                          rate_hz=args.rate, stride=args.stride, view_size=args.view_size, out_size=args.size,
                          depth_codec=args.depth_codec, flow_coder=args.flow_coder,
                          event_latency_ms=args.event_latency_ms, event_stride=args.event_stride, out_dir=args.out)
    print_dynamic_tables(r)
    print(f"written: {args.out}/dynamic.json, {args.out}/dynamic.png")
    return 0


def cmd_bench_split(args) -> int:
    from .split_bench import print_split_table, run_split_bench

    r = run_split_bench(out_dir=args.out, duration_s=args.duration, stride=args.stride, out_size=args.size)
    print_split_table(r)
    print(f"written: {args.out}/split.json")
    return 0


def cmd_bench_pareto(args) -> int:
    from .pareto import print_pareto_table, run_pareto_bench

    result = run_pareto_bench(scenes=args.scene, methods=args.method, windows=args.windows,
                              latency_ms=args.latency_ms, rate_hz=args.rate, stride=args.stride,
                              view_size=args.view_size, out_size=args.size, speed_sizes=args.speed_sizes,
                              speed_frames=args.speed_frames, flip_every=args.flip_every,
                              depth_codec=args.depth_codec, out_dir=args.out)
    print_pareto_table(result)
    print(f"written: {args.out}/pareto.json, pareto.png")
    return 0


def _trade_knobs(text: str) -> tuple:
    from pibr.protocol.errors import ConfigError

    from .trade import parse_knobs

    try:
        return parse_knobs(text)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def cmd_bench_trade(args) -> int:
    from .trade import KNOBS, print_trade_tables, run_trade_bench

    knobs = args.knobs or tuple(KNOBS)
    result = run_trade_bench(scenes=args.scenes, knobs=knobs, windows=args.windows, window_s=args.window_seconds,
                             stride=args.stride, out_size=args.size, flip_every=args.flip_every, seed=args.seed, out_dir=args.out)
    print_trade_tables(result)
    print(f"written: {args.out}/trade.json, " + ", ".join(f"trade_{k}.png" for k in knobs))
    return 0


def cmd_demo(args) -> int:
    from .demo import print_report, run_demo

    from pibr.scenes.registry import with_up

    metrics = run_demo(out_dir=args.out, scene=with_up(args.scene, args.up), trace=args.trace, start_s=args.start,
                       duration_s=args.duration, rate_hz=args.rate, size=args.size, latency_ms=args.latency_ms,
                       methods=args.method, clock=args.clock, flip_every=args.flip_every, anchor=args.anchor,
                       server_args=("--depth-codec", args.depth_codec),
                       client_args=("--motion", args.motion) if args.motion else ())
    print_report(metrics, args.out)
    return 0


def cmd_evaluate(args) -> int:
    from .evaluate import evaluate_run, summary_table

    metrics = evaluate_run(args.run, scene_spec=args.scene, flip_every=args.flip_every, workers=args.workers,
                           side_by_side=not args.no_video)
    print(summary_table(metrics))
    print(f"written: {args.run}/metrics.json, metrics_frames.csv, quality.png"
          + ("" if args.no_video else ", side_by_side.mp4"))
    return 0


def cmd_bench_server(args) -> int:
    from .pipeline_bench import bench_server, print_server_table

    result = bench_server(scene_spec=args.scene, trace=args.trace, frames=args.frames, view_size=args.view_size,
                          projections=args.projection, extra_view=args.extra_view, bitrate_kbps=args.bitrate_kbps,
                          edge_angles=args.max_edge_deg, out_dir=args.out,
                          lod={"on": (True,), "off": (False,), "both": (False, True)}[args.lod],
                          accuracy=args.accuracy, cube_scale=args.cube_scale)
    print_server_table(result)
    return 0


def cmd_bench_client(args) -> int:
    from .pipeline_bench import bench_client, print_client_table

    result = bench_client(scene_spec=args.scene, trace=args.trace, frames=args.frames, view_size=args.view_size,
                          out_size=args.size, methods=args.method, out_dir=args.out)
    print_client_table(result)
    return 0


def cmd_bench_coverage(args) -> int:
    from .coverage import print_coverage_table, run_coverage_bench

    result = run_coverage_bench(scene_spec=args.scene, windows=args.windows, latency_ms=args.latency_ms,
                                rate_hz=args.rate, view_size=args.view_size, out_size=args.size, offset=args.offset,
                                stride=args.stride, out_dir=args.out)
    print_coverage_table(result)
    print(f"written: {args.out}/coverage.json, {args.out}/coverage.png")
    return 0


def cmd_bench_ibr(args) -> int:
    from pibr.protocol.errors import ConfigError

    from .ibr_bench import print_ibr_tables, run_ibr_bench

    bad = [lv for lv in args.lod_levels if lv not in ("original", "proxy", "box")]
    if bad:
        raise ConfigError(f"--lod-levels: unknown level(s) {', '.join(bad)}; expected original, proxy, box")
    r = run_ibr_bench(scene_spec=args.scene, windows=args.windows, latency_ms=args.latency_ms, rate_hz=args.rate,
                      view_size=args.view_size, out_size=args.size, stride=args.stride, lod_targets=args.lod_targets,
                      lod_levels=args.lod_levels, speed_sizes=args.speed_sizes, speed_frames=args.speed_frames,
                      out_dir=args.out)
    print_ibr_tables(r)
    print(f"written: {args.out}/ibr.json")
    return 0


def cmd_bench_codec(args) -> int:
    from .codec_bench import (DEFAULT_LOG_BITS, DEFAULT_THRESHOLDS, DEFAULT_TOTALS_KBPS, print_codec_table,
                              run_codec_bench)

    opts = dict(scene_spec=args.scene, windows=args.windows, window_s=args.duration, view_size=args.view_size,
                thresholds=args.thresholds or DEFAULT_THRESHOLDS, log_bits=args.log_bits or DEFAULT_LOG_BITS,
                totals_kbps=args.totals_kbps or DEFAULT_TOTALS_KBPS, e2e_windows=args.e2e_windows,
                out_size=args.size, out_dir=args.out, plot_path=args.plot)
    if args.quick:
        opts.update(windows=args.windows[:2], window_s=min(args.duration, 1.0), view_size=(256, 256),
                    thresholds=args.thresholds or (3.5, 16.0, 64.0), e2e_windows=1, out_size=(480, 270))
    r = run_codec_bench(**opts)
    print_codec_table(r)
    print(f"written: {args.out}/codec.json, {args.out}/codec.png" + (f", {args.plot}" if args.plot else ""))
    return 0


def cmd_bench_proxy_speed(args) -> int:
    from .proxy_speed import print_table, run
    from .results import write_result

    r = run(args.sizes, args.frames, args.repeats, args.scene)
    print_table(r)
    write_result(args.out, "proxy_speed.json", {"benchmark": "proxy-speed", "scene": args.scene,
                                                 "window": "evaluation windows (speed only)", "sizes": r})
    print(f"written: {args.out}/proxy_speed.json")
    return 0


def cmd_bench_codec_speed(args) -> int:
    from .codec_speed import print_codec_speed, run_codec_speed

    r = run_codec_speed(scene_spec=args.scene, windows=args.windows, window_s=args.duration, fps=args.fps,
                        view_size=args.view_size, baseline=args.baseline, out_dir=args.out)
    print_codec_speed(r)
    print(f"written: {args.out}/codec_speed.json")
    return 0


def cmd_bench_lod(args) -> int:
    from .lod_bench import print_lod_table, run_lod_bench

    r = run_lod_bench(scene_specs=args.scene, assets=args.asset, resolution=args.resolution,
                      target_fraction=args.fraction, out_dir=args.out, use_cache=not args.no_cache)
    print_lod_table(r)
    print(f"written: {args.out}/lod.json")
    return 0


def cmd_bench_offset(args) -> int:
    from .offset_search import search_offset

    forward, up, tilt = (args.forward, args.up, args.tilt)
    forward, up, tilt = (a if isinstance(a, list) else _range(a) for a in (forward, up, tilt))
    r = search_offset(scene_spec=args.scene, windows=args.windows, latency_ms=args.latency_ms,
                      frames_per_window=args.frames, forward=forward, up=up, tilt=tilt,
                      method=args.method, view_size=args.view_size, out_size=args.size, objective=args.objective,
                      out_dir=args.out)
    b = r["best"]
    print(f"pibr bench optimize-offset: {r['method']} search, {r['evaluations']} offsets x {r['frames']} frames")
    print(f"best offset: forward {b['forward']:g} m, up {b['up']:g} m, tilt {b['tilt']:g} deg down -> "
          f"{100 * b['missing']:.2f} % missing pixels")
    print(f"use it: pibr serve --extra-offset {b['forward']:g},{b['up']:g},{b['tilt']:g}")
    print(f"written: {args.out}/offset_search.json, {args.out}/offset_search.png")
    return 0
