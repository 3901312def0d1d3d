"""The server over real loopback sockets: handshake, frames on the virtual clock, and bad
clients that must get an Error naming the problem while everyone else is served."""
import asyncio
import struct

import pytest

from pibr.client.connection import ClientConnection
from pibr.protocol.connection import Connection
from pibr.protocol.errors import (BadMagic, MalformedMessage, MessageTooLarge, RemoteError, SceneError,
                                  UnexpectedMessage, UnsupportedVersion)
from pibr.protocol.framing import HEADER, MAGIC, encode_frame
from pibr.protocol.messages import Clock, Error, Hello, OutputConfig, PoseMsg
from pibr.protocol.pose import Pose
from pibr.server.app import Server
from pibr.server.config import ServerConfig

from ..loopback import exchange_virtual, running_server

pytestmark = pytest.mark.gl


@pytest.fixture
async def server():
    config = ServerConfig(port=0, scene="sphere", view_size=(128, 128), fps=10.0, server_delay_ms=20.0,
                          bitrate_kbps=2000, extra_view="on")
    async with running_server(config) as (srv, host, port):
        yield srv, host, port


HELLO = Hello(client="test", scene="sphere", clock="virtual", output=OutputConfig(160, 96, 90.0, 30.0))


async def _raw(host, port, data: bytes, read_timeout=10.0) -> list:
    """Send raw bytes, read until the server closes; -> messages received."""
    reader, writer = await asyncio.open_connection(host, port)
    writer.write(data)
    await writer.drain()
    conn = Connection()
    while True:
        chunk = await asyncio.wait_for(reader.read(65536), read_timeout)
        if not chunk:
            break
        conn.receive_data(chunk)
    writer.close()
    return [e.message for e in conn.events_received()]


async def _virtual_session(host, port, ticks=12, interval_us=33_333):
    """Minimal virtual-clock client: -> (Welcome, list of (vtime, Frame))."""
    c = await ClientConnection.open(host, port)
    cfg = await c.handshake(HELLO)
    frames = await exchange_virtual(c, cfg.viewer_origin, [tick * interval_us for tick in range(ticks)], interval_us)
    await c.close()
    return cfg, frames


async def test_virtual_session_schedule(server):
    srv, host, port = server
    cfg, frames = await _virtual_session(host, port)
    assert cfg.extra is not None and cfg.atlas.width == 128 + 128 + 64
    assert frames, "no frame arrived"
    for vt, f in frames:
        assert f.render_t_us % 100_000 == 0                 # the server's 10 fps grid
        assert vt == f.render_t_us + 20_000                  # + modelled render/encode (no relay here)
        assert f.pose_t_us <= f.render_t_us                 # the pose had arrived by render time
        assert f.extra_pose is not None
    assert frames[0][1].keyframe
    assert [f.frame_id for _, f in frames] == list(range(len(frames)))


@pytest.mark.parametrize("data, code, text", [
    (b"GET / HTTP/1.1\r\nHost: x\r\n\r\n", BadMagic.code, "magic"),
    (HEADER.pack(MAGIC, 1, Hello.TYPE, 0, 0, 1 << 30), MessageTooLarge.code, "exceeds the limit"),
    (HEADER.pack(MAGIC, 7, Hello.TYPE, 0, 0, 0), UnsupportedVersion.code, "framing version 7"),
    (encode_frame(PoseMsg.TYPE, PoseMsg(0, 0, Pose.identity()).serialize()), UnexpectedMessage.code,
     "expected Hello"),
    (encode_frame(Hello.TYPE, b'{"protocol": 99}'), UnsupportedVersion.code, "protocol 99"),
    (encode_frame(Hello.TYPE, b"{not json"), MalformedMessage.code, "not UTF-8 JSON"),
    (encode_frame(Hello.TYPE, b'{"protocol": 1, "scene": "atlantis"}'), SceneError.code, "available"),
])
async def test_bad_client_gets_error_and_others_are_served(server, data, code, text):
    srv, host, port = server
    good = asyncio.create_task(_virtual_session(host, port, ticks=8))
    msgs = await _raw(host, port, data)
    errors = [m for m in msgs if isinstance(m, Error)]
    assert errors and errors[0].code == code and text in errors[0].text, msgs
    cfg, frames = await good
    assert frames


async def test_nan_pose_after_handshake_is_rejected(server):
    srv, host, port = server
    bad = struct.pack("<Iq7d", 0, 0, float("nan"), 0, 0, 1, 0, 0, 0)
    msgs = await _raw(host, port, encode_frame(Hello.TYPE, HELLO.serialize()) + encode_frame(PoseMsg.TYPE, bad))
    err = [m for m in msgs if isinstance(m, Error)]
    assert err and err[0].code == MalformedMessage.code and "NaN" in err[0].text


async def test_truncated_message_then_close_leaves_server_up(server):
    srv, host, port = server
    frame = encode_frame(Hello.TYPE, HELLO.serialize())
    reader, writer = await asyncio.open_connection(host, port)
    writer.write(frame[:-5])
    await writer.drain()
    writer.close()
    await asyncio.sleep(0.2)
    cfg, frames = await _virtual_session(host, port, ticks=6)
    assert frames


async def test_client_sees_remote_error_for_unknown_scene(server):
    srv, host, port = server
    c = await ClientConnection.open(host, port)
    with pytest.raises(RemoteError, match="atlantis"):
        await c.handshake(Hello(scene="atlantis"))
    await c.close()


async def test_a_client_that_stops_reading_stalls_only_itself(server):
    srv, host, port = server
    # The stuck client keeps asking for frames but never reads a byte.
    reader, writer = await asyncio.open_connection(host, port)
    conn = Connection()
    conn.send(HELLO)
    for tick in range(600):
        t = tick * 33_333
        conn.send(PoseMsg(tick, t, Pose.make((0, 1.6, 0))), vtime_us=t)
        conn.send(Clock(), vtime_us=t + 33_333)
    writer.write(conn.data_to_send())
    await writer.drain()
    await asyncio.sleep(1.0)
    cfg, frames = await asyncio.wait_for(_virtual_session(host, port, ticks=10), 60)
    assert frames
    writer.close()


async def test_scene_without_disocclusions_gets_no_extra_view():
    srv = Server(ServerConfig(port=0, scene="sphere", view_size=(128, 128), extra_view="auto"))
    host, port = await srv.start()
    task = asyncio.create_task(srv.serve_forever())
    try:
        c = await ClientConnection.open(host, port)
        cfg = await c.handshake(HELLO)
        assert cfg.extra is None and cfg.atlas.width == 256   # colour + depth of the primary only
        await c.close()
        c = await ClientConnection.open(host, port)
        cfg = await c.handshake(Hello(scene="room", output=HELLO.output))
        assert cfg.extra is not None                            # the room asks for one
        await c.close()
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        await srv.close()


def test_the_peel_marker_is_a_session_option():
    from pibr.protocol.messages import Hello
    from pibr.scenes.registry import load_scene
    from pibr.server.config import ServerConfig
    from pibr.server.session_plan import plan_session

    room = load_scene("room")
    marked, spec = plan_session(ServerConfig(view_size=(64, 64)), room, Hello())
    assert marked.options["peel_marker"] is True and spec.mark_peeled
    plain, spec = plan_session(ServerConfig(view_size=(64, 64), peel_marker=False), room, Hello())
    assert plain.options["peel_marker"] is False and not spec.mark_peeled
    single, _ = plan_session(ServerConfig(view_size=(64, 64), extra_view="off"), room, Hello())
    assert "peel_marker" not in single.options          # no extra view, nothing to mark


async def test_real_clock_keeps_at_most_max_in_flight_frames_ahead_of_the_client():
    """A real-clock client that reports decoding only its first frame gets max_in_flight frames
    and then none while it lags (the server holds its ticks); once it reports more, frames flow
    again. A client that never reports is not held back."""
    from pibr.protocol.messages import FRAMES_DECODED, Frame, Stats

    srv = Server(ServerConfig(port=0, scene="sphere", view_size=(128, 128), fps=20.0, bitrate_kbps=2000,
                              extra_view="off", max_in_flight=2))
    host, port = await srv.start()
    task = asyncio.create_task(srv.serve_forever())
    real = Hello(client="test", scene="sphere", clock="real", output=OutputConfig(160, 96, 90.0, 30.0))

    async def frames_within(c, seconds: float) -> int:
        n, end = 0, asyncio.get_running_loop().time() + seconds
        while (left := end - asyncio.get_running_loop().time()) > 0:
            try:
                env = await c.recv(timeout=left)
            except asyncio.TimeoutError:
                break
            n += isinstance(env.message, Frame)
        return n

    try:
        silent = await ClientConnection.open(host, port)
        await silent.handshake(real)
        lagging = await ClientConnection.open(host, port)
        cfg = await lagging.handshake(real)
        for c in (silent, lagging):
            await c.send(PoseMsg(0, 0, cfg.viewer_origin))
        await lagging.send(Stats({FRAMES_DECODED: 0}))
        assert await frames_within(lagging, 2.0) == 2          # two in flight, then held
        assert await frames_within(silent, 0.1) >= 3           # the other session is not held
        await lagging.send(Stats({FRAMES_DECODED: 2}))
        assert await frames_within(lagging, 1.5) == 2          # two more, then held again
        held = sorted(s.frames_held for s in srv.sessions.values())
        assert held[0] == 0 and held[1] > 0                    # counted for the lagging one only
        for c in (silent, lagging):
            await c.close()
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        await srv.close()


async def test_a_session_closed_by_a_shutting_down_server_still_logs_its_summary(caplog):
    """The server's close cancels every handler, a session's among them while it closes its
    socket: its summary (frames, the stream adaptation's reasons) is logged before that wait."""
    import logging
    from types import SimpleNamespace

    from pibr.server.session import Session
    from pibr.server.stream_adaptation import StreamAdaptation

    class StuckWriter:             # a socket whose close never completes
        def get_extra_info(self, name):
            return ("127.0.0.1", 1)

        def write(self, data):
            pass

        async def drain(self):
            pass

        def close(self):
            pass

        async def wait_closed(self):
            await asyncio.Event().wait()

    server = SimpleNamespace(config=ServerConfig(port=0))
    session = Session(server, None, StuckWriter(), 7)
    session.frames_sent = 12
    session.adaptation = StreamAdaptation(8000.0)
    with caplog.at_level(logging.INFO, logger="pibr.server.session"):
        closing = asyncio.create_task(session._close())
        await asyncio.sleep(0.05)
        assert not closing.done()   # waiting for the socket to close
        closing.cancel()
        await asyncio.gather(closing, return_exceptions=True)
    messages = caplog.messages
    assert any("session 7: closed after 12 frames" in m for m in messages)
    assert any(m.startswith("session 7: stream adaptation: 0 reports") for m in messages)
