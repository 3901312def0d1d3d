"""Access options on the command line: off loopback without a token is refused in one line,
and bad token or TLS options are named before anything starts."""
import os
import subprocess
import sys

import pytest

from pibr.cli import build_parser, main


@pytest.fixture(autouse=True)
def no_token_in_environment(monkeypatch):
    monkeypatch.delenv("PIBR_TOKEN", raising=False)


def test_serve_off_loopback_without_a_token_exits_with_the_fix():
    """A real process: exit code 2 and one line naming the fix, before any OpenGL or socket."""
    env = {k: v for k, v in os.environ.items() if k != "PIBR_TOKEN"}
    done = subprocess.run([sys.executable, "-m", "pibr", "serve", "--host", "0.0.0.0", "--port", "0"],
                          capture_output=True, text=True, timeout=120, env=env)
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr
    assert done.stderr.startswith("pibr serve: error: the server would listen on 0.0.0.0, reachable from other "
                                  "machines, without a token: set PIBR_TOKEN or pass --token-file FILE")


@pytest.mark.parametrize("argv, message", [
    (["relay", "--listen", "0.0.0.0:0"], "the relay would listen on 0.0.0.0, reachable from other machines"),
    (["serve", "--host", "", "--port", "0"], "the server would listen on every interface"),
    (["serve", "--port", "0", "--token", "short"], "the server's token is 5 characters long; use at least 16"),
    (["serve", "--port", "0", "--token-file", "/nonexistent/token"],
     "cannot read the token file '/nonexistent/token': No such file or directory"),
    (["serve", "--port", "0", "--tls-cert", "/nonexistent/c.pem", "--tls-key", "/nonexistent/k.pem"],
     "cannot read the TLS certificate '/nonexistent/c.pem'"),
    (["serve", "--port", "0", "--tls-cert", "/nonexistent/c.pem"], "needs both --tls-cert and --tls-key"),
    (["relay", "--listen", ":0", "--upstream-tls-pin", "abc"], "64 hex digits"),
    (["relay", "--listen", ":0", "--buffer-mib", "1"], "cannot hold one message"),
    (["relay", "--listen", ":0", "--max-connections", "0"], "connection limit must be in 1..100000"),
    (["client", "--tls-ca", "/nonexistent/ca.pem"], "cannot read the TLS CA file '/nonexistent/ca.pem'"),
    (["client", "--tls-ca", "x", "--tls-pin", "ab" * 32], "exactly one of --tls-ca FILE and --tls-pin SHA256"),
    (["client", "--token", "has space"], "printable ASCII characters without spaces"),
])
def test_bad_access_options_are_one_clear_line(capsys, argv, message):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_the_token_from_the_environment_lets_the_server_listen_off_loopback(monkeypatch):
    from pibr.protocol.access import resolve_token
    from pibr.server.config import ServerConfig

    monkeypatch.setenv("PIBR_TOKEN", "token-from-the-environment")
    args = build_parser().parse_args(["serve", "--host", "0.0.0.0"])
    config = ServerConfig(host=args.host, token=resolve_token(args.token, args.token_file))
    assert config.token == "token-from-the-environment"


def test_access_options_are_documented():
    parser = build_parser()
    sub = parser._subparsers._group_actions[0].choices
    serve, relay, client = (sub[name].format_help() for name in ("serve", "relay", "client"))
    for text in (serve, relay):
        assert "--token-file" in text and "--tls-cert" in text and "--tls-key" in text and "PIBR_TOKEN" in text
    assert "--upstream-tls-ca" in relay and "--upstream-tls-pin" in relay and "--max-connections" in relay
    assert "--tls-ca" in client and "--tls-pin" in client and "--token-file" in client


def test_docker_compose_gives_every_process_the_shared_token():
    """Server and relay listen on every interface of their containers: compose passes them, and
    the client, PIBR_TOKEN from the environment, and refuses to start without it."""
    import yaml

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    with open(os.path.join(root, "docker-compose.yml")) as f:
        services = yaml.safe_load(f)["services"]
    for name in ("server", "relay", "client"):
        assert services[name]["environment"]["PIBR_TOKEN"].startswith("${PIBR_TOKEN:?set PIBR_TOKEN")
