"""The quadtree payload: golden bytes, round trips, strict decoding of hostile bytes, and the
Hello / Frame fields that carry it."""
from __future__ import annotations

import os
import struct
import tracemalloc

import numpy as np
import pytest
import zstandard
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pibr.protocol.errors import CodecError, MalformedMessage
from pibr.protocol.messages import MAX_QUADTREE_THRESHOLD, Frame, Hello, PayloadKind
from pibr.protocol.quadtree import (decode_quadtrees, encode_quadtrees, leaves_from_bits, max_body_size,
                                    max_split_bits, split_bits)

from .golden_messages import golden_bytes
from .golden_quadtree import GOLDEN_DIR, NAMES, golden_payload, golden_sizes, golden_views

FUZZ = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True)
TILES = (1, 2, 4, 8, 16, 32, 64)


def random_tree(width: int, height: int, tile: int, seed: int, p_split: float) -> np.ndarray:
    """Leaves (n, 3) in pre-order of a quadtree whose nodes split at random."""
    rng = np.random.default_rng(seed)
    out = []

    def visit(x, y, s):
        if x >= width or y >= height:
            return
        if s == 1 or rng.random() >= p_split:
            out.append((x, y, s))
            return
        h = s // 2
        for dy, dx in ((0, 0), (0, h), (h, 0), (h, h)):
            visit(x + dx, y + dy, h)

    for ty in range(0, height, tile):
        for tx in range(0, width, tile):
            visit(tx, ty, tile)
    return np.array(out, np.int32).reshape(-1, 3)


def _compress(body: bytes, **kw) -> bytes:
    return zstandard.ZstdCompressor(**kw).compress(body)


def _body(views) -> bytes:
    """The uncompressed payload of views (index, w, h, tile, nbits, packed bits bytes)."""
    parts = [struct.pack("<BB", 1, len(views))]
    for index, w, h, tile, nbits, packed in views:
        parts.append(struct.pack("<BHHHI", index, w, h, tile, nbits) + packed)
    return b"".join(parts)


# ------------------------------------------------------------------ golden bytes

@pytest.mark.parametrize("name", NAMES)
def test_encoder_reproduces_the_golden_payload(name):
    with open(os.path.join(GOLDEN_DIR, f"{name}.bin"), "rb") as f:
        golden = f.read()
    assert golden_payload(name) == golden, f"the quadtree bitstream of {name} changed"
    decoded = decode_quadtrees(golden, golden_sizes(name))
    for index, _, _, _, leaves in golden_views(name):
        np.testing.assert_array_equal(decoded[index], leaves)


def test_golden_clipped_view_has_clipped_leaves():
    (_, w, h, tile, leaves), = golden_views("quadtree_clipped")
    assert (w % tile, h % tile) != (0, 0)
    reach = (leaves[:, 0] + leaves[:, 2] > w) | (leaves[:, 1] + leaves[:, 2] > h)
    assert reach.any()                          # leaves reaching past the image's edge exist
    cover = np.zeros((h, w), int)
    for x, y, s in leaves:
        cover[y:y + s, x:x + s] += 1
    assert (cover == 1).all()                   # and they tile the image exactly


# ------------------------------------------------------------------ round trips

@FUZZ
@given(st.integers(1, 90), st.integers(1, 90), st.sampled_from(TILES), st.integers(0, 2 ** 32 - 1),
       st.floats(0.0, 1.0))
def test_round_trip_of_random_trees(width, height, tile, seed, p_split):
    leaves = random_tree(width, height, tile, seed, p_split)
    bits = split_bits(leaves, width, height, tile)
    assert len(bits) <= max_split_bits(width, height, tile)
    np.testing.assert_array_equal(leaves_from_bits(bits, width, height, tile), leaves)
    data = encode_quadtrees([(0, width, height, tile, leaves)])
    np.testing.assert_array_equal(decode_quadtrees(data, [(width, height)])[0], leaves)


@FUZZ
@given(st.integers(1, 60), st.integers(1, 60), st.sampled_from(TILES), st.sampled_from(TILES), st.integers(0, 999))
def test_two_views_round_trip_in_any_order(w, h, tile0, tile1, seed):
    a = random_tree(w, h, tile0, seed, 0.6)
    b = random_tree(max(w // 2, 1), max(h // 2, 1), tile1, seed + 1, 0.6)
    views = [(1, max(w // 2, 1), max(h // 2, 1), tile1, b), (0, w, h, tile0, a)]
    out = decode_quadtrees(encode_quadtrees(views), [(w, h), (max(w // 2, 1), max(h // 2, 1))])
    np.testing.assert_array_equal(out[0], a)
    np.testing.assert_array_equal(out[1], b)


def test_extreme_trees():
    # One leaf per tile (a constant image) carries one 0 bit per tile; all-pixel trees carry
    # only 1s; a 1-pixel tile carries no bits at all.
    w, h = 130, 70
    tiles = [(x, y, 64) for y in range(0, h, 64) for x in range(0, w, 64)]
    assert split_bits(np.array(tiles), w, h, 64).tolist() == [0] * 6
    pixels = random_tree(w, h, 8, 0, 1.0)
    assert len(pixels) == w * h and (pixels[:, 2] == 1).all()
    bits = split_bits(pixels, w, h, 8)
    assert bits.all() and len(bits) == max_split_bits(w, h, 8)
    assert len(split_bits(random_tree(5, 3, 1, 0, 1.0), 5, 3, 1)) == 0


@pytest.mark.parametrize("leaves, problem", [
    ([(0, 0, 4), (4, 0, 4)], "gap"),                       # the bottom half is missing
    ([(0, 0, 8), (0, 0, 4)], "twice"),
    ([(0, 0, 8), (4, 4, 4)], "overlap"),
    ([(2, 0, 4)], "not a quadtree node"),                 # misaligned
    ([(0, 0, 3)], "not a quadtree node"),                 # not a power of two
    ([(0, 0, 16)], "not a quadtree node"),                # larger than the tile
    ([(8, 0, 1)], "not a quadtree node"),                 # outside the image
])
def test_encoder_rejects_leaves_that_are_no_quadtree(leaves, problem):
    with pytest.raises(ValueError, match=problem):
        split_bits(np.array(leaves), 8, 8, 8)


# ------------------------------------------------------------------ hostile bytes

SIZES = [(40, 24), (20, 12)]
GOOD = golden_payload("quadtree_two_views")


def _decode_or_codec_error(data, sizes=SIZES):
    try:
        out = decode_quadtrees(data, sizes)
    except CodecError:
        return None
    for (w, h), leaves in zip(sizes, out):     # whatever decodes is a tree of the announced size
        cover = np.zeros((h, w), int)
        for x, y, s in leaves:
            cover[y:y + s, x:x + s] += 1
        assert (cover == 1).all()
    return out


@FUZZ
@given(st.binary(max_size=300))
def test_arbitrary_bytes_raise_only_codec_error(data):
    _decode_or_codec_error(data)


@FUZZ
@given(st.binary(max_size=300))
def test_arbitrary_bodies_raise_only_codec_error(body):
    _decode_or_codec_error(_compress(body))


@FUZZ
@given(st.integers(0, 10_000), st.integers(0, 7), st.integers(0, 100))
def test_bit_flips_and_truncations_of_a_valid_body(pos, bit, cut):
    body = bytearray(zstandard.ZstdDecompressor().decompress(GOOD))
    body[pos % len(body)] ^= 1 << bit
    _decode_or_codec_error(_compress(bytes(body)))
    _decode_or_codec_error(_compress(bytes(body[:max(len(body) - cut, 0)])))
    _decode_or_codec_error(GOOD[:max(len(GOOD) - cut - 1, 0)])


def _one_view(nbits, packed, w=8, h=8, tile=8, index=0):
    return _compress(_body([(index, w, h, tile, nbits, packed)]))


@pytest.mark.parametrize("data, sizes, message", [
    (b"", [(8, 8)], "not a zstd frame"),
    (GOOD[:6] + bytes(b ^ 0x5A for b in GOOD[6:]), SIZES, "quadtree: zstd: .*corruption"),
    (GOOD[:-3], SIZES, "quadtree: zstd: "),
    (_compress(b"\x01\x01", write_content_size=False), [(8, 8)], "does not state its content size"),
    (_compress(bytes(1 << 20)), [(8, 8)], "exceed"),
    (GOOD + b"\x00", SIZES, "after the zstd frame"),
    (_compress(b"\x01"), [(8, 8)], "shorter than"),
    (_compress(b"\x02\x01"), [(8, 8)], "version 2"),
    (_compress(b"\x01\x02"), [(8, 8)], "2 views in the payload, the session has 1"),
    (_compress(b"\x01\x01\x00"), [(8, 8)], "header is truncated"),
    (_one_view(1, b"\x00", index=1), [(8, 8)], "view index 1"),
    (_one_view(1, b"\x00", w=9), [(8, 8)], "9x8, the session announced 8x8"),
    (_one_view(1, b"\x00", tile=6), [(8, 8)], "not a power of two"),
    (_one_view(1, b"\x00", tile=8192), [(8, 8)], "not a power of two"),
    (_one_view(22, b"\xff\xff\xfc"), [(8, 8)], "at most 21"),
    (_one_view(9, b"\x00"), [(8, 8)], "truncated"),
    (_one_view(1, b"\x01"), [(8, 8)], "padding bits"),
    (_one_view(1, b"\x80"), [(8, 8)], "run out"),                 # split, then nothing for the children
    (_one_view(2, b"\x00"), [(8, 8)], "left over"),
    (_one_view(1, b"\x00"), [(8, 8), (4, 4)], "1 views in the payload, the session has 2"),
    (_compress(_body([(0, 8, 8, 8, 1, b"\x00"), (0, 8, 8, 8, 1, b"\x00")])), [(8, 8), (8, 8)], "appears twice"),
    (_compress(_body([(0, 8, 8, 8, 1, b"\x00")]) + b"\x00"), [(8, 8)], "1 bytes after the last view"),
])
def test_bad_payloads_name_the_problem(data, sizes, message):
    with pytest.raises(CodecError, match=message):
        decode_quadtrees(data, sizes)


def test_a_small_bomb_is_refused_before_it_is_inflated():
    bomb = _compress(bytes(64 << 20))          # 64 MB of zeros in a few kB
    assert len(bomb) < 10_000
    tracemalloc.start()
    try:
        with pytest.raises(CodecError, match="exceed"):
            decode_quadtrees(bomb, [(1024, 1024), (512, 512)])
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 1 << 20
    assert max_body_size([(1024, 1024), (512, 512)]) < 64 << 10   # what the largest honest payload may hold


# ------------------------------------------------------------------ messages

def test_hello_asks_for_a_quadtree():
    hello = Hello(client="t", quadtree_threshold=0.025)
    payload = hello.serialize()
    assert b'"quadtree_threshold":0.025' in payload
    assert Hello.parse(payload) == hello
    assert Hello.parse(Hello(client="t").serialize()).quadtree_threshold == 0.0
    # The default leaves the field out: older Hello bytes stay the same.
    assert b"quadtree" not in Hello(client="t").serialize()
    assert b"quadtree" not in golden_bytes("hello")


@pytest.mark.parametrize("value, message", [
    ("-0.1", "outside"), (str(MAX_QUADTREE_THRESHOLD * 2), "outside"), ('"0.1"', "must be float"),
    ("true", "must be float"), ("null", "must be float"),
])
def test_hello_rejects_bad_thresholds(value, message):
    with pytest.raises(MalformedMessage, match=f"Hello: field 'quadtree_threshold'.*{message}"):
        Hello.parse(b'{"protocol": 1, "quadtree_threshold": ' + value.encode() + b"}")


def test_frame_carries_a_quadtree_payload():
    from pibr.protocol.pose import Pose

    frame = Frame(0, 0, 0, 0, 0, Pose.identity(), None, 0.1, 100.0,
                  payloads=((PayloadKind.H264_ATLAS, b"x"), (PayloadKind.QUADTREE, GOOD)))
    parsed = Frame.parse(frame.serialize())
    assert parsed.payload(PayloadKind.QUADTREE) == GOOD
    assert PayloadKind.NAMES[PayloadKind.QUADTREE] == "quadtree"
