"""Issue 13, deliverable 3, the server's side: on the real clock a frame is rendered only when the
one before has left, so a slow reader's backlog never holds more than one frame (rendered from
an old pose); the next frame is rendered from the newest pose once there is room."""
import asyncio
import socket

import numpy as np

import pytest

from pibr.protocol.connection import Connection
from pibr.protocol.messages import Hello, OutputConfig, PoseMsg
from pibr.protocol.pose import Pose
from pibr.server.app import Server
from pibr.server.config import ServerConfig

pytestmark = pytest.mark.gl


async def test_a_slow_reader_never_has_more_than_one_frame_waiting_in_the_server():
    srv = Server(ServerConfig(port=0, scene="sphere", view_size=(128, 128), fps=40.0, bitrate_kbps=8000, keyint=1,
                              extra_view="off"))
    host, port = await srv.start()
    task = asyncio.create_task(srv.serve_forever())
    try:
        sock = socket.socket()
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)   # the reader's kernel holds little
        sock.connect((host, port))    # a plain socket nobody reads from
        conn = Connection()
        conn.send(Hello(client="slow", scene="sphere", clock="real", output=OutputConfig(64, 48, 90.0, 30.0)))
        sock.sendall(conn.data_to_send())
        while not srv.sessions:
            await asyncio.sleep(0.01)
        session = next(iter(srv.sessions.values()))
        while session.config is None or session.writer.transport is None:
            await asyncio.sleep(0.01)
        server_sock = session.writer.transport.get_extra_info("socket")
        server_sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)  # and so does the server's
        sizes = [session.conn.bytes_sent]
        send = session.conn.send

        def recording_send(message, vtime_us=0):
            send(message, vtime_us)
            sizes.append(session.conn.bytes_sent)
        session.conn.send = recording_send
        conn.send(PoseMsg(0, 0, Pose.make((0, 1.6, 0))))
        sock.sendall(conn.data_to_send())

        backlog = 0
        for _ in range(1000):                     # the reader never reads: until 10 ticks were skipped
            await asyncio.sleep(0.01)
            backlog = max(backlog, session.writer.transport.get_write_buffer_size())
            if session.frames_skipped >= 10:
                break
        frame_bytes = [b - a for a, b in zip(sizes, sizes[1:])]
        assert session.frames_skipped >= 10 and session.frames_sent >= 2
        assert 0 < backlog <= max(frame_bytes)    # one frame at most, not a queue of them
        sock.close()
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        await srv.close()


async def test_a_real_clock_client_that_sends_poses_but_reads_nothing_loses_its_slot():
    """Issue 13, defect 9 on the real clock: poses keep coming, but nothing sent is read for the
    idle timeout; the session ends and its slot is free."""
    srv = Server(ServerConfig(port=0, scene="sphere", view_size=(128, 128), fps=40.0, keyint=1, extra_view="off",
                              idle_timeout_s=0.5))
    host, port = await srv.start()
    task = asyncio.create_task(srv.serve_forever())
    try:
        sock = socket.socket()
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.connect((host, port))
        sock.setblocking(False)
        conn = Connection()
        conn.send(Hello(client="deaf", scene="sphere", clock="real", output=OutputConfig(64, 48, 90.0, 30.0)))
        loop = asyncio.get_running_loop()
        await loop.sock_sendall(sock, conn.data_to_send())
        while not srv.sessions:
            await asyncio.sleep(0.01)
        session = next(iter(srv.sessions.values()))
        while session.config is None:
            await asyncio.sleep(0.01)
        session.writer.transport.get_extra_info("socket").setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)
        for i in range(1000):                     # a pose every 20 ms, until the server gives up
            conn.send(PoseMsg(i, i * 20_000, Pose.make((0, 1.6, 0))))
            await loop.sock_sendall(sock, conn.data_to_send())
            if not srv.sessions:
                break
            await asyncio.sleep(0.02)
        assert not srv.sessions and session.frames_skipped > 0
        sock.close()
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        await srv.close()


async def _frame_starts(frame_s, count: int) -> tuple[list, object]:
    """A wall-clock session at 20 fps whose every frame takes ``frame_s(n)`` seconds for its n-th
    (1-based) and sends nothing -> (the loop times its first ``count`` frames started, the session)."""
    srv = Server(ServerConfig(port=0, scene="sphere", view_size=(64, 64), fps=20.0, bitrate_kbps=2000,
                              extra_view="off", rate_control="off"))
    host, port = await srv.start()
    task = asyncio.create_task(srv.serve_forever())
    try:
        reader, writer = await asyncio.open_connection(host, port)
        conn = Connection()
        conn.send(Hello(client="paced", scene="sphere", clock="real", output=OutputConfig(64, 48, 90.0, 30.0)))
        writer.write(conn.data_to_send())
        while not srv.sessions:
            await asyncio.sleep(0.01)
        session = next(iter(srv.sessions.values()))
        starts = []

        async def costly_tick(*args, **kwargs):
            starts.append(asyncio.get_running_loop().time())
            await asyncio.sleep(frame_s(len(starts)))
        session._send_tick = costly_tick
        conn.send(PoseMsg(0, 0, Pose.make((0, 1.6, 0))))
        writer.write(conn.data_to_send())
        while len(starts) < count:
            await asyncio.sleep(0.01)
        writer.close()
        return starts[:count], session
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        await srv.close()


@pytest.mark.parametrize("frame_ms, expected_fps", [(30.0, 20.0), (65.0, 1e3 / 65.0)])
async def test_a_frame_over_its_interval_delays_the_next_without_skipping_a_slot(frame_ms, expected_fps):
    """The wall clock's frames keep --fps when they fit, and when each costs a little more than an
    interval the next starts at once: the rate is one per frame's cost, not one per two intervals
    (a fixed grid skipped the slot a frame ran into, 10 fps for 65 ms frames asked at 20)."""
    starts, session = await _frame_starts(lambda n: frame_ms / 1e3, 16)
    fps = (len(starts) - 1) / (starts[-1] - starts[0])
    assert expected_fps * 0.85 <= fps <= expected_fps * 1.05
    overran = frame_ms > 50.0
    assert (session.tick_overruns >= 14) if overran else (session.tick_overruns <= 2)


async def test_cheaper_frames_make_up_for_a_costly_one_so_the_mean_cost_sets_the_rate():
    """Every 4th frame costs 80 ms at 20 fps (50 ms), the others 35: the mean (46 ms) fits, so the
    rate holds at 20 fps (padding the cheap frames to the interval after each overrun gave 17.3)."""
    starts, session = await _frame_starts(lambda n: 0.080 if n % 4 == 0 else 0.035, 25)
    fps = (len(starts) - 1) / (starts[-1] - starts[0])
    assert 19.0 <= fps <= 21.0
    assert session.tick_overruns >= 5     # every costly frame overran its own interval
    assert np.diff(starts).min() < 0.045  # a frame after a costly one started early, on the grid
