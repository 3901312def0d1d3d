"""The command line: every documented invocation parses, errors are clear, docker-compose is valid."""
import os
import shlex
import subprocess
import sys

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
    client = parser.parse_args(services["client"]["command"])
    assert client.methods == ("none", "rotation", "proxy")     # the project's main method, beside its baselines


def test_docker_image_installs_the_whole_project():
    """The image copies the build context whole and installs it regularly; .dockerignore keeps
    out nothing the build needs (every package folder, setup.py, pyproject.toml, README.md)."""
    with open(os.path.join(ROOT, "Dockerfile")) as f:
        lines = [ln.split() for ln in f if ln.strip() and not ln.lstrip().startswith("#")]
    assert ["COPY", ".", "."] in lines
    assert any(ln[:1] == ["RUN"] and "pip install --no-cache-dir ." in " ".join(ln) and "-e" not in ln
               for ln in lines)
    with open(os.path.join(ROOT, ".dockerignore")) as f:
        ignored = {ln.strip().strip("/") for ln in f if ln.strip() and not ln.startswith("#")}
    needed = {"setup.py", "pyproject.toml", "README.md"} | {
        d for d in os.listdir(ROOT) if d != "tests" and os.path.isfile(os.path.join(ROOT, d, "__init__.py"))}
    assert len(needed) >= 9 and not needed & ignored


@pytest.mark.parametrize("argv", [
    ["serve", "--port", "0", "--projection", "tess", "--extra-view", "off"],
    ["relay", "--listen", ":0", "--upstream", "host:7450", "--jitter-ms", "5", "--kbps", "20000"],
    ["client", "--connect", "[::1]:7451", "--method", "none,rotation", "--clock", "real", "--size", "1280x720"],
    ["demo", "--duration", "2"], ["evaluate", "out"], ["bench", "server", "--projection", "vertex"],
    ["bench", "client"], ["scenes"], ["trace", "list"], ["link", "list"],
    ["relay", "--down-trace", "cellular", "--up-trace", "steps.csv"], ["serve", "--adapt", "on"],
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
    (["bench", "codec", "--duration", "-1"], "--duration: must be positive"),
    (["bench", "ibr", "--windows", "pred6dof-1@-3+2"], "need a trace, a start >= 0 and a positive duration"),
    (["bench", "coverage", "--windows", "pred6dof-1"], "expected 'evaluation', 'tuning' or TRACE@START+DURATION"),
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
    assert main(["bench", "coverage", "--windows", "pred6dof-1@1000+2"]) == 2
    assert "outside trace 'pred6dof-1'" in capsys.readouterr().err
    assert main(["bench", "codec", "--windows", "pred6dof-1@30+4", "--duration", "0.01"]) == 2
    assert "not a single frame" in capsys.readouterr().err
    assert main(["serve", "--port", "0", "--edge-kbps", "-5"]) == 2
    assert "edge codec bitrate" in capsys.readouterr().err
    assert main(["serve", "--port", "0", "--max-edge-deg", "0.5"]) == 2
    assert "max edge angle must be in 1..30 degrees" in capsys.readouterr().err


def test_bandwidth_traces_are_shown_converted_and_refused_by_name(capsys, tmp_path):
    assert main(["link", "show", "steps", "--json", "--write", str(tmp_path / "s.mm"), "--format", "mahimahi"]) == 0
    out = capsys.readouterr().out
    assert '"mean_kbps": 11800.0' in out and '"min_kbps": 3000.0' in out
    assert main(["link", "show", str(tmp_path / "s.mm")]) == 0
    assert "50 s, looping; mean 11800 kbit/s" in capsys.readouterr().out
    (tmp_path / "bad.csv").write_text("t,kbps\n0,100\n0,200\n")
    assert main(["relay", "--down-trace", str(tmp_path / "bad.csv")]) == 2
    assert "bad.csv, line 3: times must increase" in capsys.readouterr().err
    assert main(["relay", "--down-trace", "no-such-trace"]) == 2
    assert "neither a file nor a built-in (steps, oscillation, outage, cellular, steady)" in capsys.readouterr().err


def test_scenes_lists_builtins(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    assert "room" in out and "sphere" in out


@pytest.mark.parametrize("command", ["serve", "relay"])
def test_a_port_in_use_is_one_line_naming_it(capsys, command):
    import socket

    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        port = held.getsockname()[1]
        argv = ["serve", "--port", str(port)] if command == "serve" else ["relay", "--listen", f"127.0.0.1:{port}"]
        assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert f"cannot listen on 127.0.0.1:{port}: Address already in use" in err
    assert "choose another port" in err


@pytest.mark.parametrize("argv, message", [
    (["demo", "--scene", "no-such-scene"], "unknown scene 'no-such-scene'; built-in scenes:"),
    (["demo", "--scene", "missing/scene.toml"], "scene file 'missing/scene.toml' does not exist"),
    (["demo", "--trace", "no-such-trace"], "'no-such-trace' is neither a trace file nor a built-in trace"),
    (["demo", "--start", "9999"], "start 9999.0 s is outside trace 'pred6dof-1'"),
])
def test_demo_refuses_bad_names_before_starting_anything(capsys, tmp_path, argv, message):
    out = tmp_path / "out"
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not out.exists()        # refused before any process started or anything was written


def test_bench_network_runs_the_static_settings_alone_with_an_empty_adapt_start():
    args = build_parser().parse_args(["bench", "network", "--adapt-start", ""])
    assert args.adapt_start == () and args.static_kbps == (2000.0, 4000.0, 8000.0, 16000.0)
    assert build_parser().parse_args(["bench", "network"]).adapt_start == ("foot",)
    assert build_parser().parse_args(["bench", "network", "--adapt-start", "foot,probe"]).adapt_start == ("foot", "probe")


@pytest.mark.parametrize("argv, message", [
    (["--static-kbps", "", "--adapt-start", ""], "nothing to run: --static-kbps and --adapt-start are both empty"),
    (["--adapt-start", "foot,fast"], "--adapt-start: 'fast' is not one of foot, probe"),
    (["--links", "no-such-link"], "no-such-link"),
])
def test_bench_network_refuses_before_starting_anything(capsys, tmp_path, argv, message):
    out = tmp_path / "out"
    assert main(["bench", "network", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err
    assert not out.exists()


@pytest.mark.parametrize("argv", [["serve", "--port", "0"], ["demo", "--duration", "1"]])
def test_missing_egl_is_one_line_naming_the_fix(tmp_path, argv):
    """A libEGL that cannot be loaded (an empty file first on the library path, as on a machine
    without Mesa's EGL): one line naming the problem and the package to install, exit code 2."""
    fake = tmp_path / "lib"
    fake.mkdir()
    for name in ("libEGL.so", "libEGL.so.1"):
        (fake / name).write_bytes(b"")
    env = dict(os.environ, LD_LIBRARY_PATH=str(fake), PIBR_GL_BACKEND="egl")
    res = subprocess.run([sys.executable, "-m", "pibr", *argv, *(["--out", str(tmp_path / "out")]
                                                                 if argv[0] == "demo" else [])],
                         cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stderr and res.stderr.count("\n") == 1, res.stderr
    assert "no headless OpenGL" in res.stderr and "apt-get install libegl1" in res.stderr
    assert "listening on" not in res.stdout


def test_method_knobs_reach_the_client_config():
    from pibr.client.cli import method_knobs

    args = build_parser().parse_args(["client", "--method", "coarse-meshwarp,homography,proxy", "--coarse-step", "8",
                                      "--plane-distance", "3.5", "--no-extra-view", "--no-inpaint"])
    assert method_knobs(args) == {"step": 8, "plane_distance": 3.5, "extra_view": False, "inpaint": False}
    assert method_knobs(build_parser().parse_args(["client"])) == {}


@pytest.mark.parametrize("argv, message", [
    (["client", "--coarse-step", "0"], "--coarse-step: must be at least 1"),
    (["client", "--plane-distance", "inf"], "--plane-distance: expected a finite number"),
    (["client", "--point-size", "two"], "--point-size: expected a number"),
])
def test_bad_method_knobs_are_named(capsys, argv, message):
    with pytest.raises(SystemExit):
        build_parser().parse_args(argv)
    assert message in capsys.readouterr().err


def test_the_motion_knobs_parse():
    from pibr.client.cli import method_knobs

    args = build_parser().parse_args(["client", "--method", "rotation,proxy", "--motion", "flow"])
    assert method_knobs(args) == {"motion": "flow"}
    assert build_parser().parse_args(["serve", "--flow-coder", "edges"]).flow_coder == "edges"
    assert build_parser().parse_args(["serve"]).flow_coder == "blocks"
    assert build_parser().parse_args(["demo", "--scene", "dynamic", "--motion", "flow"]).motion == "flow"
    d = build_parser().parse_args(["bench", "dynamic", "--latency-ms", "64,256", "--scene", "dynamic"])
    assert d.latency_ms == (64.0, 256.0) and d.scene == ("dynamic",) and d.view_size == (512, 512)
    for argv in (["client", "--motion", "oracle"], ["serve", "--flow-coder", "dct"]):
        with pytest.raises(SystemExit):
            build_parser().parse_args(argv)


def test_bench_ibr_shows_its_defaults_and_takes_its_variants(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["bench", "ibr", "--help"])
    text = capsys.readouterr().out
    for fragment in ("(default 2)", "(default 128)", "(default 960x540)", "(default: none)", "--speed-sizes"):
        assert fragment in text, fragment
    args = build_parser().parse_args(["bench", "ibr", "--lod-targets", "2,16", "--lod-levels", "proxy,box",
                                      "--speed-sizes", "640x360"])
    assert args.lod_targets == (2.0, 16.0) and args.lod_levels == ("proxy", "box")
    assert args.speed_sizes == ((640, 360),)
    assert main(["bench", "ibr", "--lod-levels", "tiny"]) == 2
    assert "--lod-levels: unknown level(s) tiny" in capsys.readouterr().err


def test_timeouts_and_limits_are_options(capsys):
    """Issue 13: the server's deadlines and limits and the client's receive timeout."""
    args = build_parser().parse_args(["serve", "--max-pending", "5", "--hello-timeout-s", "2", "--idle-timeout-s", "3",
                                      "--idle-timeout-virtual-s", "4", "--max-clock-lead-s", "1.5"])
    assert (args.max_pending, args.hello_timeout_s, args.idle_timeout_s, args.idle_timeout_virtual_s,
            args.max_clock_lead_s) == (5, 2.0, 3.0, 4.0, 1.5)
    assert build_parser().parse_args(["client", "--receive-timeout-s", "7"]).receive_timeout_s == 7.0
    with pytest.raises(SystemExit):
        build_parser().parse_args(["client", "--receive-timeout-s", "0"])
    assert "--receive-timeout-s: must be positive" in capsys.readouterr().err
    for argv, message in [(["--idle-timeout-s", "0"], "idle timeout must be in (0, 86400] s"),
                          (["--max-pending", "0"], "max pending connections must be at least 1"),
                          (["--max-clock-lead-s", "-1"], "clock lead must be in (0, 86400] s")]:
        assert main(["serve", "--port", "0", *argv]) == 2
        assert message in capsys.readouterr().err


def test_bench_realtime_passes_only_the_server_options_set():
    from pibr.bench.commands import realtime_server_args

    parse = build_parser().parse_args
    a = parse(["bench", "realtime"])
    assert realtime_server_args(a.view_size, a.extra_view) == ()
    a = parse(["bench", "realtime", "--view-size", "512x512", "--extra-view", "off"])
    assert realtime_server_args(a.view_size, a.extra_view) == ("--view-size", "512x512", "--extra-view", "off")
    with pytest.raises(SystemExit):
        parse(["bench", "realtime", "--extra-view", "sometimes"])


def test_bench_proxy_speed_takes_its_sizes():
    a = build_parser().parse_args(["bench", "proxy-speed", "--sizes", "320x180,640x360", "--frames", "2"])
    assert a.sizes == ((320, 180), (640, 360)) and a.frames == 2 and a.repeats == 3
    with pytest.raises(SystemExit):
        build_parser().parse_args(["bench", "proxy-speed", "--frames", "0"])
