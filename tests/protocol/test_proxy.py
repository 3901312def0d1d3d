import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pibr.protocol.errors import MalformedMessage
from pibr.protocol.messages import ProxyChunk
from pibr.protocol.proxy import (BundleAssembler, ProxyObject, compress_bundle, decode_bundle, decompress_bundle,
                                 encode_bundle, split_chunks)


def _objects():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.uint32)
    still = ProxyObject("tetra", np.eye(4), False, np.array([[0, 0, 0], [1, 1, 1.0]]), (v, f), (v, f))
    t = np.eye(4)
    t[:3, 3] = [1, 2, 3]
    moving = ProxyObject("fan", t, True,
                         np.array([[-1, -1, -1], [1, 1, 1.0]]), (v * 2, f), (np.zeros((0, 3), np.float32),
                                                                           np.zeros((0, 3), np.uint32)))
    return [still, moving]


def test_round_trip():
    objs = _objects()
    back = decode_bundle(decompress_bundle(compress_bundle(encode_bundle(objs))))
    assert [o.name for o in back] == ["tetra", "fan"]
    for a, b in zip(objs, back):
        np.testing.assert_array_equal(a.transform, b.transform)
        np.testing.assert_array_equal(a.original[0], b.original[0])
        np.testing.assert_array_equal(a.proxy[1], b.proxy[1])
    assert [o.moving for o in back] == [False, True]
    v, f = back[1].level("box")
    assert v.shape == (8, 3) and f.shape == (12, 3)


def test_golden_bytes_are_stable():
    import hashlib

    raw = encode_bundle(_objects())
    # Pinned: a change here changes the wire format both ends must agree on (format 2, issue 14:
    # the per-object motion model became a moving flag).
    assert len(raw) == 694
    assert hashlib.sha256(raw).hexdigest() == "8c9d28d63ecab4f9dfedf3d6318ca0add7c95b27bc7a13ca24226e495df6cd93"
    assert encode_bundle(decode_bundle(raw)) == raw


@pytest.mark.parametrize("cut", [1, 4, 7, 20, 200, -1])
def test_truncated_bundles_are_rejected(cut):
    raw = encode_bundle(_objects())
    with pytest.raises(MalformedMessage, match="proxy bundle"):
        decode_bundle(raw[:cut])


def test_bad_indices_counts_and_trailing_bytes():
    raw = bytearray(encode_bundle(_objects()))
    with pytest.raises(MalformedMessage, match="trailing"):
        decode_bundle(bytes(raw) + b"x")
    bad = bytearray(raw)
    bad[4:8] = (10 ** 9).to_bytes(4, "little")
    with pytest.raises(MalformedMessage, match="exceed"):
        decode_bundle(bytes(bad))
    v = np.zeros((3, 3), np.float32)
    f = np.array([[0, 1, 7]], np.uint32)
    o = ProxyObject("x", np.eye(4), False, np.zeros((2, 3)), (v, f), (v, f))
    with pytest.raises(MalformedMessage, match="face index 7"):
        decode_bundle(encode_bundle([o]))


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=600))
def test_garbage_never_crashes(data):
    for d in (data, b"PXB1" + data):
        try:
            decode_bundle(d)
        except MalformedMessage:
            pass


def test_zstd_bomb_refused():
    import zstandard

    bomb = zstandard.ZstdCompressor().compress(b"\0" * (2 << 20))
    with pytest.raises(MalformedMessage, match="exceed"):
        decompress_bundle(bomb, max_size=1 << 20)


def test_assembler_checks_order_and_sizes():
    data = compress_bundle(encode_bundle(_objects()))
    parts = split_chunks(data, 100)
    a = BundleAssembler()
    for i, p in enumerate(parts):
        a.add(ProxyChunk(i, len(parts), len(data), p))
    assert a.complete and a.data() == data
    b = BundleAssembler()
    with pytest.raises(MalformedMessage, match="expected chunk 0"):
        b.add(ProxyChunk(1, len(parts), len(data), parts[1]))
    c = BundleAssembler(max_size=10)
    with pytest.raises(MalformedMessage, match="exceeds"):
        c.add(ProxyChunk(0, 1, 11, b"x"))


def test_the_bundle_carries_no_motion_model():
    """Format 2: per object only a moving flag; a flag other than 0 or 1 is refused, and the old
    format (with its motion model) is refused by its magic."""
    raw = encode_bundle(_objects())
    assert raw[:4] == b"PXB2"
    with pytest.raises(MalformedMessage, match="bad magic"):
        decode_bundle(b"PXB1" + raw[4:])
    flag_at = 4 + 4 + 2 + len("tetra") + 128
    assert raw[flag_at] == 0
    bad = bytearray(raw)
    bad[flag_at] = 2
    with pytest.raises(MalformedMessage, match="object 0 moving flag is 2"):
        decode_bundle(bytes(bad))
    assert not any(hasattr(o, "motion") or hasattr(o, "world_matrix") for o in decode_bundle(raw))
