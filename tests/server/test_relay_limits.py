"""The relay against a stand-in server (no rendering): memory bounded in bytes, a connection limit,
jitter that replays identically, its token and TLS."""
import asyncio
import logging
import socket
import ssl
import tracemalloc

import pytest

from pibr.client.connection import ClientConnection
from pibr.protocol.errors import AccessDenied, ConfigError, RemoteError, TLSError
from pibr.protocol.framing import HEADER_SIZE, encode_frame
from pibr.common.link import LinkParams
from pibr.protocol.messages import Clock, Error, Frame, Hello, PoseMsg, Welcome
from pibr.common.tls import ClientTLS, certificate_fingerprint, open_connection, server_context
from pibr.server.relay import Relay, RelayConfig

from ..tlsfiles import tls_files  # noqa: F401 (fixture)
from .fake_upstream import FakeUpstream, read_frames

TOKEN = "relay-test-token-0123456789"


async def _wait_for(predicate, what: str, timeout: float = 30.0):
    """Poll until ``predicate()`` is truthy -> its value (a deadline, not a timing measurement)."""
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while not (value := predicate()):
        if loop.time() > end:
            raise AssertionError(f"gave up waiting for {what}")
        await asyncio.sleep(0.01)
    return value


class _Running:
    """A started relay (and its stand-in server) that closes everything on exit."""

    def __init__(self, upstream: FakeUpstream, **relay_kw):
        self.upstream, self.relay_kw = upstream, relay_kw

    async def __aenter__(self):
        uhost, uport = await self.upstream.start()
        kw = {"up": LinkParams(1.0), "down": LinkParams(1.0)} | self.relay_kw
        self.relay = Relay(RelayConfig(("127.0.0.1", 0), (uhost, uport), **kw))
        self.host, self.port = await self.relay.start()
        self._task = asyncio.create_task(self.relay.serve_forever())
        return self

    async def __aexit__(self, *exc):
        self._task.cancel()
        await asyncio.gather(self._task, return_exceptions=True)
        await self.relay.close()
        await self.upstream.close()


def _hello(client: str, **kw) -> bytes:
    return encode_frame(Hello.TYPE, Hello(client=client, **kw).serialize())


async def test_a_client_that_does_not_read_holds_the_relay_to_its_byte_budget():
    """Defect 13: a non-reading client behind the relay with large frames grew it to 597 MB. Now
    each direction holds at most its budget; the server's sender stalls, and another client
    through the same relay is served meanwhile. Closing the relay then does not hang on it."""
    frame, count = 200 * 1024, 500                # 100 MB the stand-in server tries to push
    budget, max_message = 4 << 20, 256 * 1024
    upstream = FakeUpstream(frames=20, per_client={"hog": (count, frame)})
    tracemalloc.start()
    try:
        async with _Running(upstream, max_message_size=max_message, buffer_bytes=budget) as r:
            async def well_behaved(name):
                reader, writer = await asyncio.open_connection(r.host, r.port)
                writer.write(_hello(name))
                got = await read_frames(reader, limit=21)
                writer.close()
                assert [t for t, _, _ in got] == [Welcome.TYPE] + [Frame.TYPE] * 20

            await well_behaved("warm-up")   # imports and first-use allocations are not the relay's buffers
            tracemalloc.reset_peak()
            base = tracemalloc.get_traced_memory()[0]
            sock = socket.socket()
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)   # keep the kernel's share small
            sock.setblocking(False)
            await asyncio.get_running_loop().sock_connect(sock, (r.host, r.port))
            hog_reader, hog_writer = await asyncio.open_connection(sock=sock)
            hog_writer.write(_hello("hog"))
            await hog_writer.drain()
            pair = await _wait_for(lambda: next((p for p in r.relay.pairs if p.hello is not None
                                                 and p.hello.client == "hog" and "down" in p.queues), None),
                                   "the pair")
            down = pair.queues["down"]
            await _wait_for(lambda: down.peak > budget - (frame + HEADER_SIZE), "the relay's buffer to fill")

            await well_behaved("reader")    # served while the other pair is stalled

            assert down.held <= budget and down.peak <= budget
            assert upstream.sent["hog"] < count * (frame + HEADER_SIZE)   # stalled: never sent it all
            # Everything Python allocated meanwhile, relay, stand-in server and clients together: the
            # budget, and less than as much again in transit (the frame being read and framed, the
            # relay's and the stand-in server's socket buffers).
            assert tracemalloc.get_traced_memory()[1] - base < 2 * budget
        hog_writer.close()
    finally:
        tracemalloc.stop()


async def test_one_client_more_than_the_limit_is_told_the_relay_is_full():
    async with _Running(FakeUpstream(frames=3), max_connections=2) as r:
        held = []
        for name in ("a", "b"):
            reader, writer = await asyncio.open_connection(r.host, r.port)
            writer.write(_hello(name))
            assert len(await read_frames(reader, limit=4)) == 4
            held.append(writer)
        c = await ClientConnection.open(r.host, r.port)
        with pytest.raises(RemoteError, match=r"relay full: 2 connections already \(--max-connections 2\)"):
            await c.handshake(Hello(client="c"))
        await c.close()
        held[0].close()                                  # a slot frees: the next client is relayed
        await _wait_for(lambda: len(r.relay.pairs) == 1, "the closed pair to end")
        reader, writer = await asyncio.open_connection(r.host, r.port)
        writer.write(_hello("d"))
        assert [t for t, _, _ in await read_frames(reader, limit=4)] == [Welcome.TYPE] + [Frame.TYPE] * 3
        for w in (held[1], writer):
            w.close()


async def _jittered_session(r, client="replay", poses=12) -> tuple[list, list]:
    """One virtual-clock session through the relay -> (downlink vtimes, uplink vtimes)."""
    reader, writer = await asyncio.open_connection(r.host, r.port)
    pose = bytes(60)   # the relay never parses a pose: any bytes do
    writer.write(_hello(client) + b"".join(encode_frame(PoseMsg.TYPE, pose, k * 33_333) for k in range(poses)))
    down = [vt for t, vt, _ in await read_frames(reader, limit=1 + r.upstream.frames) if t == Frame.TYPE]
    writer.close()
    conn = r.upstream.connections - 1
    await _wait_for(lambda: len(r.upstream.received[conn]) == poses, "the poses to reach the server")
    return down, [vt for _, vt in r.upstream.received[conn]]


async def test_jitter_replays_identically_session_after_session():
    """Defect 14: jitter was seeded by connection number, so a second run through the same relay
    differed from the first. Now it follows from --seed and the client's Hello."""
    link = {"up": LinkParams(50.0, 20.0), "down": LinkParams(50.0, 20.0)}
    async with _Running(FakeUpstream(frames=15), seed=7, **link) as r:
        first = await _jittered_session(r)
        second = await _jittered_session(r)
        other_client = await _jittered_session(r, client="another")
    async with _Running(FakeUpstream(frames=15), seed=8, **link) as r8:
        other_seed = await _jittered_session(r8)
    assert first == second
    down, up = first
    sent_down = [k * 100_000 for k in range(15)]
    delays = [a - s for a, s in zip(down, sent_down)]
    assert len(set(delays)) > 5 and all(30_000 <= d for d in delays)   # jittered around 50 ms, in order
    assert len(up) == 12 and up != [k * 33_333 + 50_000 for k in range(12)]
    assert other_seed != first and other_client != first


async def test_relay_token_is_checked_before_the_server_is_reached():
    upstream = FakeUpstream(frames=2)
    async with _Running(upstream, token=TOKEN) as r:
        for token in ("", "x" * len(TOKEN), TOKEN[:-1] + "X"):
            c = await ClientConnection.open(r.host, r.port)
            with pytest.raises(AccessDenied, match="relay: bad or missing token: give the server's token"):
                await c.handshake(Hello(client="guess", token=token))
            await c.close()
        assert upstream.connections == 0           # nothing reached the server
        reader, writer = await asyncio.open_connection(r.host, r.port)
        writer.write(_hello("ok", token=TOKEN))
        assert [t for t, _, _ in await read_frames(reader, limit=3)] == [Welcome.TYPE, Frame.TYPE, Frame.TYPE]
        writer.close()
        assert upstream.hellos[-1].token == TOKEN   # forwarded unchanged, for a server that checks it too


def test_relay_off_loopback_needs_a_token():
    with pytest.raises(ConfigError, match="the relay would listen on 0.0.0.0, reachable from other machines, "
                                          "without a token: set PIBR_TOKEN or pass --token-file FILE"):
        RelayConfig(("0.0.0.0", 0))
    RelayConfig(("0.0.0.0", 0), token=TOKEN)
    with pytest.raises(ConfigError, match="cannot hold one message"):
        RelayConfig(buffer_bytes=1 << 20, max_message_size=1 << 20)


async def test_a_client_silent_before_its_hello_is_dropped():
    async with _Running(FakeUpstream(), hello_timeout_s=0.2) as r:
        reader, writer = await asyncio.open_connection(r.host, r.port)
        got = await read_frames(reader)
        assert [t for t, _, _ in got] == [Error.TYPE] and r.upstream.connections == 0
        writer.close()


async def test_relay_with_tls_on_both_sides(tls_files):
    """Clients reach the relay over TLS (its own certificate, checked against a CA file); the
    relay reaches a TLS server, checked by pin; a wrong pin is a clear error to the client."""
    upstream = FakeUpstream(frames=2, ssl=server_context(tls_files.cert, tls_files.key))
    pin = certificate_fingerprint(tls_files.cert)
    async with _Running(upstream, tls_cert=tls_files.cert, tls_key=tls_files.key,
                        upstream_tls=ClientTLS(pin=pin)) as r:
        reader, writer = await open_connection(r.host, r.port, ClientTLS(ca_file=tls_files.cert))
        writer.write(_hello("tls"))
        assert [t for t, _, _ in await read_frames(reader, limit=3)] == [Welcome.TYPE, Frame.TYPE, Frame.TYPE]
        writer.close()
        with pytest.raises(TLSError, match="did not verify"):
            await ClientConnection.open(r.host, r.port, tls=ClientTLS(ca_file=tls_files.other_cert))
    wrong = "ab" * 32
    async with _Running(FakeUpstream(frames=2, ssl=server_context(tls_files.cert, tls_files.key)),
                        upstream_tls=ClientTLS(pin=wrong)) as r:
        c = await ClientConnection.open(r.host, r.port)
        with pytest.raises(RemoteError, match=f"relay: TLS: the certificate of the upstream server at "
                                              f"127.0.0.1:{r.relay.config.upstream[1]} does not match the pinned "
                                              f"fingerprint: expected {wrong[:16]}..., got {pin[:16]}..."):
            await c.handshake(Hello(client="pinned"))
        await c.close()


async def test_closing_a_tls_connection_while_the_peer_still_sends_is_quiet(tls_files, caplog):
    """The peer's data arriving after our TLS close_notify makes ssl raise on close
    (APPLICATION_DATA_AFTER_CLOSE_NOTIFY): the client and the relay treat it as the end."""
    stop = asyncio.Event()

    async def chatter(reader, writer):
        try:
            while not stop.is_set():
                writer.write(encode_frame(Clock.TYPE, b"", 0) * 64)
                await writer.drain()
        except (ConnectionError, ssl.SSLError):
            pass
        finally:
            writer.close()

    server = await asyncio.start_server(chatter, "127.0.0.1", 0, ssl=server_context(tls_files.cert, tls_files.key))
    port = server.sockets[0].getsockname()[1]
    try:
        for _ in range(5):
            c = await ClientConnection.open("127.0.0.1", port, tls=ClientTLS(ca_file=tls_files.cert))
            await c.recv(10)
            await c.close()                     # raised ssl.SSLError before
        relay = Relay(RelayConfig(("127.0.0.1", 0), ("127.0.0.1", port), LinkParams(1.0), LinkParams(1.0),
                                  upstream_tls=ClientTLS(ca_file=tls_files.cert)))
        host, rport = await relay.start()
        task = asyncio.create_task(relay.serve_forever())
        with caplog.at_level(logging.INFO):
            for _ in range(2):
                reader, writer = await asyncio.open_connection(host, rport)
                writer.write(_hello("chatty"))
                await read_frames(reader, limit=64)
                writer.close()
            await _wait_for(lambda: not relay.pairs, "the pairs to close")
        task.cancel()
        await relay.close()
        assert not [rec for rec in caplog.records if rec.levelno >= logging.ERROR]
    finally:
        stop.set()
        server.close()


async def test_idle_connections_before_their_hello_keep_no_client_out():
    """Issue 28: as many idle TCP connections as the relay has slots kept every client out until
    its Hello timeout. Connections without a Hello now wait outside the slots, at most
    max_pending of them, the oldest dropped past that."""
    async with _Running(FakeUpstream(frames=2), max_connections=2, max_pending=3, hello_timeout_s=30.0) as r:
        idle = [await asyncio.open_connection(r.host, r.port) for _ in range(3)]
        await _wait_for(lambda: len(r.relay.pending) == 3, "the idle connections to be accepted")
        # a client still gets in (the oldest idle connection is dropped to make room for it)
        reader, writer = await asyncio.open_connection(r.host, r.port)
        writer.write(_hello("legit"))
        assert [t for t, _, _ in await read_frames(reader, limit=3)] == [Welcome.TYPE] + [Frame.TYPE] * 2
        dropped = await asyncio.wait_for(idle[0][0].read(), 30)    # its Error, then the end
        assert b"relay busy: 4 connections are waiting to send a Hello; this one, the oldest" in dropped
        assert len(r.relay.pending) == 2 and len(r.relay.pairs) == 1
        for _, w in [*idle, (reader, writer)]:
            w.close()
