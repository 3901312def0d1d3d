"""End to end with real processes: a server listening on every interface with a token and TLS,
a relay with its own certificate connecting to the server by pin, and a client verifying the
relay against a CA file and sending the token from a file."""
import os

import pytest

from pibr.bench.processes import run_pipeline
from pibr.client.recorder import read_records
from pibr.common.tls import certificate_fingerprint

from .tlsfiles import tls_files  # noqa: F401 (fixture)

pytestmark = [pytest.mark.integration, pytest.mark.gl]


def test_token_and_tls_through_server_relay_and_client_processes(tls_files, tmp_path, monkeypatch):
    monkeypatch.delenv("PIBR_TOKEN", raising=False)
    token = tmp_path / "token"
    token.write_text("integration-token-0123456789\n")
    tls = ["--tls-cert", tls_files.cert, "--tls-key", tls_files.key]
    out = str(tmp_path / "run")
    run_pipeline(out,
                 server_args=["--host", "0.0.0.0", "--scene", "sphere", "--view-size", "128x128",
                              "--token-file", str(token), *tls],
                 relay_args=["--up-ms", "32", "--down-ms", "32", "--token-file", str(token), *tls,
                             "--upstream-tls-pin", certificate_fingerprint(tls_files.cert)],
                 client_args=["--trace", "pred6dof-1", "--start", "12", "--duration", "1", "--rate", "10",
                              "--size", "160x96", "--method", "none", "--no-lossless",
                              "--token-file", str(token), "--tls-ca", tls_files.cert],
                 timeout=300)
    rows = read_records(os.path.join(out, "none.records.csv"))
    assert len(rows) == 10 and all(r["frame_id"] >= 0 for r in rows)
    for name in os.listdir(out) + [os.path.join("logs", n) for n in os.listdir(os.path.join(out, "logs"))]:
        path = os.path.join(out, name)
        if os.path.isfile(path):
            with open(path, "rb") as f:
                assert b"integration-token" not in f.read(), name
    with open(os.path.join(out, "logs", "client.log")) as f:
        assert "Traceback" not in f.read()
