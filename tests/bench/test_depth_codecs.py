"""The depth codecs ``pibr bench codec`` compares the edge codec with (bench/depth_codecs.py)."""
import numpy as np
import pytest

from pibr.bench.depth_codecs import (H264DepthDecoder, H264DepthEncoder, LogDepthDecoder,
                                     LogDepthEncoder, LogDepthQuantizer, ZstdDepthDecoder, ZstdDepthEncoder,
                                     h264_depth_quantizer, make_pair, probe_h264_10bit)
from pibr.bench.codec_bench import winners
from pibr.protocol.depth import PEELED
from pibr.protocol.errors import CodecError
from pibr.protocol.depth_codecs import edge_quantizer


def _scene_maps(h=37, w=53, frames=6):
    """Distance maps (h, w) of a tilted plane with a box in front, sky and peeled pixels, moving."""
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    out = []
    for k in range(frames):
        r = 2.0 + 0.05 * (xx + 2 * k) + 0.03 * yy
        r[5:15, 10 + k:25 + k] = 0.7               # a box moving right
        r[:4, :] = 0.0                             # sky
        r[30:, 40:] = PEELED                       # peeled (extra view)
        if k >= 3:
            r[20:22, :] = 0.0                      # a change in the later frames
        out.append(r)
    return out


@pytest.mark.parametrize("bits", [16, 10, 8])
def test_log_codec_is_lossless_relative_to_its_quantisation(bits):
    """Keyframes and predicted frames (block skip, temporal or spatial residuals) decode to exactly
    the quantised codes, with a size (37 x 53) that is no multiple of the block."""
    h, w = 37, 53
    q = LogDepthQuantizer(0.1, 100.0, bits)
    enc, dec = LogDepthEncoder(w, h, q, block=8, keyint=4), LogDepthDecoder(w, h, q)
    sizes = []
    for r in _scene_maps(h, w, 9):
        payload = enc.encode(r)
        back = dec.decode(payload)
        want = q.quantize(r)
        assert np.array_equal(dec.codes, want)
        assert np.array_equal(enc.reconstruction, want)
        assert np.array_equal(back, q.dequantize(want))
        sizes.append(len(payload))
    assert back.dtype == np.float32 and back.shape == (h, w)
    r = _scene_maps(h, w, 9)[-1]
    assert np.all(back[r == 0] == 0) and np.all(back[r < 0] == PEELED)
    # predicted frames are smaller than the keyframes (frames 0, 4, 8)
    assert max(sizes[1:4]) < sizes[0]


def test_log_codec_skips_unchanged_blocks():
    q = LogDepthQuantizer(0.1, 100.0, 16)
    r = _scene_maps(32, 32, 1)[0]
    enc, dec = LogDepthEncoder(32, 32, q, block=16, keyint=30), LogDepthDecoder(32, 32, q)
    key = enc.encode(r)
    same = enc.encode(r)
    dec.decode(key)
    assert np.array_equal(dec.codes, q.quantize(r))
    dec.decode(same)
    assert np.array_equal(dec.codes, q.quantize(r))
    assert len(same) < len(key) // 4    # a mask of four zero bits, nothing else


def test_log_codec_tolerance_bounds_the_error_and_both_ends_agree():
    q = LogDepthQuantizer(0.1, 100.0, 16)
    enc, dec = LogDepthEncoder(40, 40, q, block=8, tolerance=5), LogDepthDecoder(40, 40, q)
    rng = np.random.default_rng(3)
    base = np.full((40, 40), 3.0, np.float32)
    for k in range(5):
        r = base * (1 + 1e-5 * rng.standard_normal((40, 40))).astype(np.float32)   # changes of a few codes
        dec.decode(enc.encode(r))
        assert np.array_equal(dec.codes, enc.reconstruction)
        assert np.abs(dec.codes.astype(int) - q.quantize(r).astype(int)).max() <= 5


def test_log_decoder_refuses_bad_payloads():
    q = LogDepthQuantizer(0.1, 100.0, 16)
    enc = LogDepthEncoder(16, 16, q)
    r = np.full((16, 16), 2.0, np.float32)
    key, pred = enc.encode(r), enc.encode(r)
    with pytest.raises(CodecError, match="without its previous frame"):
        LogDepthDecoder(16, 16, q).decode(pred)
    with pytest.raises(CodecError, match="shorter than its header"):
        LogDepthDecoder(16, 16, q).decode(key[:5])
    with pytest.raises(CodecError, match="body bytes"):
        LogDepthDecoder(16, 16, q).decode(key[:-1])
    with pytest.raises(CodecError, match="decoder expects 8x16"):
        LogDepthDecoder(8, 16, q).decode(key)
    with pytest.raises(CodecError, match="magic"):
        LogDepthDecoder(16, 16, q).decode(b"XXXX" + key[4:])


def test_zstd_codec_round_trip_is_the_quantisation():
    q = edge_quantizer(0.1, 100.0)
    r = _scene_maps(20, 30, 1)[0]
    back = ZstdDepthDecoder(30, 20, q).decode(ZstdDepthEncoder(30, 20, q).encode(r))
    assert np.array_equal(back, q.dequantize(q.quantize(r)))
    with pytest.raises(CodecError, match="does not decompress"):
        ZstdDepthDecoder(30, 20, q).decode(b"not zstd")


@pytest.mark.parametrize("bits", [8, 10])
def test_h264_depth_alone_round_trip(bits):
    """A constant distance at a generous bitrate comes back with its exact code; a ramp within a few
    codes; sky stays sky and peeled stays peeled (the guard band)."""
    q = h264_depth_quantizer(0.1, 100.0, bits)
    assert q.min_code == 16 << (bits - 8)
    enc, dec = H264DepthEncoder(64, 48, 10.0, 4000.0, q), H264DepthDecoder(64, 48, q)
    flat = np.full((48, 64), 2.0, np.float32)
    for _ in range(2):
        dec.decode(enc.encode(flat))
        assert np.array_equal(dec.codes, q.quantize(flat))
    yy, xx = np.mgrid[0:48, 0:64]
    r = (1.0 + 0.02 * xx).astype(np.float32)
    r[:8] = 0.0
    r[40:] = PEELED
    back = dec.decode(enc.encode(r))
    assert np.abs(dec.codes.astype(int) - q.quantize(r).astype(int)).max() <= 3 << (bits - 8)
    assert np.all(back[:8] == 0) and np.all(back[40:] == PEELED)


def test_h264_10bit_probe_and_bad_input():
    info = probe_h264_10bit()
    assert set(info) == {"available", "pix_fmt", "error"}
    assert info["available"] == (info["error"] is None)
    with pytest.raises(ValueError, match="8 or 10 bits"):
        H264DepthEncoder(16, 16, 10.0, 100.0, h264_depth_quantizer(0.1, 10.0, 12))
    with pytest.raises(CodecError):
        H264DepthDecoder(16, 16, h264_depth_quantizer(0.1, 10.0, 8)).decode(b"\x00\x00\x00\x01garbage")


def test_make_pair_refuses_unknown_codec():
    with pytest.raises(ValueError, match="unknown depth codec"):
        make_pair("png", 8, 8, 0.1, 10.0, 10.0)


def test_winners_takes_the_best_point_within_each_budget():
    curves = {"a": [{"bits_per_frame": 10.0, "psnr_db": 40.0}, {"bits_per_frame": 30.0, "psnr_db": 45.0}],
              "b": [{"bits_per_frame": 20.0, "psnr_db": 50.0}]}
    w = winners(curves, "psnr_db", True)
    assert [(x["bits_per_frame"], x["winner"], x["value"]) for x in w] == [(10.0, "a", 40.0), (20.0, "b", 50.0),
                                                                           (30.0, "b", 50.0)]
    assert w[2]["by_codec"] == {"a": 45.0, "b": 50.0}
