"""``pibr trace``: convert head traces to the canonical CSV, summarise and plot them, synthesise
new ones, list the built-in recordings. numpy and matplotlib are imported inside the commands."""
from __future__ import annotations

import argparse
import json

from pibr.protocol.errors import TraceError

_DELIMITERS = {"tab": "\t", "\\t": "\t", "space": None, "whitespace": None, "auto": "auto"}
# Options that only mean something for --format csv, with their defaults.
_CSV_OPTIONS = {"rotation": "quat", "quat_order": "wxyz", "euler_order": "yxz", "radians": False,
                "left_handed": False, "delimiter": "auto", "skip_rows": 0, "drop_duplicates": False, "up": "y",
                "forward": None, "positions": "columns"}


def add_import_options(c) -> None:
    """How to read a trace file: shared by convert and show."""
    g = c.add_argument_group("reading the input")
    g.add_argument("--format", choices=("auto", "canonical", "pred6dof", "csv"), default="auto",
                   help="input format (default: from the header line; csv when --columns is given)")
    g.add_argument("--columns", metavar="MAP",
                   help="csv: KEY=COLUMN pairs, COLUMN a header name or 0-based index; keys t, px, py, pz "
                        "(or p=first index), qw, qx, qy, qz (or q=first index, see --quat-order) or Euler "
                        "angles rx, ry, rz (about the recording's x, y, z; or pitch, yaw, roll). Columns not "
                        "named are ignored")
    g.add_argument("--time-unit", choices=("s", "ms", "us", "ns", "ticks"), default=None,
                   help="unit of the time column (ticks = 100 ns); default s for csv, for pred6dof ticks if "
                        "the stamps are integers else seconds")
    g.add_argument("--rotation", choices=("quat", "euler"), default="quat", help="csv: quaternion or Euler columns")
    g.add_argument("--quat-order", choices=("wxyz", "xyzw"), default="wxyz",
                   help="csv: component order of q=INDEX (default wxyz)")
    g.add_argument("--euler", "--euler-order", dest="euler_order", default="yxz", metavar="ORDER",
                   help="csv: the axes of the Euler rotations in the order applied, intrinsically (each about "
                        "the rotated axes): yxz = yaw, pitch, roll (default); zxy, xyz, ...")
    g.add_argument("--radians", action="store_true", help="csv: Euler angles are in radians (default degrees)")
    g.add_argument("--left-handed", action="store_true",
                   help="csv: left-handed axes (Unity: +Y up, +Z forward), converted to pibr's")
    g.add_argument("--up", choices=("y", "z"), default="y", help="csv: the recording's up axis (default y)")
    g.add_argument("--forward", default=None, metavar="AXIS",
                   help="csv: where a head at identity looks, e.g. -z, z, y, x (default: -z right-handed Y-up, "
                        "z left-handed Y-up, y Z-up)")
    g.add_argument("--delimiter", default="auto",
                   help="csv: field separator: auto (per line: comma, semicolon, tab or whitespace; default), "
                        "',', ';', 'tab' or 'whitespace'")
    g.add_argument("--skip-rows", type=int, default=0, metavar="N", help="csv: lines to skip before the header")
    g.add_argument("--drop-duplicates", action="store_true",
                   help="csv: drop samples repeating the previous timestamp instead of failing")
    g.add_argument("--positions", choices=("columns", "fixed", "neck"), default="columns",
                   help="csv: columns (default), or for orientation-only traces fixed (the head at the origin) or "
                        "neck (a seated head-neck model)")
    g.add_argument("--recentre", nargs="?", const="position", choices=("position", "yaw"), default=None,
                   help="move the first position to the origin; 'yaw' also turns the first heading to -Z")


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "trace", help="convert, show, synthesise and list head traces",
        description="Head traces are timed camera poses, stored as canonical CSV "
                    "(t,px,py,pz,qw,qx,qy,qz; seconds, metres, right-handed, +Y up, camera along -Z).")
    sub = p.add_subparsers(dest="trace_command", metavar="SUBCOMMAND")
    sub.required = True

    c = sub.add_parser(
        "convert", help="convert a trace to canonical CSV (optionally resample or cut it)",
        description="Read a trace (canonical CSV, pred6dof/HoloLens CSV, a plain CSV whose columns you "
                    "name, or a built-in name) and write canonical CSV.",
        epilog="examples:\n"
               "  pibr trace convert pred6dof-1 walk.csv --rate 90\n"
               "  pibr trace convert log.csv out.csv --columns t=time,px=x,py=y,pz=z,qw=w,qx=i,qy=j,qz=k"
               " --time-unit ms\n"
               "  pibr trace convert raw.txt out.csv --delimiter whitespace --columns t=0,p=1,q=4 "
               "--quat-order xyzw --left-handed",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    c.add_argument("input", metavar="IN", help="trace file or built-in name (see 'pibr trace list')")
    c.add_argument("output", metavar="OUT", help="canonical CSV to write")
    add_import_options(c)
    c.add_argument("--rate", type=float, metavar="HZ", help="resample uniformly at this rate")
    c.add_argument("--start", type=float, default=0.0, metavar="S", help="start at this time (s)")
    c.add_argument("--duration", type=float, metavar="S", help="keep this many seconds")
    c.set_defaults(func=run_convert)

    s = sub.add_parser("show", help="summarise a trace (speeds, rate, extent), optionally plot it",
                       description="Print a trace's statistics; --plot draws the path, yaw/pitch and speeds.")
    s.add_argument("input", metavar="FILE_OR_NAME", help="trace file or built-in name; other CSV shapes with the "
                   "options of 'pibr trace convert'")
    add_import_options(s)
    s.add_argument("--plot", metavar="PNG", help="write a plot to this PNG file")
    s.add_argument("--json", action="store_true", help="print the summary as JSON")
    s.set_defaults(func=run_show)

    y = sub.add_parser("synth", help="synthesise a trace (walk, look, turns, mixed)",
                       description="Write a deterministic synthetic trace as canonical CSV; it starts at the "
                                   "origin looking along -Z.")
    y.add_argument("output", metavar="OUT", help="canonical CSV to write")
    y.add_argument("--kind", choices=("walk", "look", "turns", "mixed"), required=True)
    y.add_argument("--duration", type=float, required=True, metavar="S", help="length in seconds")
    y.add_argument("--rate", type=float, default=120.0, metavar="HZ", help="sample rate (default 120)")
    y.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    y.add_argument("--walk-speed", type=float, default=1.0, metavar="M_S", help="walking speed (default 1.0 m/s)")
    y.add_argument("--turn-speed", type=float, default=60.0, metavar="DEG_S",
                   help="peak angular speed looking around and walking (default 60 deg/s)")
    y.add_argument("--quick-turn-speed", type=float, default=250.0, metavar="DEG_S",
                   help="peak angular speed of quick turns (default 250 deg/s)")
    y.add_argument("--eye-height", type=float, default=0.0, metavar="M", help="start height (default 0)")
    y.add_argument("--loop-radius", type=float, default=2.5, metavar="M",
                   help="radius of the walking loop (default 2.5 m; grows if --turn-speed demands)")
    y.set_defaults(func=run_synth)

    ls = sub.add_parser("list", help="list the built-in traces")
    ls.set_defaults(func=run_list)


# --------------------------------------------------------------------------------- commands


def run_convert(args) -> int:
    from pibr.common.traces.canonical import write_canonical_csv

    # Cut first, then recentre: the first *kept* sample goes to the origin, not the recording's first.
    trace = read_input(args, recentre=False)
    if args.rate is not None:
        trace = trace.resample(args.rate, args.start, args.duration)
    elif args.start or args.duration is not None:
        trace = trace.slice(args.start, args.duration)
    if args.recentre:
        trace = trace.recentred(yaw=args.recentre == "yaw")
    write_canonical_csv(trace, args.output)
    print(f"wrote {args.output}: {len(trace)} samples, {trace.duration:.3f} s")
    return 0


def run_show(args) -> int:
    trace = read_input(args)
    info = trace.summary()
    if args.plot:
        plot_trace(trace, args.plot)
    if args.json:
        print(json.dumps(info, indent=2))
    else:
        print(format_summary(info))
        if args.plot:
            print(f"plot: {args.plot}")
    return 0


def run_synth(args) -> int:
    from pibr.common.traces.canonical import write_canonical_csv
    from pibr.common.traces.synthesis import synthesize

    trace = synthesize(args.kind, args.duration, rate_hz=args.rate, seed=args.seed,
                       walk_speed=args.walk_speed, turn_speed_deg=args.turn_speed,
                       quick_turn_deg_s=args.quick_turn_speed, eye_height=args.eye_height,
                       loop_radius=args.loop_radius)
    write_canonical_csv(trace, args.output)
    print(f"wrote {args.output}: {args.kind}, {len(trace)} samples, {trace.duration:.3f} s")
    return 0


def run_list(args) -> int:
    from pibr.common.traces.loading import builtin_traces

    traces = builtin_traces()
    width = max(len(n) for n in traces)
    for name, description in traces.items():
        print(f"{name:<{width}}  {description}")
    print("\nAlso accepted wherever a trace is asked for: a canonical or pred6dof CSV file. "
          "Synthetic traces: 'pibr trace synth OUT --kind walk|look|turns|mixed --duration S'.")
    return 0


# --------------------------------------------------------------------------------- helpers


def read_input(args, recentre: bool = True):
    """The trace the import options describe (format, columns, axes, and with ``recentre`` the
    recentring ``--recentre`` asks for; a caller that cuts the trace recentres after cutting)."""
    from pibr.common.traces.loading import detect_format, load_trace
    from pibr.common.traces.importers import import_csv, import_pred6dof, parse_columns

    fmt = "csv" if args.format == "auto" and args.columns else args.format
    if fmt == "csv":
        if not args.columns:
            raise TraceError("--format csv needs --columns, e.g. --columns t=time,px=x,py=y,pz=z,qw=qw,qx=qx,qy=qy,qz=qz")
        delimiter = _DELIMITERS.get(args.delimiter.lower(), args.delimiter)
        return import_csv(args.input, parse_columns(args.columns), time_unit=args.time_unit or "s",
                          rotation=args.rotation, quat_order=args.quat_order, euler_order=args.euler_order,
                          degrees=not args.radians, handedness="left" if args.left_handed else "right",
                          delimiter=delimiter, skip_rows=args.skip_rows,
                          duplicates="drop" if args.drop_duplicates else "error", up=args.up, forward=args.forward,
                          positions=args.positions, recentre=args.recentre if recentre else None)
    changed = [name for name, default in _CSV_OPTIONS.items() if getattr(args, name) != default]
    if args.columns or changed:
        options = ", ".join("--" + n.replace("_", "-") for n in (["columns"] if args.columns else []) + changed)
        raise TraceError(f"{options} only apply to --format csv (input format is {fmt})")
    import os

    if fmt == "auto" and os.path.isfile(args.input):
        fmt = detect_format(args.input)
    if fmt == "pred6dof":
        trace = import_pred6dof(args.input, args.time_unit)
    else:
        if args.time_unit is not None:
            what = f"{fmt} input" if os.path.isfile(args.input) else "a built-in or synthetic trace"
            raise TraceError(f"--time-unit applies to pred6dof and csv input, not to {what}")
        trace = load_trace(args.input, fmt)
    return trace.recentred(yaw=args.recentre == "yaw") if args.recentre and recentre else trace


def format_summary(info: dict) -> str:
    """Readable table of :meth:`HeadTrace.summary`."""
    lin, ang = info["linear_speed_m_s"], info["angular_speed_deg_s"]
    lo, hi, ext = info["position_min"], info["position_max"], info["position_extent"]
    rate = "n/a" if info["median_rate_hz"] is None else f"{info['median_rate_hz']:.1f} Hz median"
    rows = [
        ("trace", info["name"]),
        ("samples", str(info["samples"])),
        ("duration", f"{info['duration_s']:.3f} s"),
        ("rate", f"{rate}, longest gap {info['max_gap_s'] * 1e3:.1f} ms"),
        ("linear speed", f"mean {lin['mean']:.3f}  p95 {lin['p95']:.3f}  max {lin['max']:.3f} m/s"),
        ("angular speed", f"mean {ang['mean']:.1f}  p95 {ang['p95']:.1f}  max {ang['max']:.1f} deg/s"),
        ("position", "  ".join(f"{a} {l:.3f}..{h:.3f}" for a, l, h in zip("xyz", lo, hi)) + " m"),
        ("extent", " x ".join(f"{e:.3f}" for e in ext) + " m"),
    ]
    rows += [(f"assumed {k}", v) for k, v in info.get("assumptions", {}).items()]
    rows += [("warning", w) for w in info.get("warnings", [])]
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


def plot_trace(trace, path) -> None:
    """PNG with the top-down path (x right, -z up = forward at the start), yaw and pitch over
    time, and angular and linear speed over time."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from pibr.protocol.trace import yaw_pitch

    fig = Figure(figsize=(12, 6), layout="constrained")
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(2, 2, width_ratios=(1.0, 1.6))
    ax_path = fig.add_subplot(grid[:, 0])
    ax_angles = fig.add_subplot(grid[0, 1])
    ax_speed = fig.add_subplot(grid[1, 1], sharex=ax_angles)

    x, z = trace.positions[:, 0], trace.positions[:, 2]
    ax_path.plot(x, z, lw=1.0)
    ax_path.plot(x[:1], z[:1], "o", color="tab:green", label="start")
    ax_path.plot(x[-1:], z[-1:], "s", color="tab:red", label="end")
    angles = yaw_pitch(trace.orientations)
    step = max(1, len(trace) // 40)
    extent = max(np.ptp(x), np.ptp(z), 0.1)
    yaw = angles[::step, 0]
    ax_path.quiver(x[::step], z[::step], -np.sin(yaw), -np.cos(yaw), angles="xy", scale_units="xy",
                   scale=8.0 / extent, width=0.004, color="tab:gray", label="view direction")
    ax_path.set_aspect("equal", adjustable="datalim")
    ax_path.invert_yaxis()  # -Z (forward) up
    ax_path.set(xlabel="x (m)", ylabel="z (m)", title=f"{trace.name}: path from above")
    ax_path.legend(loc="best", fontsize="small")

    ax_angles.plot(trace.t, np.degrees(angles[:, 0]), lw=1.0, label="yaw")
    ax_angles.plot(trace.t, np.degrees(angles[:, 1]), lw=1.0, label="pitch")
    ax_angles.set(ylabel="degrees", title="view direction")
    ax_angles.legend(loc="best", fontsize="small")

    if len(trace) > 1:
        linear, angular = trace.speeds()
        mid = 0.5 * (trace.t[1:] + trace.t[:-1])
        ax_speed.plot(mid, np.degrees(angular), lw=0.8, color="tab:purple")
        ax_linear = ax_speed.twinx()
        ax_linear.plot(mid, linear, lw=0.8, color="tab:orange")
        ax_linear.set_ylabel("linear speed (m/s)", color="tab:orange")
    ax_speed.set(xlabel="t (s)", title="speed")
    ax_speed.set_ylabel("angular speed (deg/s)", color="tab:purple")
    try:
        fig.savefig(path, dpi=100)
    except OSError as exc:
        raise TraceError(f"{path}: cannot write plot: {exc.strerror or exc}") from exc
