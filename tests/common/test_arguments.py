"""Command-line types and the mapping of parsed arguments onto settings."""
import argparse
from dataclasses import dataclass, field

import pytest

from pibr.common import arguments


@dataclass
class _Settings:
    host: str = "localhost"
    rate_hz: float = 60.0
    view_size: tuple | None = None
    names: tuple = ()
    extra: dict = field(default_factory=dict)


def test_config_from_args_takes_the_fields_arguments_name_and_overrides_win():
    args = argparse.Namespace(host="example", rate_hz=30.0, view_size=[64, 32], names=["a"], unrelated=1)
    s = arguments.config_from_args(_Settings, args, names=("b",))
    assert s == _Settings("example", 30.0, (64, 32), ("b",), {})
    assert arguments.config_from_args(_Settings, argparse.Namespace()) == _Settings()
    with pytest.raises(TypeError, match="no field"):
        arguments.config_from_args(_Settings, args, colour="red")


def test_the_server_config_comes_from_its_command_line():
    from pibr.cli import build_parser
    from pibr.server.config import ServerConfig
    from pibr.server.config import EdgeSettings

    args = build_parser().parse_args(["serve", "--fps", "5", "--view-size", "512x256", "--no-peel-marker",
                                      "--edge-kbps", "800", "--max-in-flight", "2", "--depth-codec", "edge"])
    cfg = arguments.config_from_args(ServerConfig, args, peel_marker=not args.no_peel_marker,
                                     edge=EdgeSettings(kbps=args.edge_kbps))
    assert (cfg.fps, cfg.view_size, cfg.peel_marker, cfg.edge.kbps, cfg.max_in_flight, cfg.depth_codec) == \
        (5.0, (512, 256), False, 800.0, 2, "edge")


@pytest.mark.parametrize("kind, text, message", [
    (arguments.size, "0x4", "width and height must be in"),
    (arguments.positive, "0", "must be positive"),
    (arguments.positive, "nan", "expected a finite number"),
    (arguments.positive, "two", "expected a number"),
    (arguments.positive_int, "0", "must be at least 1"),
    (arguments.positive_int, "1.5", "expected an integer"),
    (arguments.non_negative, "-1", "must be >= 0"),
    (arguments.fraction, "1.5", "must be in (0, 1]"),
    (arguments.names, " , ", "name at least one"),
    (arguments.offset, "1,2", "expected FORWARD,UP,TILT_DEG"),
    (arguments.offset, "1,inf,2", "expected FORWARD,UP,TILT_DEG"),
])
def test_bad_values_say_why(kind, text, message):
    with pytest.raises(argparse.ArgumentTypeError, match=message.replace("(", r"\(").replace(")", r"\)")
                       .replace("[", r"\[").replace("]", r"\]")):
        kind(text)


def test_good_values_parse():
    assert arguments.size("64") == (64, 64) and arguments.sizes("8x4, 2x2") == ((8, 4), (2, 2))
    assert arguments.positives("") == () and arguments.positives("1,2.5") == (1.0, 2.5)
    assert arguments.positive_ints("3,4") == (3, 4) and arguments.offset("1.5,1.8,15") == (1.5, 1.8, 15.0)
