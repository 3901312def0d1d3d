"""Access control without sockets: tokens, loopback, the Hello's token field, TLS settings."""
import subprocess

import pytest

from pibr.protocol import access
from pibr.protocol.access import (check_listen_access, is_loopback, resolve_token, token_matches)
from pibr.protocol.errors import ConfigError, MalformedMessage
from pibr.protocol.messages import MAX_TOKEN, Hello
from pibr.common.tls import ClientTLS, certificate_fingerprint, parse_pin, server_context

from ..tlsfiles import tls_files  # noqa: F401 (fixture)

TOKEN = "s3cret-token-for-tests-0123"


@pytest.mark.parametrize("host, loopback", [
    ("127.0.0.1", True), ("127.3.2.1", True), ("::1", True), ("[::1]", True), ("localhost", True),
    ("LOCALHOST", True), ("0.0.0.0", False), ("::", False), ("", False), ("192.168.1.5", False),
    ("example.org", False), ("localhost.example.org", False),
])
def test_which_hosts_are_loopback(host, loopback):
    assert is_loopback(host) is loopback


def test_listening_off_loopback_needs_a_long_enough_token():
    check_listen_access("server", "127.0.0.1", None)
    check_listen_access("server", "0.0.0.0", TOKEN)
    for host in ("0.0.0.0", "", "10.0.0.1", "myhost"):
        with pytest.raises(ConfigError, match="without a token: set PIBR_TOKEN or pass --token-file FILE"):
            check_listen_access("server", host, None)
    with pytest.raises(ConfigError, match="token is 5 characters long; use at least 16"):
        check_listen_access("server", "127.0.0.1", "short")     # a configured token is checked on loopback too


def test_token_sources_in_order(tmp_path):
    f = tmp_path / "token"
    f.write_text("from-the-file-0123456789\nsecond line ignored\n")
    env = {"PIBR_TOKEN": "from-the-environment-0123"}
    assert resolve_token(None, None, {}) is None
    assert resolve_token(None, None, env) == "from-the-environment-0123"
    assert resolve_token(None, str(f), env) == "from-the-file-0123456789"
    assert resolve_token("from-the-option-0123456", None, env) == "from-the-option-0123456"
    with pytest.raises(ConfigError, match="--token or --token-file, not both"):
        resolve_token("a", str(f), env)
    with pytest.raises(ConfigError, match="cannot read the token file .*missing.*No such file"):
        resolve_token(None, str(tmp_path / "missing"), {})
    (tmp_path / "empty").write_text("\n")
    with pytest.raises(ConfigError, match="is empty; put the token on its first line"):
        resolve_token(None, str(tmp_path / "empty"), {})
    with pytest.raises(ConfigError, match="printable ASCII characters without spaces"):
        resolve_token("has space in it 0123", None, {})
    with pytest.raises(ConfigError, match=r"token in \$PIBR_TOKEN must be"):
        resolve_token(None, None, {"PIBR_TOKEN": "x" * (MAX_TOKEN + 1)})


def test_token_comparison_is_exact_and_uses_compare_digest(monkeypatch):
    assert token_matches(TOKEN, TOKEN)
    for given in ("", TOKEN[:-1], TOKEN + "x", "X" + TOKEN[1:], TOKEN[:-1] + "X", TOKEN.upper()):
        assert not token_matches(TOKEN, given)
    calls = []
    real = access.hmac.compare_digest
    monkeypatch.setattr(access.hmac, "compare_digest", lambda a, b: calls.append((a, b)) or real(a, b))
    assert token_matches(TOKEN, TOKEN) and not token_matches(TOKEN, "nope")
    assert calls == [(TOKEN.encode(), TOKEN.encode()), (TOKEN.encode(), b"nope")]


def test_hello_carries_the_token_only_when_given_and_never_shows_it():
    plain = Hello(client="c")
    assert b"token" not in plain.serialize()          # unchanged bytes for everyone without a token
    with_token = Hello(client="c", token=TOKEN)
    assert Hello.parse(with_token.serialize()).token == TOKEN
    assert TOKEN not in repr(with_token) and TOKEN not in str(with_token)
    too_long = with_token.serialize().replace(TOKEN.encode(), b"y" * (MAX_TOKEN + 1))
    with pytest.raises(MalformedMessage, match=f"Hello: field 'token' is longer than {MAX_TOKEN} characters") as e:
        Hello.parse(too_long)
    assert "yyy" not in str(e.value)


@pytest.mark.parametrize("text", ["AB" * 32, "ab:" * 31 + "ab", "sha256:" + "ab" * 32, "  " + "Ab" * 32 + "\n"])
def test_pins_are_accepted_in_the_usual_spellings(text):
    assert parse_pin(text) == "ab" * 32


@pytest.mark.parametrize("text", ["", "ab" * 31, "ab" * 33, "zz" * 32])
def test_bad_pins_are_refused(text):
    with pytest.raises(ConfigError, match="64 hex digits"):
        parse_pin(text)


def test_client_tls_takes_one_way_to_verify(tmp_path):
    with pytest.raises(ConfigError, match="exactly one of --tls-ca FILE and --tls-pin SHA256"):
        ClientTLS()
    with pytest.raises(ConfigError, match="exactly one of"):
        ClientTLS(ca_file="x", pin="ab" * 32)
    with pytest.raises(ConfigError, match="cannot read the TLS CA file .*nowhere.pem"):
        ClientTLS(ca_file=str(tmp_path / "nowhere.pem"))
    junk = tmp_path / "junk.pem"
    junk.write_text("not a certificate\n")
    with pytest.raises(ConfigError, match="the TLS CA file .*junk.pem.* does not load"):
        ClientTLS(ca_file=str(junk)).context()


def test_certificate_and_key_errors_name_the_file(tls_files, tmp_path):
    server_context(tls_files.cert, tls_files.key)
    with pytest.raises(ConfigError, match="cannot read the TLS certificate .*absent.crt"):
        server_context(str(tmp_path / "absent.crt"), tls_files.key)
    with pytest.raises(ConfigError, match="cannot read the TLS key .*absent.key"):
        server_context(tls_files.cert, str(tmp_path / "absent.key"))
    with pytest.raises(ConfigError, match="do not load .*an unencrypted key that matches the certificate"):
        server_context(tls_files.cert, tls_files.other_key)         # a key of another certificate
    junk = tmp_path / "junk.crt"
    junk.write_text("-----BEGIN CERTIFICATE-----\nnope\n-----END CERTIFICATE-----\n")
    with pytest.raises(ConfigError, match="do not load"):
        server_context(str(junk), tls_files.key)


def test_fingerprint_is_the_one_openssl_reports(tls_files):
    out = subprocess.run(["openssl", "x509", "-in", tls_files.cert, "-noout", "-fingerprint", "-sha256"],
                         check=True, capture_output=True, text=True).stdout
    assert certificate_fingerprint(tls_files.cert) == parse_pin(out.split("=", 1)[1])


@pytest.mark.parametrize("first_bytes", [b"\x16\x03\x01\x02\x00\x01", b"\x15\x03\x03\x00\x02", b"\x16"])
def test_a_tls_record_where_a_frame_should_be_is_named(first_bytes):
    from pibr.protocol.errors import BadMagic
    from pibr.protocol.framing import FrameReader

    with pytest.raises(BadMagic, match="a TLS record: the peer speaks TLS and this end does not"):
        FrameReader().feed(first_bytes)
    with pytest.raises(BadMagic) as e:
        FrameReader().feed(b"GET / HTTP/1.1\r\n")
    assert "TLS" not in str(e.value)
