"""Certificates made for a test run with the ``openssl`` command (no private key is committed).

``tls_files`` (a session fixture) gives two self-signed certificates for ``localhost`` and
127.0.0.1, each with its key: ``cert``/``key`` for the servers, ``other_cert`` a CA that did
not sign them. Tests that use it are skipped, saying why, where ``openssl`` is missing.
"""
from __future__ import annotations

import shutil
import subprocess
from types import SimpleNamespace

import pytest


def make_certificate(directory, name: str) -> tuple[str, str]:
    """A self-signed P-256 certificate for localhost / 127.0.0.1 -> (cert path, key path)."""
    cert, key = str(directory / f"{name}.crt"), str(directory / f"{name}.key")
    subprocess.run(["openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1",
                    "-nodes", "-keyout", key, "-out", cert, "-days", "2", "-subj", f"/CN={name}",
                    "-addext", "subjectAltName=DNS:localhost,IP:127.0.0.1"],
                   check=True, capture_output=True, timeout=60)
    return cert, key


@pytest.fixture(scope="session")
def tls_files(tmp_path_factory):
    if shutil.which("openssl") is None:
        pytest.skip("no 'openssl' command to make a test certificate with")
    d = tmp_path_factory.mktemp("tls")
    cert, key = make_certificate(d, "pibr-test")
    other_cert, other_key = make_certificate(d, "pibr-other")
    return SimpleNamespace(cert=cert, key=key, other_cert=other_cert, other_key=other_key)
