"""The edge codec's compiled quantization gives exactly DepthQuantizer.quantize's codes."""
from __future__ import annotations

import numpy as np
import pytest

from pibr.protocol.depth import DepthQuantizer
from pibr.protocol.edgecodec.quantize import quantize_codes

QUANTIZERS = [DepthQuantizer(0.1, 1000.0, bits=12, min_code=1), DepthQuantizer(0.1, 1000.0, bits=12, min_code=2),
              DepthQuantizer(0.05, 37.0, bits=16, min_code=5), DepthQuantizer(1.0, 2.0, bits=10, min_code=2)]


def _special(q: DepthQuantizer) -> np.ndarray:
    """Values at and around every branch of the formula: sky, peeled, near, far, rounding ties."""
    ties = q.near / ((np.arange(q.min_code, q.min_code + 40) - q.min_code + 0.5) / (q.max_code - q.min_code))
    return np.concatenate([
        [0.0, -0.0, -1.0, -1e-300, np.inf, -np.inf, np.nan, 1e-300, 1e300, -1e300],
        [q.near, np.nextafter(q.near, 0), np.nextafter(q.near, 1e9), q.far, np.nextafter(q.far, 0),
         np.nextafter(q.far, 1e9)],
        ties, np.nextafter(ties, 0), np.nextafter(ties, 1e9)])


@pytest.mark.parametrize("q", QUANTIZERS, ids=lambda q: f"{q.bits}b-min{q.min_code}")
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_quantize_codes_equals_the_numpy_formula(q, dtype):
    rng = np.random.default_rng(q.bits)
    r = np.exp(rng.uniform(np.log(q.near / 3), np.log(q.far * 3), (257, 301)))
    special = _special(q)
    r.flat[:special.size] = special
    with np.errstate(over="ignore"):  # 1e300 becomes inf in float32, on purpose
        r = r.astype(dtype)
    got = quantize_codes(r, q)
    assert got.dtype == np.int32 and got.shape == r.shape
    np.testing.assert_array_equal(got, q.quantize(r).astype(np.int32))


def test_quantize_codes_takes_integer_input_and_refuses_other_shapes():
    q = QUANTIZERS[1]
    r = np.array([[0, 1, 2], [5, 2000, -3]])
    np.testing.assert_array_equal(quantize_codes(r, q), q.quantize(r).astype(np.int32))
    with pytest.raises(ValueError, match=r"\(h, w\)"):
        quantize_codes(np.ones(5), q)
