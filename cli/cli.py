"""The ``pibr`` command line. Each command group lives next to what it drives and exposes
``register(subparsers)``; heavy libraries are imported inside the commands, so ``pibr --help``
and argument checking stay fast."""
from __future__ import annotations

import argparse
import importlib
import logging
import sys

from pibr import __version__

# Modules that register sub-commands, in the order ``pibr --help`` lists them.
COMMAND_MODULES = (
    "pibr.server.cli",      # serve, relay
    "pibr.client.cli",      # client
    "pibr.scenes_cli",      # scenes (pibr.scenes.cli, and --plan from pibr.server.scene_plan)
    "pibr.trace_cli",       # trace convert|show|synth
    "pibr.link_cli",        # link list|show
    "pibr.bench.cli",       # demo, evaluate, bench ...
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pibr",
        description="Hide network latency in remote rendering: a server streams wide-angle views, "
                    "a client re-renders its current view with image-based rendering.")
    parser.add_argument("--version", action="version", version=f"pibr {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv: debug)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose, 2)
    logging.basicConfig(level=level, format="%(asctime)s %(name)s %(levelname)s: %(message)s")
    from pibr.protocol.errors import PibrError

    try:
        return int(args.func(args) or 0)
    except PibrError as exc:
        print(f"pibr {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"pibr {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:   # the reader went away ('pibr ... | head'): nothing left to say
        sys.stderr.close()
        return 141
