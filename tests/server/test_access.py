"""The server with a token and TLS, end to end on loopback with the real client: the right
client is served, every wrong one gets one clear error, and the server goes on serving."""
import asyncio
import json
import logging

import pytest

from pibr.client.app import run_client
from pibr.client.config import ClientConfig
from pibr.client.connection import ClientConnection, ServerClosed
from pibr.protocol import access
from pibr.protocol.connection import Connection
from pibr.protocol.errors import AccessDenied, ConfigError, TLSError
from pibr.protocol.framing import encode_frame
from pibr.protocol.messages import Error, Hello, OutputConfig
from pibr.common.tls import ClientTLS, certificate_fingerprint, open_connection
from pibr.server.config import ServerConfig

from ..loopback import running_server

from ..tlsfiles import tls_files  # noqa: F401 (fixture)

TOKEN = "server-test-token-9876543210"
HELLO = Hello(client="test", scene="sphere", clock="virtual", output=OutputConfig(160, 96, 90.0, 30.0))


@pytest.fixture
async def secured(tls_files):
    """A server on loopback that requires TOKEN and speaks only TLS -> (host, port, files)."""
    config = ServerConfig(port=0, scene="sphere", view_size=(128, 128), bitrate_kbps=2000, token=TOKEN,
                          tls_cert=tls_files.cert, tls_key=tls_files.key)
    async with running_server(config) as (_, host, port):
        yield host, port, tls_files


async def _handshake(host, port, tls, token):
    c = await ClientConnection.open(host, port, tls=tls)
    try:
        return await c.handshake(Hello(**{**HELLO.__dict__, "token": token}))
    finally:
        await c.close()


@pytest.mark.gl
async def test_the_client_with_token_and_tls_is_served_and_records_no_secret(secured, tmp_path):
    host, port, files = secured
    cfg = ClientConfig(host=host, port=port, trace="pred6dof-1", start_s=12.0, duration_s=0.5, rate_hz=10.0,
                       methods=("none",), out_dir=str(tmp_path), width=160, height=96, progress="none",
                       scene="sphere", token=TOKEN, tls=ClientTLS(ca_file=files.cert))
    result = await run_client(cfg)
    assert result.ticks == 5 and result.frames_received > 0
    assert TOKEN not in (tmp_path / "session.json").read_text()
    assert json.loads((tmp_path / "session.json").read_text())["client"]["token"] == "(given)"
    assert TOKEN not in repr(cfg)
    # Pinning the certificate instead of a CA works as well.
    assert (await _handshake(host, port, ClientTLS(pin=certificate_fingerprint(files.cert)), TOKEN)).scene


@pytest.mark.gl
async def test_a_certificate_that_does_not_verify_is_a_clear_error(secured):
    host, port, files = secured
    with pytest.raises(TLSError, match=f"TLS: the certificate of pibr server at {host}:{port} did not verify "
                                       f"against '{files.other_cert}': self-signed certificate"):
        await ClientConnection.open(host, port, tls=ClientTLS(ca_file=files.other_cert))
    wrong = certificate_fingerprint(files.other_cert)
    right = certificate_fingerprint(files.cert)
    with pytest.raises(TLSError, match=f"does not match the pinned fingerprint: expected {wrong[:16]}..., "
                                       f"got {right[:16]}..."):
        await ClientConnection.open(host, port, tls=ClientTLS(pin=wrong))
    assert await _handshake(host, port, ClientTLS(ca_file=files.cert), TOKEN)   # still serving


@pytest.mark.gl
async def test_a_plaintext_client_fails_cleanly_and_others_are_served(secured, caplog):
    host, port, files = secured
    with caplog.at_level(logging.DEBUG):
        c = await ClientConnection.open(host, port)            # no TLS
        with pytest.raises(ServerClosed, match="without answering the Hello; if it serves TLS, connect with "
                                               "--tls-ca FILE or --tls-pin SHA256"):
            await c.handshake(Hello(**{**HELLO.__dict__, "token": TOKEN}))
        await c.close()
        reader, writer = await asyncio.open_connection(host, port)   # garbage, not even a Hello
        writer.write(b"\x00" * 4096)
        assert await asyncio.wait_for(reader.read(), 10) == b""
        writer.close()
        assert await _handshake(host, port, ClientTLS(ca_file=files.cert), TOKEN)
    assert "Traceback" not in caplog.text and not [r for r in caplog.records if r.levelno >= logging.ERROR]


@pytest.mark.gl
async def test_a_missing_or_wrong_token_is_refused_without_telling_more(secured, caplog, monkeypatch):
    host, port, files = secured
    tls = ClientTLS(ca_file=files.cert)
    compared = []
    real = access.hmac.compare_digest
    monkeypatch.setattr(access.hmac, "compare_digest", lambda a, b: compared.append(b) or real(a, b))
    guesses = ["", "x", TOKEN[:-1], TOKEN + "0", "X" + TOKEN[1:], TOKEN[:-1] + "X"]
    with caplog.at_level(logging.INFO):
        for guess in guesses:
            with pytest.raises(AccessDenied, match="^bad or missing token: give the server's token with "
                                                   "PIBR_TOKEN or --token-file$"):
                await _handshake(host, port, tls, guess)
    assert compared == [g.encode() for g in guesses]           # every one compared in constant time
    assert not [g for g in guesses[1:] if g in caplog.text]    # no guess is logged
    # On the wire: one Error, its code and text only, then the end of the stream.
    reader, writer = await open_connection(host, port, tls)
    writer.write(encode_frame(Hello.TYPE, Hello(**{**HELLO.__dict__, "token": "guess"}).serialize()))
    conn = Connection()
    while data := await asyncio.wait_for(reader.read(65536), 10):
        conn.receive_data(data)
    writer.close()
    assert [e.message for e in conn.events_received()] == [Error(AccessDenied.code, "bad or missing token")]
    assert await _handshake(host, port, tls, TOKEN)


def test_a_server_off_loopback_refuses_to_start_without_a_token():
    with pytest.raises(ConfigError, match="the server would listen on 0.0.0.0, reachable from other machines, "
                                          "without a token: set PIBR_TOKEN or pass --token-file FILE"):
        ServerConfig(host="0.0.0.0")
    ServerConfig(host="0.0.0.0", token=TOKEN)
    ServerConfig(host="::1")
    with pytest.raises(ConfigError, match="needs both --tls-cert and --tls-key"):
        ServerConfig(tls_cert="server.crt")


@pytest.mark.gl
async def test_a_tls_client_still_sending_when_refused_does_not_upset_the_server(secured, caplog):
    """The server closes (bad token) while the client keeps sending: ssl raises on the close
    (application data after close notify); the session ends quietly and others are served."""
    host, port, files = secured
    tls = ClientTLS(ca_file=files.cert)
    with caplog.at_level(logging.INFO):
        for _ in range(3):
            reader, writer = await open_connection(host, port, tls)
            writer.write(encode_frame(Hello.TYPE, Hello(**{**HELLO.__dict__, "token": "guess"}).serialize()))
            try:
                for _ in range(2000):
                    writer.write(encode_frame(8, b"", 0) * 16)     # Clock frames, on and on
                    await writer.drain()
            except (ConnectionError, OSError):
                pass
            writer.close()
        assert await _handshake(host, port, tls, TOKEN)
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR]
