"""Framing, messages and the sans-I/O connection: golden bytes, any chunking, bad input."""
import os
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pibr.protocol.connection import Connection
from pibr.protocol.errors import (BadMagic, MalformedMessage, MessageTooLarge, ProtocolError, TruncatedMessage,
                                  UnknownMessageType, UnsupportedVersion)
from pibr.protocol.framing import HEADER, HEADER_SIZE, MAGIC, FrameReader, encode_frame
from pibr.protocol.messages import Error, Frame, Hello, PoseMsg, parse_message

from .golden_messages import GOLDEN_DIR, MESSAGES, golden_bytes


def _golden(name):
    with open(os.path.join(GOLDEN_DIR, f"{name}.bin"), "rb") as f:
        return f.read()


@pytest.mark.parametrize("name", sorted(MESSAGES))
def test_golden_bytes_serialize_and_parse(name):
    data = _golden(name)
    assert golden_bytes(name) == data, f"the wire format of {name} changed"
    frames = FrameReader().feed(data)
    assert len(frames) == 1
    msg, vt = MESSAGES[name]
    assert frames[0].vtime_us == vt
    assert parse_message(frames[0].type, frames[0].payload) == msg


@pytest.mark.parametrize("name", sorted(MESSAGES))
def test_golden_truncated_is_reported_at_eof(name):
    data = _golden(name)
    for cut in sorted({1, 3, HEADER_SIZE - 1, HEADER_SIZE, len(data) - 1}):
        if cut >= len(data):
            continue
        reader = FrameReader()
        assert reader.feed(data[:cut]) == []
        with pytest.raises(TruncatedMessage):
            reader.eof()


ALL = b"".join(_golden(n) for n in sorted(MESSAGES))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(1, 64), min_size=1, max_size=200))
def test_any_chunking_gives_the_same_messages(sizes):
    conn = Connection()
    pos, i = 0, 0
    while pos < len(ALL):
        n = sizes[i % len(sizes)]
        conn.receive_data(ALL[pos:pos + n])
        pos += n
        i += 1
    conn.receive_eof()
    got = [(e.message, e.vtime_us) for e in conn.events_received()]
    assert got == [MESSAGES[n] for n in sorted(MESSAGES)]
    assert conn.error is None


def test_bad_magic_fails_fast_with_error_for_peer():
    conn = Connection()
    conn.receive_data(b"GET / HTTP/1.1\r\n")
    assert isinstance(conn.error, BadMagic)
    out = FrameReader().feed(conn.data_to_send())
    err = parse_message(out[0].type, out[0].payload)
    assert isinstance(err, Error) and err.code == BadMagic.code and "magic" in err.text
    conn.receive_data(_golden("pose"))        # a failed connection ignores anything further
    assert conn.events_received() == []


def test_oversized_length_rejected_before_reading_payload():
    reader = FrameReader(max_message_size=1000)
    header = HEADER.pack(MAGIC, 1, PoseMsg.TYPE, 0, 0, 10 ** 9)
    with pytest.raises(MessageTooLarge, match="1000000000 bytes exceeds the limit of 1000"):
        reader.feed(header)


def test_version_flags_and_type_checked():
    with pytest.raises(UnsupportedVersion, match="framing version 9"):
        FrameReader().feed(HEADER.pack(MAGIC, 9, 1, 0, 0, 0))
    with pytest.raises(MalformedMessage, match="flags"):
        FrameReader().feed(HEADER.pack(MAGIC, 1, 1, 4, 0, 0))
    conn = Connection()
    conn.receive_data(encode_frame(200, b""))
    assert isinstance(conn.error, UnknownMessageType)


def test_reader_stays_failed():
    reader = FrameReader()
    with pytest.raises(BadMagic):
        reader.feed(b"XXXX")
    with pytest.raises(BadMagic):
        reader.feed(_golden("pose"))


@pytest.mark.parametrize("payload, match", [
    (b"\xff\xfe", "not UTF-8 JSON"),
    (b"[1, 2]", "must be a JSON object"),
    (b'{"protocol": "one"}', "'protocol' must be int"),
    (b'{"protocol": 1, "clock": "sundial"}', "'clock' = 'sundial' is not one of virtual, real"),
    (b'{"protocol": 1, "output": {"width": 5, "height": 100, "fov_deg": 90, "rate_hz": 60}}', "outside"),
    (b'{"protocol": 1, "output": {"width": 960, "height": 540, "fov_deg": NaN, "rate_hz": 60}}', "fov_deg"),
])
def test_malformed_hello(payload, match):
    with pytest.raises(MalformedMessage, match=match):
        parse_message(Hello.TYPE, payload)


def test_pose_with_nan_or_zero_quaternion_rejected():
    good = _golden("pose")[HEADER_SIZE:]
    seq, t = struct.unpack_from("<Iq", good)
    nan = struct.pack("<Iq7d", seq, t, 0.0, float("nan"), 0.0, 1.0, 0.0, 0.0, 0.0)
    zero = struct.pack("<Iq7d", seq, t, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    with pytest.raises(MalformedMessage, match="invalid pose: position has a NaN"):
        parse_message(PoseMsg.TYPE, nan)
    with pytest.raises(MalformedMessage, match="zero quaternion"):
        parse_message(PoseMsg.TYPE, zero)
    with pytest.raises(MalformedMessage, match="must be 68 bytes"):
        parse_message(PoseMsg.TYPE, good[:-1])


def test_frame_payload_lengths_are_checked():
    good = _golden("frame")[HEADER_SIZE:]
    with pytest.raises(MalformedMessage, match="claims"):
        parse_message(Frame.TYPE, good[:-3])
    with pytest.raises(MalformedMessage, match="trailing"):
        parse_message(Frame.TYPE, good + b"x")
    with pytest.raises(MalformedMessage, match="shorter than"):
        parse_message(Frame.TYPE, good[:40])


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=400), st.integers(1, 9))
def test_garbage_payloads_never_crash(payload, mtype):
    conn = Connection()
    conn.receive_data(encode_frame(mtype, payload))
    # Either a message came out or the connection failed with a named protocol error.
    events = conn.events_received()
    assert bool(events) != (conn.error is not None)
    if conn.error is not None:
        assert str(conn.error)


def test_a_valid_frame_before_garbage_in_one_read_is_delivered_then_the_stream_fails():
    hello = golden_bytes("hello")
    reader = FrameReader()
    frames = reader.feed(hello + b"XBAD")
    assert [f.type for f in frames] == [Hello.TYPE] and isinstance(reader.error, BadMagic)
    with pytest.raises(BadMagic):
        reader.feed(hello)                  # never read past the error
    with pytest.raises(BadMagic):
        reader.eof()                        # nor lost when the peer closes next
    conn = Connection()
    conn.receive_data(hello + b"XBAD")
    assert [type(e.message) for e in conn.events_received()] == [Hello]
    assert isinstance(conn.error, BadMagic) and conn.data_to_send()   # the peer is told why


@settings(max_examples=200, deadline=None)
@given(st.one_of(st.binary(min_size=1, max_size=300), st.binary(max_size=300).map(lambda b: MAGIC + b),
                 st.binary(max_size=300).map(lambda b: golden_bytes("hello") + b)))
def test_random_streams_fail_cleanly(data):
    """Bytes that are not whole frames of valid messages fail the connection with a named
    protocol error, an Error queued for the peer when it can still be told; whole valid frames
    before the garbage are still delivered; nothing is read after the failure."""
    conn = Connection(max_message_size=256)
    conn.receive_data(data)
    failed_while_open = conn.error is not None
    conn.receive_eof()
    events = conn.events_received()
    hello = golden_bytes("hello")
    if not data.startswith(MAGIC):
        expected = BadMagic if len(data) >= HEADER_SIZE else (BadMagic, TruncatedMessage)
        assert isinstance(conn.error, expected) and not events
    if data.startswith(hello):
        assert events and isinstance(events[0].message, Hello)
    if conn.error is None:        # a clean end: the stream was whole frames of valid messages
        assert events and sum(e.wire_size for e in events) == len(data)
    else:
        assert isinstance(conn.error, ProtocolError) and str(conn.error)
        sent = conn.data_to_send()
        assert bool(sent) == failed_while_open   # told the peer, unless the error came with the end
        conn.receive_data(golden_bytes("hello"))
        assert conn.events_received() == []


def test_send_respects_size_limit():
    conn = Connection(max_message_size=100)
    with pytest.raises(ValueError, match="exceeds the message size limit"):
        conn.send(Error(1, "x" * 200))


def test_hello_states_a_bandwidth_and_old_bytes_stay_the_same():
    from pibr.protocol.messages import MAX_BANDWIDTH_KBPS

    hello = Hello(client="t", bandwidth_kbps=2500.0)
    assert b'"bandwidth_kbps":2500.0' in hello.serialize()
    assert Hello.parse(hello.serialize()) == hello
    # Not stated: left out, so a Hello reads (and the golden bytes stay) as before the field existed.
    assert b"bandwidth" not in Hello(client="t").serialize() and b"bandwidth" not in golden_bytes("hello")
    assert Hello.parse(golden_bytes("hello")[HEADER_SIZE:]).bandwidth_kbps == 0.0
    for bad, message in (("-1", "outside"), (str(MAX_BANDWIDTH_KBPS * 2), "outside"), ('"fast"', "must be float")):
        with pytest.raises(MalformedMessage, match=f"Hello: field 'bandwidth_kbps'.*{message}"):
            Hello.parse(b'{"protocol": 1, "bandwidth_kbps": ' + bad.encode() + b"}")


def test_hello_asks_for_two_eyes_and_old_bytes_stay_the_same():
    hello = Hello(client="t", stereo="alternate", ipd_mm=63.5)
    assert b'"stereo":"alternate"' in hello.serialize() and b'"ipd_mm":63.5' in hello.serialize()
    assert Hello.parse(hello.serialize()) == hello
    assert b"stereo" not in Hello(client="t").serialize() and b"stereo" not in golden_bytes("hello")
    assert Hello.parse(golden_bytes("hello")[HEADER_SIZE:]).stereo == ""
    for payload, message in ((b'{"protocol": 1, "stereo": "both", "ipd_mm": 64}', "field 'stereo'"),
                             (b'{"protocol": 1, "stereo": "cyclops"}', "interpupillary distance"),
                             (b'{"protocol": 1, "stereo": "cyclops", "ipd_mm": 500}', "field 'ipd_mm'.*outside"),
                             (b'{"protocol": 1, "ipd_mm": 64}', "ipd_mm without stereo")):
        with pytest.raises(MalformedMessage, match=f"Hello: .*{message}"):
            Hello.parse(payload)


def test_a_frames_eye_is_one_byte():
    from pibr.protocol.messages import PayloadKind, decode_eye, encode_eye

    assert [decode_eye(encode_eye(e)) for e in ("left", "right")] == ["left", "right"]
    assert PayloadKind.NAMES[PayloadKind.EYE] == "eye"
    for bad in (b"", b"\x02", b"\x00\x01"):
        with pytest.raises(MalformedMessage, match="eye payload"):
            decode_eye(bad)
    with pytest.raises(ValueError, match="left or right"):
        encode_eye("centre")
