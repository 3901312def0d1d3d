"""The command line: every documented invocation parses, errors are clear, docker-compose is valid."""
import os
import shlex

import pytest
import yaml

from pibr.cli import build_parser, main

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_docker_compose_commands_are_valid_pibr_invocations():
    with open(os.path.join(ROOT, "docker-compose.yml")) as f:
        compose = yaml.safe_load(f)
    services = compose["services"]
    assert {"server", "relay", "client"} <= set(services)
    with open(os.path.join(ROOT, "Dockerfile")) as f:
        dockerfile = f.read()
    assert 'ENTRYPOINT ["pibr"]' in dockerfile and "libegl" in dockerfile
    parser = build_parser()
    for name, svc in services.items():
        cmd = svc["command"]
        argv = shlex.split(cmd) if isinstance(cmd, str) else [str(a) for a in cmd]
        args = parser.parse_args(argv)     # argparse exits on anything it does not accept
        assert args.command in ("serve", "relay", "client")
    relay = parser.parse_args(services["relay"]["command"])
    assert relay.up_ms + relay.down_ms == 128


@pytest.mark.parametrize("argv", [
    ["serve", "--port", "0", "--projection", "tess", "--extra-view", "off"],
    ["relay", "--listen", ":0", "--upstream", "host:7450", "--jitter-ms", "5", "--kbps", "20000"],
    ["client", "--connect", "[::1]:7451", "--method", "none,rotation", "--clock", "real", "--size", "1280x720"],
    ["demo", "--duration", "2"], ["evaluate", "out"], ["bench", "server", "--projection", "vertex"],
    ["bench", "client"], ["scenes"], ["trace", "list"],
])
def test_documented_invocations_parse(argv):
    build_parser().parse_args(argv)


def test_bad_cli_values_are_reported(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["client", "--method", "warp"])
    assert "unknown method" in capsys.readouterr().err
    assert main(["relay", "--up-ms", "-5"]) == 2
    assert "delay_ms must be" in capsys.readouterr().err
    assert main(["client", "--connect", "nohost"]) == 2
    assert "expected HOST:PORT" in capsys.readouterr().err


@pytest.mark.parametrize("argv, message", [
    (["bench", "codec", "--size", "0x0"], "width and height must be in"),
    (["bench", "coverage", "--rate", "0"], "--rate: must be positive"),
    (["bench", "ibr", "--duration", "-1"], "--duration: must be positive"),
    (["bench", "ibr", "--latency-ms", "nan"], "finite"),
    (["bench", "optimize-offset", "--frames", "0"], "--frames: must be at least 1"),
    (["bench", "lod", "--fraction", "2"], "must be in (0, 1]"),
    (["bench", "server", "--max-edge-deg", "6,0.5"], "expected angles in 1..30 degrees"),
    (["demo", "--flip-every", "-1"], "--flip-every: must be >= 0"),
])
def test_bad_bench_arguments_are_named(capsys, argv, message):
    with pytest.raises(SystemExit):
        build_parser().parse_args(argv)
    assert message in capsys.readouterr().err


def test_bench_schedules_outside_the_trace_are_refused(capsys):
    assert main(["bench", "coverage", "--trace", "pred6dof-1", "--start", "1000"]) == 2
    assert "outside trace 'pred6dof-1'" in capsys.readouterr().err
    assert main(["bench", "codec", "--trace", "pred6dof-1", "--duration", "0.01"]) == 2
    assert "not a single frame" in capsys.readouterr().err
    assert main(["serve", "--port", "0", "--edge-kbps", "-5"]) == 2
    assert "edge codec bitrate" in capsys.readouterr().err
    assert main(["serve", "--port", "0", "--max-edge-deg", "0.5"]) == 2
    assert "max edge angle must be in 1..30 degrees" in capsys.readouterr().err


def test_scenes_lists_builtins(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    assert "room" in out and "sphere" in out
