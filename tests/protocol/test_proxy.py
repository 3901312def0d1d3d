import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pibr.protocol.errors import MalformedMessage
from pibr.protocol.messages import ProxyChunk
from pibr.protocol.proxy import (MAGIC, MAX_CHUNKS, MIN_CHUNK_BYTES, BundleAssembler, BundleInfo, ProxyObject,
                                 compress_bundle, decode_bundle, decompress_bundle, encode_bundle, split_chunks)


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
    raw = encode_bundle(objs)
    back = decode_bundle(decompress_bundle(compress_bundle(raw), len(raw), objects=2))
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


def _zeros_frame(prefix: bytes, size: int, content_size: bool, window_log: int = 20) -> bytes:
    """A small zstd frame that inflates to ``prefix`` + zeros, ``size`` bytes in all, built
    without ever holding the inflated bytes."""
    import zstandard

    params = zstandard.ZstdCompressionParameters.from_level(1, window_log=window_log,
                                                            write_content_size=content_size)
    cobj = zstandard.ZstdCompressor(compression_params=params).compressobj(size=size if content_size else -1)
    parts = [cobj.compress(prefix)]
    zeros = bytes(1 << 20)
    left = size - len(prefix)
    while left > 0:
        parts.append(cobj.compress(zeros[:min(left, len(zeros))]))
        left -= len(zeros)
    parts.append(cobj.flush())
    return b"".join(parts)


def _peak_bytes(fn):
    """fn() -> (its exception, the peak of Python allocations while it ran)."""
    import tracemalloc

    tracemalloc.start()
    try:
        fn()
    except MalformedMessage as exc:
        error = exc
    else:
        error = None
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return error, peak


def test_gigabyte_bomb_is_refused_from_its_header():
    """The 32,789-byte frame of 1 GiB of zeros (issue 13, defect 5): its header declares more
    than the announced size, so nothing is inflated."""
    bomb = _zeros_frame(b"", 1 << 30, content_size=True)
    assert len(bomb) < 33_000
    error, peak = _peak_bytes(lambda: decompress_bundle(bomb, 870))
    assert error is not None and "declares 1073741824 bytes uncompressed, the Welcome announced 870" in str(error)
    assert peak < 1 << 20


@pytest.mark.parametrize("prefix, match", [
    (b"", "bad magic"),                                     # zeros: wrong from the first bytes
    (MAGIC + (5).to_bytes(4, "little"), "holds 5 objects, the Welcome announced 2"),
    (MAGIC + (2).to_bytes(4, "little"), "more than the 2097152 bytes"),   # a valid start, then too much
])
def test_bombs_without_a_declared_size_stop_at_the_announced_size(prefix, match):
    bomb = _zeros_frame(prefix, 256 << 20, content_size=False)
    error, peak = _peak_bytes(lambda: decompress_bundle(bomb, 2 << 20, objects=2))
    assert error is not None and match in str(error), error
    assert peak < (2 << 20) + (3 << 20)     # the announced 2 MiB and one decompression step, never 256 MiB


def test_a_window_larger_than_the_announced_bundle_is_refused():
    bomb = _zeros_frame(MAGIC, 16 << 20, content_size=False, window_log=23)
    with pytest.raises(MalformedMessage, match="8388608-byte window, more than the 2097152 bytes"):
        decompress_bundle(bomb, 2 << 20)


def test_short_output_is_refused():
    import zstandard

    raw = encode_bundle(_objects())
    frame = zstandard.ZstdCompressor(write_content_size=False).compress(raw)
    with pytest.raises(MalformedMessage, match=f"decompresses to {len(raw)} bytes, the Welcome announced"):
        decompress_bundle(frame, len(raw) + 100)


def _info(data: bytes, chunk_bytes: int = MIN_CHUNK_BYTES) -> BundleInfo:
    return BundleInfo(2, len(data), 870, chunk_bytes, {})


def test_assembler_accepts_the_announced_chunks_in_any_order():
    data = bytes(range(256)) * 9                      # 2304 bytes: chunks of 1024, 1024, 256
    info = _info(data)
    parts = split_chunks(data, info.chunk_bytes)
    assert info.chunks == len(parts) == 3
    a = BundleAssembler(info)
    for i in (2, 0, 1):
        assert not a.complete
        a.add(ProxyChunk(i, 3, len(data), parts[i]))
    assert a.complete and a.data() == data


@pytest.mark.parametrize("chunk, match", [
    (ProxyChunk(0, (1 << 32) - 1, 2304, b""), "count 4294967295 differs from the 3 chunks"),
    (ProxyChunk(0, 3, 1 << 30, b"x" * 1024), "total size 1073741824 differs from the 2304 bytes"),
    (ProxyChunk(1, 3, 2304, b""), "chunk 1 is empty"),
    (ProxyChunk(2, 3, 2304, b"x" * 1024), "chunk 2 carries 1024 bytes, the announcement implies 256"),
    (ProxyChunk(0, 3, 2304, b"x" * 1025), "chunk 0 carries 1025 bytes, the announcement implies 1024"),
    (ProxyChunk(3, 3, 2304, b"x"), "index 3 is outside 0..2"),
])
def test_assembler_refuses_chunks_the_announcement_does_not_allow(chunk, match):
    with pytest.raises(MalformedMessage, match=match):
        BundleAssembler(_info(bytes(2304))).add(chunk)


def test_assembler_refuses_a_chunk_twice_and_data_before_completion():
    a = BundleAssembler(_info(bytes(2304)))
    a.add(ProxyChunk(0, 3, 2304, bytes(1024)))
    with pytest.raises(MalformedMessage, match="chunk 0 arrived twice"):
        a.add(ProxyChunk(0, 3, 2304, bytes(1024)))
    with pytest.raises(MalformedMessage, match="1 of 3 chunks received"):
        a.data()


def test_the_announcement_bounds_the_chunk_count():
    """40,000 chunks of one byte, or 2**32-1 chunks, cannot be announced (issue 13, defect 6)."""
    good = BundleInfo(1, 40_000, 870, MIN_CHUNK_BYTES, {}).to_json()
    assert BundleInfo.from_json(good).chunks == 40
    for change, match in [({"chunk_bytes": 1, "chunks": 40_000}, "'chunk_bytes' = 1 is outside"),
                          ({"chunks": (1 << 32) - 1}, "'chunks' = 4294967295 is outside"),
                          ({"chunks": 41}, "41 chunks do not carry 40000 bytes"),
                          ({"raw_bytes": 1 << 40}, "'raw_bytes' = 1099511627776 is outside"),
                          ({"bytes": 0}, "'bytes' = 0 is outside"),
                          ({"objects": 10 ** 9}, "'objects' = 1000000000 is outside"),
                          ({"raw_bytes": 1e3}, "'raw_bytes' must be an integer")]:
        with pytest.raises(MalformedMessage, match=match):
            BundleInfo.from_json(good | change)
    with pytest.raises(ValueError, match=f"more than the limit of {MAX_CHUNKS}"):
        BundleInfo(1, (MAX_CHUNKS + 1) * MIN_CHUNK_BYTES, 870, MIN_CHUNK_BYTES, {})


def test_welcome_config_validates_the_proxy_announcement():
    from pibr.protocol.atlas import build_layout
    from pibr.protocol.session import SessionConfig, ViewConfig

    cfg = SessionConfig(scene={"name": "t", "near": 0.1, "far": 100.0, "viewer_origin": [0, 1.6, 0, 1, 0, 0, 0]},
                        clock="virtual", server_fps=10.0, server_delay_us=20_000, primary=ViewConfig(64, 64),
                        extra=None, extra_offset=None, atlas=build_layout((64, 64), None, True),
                        video_bitrate_kbps=1000.0, keyint=30).to_json()
    cfg["proxies"] = BundleInfo(1, 40_000, 870, MIN_CHUNK_BYTES, {"proxy": 12}).to_json()
    assert SessionConfig.from_json(cfg).proxies["chunks"] == 40
    cfg["proxies"]["chunks"] = (1 << 32) - 1
    with pytest.raises(MalformedMessage, match="Welcome.config.proxies: field 'chunks'"):
        SessionConfig.from_json(cfg)


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


def test_a_large_bundle_is_held_once_while_decompressed_and_decoded():
    """Issue 28: a bundle near the size cap made the client hold it two to three times (the raw
    buffer copied to bytes, each mesh sliced and copied again). Now the decompressed bytearray is
    the only allocation of its size and the meshes are views of it: peak at most the raw size plus
    a quarter (one mesh's finiteness check)."""
    import struct
    import tracemalloc

    import zstandard

    from pibr.protocol.proxy import MAGIC, decode_bundle, decompress_bundle, split_chunks

    n = 8_000_000                      # vertices and faces of one mesh: 192 MB of zeros
    head = (MAGIC + struct.pack("<I", 1) + struct.pack("<H", 3) + b"big" + bytes(128) + b"\0" + bytes(48)
            + struct.pack("<II", n, n))
    tail = struct.pack("<II", 3, 1) + bytes(36) + bytes(12)      # the proxy: one degenerate triangle
    raw_size = len(head) + 24 * n + len(tail)
    cobj = zstandard.ZstdCompressor(level=1).compressobj(size=raw_size)
    zeros = bytes(1 << 20)
    parts = [cobj.compress(head)]
    left = 24 * n
    while left:
        parts.append(cobj.compress(zeros[:min(left, len(zeros))]))
        left -= min(left, len(zeros))
    parts += [cobj.compress(tail), cobj.flush()]
    chunks = split_chunks(b"".join(parts), 16 << 10)
    del parts, zeros
    tracemalloc.start()
    try:
        objects = decode_bundle(decompress_bundle(chunks, raw_size, 1))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    v, f = objects[0].original
    assert v.shape == (n, 3) and f.shape == (n, 3) and not v.any()
    assert objects[0].proxy[0].shape == (3, 3)
    assert peak < raw_size * 1.25, (peak, raw_size)
