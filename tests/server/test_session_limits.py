"""Peers that hold on to the server without using it, and clocks that ask for too much: each
is cut off with an Error naming the problem, and legitimate clients keep being served.
Deadlines are configured short here; no test waits for a default."""
import asyncio
import threading

import pytest

from pibr.client.connection import ClientConnection
from pibr.protocol.connection import Connection
from pibr.protocol.errors import ConfigError, PeerTimeout, RemoteError, UnexpectedMessage
from pibr.protocol.framing import encode_frame
from pibr.protocol.messages import Clock, Error, Frame, Hello, OutputConfig, PoseMsg
from pibr.protocol.pose import Pose
from pibr.server.app import Server
from pibr.server.config import ServerConfig

pytestmark = pytest.mark.gl

HELLO = Hello(client="test", scene="sphere", clock="virtual", output=OutputConfig(160, 96, 90.0, 30.0))
REAL_HELLO = Hello(client="test", scene="sphere", clock="real", output=OutputConfig(160, 96, 90.0, 30.0))


async def _serving(**kw):
    config = dict(port=0, scene="sphere", view_size=(64, 64), fps=10.0, bitrate_kbps=1000, extra_view="off")
    config.update(kw)
    srv = Server(ServerConfig(**config))
    host, port = await srv.start()
    task = asyncio.create_task(srv.serve_forever())
    return srv, host, port, task


async def _stop(srv, task):
    task.cancel()
    await asyncio.gather(task, return_exceptions=True)
    await srv.close()


async def _messages_until_closed(reader, timeout: float) -> list:
    """Read until the server closes (TimeoutError if it has not within ``timeout``)."""
    conn = Connection()
    async with asyncio.timeout(timeout):
        while chunk := await reader.read(65536):
            conn.receive_data(chunk)
    return [e.message for e in conn.events_received()]


async def _welcomed(host, port, hello=HELLO, timeout: float = 30.0):
    c = await ClientConnection.open(host, port)
    await asyncio.wait_for(c.handshake(hello), timeout)
    return c


async def test_a_trickled_hello_is_cut_at_the_handshake_deadline():
    """Defect 8: one byte of Hello every 0.3 s; the deadline covers the whole Hello, not each read."""
    srv, host, port, task = await _serving(hello_timeout_s=1.0)
    try:
        reader, writer = await asyncio.open_connection(host, port)
        data = encode_frame(Hello.TYPE, HELLO.serialize())

        async def trickle():
            for i in range(len(data)):
                writer.write(data[i:i + 1])
                await asyncio.sleep(0.3)
        trickler = asyncio.create_task(trickle())
        try:
            msgs = await _messages_until_closed(reader, timeout=5.0)
        finally:
            trickler.cancel()
        assert [type(m) for m in msgs] == [Error]
        assert msgs[0].code == PeerTimeout.code and "no complete Hello within 1 s of connecting" in msgs[0].text
        writer.close()
    finally:
        await _stop(srv, task)


@pytest.mark.parametrize("hello, knob", [(HELLO, "idle_timeout_virtual_s"), (REAL_HELLO, "idle_timeout_s")])
async def test_a_client_silent_after_its_hello_loses_its_slot(hello, knob):
    """Defect 9: the only slot is taken by a client that says Hello and nothing more; it is closed
    after the idle timeout and the next client is served."""
    srv, host, port, task = await _serving(max_sessions=1, **{knob: 0.5})
    try:
        silent = await _welcomed(host, port, hello)
        with pytest.raises(RemoteError, match=r"no message from the client for 0.5 s \(idle timeout\)") as err:
            while True:
                await silent.recv(timeout=10)
        assert err.value.code == PeerTimeout.code
        await silent.close()
        served = await _welcomed(host, port, hello)
        await served.close()
    finally:
        await _stop(srv, task)


async def test_a_client_that_reads_nothing_loses_its_slot():
    """Defect 9: a virtual-clock client that asks for frames but never reads one is closed once
    the server has waited the idle timeout to send, and the slot is free again."""
    srv, host, port, task = await _serving(max_sessions=1, idle_timeout_virtual_s=0.5)
    try:
        reader, writer = await asyncio.open_connection(host, port)
        conn = Connection()
        conn.send(HELLO)
        for tick in range(3000):
            conn.send(PoseMsg(tick, tick * 33_333, Pose.make((0, 1.6, 0))), vtime_us=tick * 33_333)
        conn.send(Clock(), vtime_us=3000 * 33_333)
        writer.write(conn.data_to_send())
        await writer.drain()
        async def sessions_become(n: int) -> None:
            while len(srv.sessions) != n:
                await asyncio.sleep(0.05)
        await asyncio.wait_for(sessions_become(1), 10)     # it is served ...
        await asyncio.wait_for(sessions_become(0), 10)     # ... until the server gives up on it
        served = await _welcomed(host, port)
        await served.close()
        writer.close()
    finally:
        await _stop(srv, task)


async def test_idle_connections_before_hello_take_no_slot():
    """Defect 10: 12 connections that never say Hello; a client connecting after them is served at
    once, and the oldest idle ones beyond max_pending are dropped with an Error saying why."""
    srv, host, port, task = await _serving(max_sessions=1, max_pending=4, hello_timeout_s=30.0, admit_wait_s=0.3)
    idle = []
    try:
        for _ in range(12):
            idle.append(await asyncio.open_connection(host, port))
        await asyncio.sleep(0.2)
        assert len(srv.pending) == 4 and not srv.sessions
        served = await _welcomed(host, port, timeout=10.0)
        assert len(srv.sessions) == 1
        dropped = await _messages_until_closed(idle[0][0], timeout=5.0)
        assert dropped[0].code == PeerTimeout.code and "the oldest, is dropped" in dropped[0].text
        # The slot counts from the Hello: a second Hello finds the server full.
        with pytest.raises(RemoteError, match=r"server full: 1 sessions already \(waited 0.3 s for one to end\)") \
                as err:
            await _welcomed(host, port, timeout=10.0)
        assert err.value.code == ConfigError.code
        # A Hello the server cannot serve is told so, full or not: it never takes a slot.
        with pytest.raises(RemoteError, match="scene 'atlantis' is not served here"):
            await _welcomed(host, port, Hello(scene="atlantis"), timeout=10.0)
        await served.close()
    finally:
        for _, writer in idle:
            writer.close()
        await _stop(srv, task)


async def test_a_hello_at_a_full_server_waits_for_a_slot_first_come_first_served():
    """A client reconnecting the moment its previous session ends (before the server has noticed)
    is not told "server full": Hellos wait up to admit_wait_s for a slot, in arrival order."""
    srv, host, port, task = await _serving(max_sessions=1, admit_wait_s=10.0)
    try:
        first = await _welcomed(host, port)
        order = []

        async def queued(name):
            c = await _welcomed(host, port, timeout=20.0)
            order.append(name)
            return c
        second = asyncio.create_task(queued("second"))
        await asyncio.sleep(0.3)
        third = asyncio.create_task(queued("third"))
        await asyncio.sleep(0.3)
        assert list(srv._slot_waiters) and len(srv._slot_waiters) == 2 and not second.done()
        await first.close()
        c2 = await asyncio.wait_for(second, 10)
        assert order == ["second"] and not third.done()
        await c2.close()
        c3 = await asyncio.wait_for(third, 10)
        assert order == ["second", "third"] and not srv._slot_waiters
        await c3.close()
    finally:
        await _stop(srv, task)


async def test_a_far_future_clock_is_refused():
    """Defect 11: a clock promise far beyond the next frame would make the session render flat out
    for nobody; it closes the session with an Error naming the lead."""
    srv, host, port, task = await _serving(max_clock_lead_s=2.0)
    try:
        c = await _welcomed(host, port)
        cfg = c.config
        await c.send(PoseMsg(0, 0, cfg.viewer_origin), vtime_us=0, flush=False)
        await c.send(Clock(), vtime_us=33_333)
        frames = 0
        while frames == 0:
            frames += isinstance((await c.recv(timeout=10)).message, Frame)
        await c.send(Clock(), vtime_us=10 ** 15)
        refused = r"runs 1e\+09 s ahead of the next frame .* more than the 2.12 s allowed"
        with pytest.raises(RemoteError, match=refused) as err:
            for _ in range(10):     # rendering flat out, the server would send frame after frame instead
                await c.recv(timeout=10)
        assert err.value.code == UnexpectedMessage.code
        await c.close()
    finally:
        await _stop(srv, task)


async def test_a_clock_within_the_lead_is_served():
    """A legitimate clock, one client tick and the link delays ahead, is never refused."""
    srv, host, port, task = await _serving(max_clock_lead_s=0.05)
    try:
        from ..loopback import exchange_virtual

        c = await _welcomed(host, port)
        frames = await exchange_virtual(c, c.config.viewer_origin, [t * 33_333 for t in range(24)], 33_333)
        assert [f.frame_id for _, f in frames] == list(range(8))    # every tick of 10 fps in 0.8 s
        await c.close()
    finally:
        await _stop(srv, task)


@pytest.mark.parametrize("slow", ["scene", "bundle"])
async def test_a_slow_scene_load_does_not_block_other_handshakes(monkeypatch, slow):
    """Defect 12: while the room loads (held here until the test lets it finish), a client of the
    already loaded sphere gets its Welcome (and its proxies); then the room's client gets its own."""
    import pibr.scenes.registry as registry
    import pibr.server.proxies as proxies

    release = threading.Event()
    started = threading.Event()
    real = {"scene": registry.load_scene, "bundle": proxies.build_bundle}[slow]

    def held(first, *args, **kw):
        if (first if slow == "scene" else first.name) == "room":
            started.set()
            assert release.wait(60), "the test never released the load"
        return real(first, *args, **kw)

    monkeypatch.setattr(registry if slow == "scene" else proxies, "load_scene" if slow == "scene" else "build_bundle",
                        held)
    srv, host, port, task = await _serving()
    try:
        room_hello = Hello(scene="room", output=HELLO.output, want_proxies=True)
        sphere_hello = Hello(scene="sphere", output=HELLO.output, want_proxies=True)
        if slow == "bundle":
            await srv.get_scene("room")           # the scene is there; its proxies are not
        room = asyncio.create_task(_welcomed(host, port, room_hello, timeout=120))
        while not started.is_set():
            await asyncio.sleep(0.05)
        sphere = await _welcomed(host, port, sphere_hello, timeout=20)
        assert sphere.config.scene["name"] == "sphere" and not room.done()
        release.set()
        room_client = await room
        assert room_client.config.scene["name"] == "room"
        for c in (sphere, room_client):
            await c.close()
    finally:
        release.set()
        await _stop(srv, task)


async def test_silent_hellos_cannot_keep_a_running_client_out():
    """Issue 28: sessions that say Hello and then nothing (re-sent every idle timeout) held every
    slot of a server without a token. A Hello that waits for a slot now takes the slot of the
    session silent longest since its Welcome (past silent_slot_s); sessions that send poses keep theirs."""
    srv, host, port, task = await _serving(max_sessions=2, admit_wait_s=5.0, silent_slot_s=0.5)
    try:
        silent = await _welcomed(host, port)
        running = await _welcomed(host, port)
        await running.send(PoseMsg(0, 0, Pose.identity()), vtime_us=0)
        await asyncio.sleep(0.2)
        # a third client finds both slots taken; the silent one gives its slot up, the running one keeps it
        third = await _welcomed(host, port, timeout=10.0)
        with pytest.raises(RemoteError, match="no pose .* after the Welcome while another client waited"):
            while True:
                await silent.recv(timeout=5.0)
        assert set(srv.sessions) == {running.welcome.session, third.welcome.session}
        await third.close()
        await running.close()
        await silent.close()
    finally:
        await _stop(srv, task)
