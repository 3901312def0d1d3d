"""The session's message order, sans-I/O: each side driven with bytes only (no socket).

The server's side: a Hello first (token, then protocol version), then poses and clocks whose
virtual time never goes backwards nor runs too far ahead of the next frame; Stats taken in
passing. The client's side: a Welcome that fits the Hello, the proxies when asked for, then
frames and clocks whose virtual time never goes backwards. Both: Bye and Error end the session,
checks run when a message is taken, and any chunking of the stream gives the same events.
"""
import json
import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pibr.protocol.atlas import build_layout
from pibr.protocol.errors import (AccessDenied, BadMagic, ClientClosed, MalformedMessage, RemoteError,
                                  ServerClosed, TruncatedMessage, UnexpectedMessage, UnsupportedVersion)
from pibr.protocol.framing import FrameReader, encode_frame
from pibr.protocol.messages import (PROTOCOL_VERSION, Bye, Clock, Error, Frame, Hello, PoseMsg, ProxyChunk, Stats,
                                    Welcome, parse_message)
from pibr.protocol.pose import Pose, dual_view_offset
from pibr.protocol.proxy import BundleInfo
from pibr.protocol.session import SessionConfig, ViewConfig
from pibr.protocol.sides import ClientSide, ClientState, ServerSide, ServerState

TOKEN = "s3cret-token"
ORIGIN = Pose.make((0.0, 1.6, 0.0))


def wire(*items) -> bytes:
    """The bytes of messages, each a message or (message, virtual time us)."""
    out = []
    for item in items:
        msg, vtime_us = item if isinstance(item, tuple) else (item, 0)
        out.append(encode_frame(msg.TYPE, msg.serialize(), vtime_us))
    return b"".join(out)


def taken(side) -> list:
    """Every message the side hands out until it needs more bytes -> [(message, vtime us)]."""
    out = []
    while (env := side.next_event()) is not None:
        out.append((env.message, env.vtime_us))
    return out


def pose(seq: int, t_us: int) -> tuple:
    return PoseMsg(seq, t_us, ORIGIN), t_us


def sent(side) -> list:
    """The messages the side queued for its peer."""
    return [parse_message(f.type, f.payload) for f in FrameReader().feed(side.data_to_send())]


# ---------------------------------------------------------------- the server's side

def server(token=None, clock="virtual", **hello) -> ServerSide:
    """A server side that has accepted a Hello on ``clock``."""
    side = ServerSide(token)
    side.receive_data(wire(Hello(clock=clock, token=token or "", **hello)))
    assert [type(m) for m, _ in taken(side)] == [Hello]
    return side


def test_a_hello_first_is_accepted():
    side = ServerSide()
    assert side.state is ServerState.AWAITING_HELLO
    hello = Hello(client="me", scene="room", clock="real")
    side.receive_data(wire(hello))
    assert taken(side) == [(hello, 0)]
    assert side.hello == hello and side.state is ServerState.OPEN
    assert side.data_to_send() == b""


@pytest.mark.parametrize("first", [PoseMsg(0, 0, ORIGIN), Clock(), Welcome("s", 1, {}), ProxyChunk(0, 1, 1, b"x"),
                                   Frame(0, 0, 0, 0, 0, ORIGIN, None, 0.1, 10.0)])
def test_anything_else_first_is_refused(first):
    side = ServerSide()
    side.receive_data(wire(first, Hello()))
    with pytest.raises(UnexpectedMessage) as err:
        side.next_event()
    assert str(err.value) == f"expected Hello as the first message, got {first.NAME}"
    assert side.state is ServerState.CLOSED and side.hello is None
    assert side.data_to_send() == b""          # what the peer is told is the adapter's business


@pytest.mark.parametrize("clock", ["virtual", "real"])
def test_a_second_hello_is_refused(clock):
    side = server(clock=clock)
    side.receive_data(wire(pose(0, 0), (Hello(clock=clock), 10)))
    assert type(side.next_event().message) is PoseMsg
    with pytest.raises(UnexpectedMessage, match="^unexpected Hello from the client$"):
        side.next_event()


@pytest.mark.parametrize("given", ["", "guess", TOKEN[:-1], TOKEN + "x"])
def test_a_bad_token_is_refused_before_anything_else(given):
    """Even a Hello of another protocol version learns only that its token is wrong."""
    side = ServerSide(TOKEN)
    side.receive_data(wire(Hello(token=given, protocol=PROTOCOL_VERSION + 1)))
    with pytest.raises(AccessDenied) as err:
        side.next_event()
    assert str(err.value) == "bad or missing token" and type(err.value) is AccessDenied
    assert side.hello is None


def test_the_right_token_is_accepted_and_no_token_needs_none():
    assert server(TOKEN).hello.token == TOKEN
    side = ServerSide(None)
    side.receive_data(wire(Hello(token="anything")))
    assert side.next_event().message.token == "anything"


def test_another_protocol_version_is_refused():
    side = ServerSide()
    side.receive_data(wire(Hello(protocol=PROTOCOL_VERSION + 1)))
    with pytest.raises(UnsupportedVersion) as err:
        side.next_event()
    assert str(err.value) == (f"client speaks protocol {PROTOCOL_VERSION + 1}, this server speaks "
                              f"{PROTOCOL_VERSION}")


def test_virtual_time_going_backwards_is_refused():
    side = server()
    side.receive_data(wire(pose(0, 100), (Clock(), 100), (Clock(), 99)))
    assert [side.next_event().vtime_us for _ in range(2)] == [100, 100]
    assert side.horizon_us == 100
    with pytest.raises(UnexpectedMessage) as err:
        side.next_event()
    assert str(err.value) == "virtual time went backwards (99 us after 100 us)"


def test_the_real_clock_has_no_time_rule():
    side = server(clock="real")
    side.receive_data(wire(pose(0, 100), pose(1, 50), (Clock(), 0)))
    assert [vt for _, vt in taken(side)] == [100, 50, 0]


def test_a_clock_too_far_ahead_of_the_next_frame_is_refused():
    side = server()
    side.next_frame(100_000, 2_000_000)
    side.receive_data(wire(pose(0, 2_100_000), (Clock(), 2_100_001)))
    assert side.next_event().vtime_us == 2_100_000              # exactly the lead allowed
    with pytest.raises(UnexpectedMessage) as err:
        side.next_event()
    assert str(err.value) == ("the client's clock (2100001 us) runs 2 s ahead of the next frame (100000 us), "
                              "more than the 2 s allowed")


def test_no_lead_limit_before_a_frame_is_scheduled():
    side = server()
    side.next_frame(None, 1_000)
    side.receive_data(wire((Clock(), 10 ** 15)))
    assert taken(side) == [(Clock(), 10 ** 15)]


def test_checks_run_when_a_message_is_taken_not_when_it_is_parsed():
    """Both clocks arrive in one read; the second is within the lead only once the session has
    moved its next frame on, as it does between taking them."""
    side = server()
    side.receive_data(wire((Clock(), 0), (Clock(), 5_000)))
    side.next_frame(0, 1_000)
    assert side.next_event().vtime_us == 0
    side.next_frame(4_000, 1_000)
    assert side.next_event().vtime_us == 5_000
    refused = server()
    refused.receive_data(wire((Clock(), 0), (Clock(), 5_000)))
    refused.next_frame(0, 1_000)
    assert refused.next_event().vtime_us == 0
    with pytest.raises(UnexpectedMessage, match=r"runs 0\.005 s ahead of the next frame \(0 us\)"):
        refused.next_event()


def test_stats_are_collected_and_not_handed_out():
    side = ServerSide()
    side.receive_data(wire((Stats({"a": 1.0}), 500), Hello(), pose(0, 100), (Stats({"a": 2.0, "b": 3.0}), 7),
                           pose(1, 200)))
    assert [type(m) for m, _ in taken(side)] == [Hello, PoseMsg, PoseMsg]
    assert side.client_stats == {"a": 2.0, "b": 3.0}
    assert side.horizon_us == 200        # a Stats' time (7 us, after 100) moved nothing and broke no rule


@pytest.mark.parametrize("end, text", [
    (Bye("done"), "client said bye (done)"),
    (Bye(), "client said bye (no reason)"),
    (Error(8, "nope"), "client reported error 8: nope"),
])
@pytest.mark.parametrize("after_hello", [False, True])
def test_bye_or_error_ends_the_session(end, text, after_hello):
    side = server() if after_hello else ServerSide()
    side.receive_data(wire(end, pose(0, 0)))
    with pytest.raises(ClientClosed) as err:
        side.next_event()
    assert str(err.value) == text and side.state is ServerState.CLOSED
    with pytest.raises(ClientClosed, match=re.escape(text)):   # over: the messages after it are never taken
        side.next_event()


def test_the_end_of_the_stream_ends_the_session():
    side = server()
    side.receive_data(wire(pose(0, 0)))
    side.receive_eof()
    assert side.next_event().message.seq == 0          # what came before the end is still taken
    with pytest.raises(ClientClosed, match="^client closed the connection$"):
        side.next_event()


def test_a_stream_ending_mid_message_is_truncated():
    side = server()
    side.receive_data(wire(pose(0, 0))[:-3])
    assert side.next_event() is None
    side.receive_eof()
    with pytest.raises(TruncatedMessage):
        side.next_event()


def test_a_bad_stream_is_refused_after_the_messages_before_it_and_the_peer_is_told():
    side = ServerSide()
    side.receive_data(wire(Hello()))
    side.receive_data(b"GET / HTTP/1.1\r\n\r\n")      # parsed before the Hello is taken
    assert type(side.next_event().message) is Hello
    with pytest.raises(BadMagic) as err:
        side.next_event()
    assert sent(side) == [Error(BadMagic.code, str(err.value))]


# ---------------------------------------------------------------- the client's side

def config(clock="virtual", proxies=None, atlas=None) -> dict:
    """A Welcome's config for a 64x64 dual view."""
    cfg = SessionConfig(
        scene={"name": "room", "near": 0.1, "far": 100.0, "viewer_origin": [0, 1.6, 0, 1, 0, 0, 0]},
        clock=clock, server_fps=10.0, server_delay_us=20_000, primary=ViewConfig(64, 64), extra=ViewConfig(32, 32),
        extra_offset=dual_view_offset(1.5, 1.8, 15),
        atlas=atlas or build_layout((64, 64), (32, 32), depth_in_atlas=True), video_bitrate_kbps=2000.0, keyint=30,
        proxies=proxies)
    return json.loads(json.dumps(cfg.to_json()))


BUNDLE = bytes(range(256)) * 10                       # 2560 bytes in chunks of 1024, 1024, 512
INFO = BundleInfo(2, len(BUNDLE), 4000, 1024, {"proxy": 12})
CHUNKS = [ProxyChunk(i, 3, len(BUNDLE), BUNDLE[i * 1024:(i + 1) * 1024]) for i in range(3)]


def frame(frame_id: int, t_us: int) -> tuple:
    return Frame(frame_id, t_us, t_us, frame_id, t_us, ORIGIN, None, 0.1, 100.0), t_us + 20_000


def client(clock="virtual", want_proxies=False, welcome_config=None) -> ClientSide:
    side = ClientSide()
    side.send_hello(Hello(clock=clock, want_proxies=want_proxies))
    side.data_to_send()
    cfg = welcome_config or config(clock, INFO.to_json() if want_proxies else None)
    side.receive_data(wire(Welcome("srv", 7, cfg)))
    return side


def test_idle_nothing_is_expected_yet():
    """Before our Hello nothing is checked (a bare connection reads what comes, even time going
    backwards), but an Error still ends the session."""
    side = ClientSide()
    side.receive_data(wire((Clock(), 5), frame(0, 0), Error(3, "busy")))
    assert [side.next_event().vtime_us, side.next_event().vtime_us] == [5, 20_000]
    with pytest.raises(RemoteError) as err:
        side.next_event()
    assert (err.value.code, err.value.text) == (3, "busy") and side.state is ClientState.CLOSED


def test_the_hello_is_sent_and_a_welcome_accepted():
    side = ClientSide()
    assert side.state is ClientState.IDLE
    hello = Hello(clock="virtual")
    side.send_hello(hello)
    assert sent(side) == [hello] and side.state is ClientState.AWAITING_WELCOME
    welcome = Welcome("srv", 7, config())
    side.receive_data(wire(welcome))
    assert taken(side) == [(welcome, 0)]
    assert side.welcome == welcome and side.config == SessionConfig.from_json(config())
    assert side.state is ClientState.STREAMING and side.proxies is None
    with pytest.raises(RuntimeError, match="already sent"):
        side.send_hello(hello)


@pytest.mark.parametrize("first", [frame(0, 0), (Clock(), 0), (ProxyChunk(0, 1, 1, b"x"), 0), (Stats({}), 0),
                                   (Hello(), 0)])
def test_a_first_answer_other_than_a_welcome_is_refused(first):
    side = ClientSide()
    side.send_hello(Hello())
    side.receive_data(wire(first, Welcome("srv", 1, config())))
    with pytest.raises(UnexpectedMessage) as err:
        side.next_event()
    assert str(err.value) == f"expected Welcome, got {first[0].NAME}"
    assert side.state is ClientState.CLOSED and side.welcome is None
    assert sent(side) == [Hello()]        # and no Error: the client says Bye when it closes


def test_a_welcome_of_another_protocol_is_refused():
    side = ClientSide()
    side.send_hello(Hello())
    side.receive_data(wire(Welcome("srv", 1, config(), protocol=PROTOCOL_VERSION + 1)))
    with pytest.raises(UnexpectedMessage) as err:
        side.next_event()
    assert str(err.value) == f"server speaks protocol {PROTOCOL_VERSION + 1}, we speak {PROTOCOL_VERSION}"
    assert side.config is None


def test_a_welcome_on_another_clock_is_refused():
    side = ClientSide()
    side.send_hello(Hello(clock="virtual"))
    side.receive_data(wire(Welcome("srv", 1, config("real"))))
    with pytest.raises(UnexpectedMessage, match="^server runs the real clock, we asked for virtual$"):
        side.next_event()


def test_a_welcome_whose_atlas_is_not_its_views_layout_is_refused():
    big = build_layout((64, 64), (32, 32), depth_in_atlas=True)
    big = type(big)(4096, 4096, big.rects)
    side = ClientSide()
    side.send_hello(Hello())
    side.receive_data(wire(Welcome("srv", 1, config(atlas=big))))
    with pytest.raises(MalformedMessage, match=r"^Welcome.config.atlas: 4096x4096 with .* is not the layout of its "
                                               r"views \(160x64 with"):
        side.next_event()


def test_a_welcome_without_the_proxies_asked_for_is_refused():
    side = client(want_proxies=True, welcome_config=config())
    with pytest.raises(UnexpectedMessage, match="^asked for proxies, but the server's Welcome announces none$"):
        side.next_event()


def test_the_proxies_follow_the_welcome():
    side = client(want_proxies=True)
    side.receive_data(wire(*CHUNKS[:2]))
    assert [type(m) for m, _ in taken(side)] == [Welcome, ProxyChunk, ProxyChunk]
    assert side.state is ClientState.PROXIES and not side.proxies.complete
    side.receive_data(wire(CHUNKS[2], frame(0, 0)))
    assert [type(m) for m, _ in taken(side)] == [ProxyChunk, Frame]
    assert side.state is ClientState.STREAMING and side.proxies.data() == BUNDLE


@pytest.mark.parametrize("other", [frame(0, 0), (Clock(), 0), (Stats({}), 0), (Welcome("srv", 1, {}), 0)])
def test_anything_but_a_proxy_chunk_while_proxies_are_expected_is_refused(other):
    side = client(want_proxies=True)
    side.receive_data(wire(CHUNKS[0], other, *CHUNKS[1:]))
    assert [type(side.next_event().message) for _ in range(2)] == [Welcome, ProxyChunk]
    with pytest.raises(UnexpectedMessage) as err:
        side.next_event()
    assert str(err.value) == f"expected ProxyChunk, got {other[0].NAME}"


def test_a_chunk_outside_the_announcement_is_refused():
    side = client(want_proxies=True)
    side.receive_data(wire(ProxyChunk(0, 4, len(BUNDLE), BUNDLE[:1024])))
    assert type(side.next_event().message) is Welcome
    with pytest.raises(MalformedMessage, match="^ProxyChunk: count 4 differs from the 3 chunks the Welcome announced$"):
        side.next_event()


def test_streaming_takes_frames_clocks_and_stats():
    side = client()
    side.receive_data(wire(frame(0, 0), (Clock(), 120_000), (Stats({"x": 1.0}), 120_000), frame(1, 100_000)))
    assert [(type(m), vt) for m, vt in taken(side)] == [(Welcome, 0), (Frame, 20_000), (Clock, 120_000),
                                                        (Stats, 120_000), (Frame, 120_000)]
    assert side.horizon_us == 120_000


@pytest.mark.parametrize("other", [Welcome("srv", 1, {}), ProxyChunk(0, 1, 1, b"x"), PoseMsg(0, 0, ORIGIN), Hello()])
def test_streaming_refuses_anything_else(other):
    side = client()
    side.receive_data(wire(frame(0, 0), (other, 30_000)))
    assert [type(side.next_event().message) for _ in range(2)] == [Welcome, Frame]
    with pytest.raises(UnexpectedMessage) as err:
        side.next_event()
    assert str(err.value) == f"unexpected {other.NAME} from the server"


@pytest.mark.parametrize("late", [frame(1, -15_000)[0], Clock(), Stats({})])
def test_the_servers_virtual_time_going_backwards_is_refused(late):
    side = client()
    side.receive_data(wire(frame(0, 0), (late, 5)))
    assert [side.next_event().vtime_us for _ in range(2)] == [0, 20_000]
    with pytest.raises(UnexpectedMessage) as err:
        side.next_event()
    assert str(err.value) == "server's virtual time went backwards (5 < 20000)"


def test_the_servers_real_clock_has_no_time_rule():
    side = client("real")
    side.receive_data(wire(frame(0, 0), (Clock(), 5), frame(1, -20_000)))
    assert [vt for _, vt in taken(side)] == [0, 20_000, 5, 0]


@pytest.mark.parametrize("state", ["idle", "awaiting Welcome", "receiving proxies", "streaming"])
@pytest.mark.parametrize("end, raised, text", [
    (Bye("maintenance"), ServerClosed, "server said bye (maintenance)"),
    (Bye(), ServerClosed, "server said bye (no reason)"),
    (Error(13, "bad or missing token"), RemoteError, "peer reported error 13: bad or missing token"),
])
def test_bye_or_error_from_the_server_ends_the_session(state, end, raised, text):
    if state == "idle":
        side = ClientSide()
    elif state == "awaiting Welcome":
        side = ClientSide()
        side.send_hello(Hello())
    else:
        side = client(want_proxies=state == "receiving proxies")
        side.next_event()
    assert side.state.value == state
    side.receive_data(wire(end, frame(0, 0)))
    with pytest.raises(raised) as err:
        side.next_event()
    assert type(err.value) is raised and str(err.value) == text and side.state is ClientState.CLOSED
    with pytest.raises(raised):
        side.next_event()


def test_the_end_of_the_servers_stream_ends_the_session():
    side = client()
    side.receive_eof()
    assert type(side.next_event().message) is Welcome
    with pytest.raises(ServerClosed, match="^server closed the connection$"):
        side.next_event()


# ---------------------------------------------------------------- any chunking, the same events

def _outcome(side, data: bytes, cuts: list) -> tuple:
    """Feed ``data`` cut at ``cuts`` (taking every event after each piece), then its end ->
    (messages taken with their times, the exception that ended it as (type, text))."""
    got = []

    def take():
        while (env := side.next_event()) is not None:
            got.append((env.message, env.vtime_us))

    bounds = [0, *sorted(c % (len(data) + 1) for c in cuts), len(data)]
    try:
        for a, b in zip(bounds, bounds[1:]):
            side.receive_data(data[a:b])
            take()
        side.receive_eof()
        take()
    except Exception as exc:
        return got, (type(exc), str(exc))
    return got, None


SERVER_STREAMS = {
    "good": wire((Stats({"a": 1.0}), 0), Hello(token=TOKEN), pose(0, 0), (Clock(), 33_333), (Stats({"a": 2.0}), 9),
                 pose(1, 33_333), (Clock(), 66_666), Bye("done")),
    "backwards": wire(Hello(token=TOKEN), pose(0, 100), (Clock(), 200), pose(1, 150), (Clock(), 300)),
    "second hello": wire(Hello(token=TOKEN), pose(0, 0), Hello(token=TOKEN), pose(1, 10)),
    "bad token": wire(Hello(token="guess"), pose(0, 0)),
    "truncated": wire(Hello(token=TOKEN), pose(0, 0))[:-1],
}


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(sorted(SERVER_STREAMS)), st.lists(st.integers(0, 10_000), max_size=12))
def test_the_server_side_gives_the_same_events_however_the_stream_is_cut(name, cuts):
    data = SERVER_STREAMS[name]
    whole = _outcome(ServerSide(TOKEN), data, [])
    cut = _outcome(ServerSide(TOKEN), data, cuts)
    assert cut == whole
    assert whole[1] is not None     # every stream ends somehow, and the good one ends with its Bye
    if name == "good":
        assert [type(m) for m, _ in whole[0]] == [Hello, PoseMsg, Clock, PoseMsg, Clock]
        assert whole[1] == (ClientClosed, "client said bye (done)")


CLIENT_STREAMS = {
    "good": wire(Welcome("srv", 7, config(proxies=INFO.to_json())), *CHUNKS, frame(0, 0), (Clock(), 100_000),
                 frame(1, 100_000), Bye("done")),
    "backwards": wire(Welcome("srv", 7, config(proxies=INFO.to_json())), *CHUNKS, (Clock(), 100_000), frame(0, 0)),
    "early frame": wire(Welcome("srv", 7, config(proxies=INFO.to_json())), CHUNKS[0], frame(0, 0), *CHUNKS[1:]),
    "no welcome": wire(frame(0, 0), Welcome("srv", 7, config(proxies=INFO.to_json()))),
}


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(sorted(CLIENT_STREAMS)), st.lists(st.integers(0, 20_000), max_size=12))
def test_the_client_side_gives_the_same_events_however_the_stream_is_cut(name, cuts):
    def side():
        s = ClientSide()
        s.send_hello(Hello(want_proxies=True))
        return s

    data = CLIENT_STREAMS[name]
    whole = _outcome(side(), data, [])
    assert _outcome(side(), data, cuts) == whole
    if name == "good":
        assert [type(m) for m, _ in whole[0]] == [Welcome, *[ProxyChunk] * 3, Frame, Clock, Frame]
        assert whole[1] == (ServerClosed, "server said bye (done)")
    else:
        assert whole[1][0] is UnexpectedMessage
