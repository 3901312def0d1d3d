"""The edge codec: arithmetic coder (reference vs numba), edge image, values, bitstream, robustness."""
from __future__ import annotations

import hashlib
import os
import struct
import subprocess
import sys
import tracemalloc

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pibr.protocol.depth import DepthQuantizer
from pibr.protocol.edgecodec import arith, bitstream
from pibr.protocol.edgecodec.codec import (DecodedSamples, EdgeDecoder, EdgeEncoder, laplacian, select_edges,
                                           warp_samples)
from pibr.protocol.edgecodec.edges import decode_edge_image, encode_edge_image, temporal_context
from pibr.protocol.edgecodec.motion import dequantize_motion, quantize_motion
from pibr.protocol.edgecodec.regular import nearest_index, sample_positions
from pibr.protocol.errors import CodecError
from pibr.protocol.pose import Pose, quat_from_axis_angle

from . import arith_reference as arith_ref
from . import edgecodec_reference
from .codec_fuzz import decode_or_codec_error
from .golden_edge import (GOLDEN_DIR, cluttered_codes, HEIGHT, NAMES, POSE, QUANTIZER, WIDTH, golden_payload, piecewise_planar,
                          piecewise_planar_codes)

FUZZ = settings(max_examples=300, deadline=2000, suppress_health_check=[HealthCheck.too_slow],
                derandomize=True)


# ------------------------------------------------------------------------------------------
# Arithmetic coder
# ------------------------------------------------------------------------------------------

def _random_ops(seed: int, n: int):
    rng = np.random.default_rng(seed)
    n_slots = 8
    kinds = rng.choice(4, size=n, p=[0.6, 0.1, 0.15, 0.15])
    bit_ctx = rng.integers(0, 40, n)
    slot = rng.integers(0, n_slots, n) * arith.INT_SLOT + 40
    ctxs = np.where(kinds == arith_ref.OP_BIT, bit_ctx, slot)
    skew = rng.random(n) < rng.choice([0.02, 0.3, 0.5], n)
    mags = np.minimum(rng.geometric(rng.choice([0.5, 0.05, 0.001], n)) - 1, (1 << (arith.KMAX + 1)) - 2)
    values = np.where(kinds <= arith_ref.OP_RAW, skew.astype(np.int64), mags)
    values = np.where(kinds == arith_ref.OP_SINT, values * rng.choice([-1, 1], n), values)
    return kinds, ctxs, values, 40 + n_slots * arith.INT_SLOT


@pytest.mark.parametrize("seed", range(6))
def test_reference_and_numba_coders_give_identical_bytes(seed):
    kinds, ctxs, values, n_ctx = _random_ops(seed, 3000 + 1000 * seed)
    ref = arith_ref.encode_ops_python(kinds, ctxs, values, n_ctx)
    fast = arith_ref.encode_ops_numba(kinds, ctxs, values, n_ctx)
    assert ref == fast
    for decode in (arith_ref.decode_ops_python, arith_ref.decode_ops_numba):
        out, ok = decode(ref, kinds, ctxs, n_ctx)
        assert ok
        np.testing.assert_array_equal(out, values)


def test_integer_extremes_round_trip():
    top = (1 << (arith.KMAX + 1)) - 1
    values = np.array([0, 1, 2, top - 1, top, 0, -top, top, -1, 1 << 16, -(1 << 16)], dtype=np.int64)
    kinds = np.where(values < 0, arith_ref.OP_SINT, np.array([arith_ref.OP_UINT, arith_ref.OP_SINT] * 6)[:len(values)])
    ctxs = np.zeros(len(values), dtype=np.int64)
    data = arith_ref.encode_ops_numba(kinds, ctxs, values, arith.INT_SLOT)
    assert data == arith_ref.encode_ops_python(kinds, ctxs, values, arith.INT_SLOT)
    out, ok = arith_ref.decode_ops_numba(data, kinds, ctxs, arith.INT_SLOT)
    assert ok
    np.testing.assert_array_equal(out, values)


def test_long_runs_drive_probabilities_to_their_limits():
    n = 1_000_000
    ctxs = np.zeros(n, dtype=np.int64)
    for fill in (0, 1):
        bits = np.full(n, fill, dtype=np.uint8)
        bits[n // 2] = 1 - fill  # one surprise at the floor probability, then the run goes on
        data = arith_ref.encode_bits_numba(bits, ctxs, 1)
        assert len(data) < 40  # ~1e-4 bit per certain symbol, ~15 bits for the surprise
        out, ok = arith_ref.decode_bits_numba(data, ctxs, 1)
        assert ok
        np.testing.assert_array_equal(out, bits)
    short = np.zeros(20000, dtype=np.uint8)
    assert arith_ref.encode_bits_python(short, ctxs[:20000], 1) == arith_ref.encode_bits_numba(short, ctxs[:20000], 1)


def test_models_with_priors_agree():
    rng = np.random.default_rng(7)
    prior = rng.random(16)
    bits = (rng.random(5000) < 0.2).astype(np.uint8)
    ctxs = rng.integers(0, 16, 5000)
    enc, model = arith_ref.RangeEncoder(), arith_ref.AdaptiveBitModel.from_state(arith.new_model(16, prior, 3))
    for b, c in zip(bits.tolist(), ctxs.tolist()):
        arith_ref.encode_bit(enc, model, c, b)
    buf = np.zeros(4096, np.uint8)
    es = arith_ref._encode_bits_kernel(buf, arith.new_model(16, prior, 3), arith.RATE_SHIFT, bits,
                                       ctxs.astype(np.int64))
    assert enc.finish() == arith.encoder_bytes(es, buf)


def test_model_probability_stays_within_coder_range():
    m = arith_ref.AdaptiveBitModel(2)
    for _ in range(5000):
        m.update(0, 1)
        m.update(1, 0)
    assert m.p1(0) == 32767 or 32700 < m.p1(0) <= 32767
    assert 1 <= m.p1(1) < 10


def test_empty_stream_is_empty_and_decodes():
    assert arith_ref.encode_ops_python(np.zeros(0, int), np.zeros(0, int), np.zeros(0, int), 1) == b""
    out, ok = arith_ref.decode_ops_numba(b"", np.zeros(0, int), np.zeros(0, int), 1)
    assert ok and len(out) == 0


@FUZZ
@given(st.binary(max_size=64))
def test_decoder_on_random_bytes_is_bounded(data):
    kinds = np.full(500, arith_ref.OP_SINT)
    ctxs = np.zeros(500, dtype=np.int64)
    out, ok = arith_ref.decode_ops_numba(data, kinds, ctxs, arith.INT_SLOT)
    assert np.all(np.abs(out) < (1 << (arith.KMAX + 1)))
    ref, ok_ref = arith_ref.decode_ops_python(data, kinds, ctxs, arith.INT_SLOT)
    np.testing.assert_array_equal(out, ref)
    assert ok == ok_ref


# ------------------------------------------------------------------------------------------
# Edge image
# ------------------------------------------------------------------------------------------

def _masks():
    rng = np.random.default_rng(3)
    yield "none", np.zeros((40, 50), bool)
    yield "all", np.ones((40, 50), bool)
    one = np.zeros((31, 29), bool)
    one[17, 11] = True
    yield "single", one
    yield "1x1", np.ones((1, 1), bool)
    yield "1xn", rng.random((1, 37)) < 0.3
    yield "nx1", rng.random((23, 1)) < 0.3
    yield "odd", rng.random((33, 17)) < 0.2
    yield "lines", select_edges(piecewise_planar_codes(61, 93))[0]


@pytest.mark.parametrize("four", [True, False])
def test_edge_image_round_trips_losslessly(four):
    for name, mask in _masks():
        h, w = mask.shape
        for prev in (None, np.roll(mask, 1, axis=1)):
            tctx = temporal_context(prev, h, w)
            data = encode_edge_image(mask, tctx, four)
            out, ok = decode_edge_image(data, h, w, tctx, four)
            assert ok, name
            np.testing.assert_array_equal(out, mask, err_msg=name)


@FUZZ
@given(h=st.integers(1, 41), w=st.integers(1, 41), density=st.sampled_from([0.0, 0.002, 0.05, 0.5, 1.0]),
       four=st.booleans(), temporal=st.sampled_from(["none", "same", "shifted", "random"]),
       block_log2=st.integers(2, 5), seed=st.integers(0, 2**32 - 1))
def test_edge_image_property_round_trip(h, w, density, four, temporal, block_log2, seed):
    """Any mask, any size (block multiples or not), any temporal context: decoded exactly, cleanly."""
    rng = np.random.default_rng(seed)
    mask = rng.random((h, w)) < density
    prev = {"none": None, "same": mask, "shifted": np.roll(mask, (1, -2), axis=(0, 1)),
            "random": rng.random((h, w)) < 0.1}[temporal]
    tctx = None if prev is None else temporal_context(prev, h, w)
    data = encode_edge_image(mask, tctx, four, block_log2)
    out, ok = decode_edge_image(data, h, w, tctx, four, block_log2)
    assert ok
    np.testing.assert_array_equal(out, mask)


def test_occupancy_map_spends_bits_only_on_occupied_blocks():
    """Edges in one 8 x 8 block of a large image: the rest is one cheap occupancy symbol per block."""
    one_block = np.zeros((512, 512), bool)
    one_block[200:206, 203] = True
    spread = np.zeros((512, 512), bool)
    spread[::64, 203] = True  # as many edges, in 8 blocks
    assert len(encode_edge_image(one_block)) < len(encode_edge_image(spread))
    assert len(encode_edge_image(one_block)) < 30
    out, ok = decode_edge_image(encode_edge_image(one_block), 512, 512)
    assert ok and np.array_equal(out, one_block)


def _hand_coded_edge_image(h, w, occ, pixel_on):
    """Four-pass stream (intra, 8 x 8 blocks) of occupancy ``occ`` whose occupied pixels are 0
    except ``pixel_on`` (y, x) or None, coded with the reference coder."""
    from pibr.protocol.edgecodec import edges as edge_module

    tctx = temporal_context(None, h, w)
    model = arith_ref.AdaptiveBitModel.from_state(edge_module._model(True))
    enc = arith_ref.RangeEncoder()
    tmax = np.zeros(occ.shape, np.uint8)  # the largest temporal context per block
    edge_module.block_maps(tctx, tctx, h, w, 3, None, tmax)
    for by in range(occ.shape[0]):
        for bx in range(occ.shape[1]):
            c = edge_module._block_ctx(occ, tmax, by, bx, edge_module._occ_offset(True))
            arith_ref.encode_bit(enc, model, c, int(occ[by, bx]))
    pad = edge_module.PAD
    img = np.zeros((h + 2 * pad, w + 2 * pad), np.uint8)
    for phase, (py, px) in enumerate(edgecodec_reference.PASS_PHASES):
        for y in range(py, h, 2):
            for x in range(px, w, 2):
                if occ[y >> 3, x >> 3]:
                    bit = int((y, x) == pixel_on)
                    c = edgecodec_reference.ctx_pass(img, tctx, phase, pad + y, pad + x, True)
                    arith_ref.encode_bit(enc, model, c, bit)
                    img[pad + y, pad + x] = bit
    return enc.finish()


def test_decoder_rejects_an_occupied_block_without_edges():
    """A stream that marks a block occupied and then codes it empty was not written by the encoder."""
    occ = np.zeros((2, 2), np.uint8)
    occ[0, 1] = 1
    out, ok = decode_edge_image(_hand_coded_edge_image(16, 16, occ, (3, 12)), 16, 16)
    assert ok and out.sum() == 1 and out[3, 12]  # the hand-made stream is a valid one ...
    assert _hand_coded_edge_image(16, 16, occ, (3, 12)) == encode_edge_image(out)
    out, ok = decode_edge_image(_hand_coded_edge_image(16, 16, occ, None), 16, 16)
    assert not ok  # ... until its occupied block holds no edge


def test_edge_image_extremes_cost_almost_nothing():
    for fill in (False, True):
        mask = np.full((512, 512), fill)
        assert len(encode_edge_image(mask)) < 40


def test_temporal_context_makes_an_unchanged_edge_image_cheap():
    mask = select_edges(cluttered_codes(192, 256))[0]
    intra = len(encode_edge_image(mask))
    inter = len(encode_edge_image(mask, temporal_context(mask, *mask.shape)))
    assert inter < 0.25 * intra


# ------------------------------------------------------------------------------------------
# Codec round trips
# ------------------------------------------------------------------------------------------

def _round_trip(distance, quantizer=QUANTIZER, **kw):
    h, w = distance.shape
    enc = EdgeEncoder(w, h, quantizer.bits, quantizer, **kw)
    out = enc.encode(distance)
    dec = EdgeDecoder(w, h, quantizer.bits, quantizer).decode(out.payload)
    for name in ("edges", "signs", "codes", "valid", "regular"):
        np.testing.assert_array_equal(getattr(dec, name), getattr(out.samples, name), err_msg=name)
    return enc.codes(distance), out, dec


def _assert_lossless(codes, dec: DecodedSamples):
    np.testing.assert_array_equal(dec.codes[dec.valid], codes[dec.valid])
    lap = laplacian(codes)
    np.testing.assert_array_equal(dec.signs[dec.edges], np.where(lap[dec.edges] > 0, 1, -1))


@pytest.mark.parametrize("shape", [(48, 64), (17, 33), (33, 17), (1, 1), (1, 40), (40, 1), (2, 2), (65, 97)])
@pytest.mark.parametrize("passes", [4, 1])
def test_lossless_round_trip(shape, passes):
    distance = piecewise_planar(*shape)
    codes, out, dec = _round_trip(distance, passes=passes)
    _assert_lossless(codes, dec)
    assert out.stats.total_bytes == len(out.payload)
    assert out.stats.n_edges == int(dec.edges.sum())


def test_numerical_extremes():
    q = QUANTIZER
    h, w = 24, 40
    cases = {
        "constant": np.full((h, w), 3.0, np.float32),
        "all sky": np.zeros((h, w), np.float32),
        "near sphere": np.full((h, w), q.near, np.float32),
        "beyond far is sky": np.full((h, w), 2 * q.far, np.float32),
        "near and sky checker": np.where((np.indices((h, w)).sum(0) % 2) == 0, q.near, 0.0).astype(np.float32),
        "nan and inf": np.where(np.arange(w) % 3 == 0, np.nan, np.where(np.arange(w) % 3 == 1, np.inf, 5.0))
        * np.ones((h, 1), np.float32),
    }
    for name, distance in cases.items():
        codes, out, dec = _round_trip(distance)
        _assert_lossless(codes, dec)
        if name == "constant":
            assert out.stats.n_edges == 0
        if name == "near and sky checker":
            assert dec.edges.all() and codes.max() == q.max_code
    all_edges = _round_trip(cases["near and sky checker"])[1]
    assert all_edges.stats.total_bytes < 200


@pytest.mark.parametrize("q", [2, 3, 8, 64])
def test_lossy_values_stay_within_q_and_keep_sky(q):
    distance = piecewise_planar(61, 93)
    codes, out, dec = _round_trip(distance, q=q)
    err = np.abs(dec.codes[dec.valid].astype(int) - codes[dec.valid])
    surface = codes[dec.valid] > 0
    assert np.all(err[codes[dec.valid] == 0] == 0)  # sky is exact
    assert np.all(dec.codes[dec.valid][surface] > 0)  # a surface never becomes sky
    assert np.all(err[surface & (codes[dec.valid] >= q)] <= q // 2)
    assert np.all(err <= q)
    _, lossless, _ = _round_trip(distance)
    assert out.stats.value_bytes < lossless.stats.value_bytes


def test_explicit_edges_and_threshold():
    distance = piecewise_planar(48, 64)
    enc = EdgeEncoder(64, 48, 12, QUANTIZER)
    few = enc.encode(distance, threshold=1000.0)
    many = enc.encode(distance, threshold=0.5)
    assert few.stats.n_edges < many.stats.n_edges
    mask = np.zeros((48, 64), bool)
    mask[10, 5:20] = True
    out = enc.encode(distance, edges=mask)
    dec = EdgeDecoder(64, 48, 12, QUANTIZER).decode(out.payload)
    np.testing.assert_array_equal(dec.edges, mask)
    np.testing.assert_array_equal(dec.codes[mask], enc.codes(distance)[mask])


def test_bits_from_eight_to_sixteen():
    with pytest.raises(ValueError):
        EdgeEncoder(8, 8, 7, DepthQuantizer(0.1, 10.0, bits=7, min_code=1))
    eight = DepthQuantizer(0.1, 1000.0, bits=8, min_code=1)
    codes, _, dec = _round_trip(piecewise_planar(20, 30, quantizer=eight), eight)
    _assert_lossless(codes, dec)
    sixteen = DepthQuantizer(0.1, 1000.0, bits=16, min_code=1)
    codes, _, dec = _round_trip(piecewise_planar(20, 30, quantizer=sixteen), sixteen)
    _assert_lossless(codes, dec)


def test_regular_samples_cover_the_borders():
    rows, cols = sample_positions(1024, 1000, 5)
    assert (len(rows), len(cols)) == (32, 32)
    assert rows[0] == 0 and rows[-1] == 999 and cols[-1] == 1023
    for positions, size in ((rows, 1000), (cols, 1024), (np.array([3]), 7)):
        brute = np.array([np.argmin(np.abs(positions - y)) for y in range(size)])
        np.testing.assert_array_equal(nearest_index(positions, size), brute)


# ------------------------------------------------------------------------------------------
# Temporal context and warp
# ------------------------------------------------------------------------------------------

def test_identity_warp_reproduces_the_edge_samples():
    distance = piecewise_planar(61, 93)
    enc = EdgeEncoder(93, 61, 12, QUANTIZER)
    samples = enc.encode(distance).samples
    warped = warp_samples(samples, POSE, POSE, QUANTIZER)
    np.testing.assert_array_equal(warped.edges, samples.edges)
    np.testing.assert_array_equal(warped.values[samples.edges], samples.codes[samples.edges])
    assert np.all(warped.values[~samples.edges] == -1)


def test_rotation_warp_moves_samples_and_keeps_sky():
    distance = piecewise_planar(64, 64)
    samples = EdgeEncoder(64, 64, 12, QUANTIZER).encode(distance).samples
    turned = Pose.make(POSE.p, quat_from_axis_angle((0, 1, 0), np.radians(5.0)))
    warped = warp_samples(samples, POSE, turned, QUANTIZER)
    # turning left moves the image right by about 5 degrees = 64 / pi * 5 deg ~ 3.5 pixels at the centre
    assert 0 < warped.edges.sum() <= samples.edges.sum()
    assert not np.array_equal(warped.edges, samples.edges)
    sky_codes = samples.codes[samples.edges & (samples.codes == 0)]
    assert len(sky_codes) and (warped.values == 0).sum() > 0
    again = warp_samples(samples, POSE, turned, QUANTIZER)
    np.testing.assert_array_equal(again.values, warped.values)


def test_identical_frames_cost_much_less_with_temporal_context():
    distance = QUANTIZER.dequantize(cluttered_codes(192, 256))
    enc = EdgeEncoder(256, 192, 12, QUANTIZER)
    dec = EdgeDecoder(256, 192, 12, QUANTIZER)
    first = enc.encode(distance)
    warped = warp_samples(dec.decode(first.payload), POSE, POSE, QUANTIZER)
    second = enc.encode(distance, warped.edges, warped.values)
    assert second.stats.temporal
    assert second.stats.edge_bytes < 0.25 * first.stats.edge_bytes
    assert second.stats.value_bytes < 0.25 * first.stats.value_bytes
    assert second.stats.total_bytes < 0.5 * first.stats.total_bytes
    got = dec.decode(second.payload, warped.edges, warped.values)
    np.testing.assert_array_equal(got.codes, second.samples.codes)
    with pytest.raises(CodecError, match="previous frame"):
        dec.decode(second.payload)


def test_temporal_off_ignores_the_previous_frame():
    distance = piecewise_planar(48, 64)
    enc = EdgeEncoder(64, 48, 12, QUANTIZER, temporal=False)
    warped = warp_samples(enc.encode(distance).samples, POSE, POSE, QUANTIZER)
    out = enc.encode(distance, warped.edges, warped.values)
    assert not out.stats.temporal
    assert out.payload == enc.encode(distance).payload


# ------------------------------------------------------------------------------------------
# Motion
# ------------------------------------------------------------------------------------------

def test_motion_quantization_favours_slow_motion():
    v = np.array([0.0, 0.01, 0.1, 1.0, -1.0, 10.0, -100.0])
    back = dequantize_motion(quantize_motion(v, 8), 8)
    assert abs(back[3] - 1.0) < 0.07 and abs(back[4] + 1.0) < 0.07
    assert np.all(np.abs(back - v) <= np.sqrt(np.abs(v)) / 8 + 1 / 64 + 1e-6)
    assert np.all(np.sign(back) == np.sign(np.round(8 * np.sqrt(np.abs(v))) * np.sign(v)))


def test_motion_round_trip_and_empty_motion_is_free():
    distance = piecewise_planar(48, 64)
    enc = EdgeEncoder(64, 48, 12, QUANTIZER)
    dec = EdgeDecoder(64, 48, 12, QUANTIZER)
    still = enc.encode(distance, motion=np.zeros((48, 64, 2), np.float32))
    assert still.stats.motion_bytes == 0
    assert still.payload == enc.encode(distance).payload
    assert dec.decode(still.payload).motion is None
    motion = np.zeros((48, 64, 2), np.float32)
    motion[10:30, 8:30] = (2.0, -0.5)
    motion[10:30, 30:34] = (2.5, -0.5)
    out = enc.encode(distance, motion=motion)
    got = dec.decode(out.payload)
    moving = np.any(motion != 0, axis=-1)
    np.testing.assert_array_equal(got.moving, moving)
    np.testing.assert_array_equal(got.motion, out.samples.motion)
    assert np.all(got.motion[~moving] == 0)
    assert np.max(np.abs(got.motion[moving] - motion[moving])) < 0.3
    assert 0 < out.stats.motion_bytes < 80


# ------------------------------------------------------------------------------------------
# Golden bytes and the pure-Python path
# ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", NAMES)
def test_golden_payloads(name):
    with open(os.path.join(GOLDEN_DIR, f"{name}.bin"), "rb") as f:
        golden = f.read()
    assert golden_payload(name) == golden, f"{name}: bitstream changed (regenerate with python -m tests.protocol.golden_edge)"
    dec = EdgeDecoder(WIDTH, HEIGHT, 12, QUANTIZER)
    if name == "edge_temporal":
        first = dec.decode(golden_payload("edge_intra"))
        warped = warp_samples(first, POSE, POSE, QUANTIZER)
        got = dec.decode(golden, warped.edges, warped.values)
        codes = QUANTIZER.quantize(piecewise_planar(shift=2)).astype(int)
    else:
        got = dec.decode(golden)
        codes = QUANTIZER.quantize(piecewise_planar()).astype(int)
    if name != "edge_lossy":
        np.testing.assert_array_equal(got.codes[got.valid], codes[got.valid])


_PURE_PYTHON_SCRIPT = """
import sys, hashlib
from tests.protocol.golden_edge import golden_payload, NAMES, WIDTH, HEIGHT, QUANTIZER
from pibr.protocol.edgecodec.codec import EdgeDecoder
out = [golden_payload(n).hex() for n in NAMES]
for n in ("edge_intra", "edge_motion"):
    s = EdgeDecoder(WIDTH, HEIGHT, 12, QUANTIZER).decode(golden_payload(n))
    parts = [s.codes, s.signs, s.valid] + ([s.motion] if s.motion is not None else [])
    out.append(hashlib.sha256(b"".join(a.tobytes() for a in parts)).hexdigest())
sys.stdout.write("\\n".join(out))
"""


def test_pure_python_kernels_give_the_same_bytes():
    """The whole codec with numba disabled (plain Python running the kernels) writes and reads the same."""
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    res = subprocess.run([sys.executable, "-c", _PURE_PYTHON_SCRIPT], cwd=root, env=env, capture_output=True,
                         text=True, timeout=240)
    assert res.returncode == 0, res.stderr[-2000:]
    lines = res.stdout.split()
    assert len(lines) == len(NAMES) + 2
    assert [bytes.fromhex(x) for x in lines[:len(NAMES)]] == [golden_payload(n) for n in NAMES]
    for line, name in zip(lines[len(NAMES):], ("edge_intra", "edge_motion")):
        s = DECODER.decode(golden_payload(name))
        parts = [s.codes, s.signs, s.valid] + ([s.motion] if s.motion is not None else [])
        assert line == hashlib.sha256(b"".join(a.tobytes() for a in parts)).hexdigest(), name


# ------------------------------------------------------------------------------------------
# Robustness: only CodecError, bounded work, bounded memory
# ------------------------------------------------------------------------------------------

GOOD = {name: golden_payload(name) for name in ("edge_intra", "edge_motion")}
DECODER = EdgeDecoder(WIDTH, HEIGHT, 12, QUANTIZER)


def _decode_only_codec_errors(payload):
    return decode_or_codec_error(DECODER.decode, payload, "edge codec: ")


@FUZZ
@given(st.sampled_from(sorted(GOOD)), st.integers(min_value=0))
def test_truncated_payloads_raise_codec_error(name, cut):
    good = GOOD[name]
    with pytest.raises(CodecError):
        DECODER.decode(good[:cut % len(good)])


@FUZZ
@given(st.sampled_from(sorted(GOOD)), st.lists(st.integers(min_value=0), min_size=1, max_size=8))
def test_bit_flips_raise_only_codec_error(name, positions):
    data = bytearray(GOOD[name])
    for p in positions:
        p %= 8 * len(data)
        data[p // 8] ^= 1 << (p % 8)
    out = _decode_only_codec_errors(bytes(data))
    if out is not None:
        assert out.codes.shape == (HEIGHT, WIDTH) and out.codes.dtype == np.uint16


@FUZZ
@given(st.binary(max_size=600))
def test_random_payloads_raise_codec_error(data):
    with pytest.raises(CodecError):
        DECODER.decode(data)


@FUZZ
@given(st.binary(min_size=0, max_size=400), st.integers(0, 255), st.integers(0, 7))
def test_random_sections_behind_a_valid_header_raise_only_codec_error(body, flags_bit, section):
    """A valid header (edge count ``flags_bit``) over random section bytes: the arithmetic decoders
    must not crash or run away."""
    lengths = [0, 0, 0, 0]
    lengths[section % 4] = len(body)
    flags = (bitstream.FLAG_FOUR_PASSES if flags_bit & 1 else 0) | (bitstream.FLAG_MOTION if section % 4 == 3 else 0)
    head = struct.pack("<4sBBHHBBHHI4I", b"PIBE", 1, flags, WIDTH, HEIGHT, 12, 5, 1, 1, flags_bit, *lengths)
    _decode_only_codec_errors(head + body)


def test_header_fields_are_checked_before_allocating():
    good = bytearray(GOOD["edge_intra"])

    def patched(offset, fmt, value):
        data = bytearray(good)
        struct.pack_into(fmt, data, offset, value)
        return bytes(data)

    cases = {
        "bad magic": patched(0, "<4s", b"XXXX"),
        "version": patched(4, "<B", 9),
        "unknown flags": patched(5, "<B", 0x80),
        "size": patched(6, "<H", 8192),
        "size outside": patched(6, "<H", 9000),
        "zero height": patched(8, "<H", 0),
        "bits": patched(10, "<B", 9),
        "spacing": patched(11, "<B", 12),
        "min_code": patched(12, "<H", 5000),
        "q": patched(14, "<H", 0),
        "edges": patched(16, "<I", WIDTH * HEIGHT + 1),
        "edge section": patched(20, "<I", 0xFFFFFFFF),
        "value section": patched(28, "<I", 10 ** 8),
        "trailing bytes": bytes(good) + b"\x00",
    }
    for name, data in cases.items():
        tracemalloc.start()
        try:
            with pytest.raises(CodecError) as info:
                DECODER.decode(data)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert peak < 200_000, (name, peak)
        assert str(info.value).startswith("edge codec: "), name
    big = EdgeDecoder(4096, 4096, 12, QUANTIZER)
    with pytest.raises(CodecError, match="decoder expects 4096x4096"):
        big.decode(bytes(good))
    with pytest.raises(CodecError, match="bytes"):
        DECODER.decode("not bytes")


def test_corrupt_payload_memory_is_bounded_by_the_frame():
    rng = np.random.default_rng(5)
    good = GOOD["edge_motion"]
    tracemalloc.start()
    try:
        for _ in range(30):
            data = bytearray(good)
            for p in rng.integers(bitstream.HEADER_SIZE * 8, 8 * len(data), 4):
                data[p // 8] ^= 1 << (p % 8)
            _decode_only_codec_errors(bytes(data))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 64 * WIDTH * HEIGHT + 1_000_000


# ------------------------------------------------------------------------------------------
# Compiled helpers against their numpy definitions
# ------------------------------------------------------------------------------------------

def _temporal_context_numpy(e):
    h, w = e.shape
    p = np.zeros((h + 2, w + 2), dtype=bool)
    p[1:-1, 1:-1] = e
    around = np.zeros((h, w), dtype=bool)
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            if dy != 1 or dx != 1:
                around |= p[dy:dy + h, dx:dx + w]
    out = np.zeros((h + 8, w + 8), dtype=np.uint8)
    out[4:-4, 4:-4] = 2 * e.astype(np.uint8) + around.astype(np.uint8)
    return out


@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (6, 1), (13, 17), (64, 48)])
def test_compiled_temporal_helpers_and_assembly_match_numpy(shape):
    from pibr.protocol.edgecodec import codec as codec_module
    from pibr.protocol.edgecodec.values import PAD as VPAD, temporal_values

    rng = np.random.default_rng(shape[0] * 100 + shape[1])
    h, w = shape
    e = rng.random(shape) < 0.2
    np.testing.assert_array_equal(temporal_context(e, h, w), _temporal_context_numpy(e))
    v = np.where(rng.random(shape) < 0.5, rng.integers(0, 4096, shape), rng.integers(-3, 0, shape)).astype(np.int32)
    ref = np.full((h + 2 * VPAD, w + 2 * VPAD), -1, np.int32)
    ref[VPAD:h + VPAD, VPAD:w + VPAD] = np.where(v < 0, -1, v)
    np.testing.assert_array_equal(temporal_values(v, h, w), ref)
    np.testing.assert_array_equal(temporal_values(v.astype(np.int64), h, w), ref)
    rows, cols = sample_positions(w, h, 2)
    regular = rng.integers(1, 4096, (len(rows), len(cols)))
    values = rng.integers(0, 4096, shape).astype(np.int32)
    s = codec_module._assemble(e, np.where(e, 1, 0).astype(np.int8), values, regular, rows, cols, 12, 1, 1)
    codes = np.zeros(shape, np.uint16)
    codes[np.ix_(rows, cols)] = regular
    codes[e] = values[e]
    valid = e.copy()
    valid[np.ix_(rows, cols)] = True
    np.testing.assert_array_equal(s.codes, codes)
    np.testing.assert_array_equal(s.valid, valid)
    assert s.codes.dtype == np.uint16 and s.valid.dtype == bool


@pytest.mark.parametrize("shape", [(1, 1), (1, 2), (2, 1), (1, 6), (6, 1), (2, 2), (2, 9), (3, 3), (3, 8), (9, 4), (31, 47)])
def test_compiled_laplacian_matches_its_numpy_definition(shape):
    from .edgecodec_reference import laplacian_numpy

    rng = np.random.default_rng(shape[0] * 31 + shape[1])
    y, x = np.indices(shape)
    for codes in (rng.integers(0, 4096, shape), 700 + 3 * y - 5 * x,  # random, a plane (linear borders)
                  700 + 3 * y - 5 * x + rng.integers(-1, 2, shape), piecewise_planar_codes(*shape)):
        np.testing.assert_array_equal(laplacian(codes), laplacian_numpy(codes))


@pytest.mark.parametrize("min_code", [1, 2])
def test_compiled_warp_matches_its_numpy_definition(min_code):
    """Random samples (sky, peeled, near and far codes) under random motions: the same splat, bit for bit."""
    from pibr.protocol.edgecodec import codec as codec_module

    q = DepthQuantizer(0.1, 1000.0, bits=12, min_code=min_code)
    rng = np.random.default_rng(min_code)
    h, w = 61, 83
    rows, cols = sample_positions(w, h, 5)
    for trial in range(12):
        edges = rng.random((h, w)) < 0.3
        codes = rng.integers(0, 4096, (h, w)).astype(np.uint16)
        codes[rng.random((h, w)) < 0.1] = 0
        codes[rng.random((h, w)) < 0.05] = 1
        s = codec_module._assemble(edges, np.where(edges, 1, 0).astype(np.int8), codes.astype(np.int32),
                                   codes[np.ix_(rows, cols)], rows, cols, 12, min_code, 1)
        axis = rng.normal(size=3)
        prev = Pose.make(rng.normal(0, 2, 3), quat_from_axis_angle(axis, rng.uniform(-3, 3)))
        cur = Pose.make(prev.position + rng.normal(0, 0.3 if trial % 2 else 3.0, 3),
                        quat_from_axis_angle(rng.normal(size=3), rng.uniform(-3, 3)))
        for a, b in ((prev, cur), (prev, prev)):
            got = warp_samples(s, a, b, q)
            want = edgecodec_reference.warp_samples_numpy(s, a, b, q)
            np.testing.assert_array_equal(got.values, want.values)
            np.testing.assert_array_equal(got.edges, want.edges)
        assert got.values.dtype == np.int32


@pytest.mark.parametrize("shape", [(1, 1), (1, 2), (2, 1), (1, 6), (6, 1), (2, 2), (2, 9), (3, 3), (3, 8), (9, 4), (31, 47)])
@pytest.mark.parametrize("threshold, weight", [(3.5, 1.0), (8.0, 1.0), (2.0, 0.7)])
def test_fused_depth_edges_match_the_selection_of_their_significance(shape, threshold, weight):
    """depth_edges (one compiled pass) = select_edges of weight * |Laplacian| computed in numpy:
    edges, signs and significance, on random codes, planes with sky and piecewise-planar scenes."""
    from pibr.protocol.edgecodec.codec import depth_edges

    rng = np.random.default_rng(shape[0] * 7 + shape[1])
    y, x = np.indices(shape)
    with_sky = np.where(rng.random(shape) < 0.2, 0, 700 + 3 * y - 5 * x)
    for codes in (rng.integers(0, 4096, shape), with_sky, piecewise_planar_codes(*shape)):
        lap = laplacian(codes)
        sig = weight * np.abs(lap).astype(np.float32)
        edges, signs = select_edges(codes, threshold, sig, lap)
        got_edges, got_signs, got_sig = depth_edges(codes, threshold, weight)
        np.testing.assert_array_equal(got_edges, edges)
        np.testing.assert_array_equal(got_signs, signs)
        np.testing.assert_array_equal(got_sig, sig)
        assert got_sig.dtype == np.float32 and got_signs.dtype == np.int8


def test_value_workspace_reused_across_frames_gives_the_bytes_of_fresh_buffers():
    """The encoder's value workspace (kept from frame to frame, cleared at the last frame's
    edges): the same bytes and decoded values as new buffers, frame after frame, also when
    the first output buffer is too small (random codes: large residuals) and the coder retries."""
    from pibr.protocol.edgecodec.values import ValueWorkspace, encode_values, temporal_values

    h, w = 40, 56
    rows, cols = sample_positions(w, h, 3)
    nr, nc = nearest_index(rows, h), nearest_index(cols, w)
    ws = ValueWorkspace(h, w)
    rng = np.random.default_rng(5)
    retried = False
    for frame in range(6):
        edges = rng.random((h, w)) < (0.05 if frame % 2 else 0.4)
        codes = rng.integers(0, 65536, (h, w)) if frame % 3 == 0 else piecewise_planar_codes(h, w) + frame
        signs = np.where(rng.random((h, w)) < 0.5, 1, -1)
        regular = codes[np.ix_(rows, cols)]
        prev = np.where(rng.random((h, w)) < 0.1, rng.integers(0, 4096, (h, w)), -1) if frame else None
        fresh_bytes, fresh_dec = encode_values(edges, codes, signs, regular, nr, nc, 1, 65535,
                                               temporal_values(prev, h, w))
        got_bytes, got_dec = encode_values(edges, codes, signs, regular, nr, nc, 1, 65535,
                                           ws.temporal_values(prev), workspace=ws)
        assert got_bytes == fresh_bytes
        retried |= len(got_bytes) > 2 * edges.sum() + 256
        np.testing.assert_array_equal(got_dec[edges], fresh_dec[edges])
        assert not ws.S.any() and not ws.A.any()
    assert retried  # the first output buffer was too small at least once
    with pytest.raises(ValueError, match="workspace is for"):
        encode_values(edges[:-1], codes[:-1], signs[:-1], regular, nr, nc[:w], 1, 4095, workspace=ws)



@pytest.mark.parametrize("shape", [(1, 1), (5, 13), (16, 16), (19, 8), (33, 41)])
def test_block_maps_match_their_numpy_definition(shape):
    """Occupancy and largest temporal context per 8 x 8 block, partial blocks at the border included."""
    from pibr.protocol.edgecodec import edges as edge_module

    pad, h, w = edge_module.PAD, *shape
    rng = np.random.default_rng(shape[0] * 53 + shape[1])
    img = np.zeros((h + 2 * pad, w + 2 * pad), np.uint8)
    img[pad:-pad, pad:-pad] = rng.random(shape) < 0.01
    tc = np.zeros_like(img)
    tc[pad:-pad, pad:-pad] = np.where(rng.random(shape) < 0.05, rng.integers(0, 4, shape), 0)
    occ_shape = edge_module.occupancy_shape(h, w, 3)
    occ, tmax, tmax_only = (np.zeros(occ_shape, np.uint8) for _ in range(3))
    edge_module.block_maps(img, tc, h, w, 3, occ, tmax)
    edge_module.block_maps(img, tc, h, w, 3, None, tmax_only)
    for by in range(occ_shape[0]):
        for bx in range(occ_shape[1]):
            block = (slice(pad + 8 * by, pad + min(8 * by + 8, h)), slice(pad + 8 * bx, pad + min(8 * bx + 8, w)))
            assert occ[by, bx] == int(img[block].any())
            assert tmax[by, bx] == tmax_only[by, bx] == tc[block].max()


def test_decoder_value_workspace_reused_across_frames_gives_fresh_results():
    """The decoder's value workspace kept from frame to frame (also across a corrupt payload):
    the same codes and signs as a fresh decode, 0 away from the edges."""
    from pibr.protocol.edgecodec.values import ValueWorkspace, decode_values, encode_values

    h, w = 40, 56
    rows, cols = sample_positions(w, h, 3)
    nr, nc = nearest_index(rows, h), nearest_index(cols, w)
    ws = ValueWorkspace(h, w)
    rng = np.random.default_rng(8)
    for frame in range(5):
        edges = rng.random((h, w)) < (0.05 if frame % 2 else 0.4)
        codes = piecewise_planar_codes(h, w) + 7 * frame
        signs = np.where(rng.random((h, w)) < 0.5, 1, -1)
        regular = codes[np.ix_(rows, cols)]
        data, _ = encode_values(edges, codes, signs, regular, nr, nc, 1, 4095)
        if frame == 2:
            data = data[: len(data) // 2]  # corrupt: decoding stops early
        fresh = decode_values(data, edges, regular, nr, nc, 1, 4095)
        got = decode_values(data, edges, regular, nr, nc, 1, 4095, workspace=ws)
        assert got[2] == fresh[2] == (frame != 2)
        np.testing.assert_array_equal(got[0], fresh[0])
        np.testing.assert_array_equal(got[1], fresh[1])
        assert not got[0][~edges].any() and not ws.S.any() and not ws.A.any()
        if frame != 2:
            np.testing.assert_array_equal(got[0][edges], codes[edges])
