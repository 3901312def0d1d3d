"""Numpy definitions and helpers of the edge codec (pibr/protocol/edgecodec/codec.py and edges.py)
that only tests use, moved here from the codec: the tests hold the compiled ``codec.laplacian`` and
``codec.warp_samples`` to their numpy definitions bit for bit, and code hand-made edge-image
streams with the four passes' contexts."""
from __future__ import annotations

import numpy as np
from numba import njit

from pibr.protocol.depth import DEQUANTIZE, DepthQuantizer
from pibr.protocol.edgecodec.edges import _ctx_a, _ctx_b, _ctx_c, _ctx_d
from pibr.protocol.edgecodec.codec import DecodedSamples, WarpedPrevious
from pibr.protocol.pose import Pose
from pibr.protocol.projection import FORWARD, INVERSE

#: (row, column) parity of the edge coder's passes A, B, C, D.
PASS_PHASES = ((0, 0), (1, 1), (1, 0), (0, 1))


def _border_pad(c0, c1, c2):
    """Value beyond a border row c0 (c1, c2 inside): linear extrapolation where c2, c1, c0 lie on a
    line (up to quantization), else c0 repeated, so a step right at the border still shows."""
    linear = np.abs(c0 - 2 * c1 + c2) <= 2
    return np.where(linear, 2 * c0 - c1, c0)


def laplacian_numpy(codes) -> np.ndarray:
    """The definition of ``codec.laplacian`` in numpy (the tests hold the compiled one to it)."""
    c = np.asarray(codes, dtype=np.int32)
    h, w = c.shape
    p = np.pad(c, 1, mode="edge")
    if h >= 3:
        p[0, 1:-1] = _border_pad(c[0], c[1], c[2])
        p[-1, 1:-1] = _border_pad(c[-1], c[-2], c[-3])
    if w >= 3:
        p[1:-1, 0] = _border_pad(c[:, 0], c[:, 1], c[:, 2])
        p[1:-1, -1] = _border_pad(c[:, -1], c[:, -2], c[:, -3])
    return p[:-2, 1:-1] + p[2:, 1:-1] + p[1:-1, :-2] + p[1:-1, 2:] - 4 * c


def _rotate(m, x, y, z):
    """Rows of m (3, 3) applied to vectors (x, y, z) (n,), written out so no BLAS reorders the sums."""
    return (m[0, 0] * x + m[0, 1] * y + m[0, 2] * z,
            m[1, 0] * x + m[1, 1] * y + m[1, 2] * z,
            m[2, 0] * x + m[2, 1] * y + m[2, 2] * z)


def warp_samples_numpy(samples: DecodedSamples, prev_pose: Pose, cur_pose: Pose,
                       quantizer: DepthQuantizer) -> WarpedPrevious:
    """The definition of ``codec.warp_samples`` in numpy (the tests hold the compiled one to it).

    Forward-splat the previous frame's decoded edge samples into the current wide-angle view.

    Each edge sample is unprojected through its pixel centre at its decoded distance (sky: a
    direction at infinity), moved from ``prev_pose`` to ``cur_pose`` (camera-to-world poses),
    projected, and splatted to the pixel containing it with its re-quantized code; where
    several land on one pixel the nearest (largest code) wins. Pure numpy, elementwise
    IEEE operations only, so encoder and decoder get identical results.
    """
    h, w = samples.shape
    values = np.full(h * w, -1, dtype=np.int32)
    ys, xs = np.nonzero(samples.edges)
    if len(ys):
        code = samples.codes[ys, xs].astype(np.float64)
        tx = (xs + 0.5) / w * 2.0 - 1.0
        ty = 1.0 - (ys + 0.5) / h * 2.0
        dx, dy, dz = INVERSE.numpy(vx=tx, vy=ty)
        mc = float(quantizer.max_code)
        r = DEQUANTIZE.numpy(code=code, near=quantizer.near, far=quantizer.far, min_code=float(quantizer.min_code),
                             max_code=mc)
        sky = r <= 0.0
        r = np.where(sky, 1.0, r)
        r_prev, r_cur = prev_pose.rotation(), cur_pose.rotation()
        # world = R_prev p + t_prev; current camera = R_cur^T (world - t_cur); sky: rotation only
        wx, wy, wz = _rotate(r_prev, dx * r, dy * r, dz * r)
        t = np.asarray(prev_pose.position) - np.asarray(cur_pose.position)
        wx = np.where(sky, wx, wx + t[0])
        wy = np.where(sky, wy, wy + t[1])
        wz = np.where(sky, wz, wz + t[2])
        cx, cy, cz = _rotate(r_cur.T, wx, wy, wz)
        px, py, dist = FORWARD.numpy(px=cx, py=cy, pz=cz)
        col = np.floor((px + 1.0) * 0.5 * w).astype(np.int64)
        row = np.floor((1.0 - py) * 0.5 * h).astype(np.int64)
        keep = (cz <= 0.0) & (col >= 0) & (col < w) & (row >= 0) & (row < h)
        new = quantizer.quantize(np.where(sky, 0.0, dist)).astype(np.int32)
        np.maximum.at(values, row[keep] * w + col[keep], new[keep])
    values = values.reshape(h, w)
    return WarpedPrevious(edges=values >= 0, values=values)


@njit(cache=True, nogil=True)
def ctx_pass(img, tc, phase, y, x, big):
    """Context of padded pixel (y, x) in pass ``phase`` (0..3 = A..D) of the four-pass order, as
    the edge coder's loops dispatch it (written out there: through this call a 1024² edge image
    coded 1.05-1.6x slower).

    ``big``: the larger templates (intra frames); else the smaller ones (with a temporal
    context, which carries most of the information and learns faster in fewer contexts).
    """
    if phase == 0:
        return _ctx_a(img, tc, y, x, big)
    if phase == 1:
        return _ctx_b(img, tc, y, x, big)
    if phase == 2:
        return _ctx_c(img, tc, y, x, big)
    return _ctx_d(img, tc, y, x, big)
