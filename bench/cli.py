"""``pibr demo``, ``pibr evaluate`` and ``pibr bench ...``: what each command takes (bench/commands.py
runs them)."""
from __future__ import annotations

import argparse

from pibr.client.cli import parse_methods
from pibr.common import arguments
from pibr.common.bandwidth import BUILTIN as BUILTIN_LINKS
from pibr.protocol.depth_codecs import DEPTH_CODECS
from pibr.protocol.messages import CLOCKS
from pibr.protocol.motion_flow import FLOW_CODERS

from . import commands   # the runners: they import what they run when they run
from .processes import PLACEMENTS

#: The benchmarks' primary view (bench/simulation.py BENCH_VIEW_SIZE, repeated here so that
#: ``pibr --help`` needs no GL or codec import; a test keeps them equal).
BENCH_VIEW_SIZE = (1024, 1024)

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
    bad = [c for c in codecs if c not in DEPTH_CODECS]
    if bad or not codecs:
        raise argparse.ArgumentTypeError(f"expected depth codecs among {', '.join(DEPTH_CODECS)}, got {text!r}")
    return codecs


def _range(text: str) -> list:
    from .offset_search import parse_range

    try:
        return parse_range(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _angles(text: str) -> tuple:
    from pibr.server.config import MAX_EDGE_DEG, MIN_EDGE_DEG

    angles = tuple(arguments.number(x.strip()) for x in text.split(",") if x.strip())
    if not angles or not all(MIN_EDGE_DEG <= a <= MAX_EDGE_DEG for a in angles):
        raise argparse.ArgumentTypeError(f"expected angles in {MIN_EDGE_DEG:g}..{MAX_EDGE_DEG:g} degrees, got {text!r}")
    return angles


def _numbers(text: str) -> tuple:
    vals = arguments.positives(text)
    if not vals:
        raise argparse.ArgumentTypeError(f"expected positive numbers separated by commas, got {text!r}")
    return vals


# Options many benchmarks share, each declared once.
def _scene(p, default="room", help=None):
    p.add_argument("--scene", default=default, help=help or f"scene spec (default {default})")


def _windows_option(p, default="evaluation", help=_WINDOWS_HELP):
    p.add_argument("--windows", type=_windows, default=default, help=help)


def _latency(p, default=128.0):
    p.add_argument("--latency-ms", type=arguments.non_negative, default=default,
                   help=f"round trip in ms, split evenly between the directions (default {default:g})")


def _rate(p, default=30.0):
    p.add_argument("--rate", type=arguments.positive, default=default, help=f"display rate Hz (default {default:g})")


def _view_size(p, default=BENCH_VIEW_SIZE, help=None):
    p.add_argument("--view-size", type=arguments.size, default=default, metavar="WxH",
                   help=help or f"the server's primary view size (default {default[0]}x{default[1]})")


def _output_size(p, default=(960, 540), help=None):
    p.add_argument("--size", type=arguments.size, default=default, metavar="WxH",
                   help=help or f"output size (default {default[0]}x{default[1]})")


def _placement(p):
    """Where a sweep's independent points run: this process, or Ray workers (pibr[cluster])."""
    g = p.add_argument_group("workers (Ray: pip install 'pibr[cluster]')")
    g.add_argument("--workers", type=arguments.positive_int, default=None, metavar="N",
                   help="run the sweep's points on N Ray workers, each with its own GL context and CPU (default: "
                        "in this process; the numbers are the same)")
    g.add_argument("--ray-address", default=None, metavar="ADDRESS",
                   help="a running Ray cluster (ray://HOST:10001, or auto) instead of a local Ray; --workers "
                        "defaults to its CPUs (or GPUs, with --gpus-per-worker)")
    g.add_argument("--gpus-per-worker", type=arguments.non_negative, default=0.0, metavar="G",
                   help="GPUs each worker asks Ray for (default 0; 1 on a cluster with a GPU per worker)")


def _out(p, default="out/bench"):
    p.add_argument("--out", default=default, help=f"output directory (default {default})")


def register(sub) -> None:
    from pibr.client.object_motion import CLIENT_MOTION_MODES

    d = sub.add_parser("demo", help="run server, relay and client on loopback and score the result",
                       description="Start a server, a 128 ms relay and a client as separate processes, replay a "
                                   "real head trace, then compare the methods against ground truth.")
    _out(d, "out")
    d.add_argument("--scene", default="room",
                   help="a built-in name, a scene description or an asset file (FILE#up=z for a Z-up asset)")
    d.add_argument("--up", choices=("y", "z", "auto"), default=None, help="an asset file's up axis (default auto)")
    d.add_argument("--trace", default="pred6dof-1")
    d.add_argument("--start", type=arguments.non_negative, default=30.0,
                   help="seconds into the trace (default 30: an evaluation window, away from where defaults were tuned)")
    d.add_argument("--anchor", choices=("start", "origin", "none"), default="start",
                   help="how the trace is placed in the scene (see 'pibr client --help'; default start)")
    d.add_argument("--duration", type=arguments.positive, default=6.0, help="seconds to replay (default 6)")
    _rate(d)
    _output_size(d)
    _latency(d)
    d.add_argument("--method", type=parse_methods, default=("none", "rotation", "proxy"),
                   help="methods to compare, comma-separated (default none,rotation,proxy)")
    d.add_argument("--depth-codec", choices=tuple(DEPTH_CODECS), default="h264", help="depth transport")

    d.add_argument("--clock", choices=CLOCKS, default="virtual")
    d.add_argument("--flip-every", type=arguments.non_negative_int, default=4, help="FLIP on every Nth frame, 0: never (default 4)")
    d.add_argument("--motion", choices=CLIENT_MOTION_MODES, default=None,
                   help="how the client brings moving objects to the display time (see 'pibr client --help'; "
                        "try --scene dynamic --motion flow)")
    d.add_argument("--stereo", choices=("cyclops", "alternate", "per-eye"), default=None,
                   help="two eyes (see 'pibr client --help'): each scored against its own ground truth, and each "
                        "pair's binocular consistency (default: one view)")
    d.add_argument("--ipd-mm", type=arguments.positive, default=None, help="with --stereo: the eyes' distance "
                                                                            "(default 64)")
    d.add_argument("--anaglyph", action="store_true", help="with --stereo: also a red-cyan anaglyph video per method")
    d.add_argument("--eye-fov-deg", type=arguments.eye_fov, default=None, metavar="OUTER,INNER,UP,DOWN",
                   help="with --stereo: each eye's asymmetric frustum (see 'pibr client --help'), each scored "
                        "against ground truth through it")
    d.add_argument("--live", type=arguments.non_negative_int, default=None, metavar="PORT",
                   help="show the client's session live at http://127.0.0.1:PORT/ while it runs (0: any free port)")
    d.set_defaults(func=commands.cmd_demo)

    e = sub.add_parser("evaluate", help="score a client recording against ground truth",
                       description="Render ground truth for every displayed tick of a 'pibr client' recording and "
                                   "compute PSNR, SSIM, DSSIM, FLIP and hole fraction per method.")
    e.add_argument("run", help="the client's --out directory")
    e.add_argument("--scene", default=None, help="scene spec if the recording's scene name is not a built-in")
    e.add_argument("--flip-every", type=arguments.non_negative_int, default=1)
    e.add_argument("--workers", type=arguments.positive_int, default=2, help="metric worker processes (default 2)")
    e.add_argument("--no-video", action="store_true", help="skip side_by_side.mp4")
    e.set_defaults(func=commands.cmd_evaluate)

    b = sub.add_parser("bench", help="benchmarks: speed, size and quality trades",
                       description="Benchmarks print a table and write JSON (and plots) to --out.")
    bs = b.add_subparsers(dest="bench", metavar="BENCH")
    bs.required = True
    s = bs.add_parser("server", help="server ms per frame by stage, and bitrate")
    _scene(s)
    s.add_argument("--trace", default="pred6dof-1")
    s.add_argument("--frames", type=arguments.positive_int, default=40)
    _view_size(s)
    s.add_argument("--projection", type=arguments.names, default=("vertex", "tess"),
                   help="which to measure: vertex, tess, cube (default vertex,tess)")
    s.add_argument("--cube-scale", type=arguments.positive, default=0.75,
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
    s.add_argument("--bitrate-kbps", type=arguments.positive, default=16000.0)
    _out(s)
    s.set_defaults(func=commands.cmd_bench_server)
    c = bs.add_parser("client", help="client ms per frame by stage")
    _scene(c)
    c.add_argument("--trace", default="pred6dof-1")
    c.add_argument("--frames", type=arguments.positive_int, default=40)
    _view_size(c)
    _output_size(c, help="client output size (default 960x540)")
    c.add_argument("--method", type=parse_methods, default=("none", "rotation", "proxy"))
    _out(c)
    c.set_defaults(func=commands.cmd_bench_client)

    cov = bs.add_parser("coverage", help="pixels no transmitted view covers: primary, peeling, offset, both",
                        description="Reproduces Reinert et al.'s Figure 4: the fraction of displayed pixels that no "
                                    "transmitted view covers, for four dual-view variants, along real traces.")
    _scene(cov)
    _windows_option(cov)
    cov.add_argument("--stride", type=arguments.positive_int, default=2, help="measure every Nth displayed tick (default 2)")
    _latency(cov)
    _rate(cov)
    _view_size(cov)
    _output_size(cov, (320, 180), help="displayed view size (default 320x180)")
    cov.add_argument("--offset", type=arguments.offset, default=None, metavar="F,U,TILT",
                     help="extra view offset (default: the scene's, else Reinert et al.'s 1.5,1.8,15)")
    _out(cov)
    _placement(cov)
    cov.set_defaults(func=commands.cmd_bench_coverage)

    i = bs.add_parser("ibr", help="none / rotation / proxy against ground truth, proxy speed against a floor",
                      description="Quality of the client methods at the given latency on real traces (in one "
                                  "process, on the virtual clock's schedule), the LoD trade, and proxy IBR's ms per "
                                  "frame next to a full-screen pass with the same texture lookups.")
    _scene(i)
    _windows_option(i)
    _latency(i)
    _rate(i)
    i.add_argument("--stride", type=arguments.positive_int, default=2, help="score every Nth displayed tick (default 2)")
    _output_size(i)
    _view_size(i)
    i.add_argument("--lod-targets", type=arguments.positives, default=(), metavar="PX,...",
                   help="also score proxy at these LoD pixel targets, e.g. 2,16 (default: none)")
    i.add_argument("--lod-levels", type=arguments.names, default=(), metavar="LEVEL,...",
                   help="also score proxy with every object at this level: original, proxy, box (default: none)")
    i.add_argument("--speed-sizes", type=arguments.sizes, default=((960, 540), (1280, 720)), metavar="WxH,...",
                   help="output sizes of the speed comparison with the floor (default 960x540,1280x720; '' for none)")
    i.add_argument("--speed-frames", type=arguments.positive_int, default=20, help="frames timed per size (default 20)")
    _out(i)
    i.set_defaults(func=commands.cmd_bench_ibr)

    cd = bs.add_parser("codec", help="depth codecs on rate-distortion curves at equal bitrate",
                       description="Bits per frame against disparity PSNR and 1 % outliers of the edge codec over its "
                                   "thresholds, H.264 depth alone (8- and 10-bit) at the edge codec's rates, "
                                   "Koniaris-style log depth with temporal coding and zstd, lossless 12-bit zstd; proxy "
                                   "DSSIM at equal total bitrate; the quantisers' error from 1 cm to 10 km. Full run "
                                   "(defaults): 7 evaluation windows x 2 s at 1024^2, about 20-30 min on 2 cores.")
    _scene(cd)
    _windows_option(cd)
    cd.add_argument("--duration", type=arguments.positive, default=2.0, help="seconds of each window (default 2)")
    _view_size(cd)
    cd.add_argument("--thresholds", type=_numbers, default=None, metavar="T,...",
                    help="edge codec significance thresholds (default 2,3.5,8,16,32,64,128)")
    cd.add_argument("--log-bits", type=arguments.positive_ints, default=None, metavar="B,...",
                    help="bits of the log-depth codec's settings (default 16,12,10,8)")
    cd.add_argument("--totals-kbps", type=_numbers, default=None, metavar="KBPS,...",
                    help="total bitrates (colour + depth) of the end-to-end comparison (default 4000,8000,16000)")
    cd.add_argument("--e2e-windows", type=arguments.positive_int, default=2,
                    help="how many of the windows the end-to-end comparison runs on (default 2)")
    _output_size(cd, help="client output size of the end-to-end comparison (default 960x540)")
    cd.add_argument("--quick", action="store_true",
                    help="small run: 256x256 view, 1 s of the first two windows, 3 thresholds, 1 end-to-end window")
    cd.add_argument("--plot", default=None, help="also write the chart here (e.g. docs/depth_rd.png)")
    _out(cd)
    cd.set_defaults(func=commands.cmd_bench_codec)

    cs = bs.add_parser("codec-speed", help="the edge codec's CPU ms stage by stage, bytes and PSNR, vs a baseline",
                       description="Encode and decode (with diffusion) of the edge codec on rendered frames along "
                                   "real traces, process CPU ms per stage; with --baseline, another pibr checkout "
                                   "runs interleaved frame by frame in its own process and the table shows both, "
                                   "the ratio, the bytes ratio and whether payloads are identical.")
    _scene(cs)
    _windows_option(cs)
    cs.add_argument("--duration", type=arguments.positive, default=1.0, help="seconds of each window (default 1)")
    cs.add_argument("--fps", type=arguments.positive, default=10.0, help="server frames per second (default 10)")
    _view_size(cs)
    cs.add_argument("--baseline", default=None, metavar="CHECKOUT",
                    help="a pibr source tree to compare against, e.g. a git worktree of main")
    _out(cs)
    cs.set_defaults(func=commands.cmd_bench_codec_speed)

    ps = bs.add_parser("proxy-speed", help="proxy's CPU ms against the passes it replaced, --no-carve and the floor",
                       description="CPU ms of proxy's passes in one run: the default carving, carve_all (the passes "
                                   "it replaced: the same image), both without inpainting (--no-inpaint), carve=False, "
                                   "the default and carve=False drawing every back face (cull=False), and the floor "
                                   "of 'pibr bench ibr', interleaved frame by frame on room frames along the "
                                   "evaluation windows, and how far the default's images are from carve_all's and "
                                   "cull=False's (and the two without inpainting from each other). Writes "
                                   "proxy_speed.json.")
    _scene(ps)
    ps.add_argument("--sizes", type=arguments.sizes, default=((960, 540), (1280, 720)), metavar="WxH,...",
                    help="output sizes (default 960x540,1280x720)")
    ps.add_argument("--frames", type=arguments.positive_int, default=12, help="display samples (default 12)")
    ps.add_argument("--repeats", type=arguments.positive_int, default=3, help="renders of each sample (default 3)")
    _out(ps)
    ps.set_defaults(func=commands.cmd_bench_proxy_speed)

    pa = bs.add_parser("pareto", help="every method and knob: client ms against DSSIM (Reinert et al.'s Figure 9)",
                       description="Runs every client method with each of its knobs (and a zero-latency oracle) on "
                                   "the scenes and head-trace windows, scores each against ground truth (DSSIM, "
                                   "PSNR, FLIP, geometric and own holes) and times it at each output size. Writes "
                                   "pareto.json and pareto.png.")
    pa.add_argument("--scene", type=arguments.names, default=("room",),
                    help="comma-separated scenes (default room; the sphere scene's frames are mostly sky on the "
                         "shared traces)")
    pa.add_argument("--method", type=parse_methods, default=None, help="only these methods (default: all)")
    _windows_option(pa)
    _latency(pa)
    _rate(pa)
    pa.add_argument("--stride", type=arguments.positive_int, default=8, help="score every Nth displayed tick (default 8)")
    _view_size(pa)
    _output_size(pa, help="output size scored (default 960x540)")
    pa.add_argument("--speed-sizes", type=arguments.sizes, default=((960, 540), (1280, 720)), metavar="WxH,...",
                    help="output sizes timed (default 960x540,1280x720)")
    pa.add_argument("--speed-frames", type=arguments.positive_int, default=12,
                    help="frames timed per size and scene (default 12)")
    pa.add_argument("--flip-every", type=arguments.non_negative_int, default=4, help="FLIP on every Nth scored frame, 0: never")
    pa.add_argument("--depth-codec", choices=tuple(DEPTH_CODECS), default="h264")
    _out(pa)
    _placement(pa)
    pa.set_defaults(func=commands.cmd_bench_pareto)

    tr = bs.add_parser("trade", help="each knob swept with the others at their defaults: quality against bits and ms",
                       description="Sweeps colour bitrate, x264 preset, keyframe interval, primary and extra view "
                                   "size, server fps, latency, jitter, a bandwidth cap, proxy tau and depth slack "
                                   "and the LoD settings, one at a time, for rotation, proxy, gridwarp and "
                                   "coarse-meshwarp: DSSIM, PSNR, FLIP, geometric holes, client and server CPU ms, "
                                   "total bits per frame. Writes trade.json and trade_KNOB.png per knob.")
    tr.add_argument("--knobs", type=_trade_knobs, default=None, metavar="NAME,...",
                    help="only these knobs (default all: bitrate, preset, keyint, view, extra, fps, latency, "
                         "jitter, cap, tau, slack, lod_resolution, lod_fraction)")
    tr.add_argument("--scenes", type=arguments.names, default=("room",), help="comma-separated scenes (default room)")
    _windows_option(tr)
    tr.add_argument("--window-seconds", type=arguments.positive, default=2.0,
                    help="the first seconds of each window (default 2; every server frame in them is rendered and "
                         "encoded, ~0.5 CPU-s each at 1024^2 here)")
    tr.add_argument("--stride", type=arguments.positive_int, default=4,
                    help="score every Nth displayed tick at 30 Hz (default 4)")
    _output_size(tr)
    tr.add_argument("--flip-every", type=arguments.non_negative_int, default=4, help="FLIP on every Nth scored tick, 0: never")
    tr.add_argument("--seed", type=arguments.non_negative_int, default=0, help="jitter seed (default 0)")
    _out(tr)
    _placement(tr)
    tr.set_defaults(func=commands.cmd_bench_trade)

    dy = bs.add_parser("dynamic", help="moving objects at the display time: static, velocity, accel, flow and the "
                                       "oracle per latency; both flow coders",
                       description="Every way the client brings moving objects to the display time (proxy with "
                                   "--motion static, velocity, accel, flow, oracle; rotation with and without flow), "
                                   "at several round trips, on scenes that move: DSSIM and PSNR over the frame and "
                                   "over the moving objects' pixels, client ms, motion bits per frame; the error "
                                   "over time around a reversal and a stop; the motion flow's bits and error with "
                                   "both flow coders. Writes dynamic.json and dynamic.png.")
    dy.add_argument("--scene", type=arguments.names, default=("dynamic", "room"), help="scenes that move (default dynamic,room)")
    dy.add_argument("--windows", type=_windows, default=None,
                    help="head-trace windows (default: pred6dof-2@50+2,synth-turns@5+2, parts of the evaluation "
                         "windows where the dynamic scene's objects are in view; " + _WINDOWS_HELP + ")")
    dy.add_argument("--latency-ms", type=arguments.positives, default=(64.0, 128.0, 256.0), metavar="MS,...",
                    help="round trips (default 64,128,256)")
    dy.add_argument("--event-latency-ms", type=arguments.positive, default=128.0,
                    help="round trip of the reversal and stop probes (default 128)")
    _rate(dy)
    dy.add_argument("--stride", type=arguments.positive_int, default=3, help="score every Nth displayed tick (default 3)")
    dy.add_argument("--event-stride", type=arguments.positive_int, default=2,
                    help="score every Nth tick around the reversals and stops (default 2)")
    _view_size(dy, (512, 512), help="server view size (default 512x512: a few minutes on 2 cores; the server's is "
                                    "1024x1024)")
    _output_size(dy, (480, 270))
    dy.add_argument("--depth-codec", choices=tuple(DEPTH_CODECS), default="h264")
    dy.add_argument("--flow-coder", choices=tuple(FLOW_CODERS), default=None,
                    help="the motion flow the flow methods receive (default: the server's); both are measured")
    _out(dy)
    _placement(dy)
    dy.set_defaults(func=commands.cmd_bench_dynamic)

    st = bs.add_parser("stereo", help="two eyes from one stream: mono, cyclops, alternate and per-eye references per "
                                      "method; per-eye quality, binocular consistency, ms per pair",
                       description="Every server reference for a headset's two eyes (mono at the head's centre, "
                                   "cyclops, alternate, per-eye; protocol/stereo.py) with each method, on the "
                                   "virtual clock: per-eye DSSIM, PSNR, FLIP and holes against each eye's ground "
                                   "truth, the binocular consistency of each pair (bench/stereo_metrics.py), client "
                                   "CPU ms per pair against one mono view, server CPU ms and bits per second per "
                                   "reference. Writes stereo.json, stereo.png, stereo-pair.png and "
                                   "stereo-anaglyph.png. About 20 min on 2 cores with the defaults.")
    st.add_argument("--scene", type=arguments.names, default=("room", "dynamic"),
                    help="scenes (default room,dynamic)")
    st.add_argument("--windows", type=_windows, default=None,
                    help="windows of every scene but dynamic (default: pred6dof-1@30+4, synth-walk@5+4, "
                         "synth-turns@5+4 and a walk that comes to rest in synth-mixed; " + _WINDOWS_HELP + ")")
    st.add_argument("--dynamic-windows", type=_windows, default=None,
                    help="windows of the dynamic scene (default pred6dof-2@50+2,synth-turns@5+2)")
    st.add_argument("--method", type=parse_methods, default=("proxy", "gridwarp", "rotation"),
                    help="methods (default proxy,gridwarp,rotation)")
    st.add_argument("--modes", type=arguments.names, default=("mono", "cyclops", "alternate", "per-eye"),
                    help="server references, mono among them (default mono,cyclops,alternate,per-eye)")
    st.add_argument("--ipd-mm", type=arguments.positive, default=64.0, help="interpupillary distance (default 64)")
    st.add_argument("--eye-fov-deg", type=arguments.eye_fov, default=None, metavar="OUTER,INNER,UP,DOWN",
                    help="each eye's asymmetric frustum, as a headset's: the left eye's degrees to its outer, inner, "
                         "top and bottom edges, the right eye mirrored; each eye drawn and scored through its own "
                         "(default: 90 degrees, symmetric)")
    _latency(st)
    _rate(st)
    st.add_argument("--stride", type=arguments.positive_int, default=4, help="score every Nth displayed tick (default 4)")
    st.add_argument("--flip-every", type=arguments.non_negative_int, default=4,
                    help="FLIP on every Nth scored tick, 0: never (default 4)")
    _view_size(st)
    _output_size(st)
    _out(st)
    st.set_defaults(func=commands.cmd_bench_stereo)

    pr = bs.add_parser("predict", help="head-pose predictors (none, velocity, accel, kalman): error against look-ahead",
                       description="Feeds every predictor of server/pose_prediction.py the trace's poses at the "
                                   "client's rate and compares its pose a look-ahead later with the trace's: mean and "
                                   "95th-percentile position (mm) and angular (degrees) error per predictor and "
                                   "look-ahead; then rotation's and proxy's DSSIM when the server renders every frame "
                                   "for the pose each predictor expects at its display. --fit searches the Kalman "
                                   "filter's noise levels on the tuning windows. Writes predict.json (predict-tuning.json "
                                   "with --fit) and a plot.")
    pr.add_argument("--windows", type=_windows, default=None,
                    help="head-trace windows (default: evaluation; tuning with --fit; " + _WINDOWS_HELP + ")")
    _rate(pr)
    pr.add_argument("--look-ahead-ms", type=arguments.positives, default=(20.0, 50.0, 100.0, 128.0, 200.0, 256.0),
                    metavar="MS,...", help="look-aheads (default 20,50,100,128,200,256)")
    pr.add_argument("--fit", action="store_true", help="fit the Kalman filter's noise levels on the tuning windows")
    pr.add_argument("--no-quality", action="store_true",
                    help="skip the DSSIM of rotation and proxy with the server rendering for each predictor's pose "
                         "at 64, 128 and 256 ms (parts of four evaluation windows at 512^2 / 480x270; minutes)")
    pr.add_argument("--stride", type=arguments.positive_int, default=4, help="quality: score every Nth tick (default 4)")
    _out(pr)
    pr.set_defaults(func=commands.cmd_bench_predict)

    nw = bs.add_parser("network", help="links whose bandwidth changes: static bitrates against the adapting stream",
                       description="Runs server, relay and client processes on the virtual clock (or the wall clock), the relay's "
                                   "downlink replaying each bandwidth trace (pibr link list), once per static "
                                   "--bitrate-kbps and once with --adapt on; scores what was shown against ground "
                                   "truth. Per run: frame age p50/p95, stalls (no new frame for 250 ms), the longest, "
                                   "the bitrate that arrived, DSSIM; per link, the adapting stream's DSSIM per 5 s "
                                   "segment against the best static setting in hindsight. Writes network.json. About "
                                   "a minute a run at the defaults (links x (statics + 1) runs).")
    nw.add_argument("--links", type=arguments.names, default=tuple(BUILTIN_LINKS),
                    metavar="TRACE,...", help="bandwidth traces, built-in (cellular:SEED: another draw of the "
                                                "cellular model) or files (default every built-in)")
    nw.add_argument("--static-kbps", type=arguments.positives, default=(2000.0, 4000.0, 8000.0, 16000.0),
                    metavar="KBPS,...", help="static bitrates to compare (default 2000,4000,8000,16000)")
    nw.add_argument("--adapt-kbps", type=arguments.positive, default=16000.0, metavar="KBPS",
                    help="the adapting stream's most (default 16000)")
    nw.add_argument("--adapt-start", type=arguments.names_or_none, default=("foot",), metavar="START,...",
                    help="one adapting run per start (pibr serve --adapt-start: foot, probe), the first the one "
                         "the verdict reads (default foot; '' for the static settings alone)")
    nw.add_argument("--method", default="proxy", help="the client's method (default proxy)")
    nw.add_argument("--trace", default="pred6dof-1", help="head trace (default pred6dof-1)")
    nw.add_argument("--start", type=arguments.non_negative, default=30.0, metavar="S", help="window start (default 30)")
    nw.add_argument("--duration", type=arguments.positive, default=30.0, metavar="S",
                    help="window length; the links loop (default 30)")
    nw.add_argument("--clock", choices=CLOCKS, default="virtual",
                    help="virtual (reproducible, the default) or real: the wall clock, where a busy client or "
                         "server delays frames as a full link does")
    nw.add_argument("--placement", choices=PLACEMENTS, default="split",
                    help="on the real clock, which cores: split (server and relay on one, the client on the "
                         "other, the default) or shared")
    _rate(nw)
    _view_size(nw, default=(512, 512))
    _output_size(nw, default=(480, 270))
    _out(nw)
    nw.set_defaults(func=commands.cmd_bench_network)

    sp = bs.add_parser("split", help="a one-mesh level, whole against cut into pieces: LoD, client ms, DSSIM",
                       description="Generates a one-mesh atrium (167k triangles) and serves it whole and cut into "
                                   "pieces (scenes/split.py): LoD build time, proxy's client ms and quality on "
                                   "synthetic walks inside it. Writes split.json.")
    sp.add_argument("--duration", type=arguments.positive, default=6.0, help="seconds of each synthetic trace (default 6)")
    sp.add_argument("--stride", type=arguments.positive_int, default=6, help="score every Nth displayed tick (default 6)")
    _output_size(sp)
    _out(sp)
    sp.set_defaults(func=commands.cmd_bench_split)

    lv = bs.add_parser("levels", help="the deadline controller's quality levels: ms and DSSIM of each",
                       description="Draws every quality level of each method (client/deadline.py: render scale, "
                                   "no inpainting, coarser proxies, the rotation fallback) on the same display ticks "
                                   "of the evaluation windows, in one process: wall and CPU ms (this machine) and "
                                   "DSSIM, PSNR and own holes against ground truth (every machine). Writes "
                                   "levels.json, whose costs_ms 'pibr client --cost-table' takes.")
    _scene(lv)
    lv.add_argument("--method", type=parse_methods, default=("proxy", "rotation"),
                    help="methods whose levels to measure (default proxy,rotation)")
    _windows_option(lv)
    _latency(lv)
    _rate(lv)
    lv.add_argument("--stride", type=arguments.positive_int, default=10,
                    help="score every Nth displayed tick (default 10)")
    _output_size(lv)
    _view_size(lv)
    _out(lv)
    lv.set_defaults(func=commands.cmd_bench_levels)

    up = bs.add_parser("upsampling", help="colour sent at a quarter of the pixels and rebuilt on the client: "
                                          "server ms, bits, PSNR/DSSIM against the whole colour",
                       description="Pajak et al.'s spatio-temporal upsampling (--colour-scale 0.5) measured alone: "
                                   "the same frames through three streams (colour whole; at a quarter of the pixels "
                                   "at the same bitrate; and at a quarter of the bitrate), still and moving heads "
                                   "from the windows: server ms per stage, bits per second, the client's rebuild ms, "
                                   "and the views' PSNR and DSSIM against their whole colour before coding, beside "
                                   "plain bilinear upscaling. Writes upsampling.json.")
    _scene(up)
    _windows_option(up)
    up.add_argument("--still-frames", type=arguments.positive_int, default=8,
                    help="frames of each window's first pose held still (default 8)")
    up.add_argument("--moving", type=arguments.positive, default=3.0,
                    help="seconds of each window at the server's frame rate (default 3)")
    up.add_argument("--fps", type=arguments.positive, default=10.0, help="server frame rate (default 10)")
    up.add_argument("--depth-codec", type=_codecs, default=tuple(DEPTH_CODECS), metavar="CODEC,...",
                    help=f"depth codecs to measure with, comma-separated (default {','.join(DEPTH_CODECS)})")
    up.add_argument("--stride", type=arguments.positive_int, default=2,
                    help="score every Nth frame of the moving sequences (default 2)")
    for name, help_ in (("spatial-sigma", "screen-distance falloff among the new samples, pixels"),
                        ("sample-sigma", "falloff of the new samples' weight with the distance to the nearest, pixels"),
                        ("decay", "the history's confidence kept from frame to frame"),
                        ("max-confidence", "the most weight the history may gather"),
                        ("depth-tolerance", "relative distance within which two points are one surface")):
        up.add_argument(f"--{name}", type=arguments.positive, default=None,
                        help=f"the rebuild's {help_} (default: client/colour_rebuild.py's)")
    _view_size(up)
    _out(up)
    up.set_defaults(func=commands.cmd_bench_upsampling)

    lo = bs.add_parser("lod", help="encaging level-of-detail proxies: triangles, enclosure, time per object",
                       description="Generate (or read from the cache) every object's encaging proxy and report the "
                                   "triangle counts, the fraction of original vertices enclosed and the time taken.")
    lo.add_argument("--scene", type=arguments.names, default=("room",), help="comma-separated scene specs")
    lo.add_argument("--asset", type=arguments.names, default=None, help="asset files to measure as well (default: the shipped real asset)")
    lo.add_argument("--resolution", type=int, default=128, help="voxels along an object's longest side")
    lo.add_argument("--fraction", type=arguments.fraction, default=0.005, help="proxy triangles / original triangles")
    lo.add_argument("--no-cache", action="store_true",
                    help="generate every proxy afresh (timing this machine) instead of reading the LoD cache")
    _out(lo)
    lo.set_defaults(func=commands.cmd_bench_lod)

    li = bs.add_parser("live", help="what watching a session live (--live, a page in Chromium) costs the client",
                       description="The same wall-clock session alone and watched by the live page in headless "
                                   "Chromium, in turn: the client's render ms and missed ticks, and the page's "
                                   "share of the tick time.")
    li.add_argument("--method", default="proxy", help="the client's method (default proxy)")
    _output_size(li, (640, 360))
    _rate(li)
    li.add_argument("--duration", type=arguments.positive, default=20.0, help="seconds of trace per run (default 20)")
    li.add_argument("--repeats", type=arguments.positive_int, default=2, help="alone/watched pairs (default 2)")
    _out(li)
    li.set_defaults(func=commands.cmd_bench_live)

    cl = bs.add_parser("cluster", help="one trade sweep in this process and on 1 and 2 Ray workers: the speed-up, "
                                       "and that the numbers are the same",
                       description="Runs the same pibr bench trade sweep in this process, then on a local Ray with "
                                   "each count of --workers, one after the other: wall seconds, speed-up, and "
                                   "whether every number but the timings is the in-process run's. Needs "
                                   "pip install 'pibr[cluster]'. Writes cluster.json.")
    cl.add_argument("--knobs", type=_trade_knobs, default=("bitrate", "latency"), metavar="NAME,...",
                    help="the trade knobs swept (default bitrate,latency: 8000 and 256 beside the defaults)")
    _windows_option(cl)
    cl.add_argument("--window-seconds", type=arguments.positive, default=1.0,
                    help="the first seconds of each window (default 1)")
    cl.add_argument("--stride", type=arguments.positive_int, default=4, help="score every Nth tick (default 4)")
    _output_size(cl)
    cl.add_argument("--workers", type=arguments.positive_ints, default=(1, 2), metavar="N,...",
                    help="Ray worker counts to time (default 1,2)")
    _out(cl)
    cl.set_defaults(func=commands.cmd_bench_cluster)

    sc = bs.add_parser("scoring", help="the demo's session streamed, then scored: both phases' seconds, and "
                                       "each scoring stage beside the libraries it reproduces",
                       description="Streams the demo's session (room, 6 s of pred6dof-1 from 30 s, 960x540, 128 ms) "
                                   "and scores it as pibr demo does: wall and CPU seconds of each phase. Then "
                                   "times each scoring stage over the first ticks, pibr's compiled SSIM, PSNR and "
                                   "FLIP beside scikit-image, numpy and flip-evaluator (pip install 'pibr[test]'), "
                                   "and checks every value is theirs to the bit. Writes scoring.json.")
    sc.add_argument("--duration", type=arguments.positive, default=6.0, help="seconds of trace (default 6)")
    _output_size(sc)
    sc.add_argument("--flip-every", type=arguments.non_negative_int, default=4,
                    help="FLIP on every Nth tick, as the demo (default 4)")
    sc.add_argument("--profile-ticks", type=arguments.positive_int, default=24,
                    help="ticks timed stage by stage (default 24)")
    _out(sc)
    sc.set_defaults(func=commands.cmd_bench_scoring)

    rt = bs.add_parser("realtime", help="server, relay and client processes on the wall clock: fps, missed "
                                        "deadlines, frame age, CPU; and the cost per session",
                       description="Runs each method with each depth codec as separate server, relay and client "
                                   "processes on the real clock and reports the server's fps, the client's output "
                                   "rate and missed deadlines, frame age p50/p99 and each process's CPU share; then "
                                   "1, 2, 4 ... clients on one server: server CPU-ms per delivered frame (virtual "
                                   "clock) and fps per client (real clock). Writes realtime.json.")
    rt.add_argument("--method", type=parse_methods, default=("rotation", "proxy"))
    rt.add_argument("--depth-codec", type=_codecs, default=tuple(DEPTH_CODECS), metavar="CODEC,...",
                    help=f"depth codecs, comma-separated (default {','.join(DEPTH_CODECS)})")
    rt.add_argument("--clients", type=arguments.positive_ints, default=(1, 2, 4), metavar="N,...",
                    help="session counts of the cost-per-session runs ('' for none; default 1,2,4)")
    rt.add_argument("--duration", type=arguments.positive, default=20.0, help="seconds of trace per real-clock run (default 20)")
    rt.add_argument("--scaling-duration", type=arguments.positive, default=6.0,
                    help="seconds of trace per client of the virtual-clock cost runs (default 6)")
    _scene(rt)
    rt.add_argument("--trace", default="pred6dof-1")
    rt.add_argument("--start", type=arguments.non_negative, default=30.0, help="seconds into the trace (default 30)")
    _rate(rt)
    _output_size(rt)
    _latency(rt)
    rt.add_argument("--server-fps", type=arguments.positive, default=10.0, help="server frame rate asked for (default 10)")
    _view_size(rt, None, help="the server's primary view size (default: the server's, sized for the output: "
                              "1088x1088 at 960x540)")
    rt.add_argument("--extra-view", choices=("auto", "on", "off"), default=None,
                    help="the server's extra view (default: the server's, auto)")
    rt.add_argument("--placement", choices=(*PLACEMENTS, "both"), default="split",
                    help="split (default): the server and the relay on one core, the client on the other, as "
                         "on two machines; shared: anywhere; both")
    rt.add_argument("--controllers", choices=("on", "off", "both"), default="both",
                    help="the client's deadline controller on, off, or both in one run (default both)")
    rt.add_argument("--no-score", action="store_true",
                    help="do not record and score what was shown (faster: speed figures only)")
    _out(rt)
    rt.set_defaults(func=commands.cmd_bench_realtime)

    from .hostile import KINDS

    so = bs.add_parser("soak", help="a server under legitimate clients and hostile peers: equal records, flat "
                                    "memory, no traceback",
                       description="Runs each legitimate client alone (virtual clock), then all of them again and "
                                   "again for --duration seconds beside hostile peers of every kind (malformed "
                                   "messages, slow and idle connections, a far-future clock, a non-reading client, "
                                   "connection floods). Passes when every soaked run equals its solo run, the "
                                   "server's memory and open files stay flat and its log has no traceback. "
                                   "Writes soak.json; exit code 1 when it fails.")
    so.add_argument("--duration", type=arguments.positive, default=60.0, help="seconds of soak (default 60)")
    so.add_argument("--clients", type=int, default=8, help="legitimate clients (default 8)")
    so.add_argument("--kinds", default=",".join(KINDS), metavar="KIND,...",
                    help="hostile kinds (default all: " + ", ".join(KINDS) + ")")
    _scene(so)
    so.add_argument("--trace", default="pred6dof-1")
    so.add_argument("--method", default="rotation", help="the legitimate clients' method (default rotation)")
    so.add_argument("--run-duration", type=arguments.positive, default=1.0,
                    help="seconds of trace per legitimate run (default 1)")
    _view_size(so, (256, 256), help="the server's primary view size (default 256x256: many sessions on two cores)")
    so.add_argument("--seed", type=int, default=0)
    _out(so)
    so.set_defaults(func=commands.cmd_bench_soak)

    fz = bs.add_parser("fuzz", help="mutation fuzzing of every parser a peer or a file feeds: documented errors only",
                       description="Mutates valid inputs (bytes, text, JSON and TOML structure) of the wire decoder, "
                                   "the edge codec and quadtree decoders, the proxy bundle decoder, the head-trace "
                                   "importers and the scene loader, runs each in a worker process with a per-input "
                                   "deadline, and reports per parser the inputs, accepted inputs, documented errors "
                                   "by class, undocumented exceptions and hangs (both must be 0: the exit status is "
                                   "1 otherwise; failing inputs are saved), peak memory and inputs/s. Writes "
                                   "fuzz.json.")
    fz.add_argument("--inputs", type=arguments.positive_int, default=100_000, help="inputs per parser (default 100000)")
    fz.add_argument("--seed", type=arguments.non_negative_int, default=0, help="mutation seed (default 0)")
    fz.add_argument("--parsers", type=arguments.names, default=None, metavar="NAME,...",
                    help="wire, edge, quadtree, proxy, trace, scene (default: all)")
    fz.add_argument("--timeout-s", type=arguments.positive, default=10.0,
                    help="an input running longer than this is a hang (default 10)")
    fz.add_argument("--replay", default=None, metavar="FILE",
                    help="run one saved input (OUT/fuzz_inputs/PARSER-KIND-INDEX.*) again and show what it raises")
    _out(fz)
    fz.set_defaults(func=commands.cmd_bench_fuzz)

    o = bs.add_parser("optimize-offset", help="search the extra view's offset for the fewest holes",
                      description="Exhaustive (or coarse-to-fine) search over forward offset, height and tilt of "
                                  "the extra view, minimising the mean missing-pixel fraction over traces.")
    _scene(o)
    o.add_argument("--windows", type=_windows, default="tuning",
                   help="where to fit: 'tuning' (default), or TRACE@START+DURATION,... (a fit on the "
                        "evaluation windows would make them tuning data)")
    _latency(o)
    o.add_argument("--frames", type=arguments.positive_int, default=12, help="displayed frames per window (default 12)")
    o.add_argument("--forward", type=_range, default="-1:2:0.5", help="metres, START:STOP:STEP or a,b,c")
    o.add_argument("--up", type=_range, default="0:1.8:0.3", help="metres")
    o.add_argument("--tilt", type=_range, default="-30:45:15", help="degrees down")
    o.add_argument("--method", choices=("exhaustive", "coarse-to-fine"), default="exhaustive")
    o.add_argument("--objective", choices=("all", "geometry"), default="all",
                   help="missing fraction over all pixels, or only over pixels showing geometry")
    _view_size(o, (512, 512))
    _output_size(o, (192, 108))
    _out(o)
    o.set_defaults(func=commands.cmd_bench_offset)

    r = sub.add_parser("report", help="one HTML page of a run or a benchmark folder: tables, videos, scrubber, plots",
                       description="Write OUT/report.html: a self-contained page (no server, no internet) with the "
                                   "run's parameters, metrics, videos in sync, a frame scrubber and plots, or a "
                                   "benchmark folder's tables and plots. demo, evaluate and every bench write it "
                                   "at their end too.")
    r.add_argument("out", help="a scored run (pibr demo, pibr evaluate) or a benchmark's --out folder")
    r.set_defaults(func=commands.cmd_report)

    # Every command that leaves results in a folder ends by writing that folder's report.
    d.set_defaults(func=commands.with_report(commands.cmd_demo, "out"))
    e.set_defaults(func=commands.with_report(commands.cmd_evaluate, "run"))
    for bench in bs.choices.values():
        bench.set_defaults(func=commands.with_report(bench.get_default("func"), "out"))


def _trade_knobs(text: str) -> tuple:
    from pibr.protocol.errors import ConfigError

    from .trade import parse_knobs

    try:
        return parse_knobs(text)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
