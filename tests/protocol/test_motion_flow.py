"""The MOTION_FLOW payload: both flow coders' bitstreams (golden bytes), the cost of a frame in
which nothing moves, flow at the quantiser's limits, and a decoder that raises CodecError and
nothing else on bad input."""
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pibr.protocol.edgecodec.flow import decode_flow_edges, flow_codes, select_flow_edges
from pibr.protocol.edgecodec.motion import MAX_MOTION
from pibr.protocol.errors import CodecError
from pibr.protocol.motion_flow import FLOW_CODERS, HEAD_BYTES, decode_motion_flow, encode_motion_flow

from .codec_fuzz import decode_or_codec_error
from .golden_motion_flow import GOLDEN_DIR, HEIGHT, NAMES, WIDTH, golden_payload, moving_field

FUZZ = settings(max_examples=200, deadline=2000, suppress_health_check=[HealthCheck.too_slow], derandomize=True)


def quantisation_bound(v, scale=8):
    """The documented error of a flow component v (pixels, |v| <= MAX_MOTION) after quantization."""
    return np.sqrt(np.abs(np.asarray(v, np.float64))) / scale + 1.0 / (4 * scale * scale)


@pytest.mark.parametrize("name", NAMES)
def test_golden_payloads(name):
    with open(os.path.join(GOLDEN_DIR, f"{name}.bin"), "rb") as f:
        golden = f.read()
    assert golden_payload(name) == golden, \
        f"{name}: bitstream changed (regenerate with python -m tests.protocol.golden_motion_flow)"
    parsed = decode_motion_flow(golden, WIDTH, HEIGHT)
    flow, moving = moving_field()
    if name == "motion_flow_blocks":
        got_flow, got_moving = parsed.dense
        np.testing.assert_array_equal(got_moving, moving)
        assert np.all(got_flow[~moving] == 0)
    elif name == "motion_flow_edges":
        s = parsed.samples
        codes = flow_codes(flow, moving, 8)
        np.testing.assert_array_equal(s.edges, select_flow_edges(*codes, moving))
        # lossless values: every sample holds the quantized flow exactly
        for k in range(2):
            expected = np.sign(codes[k]) * (codes[k] / 8.0) ** 2
            np.testing.assert_allclose(s.flow[..., k][s.valid], expected[s.valid], rtol=1e-6)
    else:
        assert parsed.coder == "none" and not parsed.dense[1].any()


@pytest.mark.parametrize("coder", FLOW_CODERS)
def test_the_decoder_sees_what_the_encoder_says(coder):
    flow, moving = moving_field()
    payload, seen = encode_motion_flow(flow, moving, coder)
    parsed = decode_motion_flow(payload, WIDTH, HEIGHT)
    assert parsed.coder == coder
    if coder == "blocks":
        for a, b in zip(seen.dense, parsed.dense):
            np.testing.assert_array_equal(a, b)
    else:
        for field in ("edges", "valid", "flow", "signs"):
            np.testing.assert_array_equal(getattr(seen.samples, field), getattr(parsed.samples, field))


def test_edge_samples_keep_both_sides_of_every_outline():
    """Pajak et al.'s two-pixel edges: a moving pixel beside a static one, and that static pixel,
    are both samples, however slowly the object moves."""
    flow, moving = moving_field()
    slow = flow * 1e-3
    codes = flow_codes(slow, moving, 8)
    edges = select_flow_edges(*codes, moving)
    outline = np.zeros_like(moving)
    outline[:-1] |= moving[:-1] != moving[1:]
    outline[1:] |= moving[:-1] != moving[1:]
    outline[:, :-1] |= moving[:, :-1] != moving[:, 1:]
    outline[:, 1:] |= moving[:, :-1] != moving[:, 1:]
    assert outline.any() and np.all(edges[outline])


@pytest.mark.parametrize("coder", FLOW_CODERS)
def test_a_frame_in_which_nothing_moves_costs_the_head_only(coder):
    h, w = 1024, 1024
    still = np.zeros((h, w), bool)
    payload, _ = encode_motion_flow(np.zeros((h, w, 2), np.float32), still, coder)
    assert len(payload) == HEAD_BYTES == 5
    # flow where nothing is flagged moving is no motion either
    payload2, _ = encode_motion_flow(np.full((h, w, 2), 3.0, np.float32), still, coder)
    assert payload2 == payload
    parsed = decode_motion_flow(payload, w, h)
    assert parsed.dense[0].shape == (h, w, 2) and not parsed.dense[0].any() and not parsed.dense[1].any()


@pytest.mark.parametrize("coder", FLOW_CODERS)
@pytest.mark.parametrize("v", [(MAX_MOTION, -MAX_MOTION), (-MAX_MOTION, 0.0), (1.0 / 256, -1.0 / 64),
                               (0.49, 17.3), (2.0 * MAX_MOTION, -5e6)])
def test_flow_at_the_quantisers_limits_round_trips_within_the_documented_error(coder, v):
    """A translating object's flow, from the smallest step to the largest flow and beyond (clamped):
    every sample (edges) or block (blocks) within sqrt|v| / s + 1 / (4 s^2) per component."""
    flow = np.zeros((HEIGHT, WIDTH, 2), np.float32)
    moving = np.zeros((HEIGHT, WIDTH), bool)
    moving[10:30, 12:40] = True
    flow[moving] = v
    payload, _ = encode_motion_flow(flow, moving, coder)
    parsed = decode_motion_flow(payload, WIDTH, HEIGHT)
    if coder == "blocks":
        got, got_moving = parsed.dense
        np.testing.assert_array_equal(got_moving, moving)
        inside = got[moving]
    else:
        inside = parsed.samples.flow[parsed.samples.valid & moving]
        assert len(inside) > 0
        assert np.all(parsed.samples.flow[parsed.samples.valid & ~moving] == 0)
    sent = np.clip(np.asarray(v, np.float32).astype(np.float64), -MAX_MOTION, MAX_MOTION)
    err = np.abs(inside.astype(np.float64) - sent)
    assert np.all(err <= quantisation_bound(sent) + 1e-6 * np.abs(sent)), (err.max(), quantisation_bound(sent))
    if abs(v[0]) >= MAX_MOTION:
        assert np.all(np.abs(inside[:, 0]) == MAX_MOTION)


def test_a_payload_for_another_view_size_is_refused():
    payload = golden_payload("motion_flow_blocks")
    with pytest.raises(CodecError, match=f"payload is {WIDTH}x{HEIGHT}, the primary view 32x48"):
        decode_motion_flow(payload, 32, HEIGHT)
    with pytest.raises(CodecError, match="unknown coder 9"):
        decode_motion_flow(b"\x09" + payload[1:], WIDTH, HEIGHT)
    with pytest.raises(CodecError, match="3 bytes after a head that says nothing moves"):
        decode_motion_flow(golden_payload("motion_flow_still") + b"abc", WIDTH, HEIGHT)
    with pytest.raises(CodecError, match="must be bytes"):
        decode_motion_flow("text", WIDTH, HEIGHT)


GOOD = {name: golden_payload(name) for name in ("motion_flow_blocks", "motion_flow_edges")}


def _only_codec_errors(payload):
    return decode_or_codec_error(lambda b: decode_motion_flow(b, WIDTH, HEIGHT), payload, "motion flow: ")


@FUZZ
@given(st.sampled_from(sorted(GOOD)), st.integers(min_value=0))
def test_truncated_payloads_raise_codec_error(name, cut):
    good = GOOD[name]
    with pytest.raises(CodecError, match="^motion flow: "):
        decode_motion_flow(good[:cut % len(good)], WIDTH, HEIGHT)


@FUZZ
@given(st.sampled_from(sorted(GOOD)), st.lists(st.integers(min_value=0), min_size=1, max_size=8))
def test_bit_flips_raise_only_codec_error(name, positions):
    data = bytearray(GOOD[name])
    for p in positions:
        p %= 8 * len(data)
        data[p // 8] ^= 1 << (p % 8)
    out = _only_codec_errors(bytes(data))
    if out is not None:   # what decodes is still a flow of the view
        flow = out.dense[0] if out.dense is not None else out.samples.flow
        assert flow.shape == (HEIGHT, WIDTH, 2) and np.all(np.isfinite(flow))


@FUZZ
@given(st.binary(min_size=0, max_size=300), st.sampled_from([0, 1, 2]))
def test_random_bytes_raise_only_codec_error(data, coder):
    head = bytes([coder]) + WIDTH.to_bytes(2, "little") + HEIGHT.to_bytes(2, "little")
    _only_codec_errors(head + data)
    _only_codec_errors(data)


def test_edge_section_lengths_are_checked_before_use():
    payload = bytearray(GOOD["motion_flow_edges"])
    # the edge image's length (after the u8 scale, spacing, q and the u32 count) claims far more than there is
    payload[HEAD_BYTES + 7:HEAD_BYTES + 11] = (10 ** 9).to_bytes(4, "little")
    with pytest.raises(CodecError, match="exceed the"):
        decode_motion_flow(bytes(payload), WIDTH, HEIGHT)
    with pytest.raises(CodecError, match="edge samples in a 64x48 view"):
        decode_flow_edges(bytes([8, 5, 1]) + (10 ** 6).to_bytes(4, "little") + bytes(12), HEIGHT, WIDTH)


def _numpy_block_means(motion, moving, block_log2):
    """The blocks coder's per-block mean motion as first written, in whole-frame numpy."""
    h, w = moving.shape
    s = 1 << block_log2
    bh, bw = -(-h // s), -(-w // s)
    mv = np.zeros((bh * s, bw * s, 2))
    mv[:h, :w] = np.where(moving[..., None], np.nan_to_num(np.asarray(motion, np.float64)), 0.0)
    cnt = np.zeros((bh * s, bw * s))
    cnt[:h, :w] = moving
    n = cnt.reshape(bh, s, bw, s).sum(axis=(1, 3))
    with np.errstate(over="ignore", invalid="ignore"):
        total = mv.reshape(bh, s, bw, s, 2).sum(axis=(1, 3))
    return total, n


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_block_sums_read_only_moving_pixels_as_the_whole_frame_numpy_did(dtype):
    from pibr.protocol.edgecodec.motion import _block_sums

    rng = np.random.default_rng(7)
    for k in range(12):
        h, w = (int(x) for x in rng.integers(1, 70, 2))
        motion = (rng.standard_normal((h, w, 2)) * 10.0 ** rng.uniform(-3, 3)).astype(dtype)
        moving = rng.random((h, w)) < rng.uniform(0.0, 1.0)
        motion[rng.random((h, w, 2)) < 0.05] = np.nan
        motion[rng.random((h, w, 2)) < 0.01] = np.inf
        motion[~moving & (rng.random((h, w)) < 0.5)] = 1e6   # static pixels' values never count
        for block_log2 in (3, 5):
            s = 1 << block_log2
            total = np.zeros((-(-h // s), -(-w // s), 2))
            n = np.zeros(total.shape[:2], np.int64)
            _block_sums(motion, moving, block_log2, total, n)
            want_total, want_n = _numpy_block_means(motion, moving, block_log2)
            np.testing.assert_array_equal(n, want_n)
            np.testing.assert_array_equal(total, want_total)


def test_the_server_gets_the_payload_without_the_decoded_flow():
    flow, moving = moving_field()
    for coder in FLOW_CODERS:
        payload, decoded = encode_motion_flow(flow, moving, coder)
        bare, none = encode_motion_flow(flow, moving, coder, decoded=False)
        assert bare == payload and none is None and decoded is not None
