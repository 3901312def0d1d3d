"""``pibr link``: list, show and convert the bandwidth traces a relay replays (common/bandwidth.py).
numpy and matplotlib are imported inside the commands."""
from __future__ import annotations

import json


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "link", help="list, show and convert bandwidth traces (for pibr relay --down-trace)",
        description="Bandwidth traces replay a link whose capacity changes: Mahimahi delivery opportunities "
                    "(one millisecond per line, each a 1500-byte packet) or t,kbps rows; both loop.")
    sub = p.add_subparsers(dest="link_command", metavar="SUBCOMMAND")
    sub.required = True
    ls = sub.add_parser("list", help="list the built-in bandwidth traces")
    ls.set_defaults(func=run_list)
    s = sub.add_parser("show", help="summarise a bandwidth trace, optionally plot it or write it in either format")
    s.add_argument("trace", metavar="FILE_OR_NAME", help="a built-in name or a trace file")
    s.add_argument("--plot", metavar="PNG", help="write the rate over one period to this PNG file")
    s.add_argument("--write", metavar="FILE", help="write the trace to FILE (format from --format)")
    s.add_argument("--format", choices=("csv", "mahimahi"), default="csv",
                   help="format of --write: t,kbps rows (default) or Mahimahi delivery opportunities")
    s.add_argument("--json", action="store_true", help="print the summary as JSON")
    s.set_defaults(func=run_show)


def run_list(args) -> int:
    from pibr.common.bandwidth import BUILTIN

    width = max(len(n) for n in BUILTIN)
    for name, (description, _) in BUILTIN.items():
        print(f"{name:<{width}}  {description}")
    print("\nAlso accepted wherever a bandwidth trace is asked for: a file of Mahimahi delivery opportunities "
          "(one millisecond per line) or of t,kbps rows (seconds, kbit/s from that time on).")
    return 0


def run_show(args) -> int:
    from pibr.common.bandwidth import load_bandwidth_trace

    trace = load_bandwidth_trace(args.trace)
    summary = trace.summary()
    if args.json:
        print(json.dumps(summary, indent=1))
    else:
        print(f"{summary['name']}: {summary['period_s']:g} s, looping; mean {summary['mean_kbps']:.0f} kbit/s; "
              f"over {summary['window_ms']:g} ms: min {summary['min_kbps']:.0f}, 10th percentile {summary['p10_kbps']:.0f}, median "
              f"{summary['median_kbps']:.0f}, max {summary['max_kbps']:.0f}; {summary['outage_s']:g} s without "
              f"any bandwidth; {summary['segments']} constant-rate segments")
    if args.write:
        text = trace.to_csv() if args.format == "csv" else trace.to_mahimahi()
        with open(args.write, "w", encoding="utf-8") as f:
            f.write(text)
        print(f"wrote {args.write} ({args.format})")
    if args.plot:
        plot_bandwidth(trace, args.plot)
        print(f"plot: {args.plot}")
    return 0


def plot_bandwidth(trace, path) -> None:
    """PNG of the rate over one period (Mbit/s against seconds)."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 3.2), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    t = trace.times_us / 1e6
    rates = np.append(trace.rates_kbps, trace.rates_kbps[-1]) / 1e3
    ax.step(t, rates, where="post", lw=1.2)
    ax.axhline(trace.mean_kbps / 1e3, color="tab:gray", ls="--", lw=0.8, label=f"mean {trace.mean_kbps / 1e3:.1f}")
    ax.set_xlabel("time in the trace (s; it loops)")
    ax.set_ylabel("Mbit/s")
    ax.set_title(f"bandwidth trace {trace.name}")
    ax.set_ylim(bottom=0)
    ax.legend(loc="upper right")
    fig.savefig(path, dpi=110)
