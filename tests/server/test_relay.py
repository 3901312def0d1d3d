"""The latency relay in-process: virtual stamping, real-clock delay, bad peers."""
import asyncio
import time

import pytest

from pibr.client.connection import ClientConnection
from pibr.protocol.connection import Connection
from pibr.common.link import LinkParams
from pibr.protocol.messages import Error, Hello, OutputConfig
from pibr.server.config import ServerConfig
from pibr.server.relay import Relay, RelayConfig

from ..loopback import exchange_virtual, running_server, server_behind_relay

pytestmark = pytest.mark.gl


@pytest.fixture
async def chain():
    config = ServerConfig(port=0, scene="sphere", view_size=(128, 128), server_delay_ms=20.0, bitrate_kbps=2000)
    async with server_behind_relay(config) as ep:
        yield ep


async def test_virtual_frames_carry_injected_delay(chain):
    host, port = chain
    c = await ClientConnection.open(host, port)
    cfg = await c.handshake(Hello(clock="virtual", output=OutputConfig(160, 96, 90.0, 30.0)))
    interval = 33_333
    frames = await exchange_virtual(c, cfg.viewer_origin, [tick * interval for tick in range(-6, 15)], interval)
    await c.close()
    assert frames
    for vt, f in frames:
        assert vt - f.render_t_us == 20_000 + 64_000        # encode model + downlink
        assert f.render_t_us - f.pose_t_us >= 64_000        # the pose needed the uplink
    for vt, f in frames:  # the newest pose that had arrived (64 ms after it was sent) by render time
        sent = [tick * interval for tick in range(-6, 15)]
        assert f.pose_t_us == max(t for t in sent if t + 64_000 <= f.render_t_us)


async def test_real_clock_delay_is_applied(chain):
    host, port = chain
    c = await ClientConnection.open(host, port)
    t0 = time.monotonic()
    await c.handshake(Hello(clock="real", output=OutputConfig(160, 96, 90.0, 30.0)))
    rtt = time.monotonic() - t0
    assert rtt >= 0.128
    await c.close()


async def test_garbage_to_relay_gets_error(chain):
    host, port = chain
    reader, writer = await asyncio.open_connection(host, port)
    writer.write(b"\x00" * 64)
    await writer.drain()
    conn = Connection()
    while True:
        chunk = await asyncio.wait_for(reader.read(65536), 10)
        if not chunk:
            break
        conn.receive_data(chunk)
    msgs = [e.message for e in conn.events_received()]
    assert msgs and isinstance(msgs[0], Error) and "relay" in msgs[0].text and "magic" in msgs[0].text


async def test_relay_reports_unreachable_upstream():
    relay = Relay(RelayConfig(("127.0.0.1", 0), ("127.0.0.1", 1), LinkParams(1.0), LinkParams(1.0)))
    host, port = await relay.start()
    task = asyncio.create_task(relay.serve_forever())
    c = await ClientConnection.open(host, port)
    from pibr.protocol.errors import RemoteError

    with pytest.raises(RemoteError, match="unreachable"):
        await c.handshake(Hello())
    await c.close()
    task.cancel()
    await asyncio.gather(task, return_exceptions=True)
    await relay.close()


async def _replay(host, port) -> list:
    c = await ClientConnection.open(host, port)
    cfg = await c.handshake(Hello(clock="virtual", output=OutputConfig(160, 96, 90.0, 30.0)))
    interval = 33_333
    frames = await exchange_virtual(c, cfg.viewer_origin, [tick * interval for tick in range(-6, 15)], interval)
    await c.close()
    return [(vt, f.frame_id, f.pose_seq, f.render_t_us) for vt, f in frames]


async def test_jittered_replays_through_one_relay_are_identical():
    """Defect 14 with the real server: the second session through the relay sees the same jitter
    (arrival stamps, and so the poses each frame was rendered with) as the first; another seed
    does not."""
    config = ServerConfig(port=0, scene="sphere", view_size=(128, 128), server_delay_ms=20.0, bitrate_kbps=2000)
    async with server_behind_relay(config, jitter_ms=30.0, seed=11) as (host, port):
        first = await _replay(host, port)
        second = await _replay(host, port)
    async with server_behind_relay(config, jitter_ms=30.0, seed=12) as (host, port):
        other = await _replay(host, port)
    assert len(first) > 5 and first == second
    assert len({vt - render for vt, _, _, render in first}) > 3          # the jitter is there
    assert [vt for vt, *_ in other] != [vt for vt, *_ in first]


async def test_a_bandwidth_trace_holds_frames_through_an_outage_on_the_virtual_clock(tmp_path):
    """pibr relay --down-trace: the downlink replays the trace from virtual time 0, so frames sent
    while it carries nothing (0.2 to 0.6 s) arrive only after it, one after the other."""
    from pibr.common.bandwidth import load_bandwidth_trace

    (tmp_path / "outage.csv").write_text("t,kbps\n0,20000\n0.2,0\n0.6,20000\n1.2,20000\n")
    trace = load_bandwidth_trace(str(tmp_path / "outage.csv"))
    config = ServerConfig(port=0, scene="sphere", view_size=(128, 128), server_delay_ms=20.0, bitrate_kbps=2000)
    async with running_server(config) as (_, host, port):
        relay = Relay(RelayConfig(("127.0.0.1", 0), (host, port), LinkParams(64.0), LinkParams(64.0, trace=trace)))
        rhost, rport = await relay.start()
        rtask = asyncio.create_task(relay.serve_forever())
        try:
            c = await ClientConnection.open(rhost, rport)
            cfg = await c.handshake(Hello(clock="virtual", output=OutputConfig(160, 96, 90.0, 30.0)))
            interval = 33_333
            frames = await exchange_virtual(c, cfg.viewer_origin, [k * interval for k in range(0, 30)], interval)
            await c.close()
        finally:
            rtask.cancel()
            await asyncio.gather(rtask, return_exceptions=True)
            await relay.close()
    in_outage = [(vt, f) for vt, f in frames if 200_000 <= f.render_t_us + 20_000 < 600_000]
    before = [(vt, f) for vt, f in frames if f.render_t_us + 20_000 < 150_000]
    assert len(in_outage) >= 3 and before
    for vt, f in before:       # 20 Mbit/s: a small frame leaves at once
        assert vt - f.render_t_us < 20_000 + 64_000 + 5_000
    for vt, f in in_outage:    # sent in the outage: leaves after it, then the downlink's delay
        assert vt >= 600_000 + 64_000
    arrivals = [vt for vt, _ in frames]
    assert arrivals == sorted(arrivals)


def test_on_the_wall_clock_the_first_ticks_pose_restarts_the_traces_and_nothing_else_does():
    """The relay reads poses only to find the client's tick 0: a warm-up pose or one that does not
    parse leaves the traces where they are (the server refuses a bad pose; the relay forwards it)."""
    from pibr.common.link import LinkModel
    from pibr.protocol.messages import WARMUP_SEQ, PoseMsg
    from pibr.protocol.pose import Pose
    from pibr.server.relay import _Pair

    pair = object.__new__(_Pair)
    pair._ticking = False
    pair.up_model, pair.down_model = LinkModel(LinkParams()), LinkModel(LinkParams(), origin_us=5)
    pose = Pose.make([0.0, 1.6, 0.0], [1.0, 0.0, 0.0, 0.0])
    pair._start_ticking(PoseMsg(WARMUP_SEQ, 2_000_000, pose).serialize(), 9_000_000)
    pair._start_ticking(b"\x00" * 7, 9_000_000)
    assert not pair._ticking and pair.down_model.origin_us == 5
    pair._start_ticking(PoseMsg(0, -500_000, pose).serialize(), 9_000_000)   # tick -preroll, 0.5 s before 0
    assert pair._ticking and pair.up_model.origin_us == pair.down_model.origin_us == 9_500_000
