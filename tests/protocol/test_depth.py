import numpy as np
import pytest

from pibr.protocol.depth import DEQUANTIZE, DepthQuantizer, GLSL, PEELED, QUANTIZE
from pibr.protocol.depth_codecs import h264_quantizer


def test_codes_span_and_sky():
    q = h264_quantizer(0.1, 1000.0)
    codes = q.quantize([0.1, 0.2, 1.0, 1000.0, 2000.0, np.inf, np.nan, 0.0, 0.05])
    assert codes.dtype == np.uint8
    assert codes[0] == 255                    # the near sphere: disparity 1
    assert codes[3] == 16                     # far geometry stays above the sky band
    assert list(codes[4:8]) == [0, 0, 0, 0]   # beyond far, inf, NaN, nothing hit: sky
    assert codes[8] == 255                    # inside the near sphere clamps to it


def test_round_trip_error_within_half_a_code():
    """Disparity is stored to the nearest code, so it comes back within half a code step; in
    distance that is the (asymmetric) image of half a step of disparity, which at the far end
    is larger than the first-order step_at(r) / 2 (6 of these 2000 distances exceed that)."""
    q = DepthQuantizer(0.1, 100.0, bits=12, min_code=1)
    r = np.geomspace(0.1, 100.0, 2000)
    back = q.dequantize(q.quantize(r)).astype(np.float64)
    assert np.all(back > 0)
    half = 0.5 / (q.max_code - q.min_code)
    disparity_err = np.abs(q.near / back - q.near / r)
    assert np.all(disparity_err <= half * (1 + 1e-5))
    d = q.near / r
    farther = np.minimum(q.near / (d - half), q.far) - r     # d - half > 0 for every r <= far here
    nearer = r - q.near / (d + half)
    bound = np.where(back >= r, farther, nearer)
    assert np.all(np.abs(back - r) <= bound + 1e-6 * r)
    np.testing.assert_allclose(back[:200], r[:200], rtol=2e-3)


def test_sky_peeled_and_the_guard_band():
    """H.264: sky 0, peeled 8, geometry from 16; coding noise of 3 levels keeps each itself."""
    q = h264_quantizer(0.1, 1000.0)
    assert list(q.quantize([0.0, PEELED, 1000.0])) == [0, 8, 16]
    r = q.dequantize(np.array([0, 3, 4, 8, 11, 12, 15, 16, 19]))
    assert list(r[:2]) == [0.0, 0.0]                    # sky and its noise
    assert list(r[2:5]) == [PEELED] * 3                 # peeled and its noise
    assert np.all(r[5:] > 0)                            # the farthest geometry and its noise
    edge = DepthQuantizer(0.1, 1000.0, bits=12, min_code=2)      # the edge codec's: sky 0, peeled 1
    assert list(edge.quantize([0.0, PEELED, 1000.0])) == [0, 1, 2]
    assert list(edge.dequantize(np.array([0, 1, 2]))[:2]) == [0.0, PEELED]
    plain = DepthQuantizer(0.1, 1000.0, bits=12, min_code=1)     # no room for peeled: it reads as sky
    assert list(plain.quantize([0.0, PEELED])) == [0, 0]


def test_near_and_bits_are_validated():
    with pytest.raises(ValueError):
        DepthQuantizer(0.0, 1.0)
    with pytest.raises(ValueError):
        DepthQuantizer(1.0, 0.5)
    with pytest.raises(ValueError):
        DepthQuantizer(0.1, 1.0, bits=17)


@pytest.mark.gl
def test_glsl_matches_numpy(gl_ctx):
    q = h264_quantizer(0.1, 1000.0)
    r = np.concatenate([np.geomspace(0.05, 2000, 3000), [0.0, 0.1, 1000.0]]).astype(np.float32)
    vs = "#version 410\n" + GLSL + """
uniform float u_near; uniform float u_far; uniform float u_min; uniform float u_max;
in float in_r;
out float out_code;
out float out_r;
void main() {
    out_code = depth_quantize(in_r, u_near, u_far, u_min, u_max);
    out_r = depth_dequantize(out_code, u_near, u_far, u_min, u_max);
}
"""
    prog = gl_ctx.program(vertex_shader=vs, varyings=["out_code", "out_r"])
    for k, v in {"u_near": 0.1, "u_far": 1000.0, "u_min": 16.0, "u_max": 255.0}.items():
        prog[k].value = v
    src = gl_ctx.buffer(r.tobytes())
    dst = gl_ctx.buffer(reserve=len(r) * 8)
    vao = gl_ctx.vertex_array(prog, [(src, "1f", "in_r")])
    fbo = gl_ctx.simple_framebuffer((1, 1))
    fbo.use()
    vao.transform(dst, vertices=len(r))
    out = np.frombuffer(dst.read(), np.float32).reshape(-1, 2)
    codes = q.quantize(r.astype(np.float64))
    # float32 rounding may move a value sitting exactly on a code boundary by one code
    assert np.mean(out[:, 0] == codes) > 0.995 and np.abs(out[:, 0] - codes).max() <= 1
    np.testing.assert_allclose(out[:, 1], q.dequantize(out[:, 0]), rtol=1e-5)
    for o in (vao, src, dst, prog, fbo):
        o.release()
    assert QUANTIZE.inputs[0] == "r" and DEQUANTIZE.outputs == ("r",)
