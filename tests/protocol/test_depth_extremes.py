"""Disparity quantisation at extreme near / far ratios: 1 cm to 10 km (a ratio of 1e6).

The bound at every distance: disparity comes back within half a code step, 1 / (2 (max - min));
in distance that is r' in [near / (d + s), near / (d - s)] (d = near / r, s the half step) while
d > s. Below that disparity (beyond near / (2 s): 4.8 m for 8 bits, 82 m for the edge codec's
12 bits at near = 1 cm) every distance decodes to that farthest code's distance: finite, never
wrapped to near, never NaN.
"""
import numpy as np
import pytest

from pibr.protocol.depth import DepthQuantizer, PEELED
from pibr.protocol.depth_codecs import h264_quantizer

NEAR, FAR = 1e-2, 1e4
R = np.geomspace(NEAR, FAR, 200001)

QUANTIZERS = {"8-bit atlas": h264_quantizer(NEAR, FAR), "12-bit edge": DepthQuantizer(NEAR, FAR, 12, 2),
              "16-bit": DepthQuantizer(NEAR, FAR, 16, 2)}


@pytest.mark.parametrize("name", list(QUANTIZERS))
def test_disparity_within_half_a_code_at_every_distance(name):
    q = QUANTIZERS[name]
    codes = q.quantize(R)
    back = q.dequantize(codes).astype(np.float64)
    assert np.all(np.isfinite(back)) and np.all(back > 0)
    assert codes.min() >= q.min_code and codes.max() <= q.max_code      # never the sky / peeled bands
    half = 0.5 / (q.max_code - q.min_code)
    # float32 decoding adds a relative rounding of 2**-24 to the distance
    assert np.all(np.abs(NEAR / back - NEAR / R) <= half + 2 ** -23 * NEAR / back)
    d = NEAR / R
    resolved = d > half
    lo, hi = NEAR / (d[resolved] + half), NEAR / (d[resolved] - half)
    assert np.all(back[resolved] >= lo * (1 - 2 ** -23)) and np.all(back[resolved] <= hi * (1 + 2 ** -23))
    # beyond the last resolved disparity everything decodes to the farthest code's distance
    farthest = min(NEAR / half, FAR)
    assert back.max() == pytest.approx(farthest, rel=1e-6)


@pytest.mark.parametrize("name", list(QUANTIZERS))
def test_decoding_is_monotone_without_wrap_around(name):
    """Farther never decodes nearer: codes fall and decoded distances rise with distance."""
    q = QUANTIZERS[name]
    codes = q.quantize(R).astype(np.int64)
    back = q.dequantize(codes).astype(np.float64)
    assert np.all(np.diff(codes) <= 0)
    assert np.all(np.diff(back) >= 0)
    assert codes[0] == q.max_code and q.quantize([FAR])[0] == q.min_code


def test_resolution_limits_documented_in_the_table():
    """The figures the codec bench's extremes table and the README quote."""
    assert h264_quantizer(NEAR, FAR).dequantize([16])[0] == pytest.approx(2 * NEAR * 239, rel=1e-6)   # 4.78 m
    assert DepthQuantizer(NEAR, FAR, 12, 2).dequantize([2])[0] == pytest.approx(2 * NEAR * 4093, rel=1e-6)


@pytest.mark.parametrize("name", list(QUANTIZERS))
def test_all_sky_and_all_one_plane(name):
    q = QUANTIZERS[name]
    sky = np.zeros((8, 8))
    assert np.all(q.quantize(sky) == 0) and np.all(q.dequantize(q.quantize(sky)) == 0)
    for r in (NEAR, 1.0, 1e3, FAR, FAR * (1 - 1e-9)):
        plane = np.full((8, 8), r)
        back = q.dequantize(q.quantize(plane))
        assert np.all(back == back[0, 0]) and back[0, 0] > 0
    # beyond the far sphere is sky, infinitely far and NaN too; peeled keeps its band
    assert list(q.quantize([FAR * 1.001, np.inf, np.nan, -np.inf])) == [0, 0, 0, 0]
    assert q.dequantize(q.quantize([PEELED]))[0] == PEELED
