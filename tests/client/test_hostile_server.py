"""The client against hand-written servers that misbehave: it ends with an error naming the
problem, promptly and without allocating what the server's claims would make it allocate."""
import asyncio
import tracemalloc

import pytest

from pibr.client.app import run_client
from pibr.client.config import ClientConfig
from pibr.protocol.errors import MalformedMessage, PeerTimeout
from pibr.protocol.messages import Hello, ProxyChunk, Welcome
from pibr.protocol.proxy import BundleInfo, encode_bundle, split_chunks

from ..loopback import scripted_server


def _session_config(clock: str, proxies: dict | None = None) -> dict:
    """A Welcome's config as the real server plans it (sphere, small views)."""
    from pibr.scenes.registry import load_scene
    from pibr.server.config import ServerConfig
    from pibr.server.session_plan import plan_session

    hello = Hello(scene="sphere", clock=clock)
    config, _ = plan_session(ServerConfig(scene="sphere", view_size=(64, 64)), load_scene("sphere"), hello, proxies)
    return config.to_json()


def _client(host, port, tmp_path, **kw) -> ClientConfig:
    base = dict(host=host, port=port, trace="pred6dof-1", start_s=12.0, duration_s=0.5, rate_hz=10.0,
                methods=("none",), out_dir=str(tmp_path), width=64, height=48, progress="none",
                receive_timeout_s=0.5)
    base.update(kw)
    return ClientConfig(**base)


async def _until_closed(peer) -> None:
    while await peer.recv(timeout=30) is not None:
        pass


@pytest.mark.gl
@pytest.mark.parametrize("clock", ["virtual", "real"])
async def test_a_server_silent_after_its_welcome_ends_the_client(tmp_path, clock):
    """Issue 13, defect 7: a Welcome and then nothing; the client gives up after its receive
    timeout, naming the server and how long it was silent."""
    async def welcome_then_silence(peer):
        hello = await peer.recv()
        assert isinstance(hello, Hello)
        await peer.send(Welcome(server="silent", session=1, config=_session_config(clock)))
        await _until_closed(peer)

    async with scripted_server(welcome_then_silence) as (host, port):
        with pytest.raises(PeerTimeout, match=f"pibr server {host}:{port} sent nothing for 0.5 s"):
            await asyncio.wait_for(run_client(_client(host, port, tmp_path, clock=clock)), 60)


async def test_a_silent_server_before_the_welcome_ends_the_handshake(tmp_path):
    async def silence(peer):
        await _until_closed(peer)

    async with scripted_server(silence) as (host, port):
        with pytest.raises(PeerTimeout, match="sent nothing for 1 s after our Hello: no Welcome"):
            from pibr.client.connection import ClientConnection

            conn = await ClientConnection.open(host, port, receive_timeout_s=0.5)
            try:
                await asyncio.wait_for(conn.handshake(Hello(), timeout=1.0), 30)
            finally:
                await conn.close()


async def _drip(peer, data: bytes, every_s: float) -> None:
    """Send ``data`` a byte at a time, ``every_s`` apart, until it is all sent or the client goes."""
    try:
        for i in range(len(data)):
            peer.writer.write(data[i:i + 1])
            await peer.writer.drain()
            await asyncio.sleep(every_s)
    except ConnectionError:
        pass


async def test_a_welcome_dripped_a_byte_at_a_time_does_not_hold_the_client(tmp_path):
    """Issue 28: a server that drips one byte every so often held the client for ever (each byte
    restarted the silence timer) and the first answer waited a fixed 120 s: now the whole Welcome
    must arrive within 4 receive timeouts."""
    from pibr.client.connection import WELCOME_WAIT_FACTOR

    async def drip_welcome(peer):
        await peer.recv()
        peer.conn.send(Welcome(server="drip", session=1, config=_session_config("virtual")))
        await _drip(peer, peer.conn.data_to_send(), 0.1)

    async with scripted_server(drip_welcome) as (host, port):
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        with pytest.raises(PeerTimeout, match=r"sent \d+ bytes of a message but not all of it within 1 s"):
            await asyncio.wait_for(run_client(_client(host, port, tmp_path, receive_timeout_s=0.25)), 30)
        assert loop.time() - t0 < WELCOME_WAIT_FACTOR * 0.25 + 2


@pytest.mark.gl
async def test_a_frame_dripped_after_the_welcome_and_a_session_that_never_ends(tmp_path):
    """After the Welcome: a message dripped byte by byte times out as a whole; and tiny messages
    that each arrive in time cannot stretch the session past its limit."""
    from pibr.protocol.messages import Clock

    async def welcome_then_drip(peer):
        await peer.recv()
        await peer.send(Welcome(server="drip", session=1, config=_session_config("virtual")))
        peer.conn.send(Clock(), vtime_us=1)
        await _drip(peer, peer.conn.data_to_send(), 0.2)

    async with scripted_server(welcome_then_drip) as (host, port):
        with pytest.raises(PeerTimeout, match="bytes of a message but not all of it within 0.5 s"):
            await asyncio.wait_for(run_client(_client(host, port, tmp_path)), 30)

    async def clocks_for_ever(peer):
        await peer.recv()
        await peer.send(Welcome(server="slow", session=1, config=_session_config("virtual")))
        try:
            while True:   # a valid message in time, but the clock never reaches the client's tick
                await peer.send(Clock(), vtime_us=0)
                await asyncio.sleep(0.1)
        except ConnectionError:
            pass

    async with scripted_server(clocks_for_ever) as (host, port):
        t0 = asyncio.get_running_loop().time()
        with pytest.raises(PeerTimeout, match="ran past its 2 s limit"):
            await asyncio.wait_for(run_client(_client(host, port, tmp_path, session_timeout_s=2.0)), 30)
        assert asyncio.get_running_loop().time() - t0 < 10


def _zero_bomb(size: int) -> bytes:
    """A zstd frame of ``size`` zeros, its size in the header, built a megabyte at a time."""
    import zstandard

    cobj = zstandard.ZstdCompressor(level=1).compressobj(size=size)
    zeros = bytes(1 << 20)
    return b"".join([cobj.compress(zeros) for _ in range(size >> 20)] + [cobj.flush()])


async def _serve_bundle(peer, info: BundleInfo, chunks: list) -> None:
    await peer.recv()
    await peer.send(Welcome(server="bomber", session=1, config=_session_config("virtual", info.to_json())))
    for chunk in chunks:
        await peer.send(chunk)
    await _until_closed(peer)


async def test_a_proxy_bomb_is_refused_without_inflating_it(tmp_path):
    """Issue 13, defect 5: 32 kB of zstd announcing 1 GiB of zeros, sent as a bundle announced
    at its real size. The client refuses it from the zstd header, never holding more than a few
    megabytes (it held 1 GiB for 7 s before finding the bad magic)."""
    bomb = _zero_bomb(1 << 30)
    info = BundleInfo(1, len(bomb), len(encode_bundle([])) + 1000, 16 << 10, {})
    chunks = [ProxyChunk(i, info.chunks, len(bomb), p) for i, p in enumerate(split_chunks(bomb, info.chunk_bytes))]

    async with scripted_server(lambda peer: _serve_bundle(peer, info, chunks)) as (host, port):
        tracemalloc.start()
        try:
            with pytest.raises(MalformedMessage, match="declares 1073741824 bytes uncompressed"):
                await asyncio.wait_for(run_client(_client(host, port, tmp_path, methods=("proxy",))), 60)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    assert peak < 64 << 20


async def test_proxy_chunks_beyond_the_announcement_are_refused(tmp_path):
    """Issue 13, defect 6: a chunk count of 2**32-1 with empty chunks is refused at the first chunk."""
    data = bytes(4000)
    info = BundleInfo(1, len(data), 1000, 1024, {})
    chunks = [ProxyChunk(i, (1 << 32) - 1, len(data), b"") for i in range(5)]

    async with scripted_server(lambda peer: _serve_bundle(peer, info, chunks)) as (host, port):
        with pytest.raises(MalformedMessage, match="count 4294967295 differs from the 4 chunks the Welcome announced"):
            await asyncio.wait_for(run_client(_client(host, port, tmp_path, methods=("proxy",))), 60)


async def test_an_atlas_larger_than_its_views_is_refused_before_allocation(tmp_path):
    """Issue 13, defect 4 (the client's side): the atlas must be the layout of the announced views."""
    config = _session_config("virtual")
    config["atlas"]["width"] = config["atlas"]["height"] = 4096   # within the protocol's limits, not the views' need

    async def oversized(peer):
        await peer.recv()
        await peer.send(Welcome(server="big", session=1, config=config))
        await _until_closed(peer)

    async with scripted_server(oversized) as (host, port):
        with pytest.raises(MalformedMessage, match="4096x4096 .* is not the layout of its views"):
            await asyncio.wait_for(run_client(_client(host, port, tmp_path)), 60)
