"""Coding of the edge samples' values (Pajak et al. 2011, Sec. 4.2): predicted, quantized residuals.

Samples are visited in raster order over the decoded edge image. Per sample:

1. **Laplacian sign** (which side of a discontinuity the sample lies on), one adaptive bit;
   context: the signs of the already coded W, N, NW, NE samples (none / - / +) and whether
   the E and S pixels are edges.
2. **Prediction** from one of ``N_PREDICTORS`` candidates, all from data the decoder has:

   ====  ==========================================================================
   W N   the left / upper sample, if it has the same sign (same surface)
   NW NE the diagonal upper samples, same sign
   W2    linear extrapolation 2 W - WW along the row (both same sign)
   N2    linear extrapolation 2 N - NN along the column (both same sign)
   W3 N3 the least-squares line through three samples along the row / column (less noise)
   NW2   2 NW - NWNW and 2 NE - NENE along the diagonals
   NE2
   F     the nearest same-sign sample beyond the 3x3 (a causal window of radius 3)
   T     the previous frame's decoded value warped to this pixel (temporal)
   Wx Nx the left / upper sample of any sign (across a crease the value is continuous)
   R     the nearest regular sample (always available)
   P     the plane W + N - NW (all three same sign)
   ====  ==========================================================================

   The choice is *learnt* per 3x3 edge configuration (the 8 neighbours' edge bits, known to
   the decoder from the edge image): every configuration keeps, per predictor, a decaying sum
   of that predictor's past absolute errors, and the available predictor with the smallest
   sum is used. Encoder and decoder update the sums identically from decoded values.
3. **Residual** ``v - prediction`` quantized by the step ``q`` (q = 1: lossless) and coded as
   an adaptive integer (:mod:`.arith`) whose context is the kind of predictor (axial or
   diagonal same-sign neighbour, temporal, further same-sign sample, other sign or regular
   sample) and the local activity (the residual sizes of the W, N, NW, NE samples plus the
   spread of the same-sign W, N, NW, NE values).

Measured on a 1024^2 room frame (43 k samples): 3.1 bits per value, 0.36 of them for the sign.
Weighting several predictors by their error sums (instead of picking one) coded 2 % larger.

With q > 1 the encoder runs the decoder's reconstruction (closed loop) and keeps sky exact:
a sky code (0) always decodes to 0 and a surface code never decodes to 0.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .arith import (INT_SLOT, RATE_SHIFT, as_data, dec_raw, dec_sint, dec_start, decoder_ok, enc_finish, enc_raw,
                    enc_sint, enc_start, encoder_bytes, model_p1, model_update, new_model, unmanaged)

PAD = 3
N_PREDICTORS = 16
_T, _R = 6, 9
#: Residual context kind per predictor: 0 axial same sign, 1 diagonal same sign, 2 temporal,
#: 3 nearest same sign further away, 4 other sign or regular sample.
_KIND = np.array([0, 0, 1, 1, 0, 0, 2, 4, 4, 4, 0, 1, 1, 3, 0, 0], dtype=np.int64)
#: Causal offsets searched (in this order) for predictor F, the nearest same-sign sample beyond the 3x3.
_FAR = np.array([(0, -2), (-2, 0), (-1, -2), (-1, 2), (-2, -1), (-2, 1), (-2, -2), (-2, 2), (0, -3), (-3, 0),
                 (-1, -3), (-1, 3), (-3, -1), (-3, 1), (-2, -3), (-2, 3), (-3, -2), (-3, 2)], dtype=np.int64)
_N_SIGN_CTX = 324
_N_BUCKETS = 7
_N_KINDS = 5
N_CONTEXTS = _N_SIGN_CTX + _N_KINDS * _N_BUCKETS * INT_SLOT
#: Error sums decay by 1/2^_SCORE_SHIFT per use; single errors are capped.
_SCORE_SHIFT = 4
_ERR_CAP = 1023
#: Initial error sums: a tie-break order until errors are learnt (same-sign neighbours first).
_PRIOR = np.array([0, 1, 3, 4, 5, 6, 2, 8, 9, 15, 7, 10, 11, 12, 13, 14], dtype=np.int32)


@njit(cache=True, nogil=True)
def quantize_residual(v, pred, q, max_code):
    """(quantized residual, reconstruction) of true code v predicted as pred, step q; keeps sky (0) exact."""
    r = v - pred
    # round half towards zero: with q = 2 a residual of +-1 costs nothing
    if r >= 0:
        rq = (r + (q - 1) // 2) // q
    else:
        rq = -((-r + (q - 1) // 2) // q)
    rec = min(max(pred + rq * q, 0), max_code)
    if v == 0 and rec != 0:
        rq = -((pred + q - 1) // q)
        rec = 0
    elif v != 0 and rec == 0:
        rq = (1 - pred + q - 1) // q
        rec = min(max(pred + rq * q, 0), max_code)
    return rq, rec


@njit(cache=True, nogil=True)
def reconstruct(pred, rq, q, max_code):
    return min(max(pred + rq * q, 0), max_code)


@njit(cache=True, nogil=True, inline='always')
def _activity_bucket(a):
    if a == 0:
        return 0
    if a <= 2:
        return 1
    if a <= 6:
        return 2
    if a <= 14:
        return 3
    if a <= 30:
        return 4
    if a <= 62:
        return 5
    return 6


@njit(cache=True, nogil=True)
def _code_values(decode, data, buf, E, xs, starts, codes, signs, TV, RG, ri, ci, h, w, q, max_code, m, rate, V, S,
                 A):
    """Encoder (``decode`` False: codes, signs (h, w) true values and signs (+1 / -1) at edges,
    output into ``buf``) and decoder (``decode`` True: from ``data``) of the edge values, one
    loop for both so they cannot drift apart. E: the padded edge image; xs, starts: its edges'
    padded columns row by row (row y's in xs[starts[y]:starts[y + 1]], :func:`_fill_edge_image`),
    so the loop visits the edges only. V, S, A: padded outputs (values, sign codes 1 / 2,
    residual sizes), zero where S is. Returns (encoder state, decoder state).

    Everything per sample is written out in this one function on purpose: helpers that take
    the arrays cost numba reference-count updates (atomic instructions) per call, which perf
    measured at ~40 % of the coder's time; only scalar helpers and the integer coders remain.
    """
    # views without reference counting for the calls into the coder (see arith.unmanaged)
    data, buf, m, rate = unmanaged(data), unmanaged(buf), unmanaged(m), unmanaged(rate)
    es = enc_start()
    ds = dec_start(data)
    scores = np.empty((256, N_PREDICTORS), dtype=np.int32)
    for i in range(256):
        for k in range(N_PREDICTORS):
            scores[i, k] = _PRIOR[k]
    preds = np.zeros(N_PREDICTORS, dtype=np.int64)
    avail = np.zeros(N_PREDICTORS, dtype=np.int64)
    for y in range(PAD, PAD + h):
        for i_edge in range(starts[y - PAD], starts[y - PAD + 1]):
            x = xs[i_edge]
            # 1. the Laplacian sign: context = signs of W, N, NW, NE and whether E, S are edges
            c = (int(S[y, x - 1]) + 3 * int(S[y - 1, x]) + 9 * int(S[y - 1, x - 1]) + 27 * int(S[y - 1, x + 1])
                 + 81 * (int(E[y, x + 1]) + 2 * int(E[y + 1, x])))
            if decode:
                ds, b = dec_raw(ds, data, model_p1(m, c))
            else:
                b = 1 if signs[y - PAD, x - PAD] > 0 else 0
                es = enc_raw(es, buf, b, model_p1(m, c))
            model_update(m, c, b, rate)
            s = 2 if b == 1 else 1
            # 2. the candidate predictions (see the module docstring's table)
            for k in range(N_PREDICTORS):
                avail[k] = 0
            sw = int(S[y, x - 1])
            sn = int(S[y - 1, x])
            snw = int(S[y - 1, x - 1])
            if sw == s:
                preds[0] = V[y, x - 1]
                avail[0] = 1
                if int(S[y, x - 2]) == s:
                    preds[4] = 2 * int(V[y, x - 1]) - int(V[y, x - 2])
                    avail[4] = 1
                    if int(S[y, x - 3]) == s:  # least-squares line through three: less rounding noise
                        preds[14] = (4 * int(V[y, x - 1]) + int(V[y, x - 2]) - 2 * int(V[y, x - 3]) + 1) // 3
                        avail[14] = 1
            if sn == s:
                preds[1] = V[y - 1, x]
                avail[1] = 1
                if int(S[y - 2, x]) == s:
                    preds[5] = 2 * int(V[y - 1, x]) - int(V[y - 2, x])
                    avail[5] = 1
                    if int(S[y - 3, x]) == s:
                        preds[15] = (4 * int(V[y - 1, x]) + int(V[y - 2, x]) - 2 * int(V[y - 3, x]) + 1) // 3
                        avail[15] = 1
            if snw == s:
                preds[2] = V[y - 1, x - 1]
                avail[2] = 1
                if sw == s and sn == s:
                    preds[10] = int(V[y, x - 1]) + int(V[y - 1, x]) - int(V[y - 1, x - 1])
                    avail[10] = 1
                if int(S[y - 2, x - 2]) == s:
                    preds[11] = 2 * int(V[y - 1, x - 1]) - int(V[y - 2, x - 2])
                    avail[11] = 1
            if int(S[y - 1, x + 1]) == s:
                preds[3] = V[y - 1, x + 1]
                avail[3] = 1
                if int(S[y - 2, x + 2]) == s:
                    preds[12] = 2 * int(V[y - 1, x + 1]) - int(V[y - 2, x + 2])
                    avail[12] = 1
            for i in range(len(_FAR)):
                yy = y + _FAR[i, 0]
                xx = x + _FAR[i, 1]
                if int(S[yy, xx]) == s:
                    preds[13] = V[yy, xx]
                    avail[13] = 1
                    break
            t = int(TV[y, x])
            if t >= 0:
                preds[_T] = t
                avail[_T] = 1
            if sw > 0:
                preds[7] = V[y, x - 1]
                avail[7] = 1
            if sn > 0:
                preds[8] = V[y - 1, x]
                avail[8] = 1
            preds[_R] = RG[ri[y - PAD], ci[x - PAD]]
            avail[_R] = 1
            # the predictor with the smallest error sum in this 3x3 edge configuration
            cfg = (int(E[y - 1, x - 1]) | (int(E[y - 1, x]) << 1) | (int(E[y - 1, x + 1]) << 2)
                   | (int(E[y, x - 1]) << 3) | (int(E[y, x + 1]) << 4) | (int(E[y + 1, x - 1]) << 5)
                   | (int(E[y + 1, x]) << 6) | (int(E[y + 1, x + 1]) << 7))
            best = _R
            best_score = scores[cfg, _R]
            for k in range(N_PREDICTORS):
                if avail[k] == 1 and scores[cfg, k] < best_score:
                    best = k
                    best_score = scores[cfg, k]
            pred = min(max(int(preds[best]), 0), max_code)
            # 3. the residual: context = kind of predictor and local activity
            a = int(A[y, x - 1]) + int(A[y - 1, x]) + int(A[y - 1, x - 1]) + int(A[y - 1, x + 1])
            lo = 1 << 30
            hi = -1
            for k in range(4):
                if avail[k] == 1:
                    lo = min(lo, int(preds[k]))
                    hi = max(hi, int(preds[k]))
            if hi >= lo:
                a += hi - lo
            slot = _N_SIGN_CTX + (_KIND[best] * _N_BUCKETS + _activity_bucket(a)) * INT_SLOT
            if decode:
                ds, rq = dec_sint(ds, data, m, rate, slot)
                rec = reconstruct(pred, rq, q, max_code)
            else:
                rq, rec = quantize_residual(int(codes[y - PAD, x - PAD]), pred, q, max_code)
                es = enc_sint(es, buf, m, rate, slot, rq)
            S[y, x] = s
            V[y, x] = rec
            A[y, x] = min(abs(rq), 1 << 16)
            # learn: every available predictor's error, decaying sums
            for k in range(N_PREDICTORS):
                if avail[k] == 1:
                    p = min(max(int(preds[k]), 0), max_code)
                    err = min(abs(rec - p), _ERR_CAP)
                    scores[cfg, k] += err - (scores[cfg, k] >> _SCORE_SHIFT)
        if decode and ds[3] != 0:
            return es, ds
    if not decode:
        es = enc_finish(es, buf)
    return es, ds


@njit(cache=True, nogil=True)
def _unpad_decoded(V, S, codes, signs):
    """Padded decoder outputs -> codes (h, w), 0 where S marks no sample (V may hold a
    workspace's stale values there), and signs (h, w): +1 / -1 for sign codes 2 / 1, else 0."""
    V, S, codes, signs = unmanaged(V), unmanaged(S), unmanaged(codes), unmanaged(signs)
    h, w = codes.shape
    for y in range(h):
        for x in range(w):
            s = S[PAD + y, PAD + x]
            codes[y, x] = V[PAD + y, PAD + x] if s != 0 else 0
            signs[y, x] = 1 if s == 2 else (-1 if s == 1 else 0)


# stand-ins for the arrays one direction of _code_values does not use
_NO_DATA = np.zeros(0, dtype=np.uint8)
_NO_BUF = np.zeros(0, dtype=np.uint8)
_NO_CODES = np.zeros((1, 1), dtype=np.int32)
_NO_SIGNS = np.zeros((1, 1), dtype=np.int8)


@njit(cache=True, nogil=True)
def _temporal_values_kernel(v, out):
    v, out = unmanaged(v), unmanaged(out)
    h, w = v.shape
    for y in range(h):
        for x in range(w):
            out[PAD + y, PAD + x] = v[y, x] if v[y, x] >= 0 else -1


def temporal_values(prev_values, height: int, width: int, out=None) -> np.ndarray:
    """Padded (h + 2 PAD, w + 2 PAD) int32 of warped previous values, -1 where none.

    prev_values : (h, w) int, -1 (or any negative) where the warped previous frame has no sample; or None.
    out : a padded array of this shape whose border is -1 (a :class:`ValueWorkspace`'s), filled
    and returned instead of a new one.
    """
    shape = (height + 2 * PAD, width + 2 * PAD)
    if out is None:
        out = np.full(shape, -1, dtype=np.int32)
    elif out.shape != shape or out.dtype != np.int32:
        raise ValueError(f"out must be {shape} int32, got {out.shape} {out.dtype}")
    elif prev_values is None:
        out.fill(-1)
    if prev_values is None:
        return out
    v = np.asarray(prev_values)
    if v.shape != (height, width):
        raise ValueError(f"warped previous values must have shape ({height}, {width}), got {v.shape}")
    if v.dtype != np.int32:
        v = np.clip(v, -1, np.iinfo(np.int32).max).astype(np.int32)
    _temporal_values_kernel(np.ascontiguousarray(v), out)
    return out


@njit(cache=True, nogil=True)
def _fill_edge_image(edges, E, xs, starts):
    """edges (h, w) bool into the interior of the padded E (uint8), and their padded columns
    row by row into xs (h * w,) and starts (h + 1,); returns the number of edges."""
    edges, E, xs, starts = unmanaged(edges), unmanaged(E), unmanaged(xs), unmanaged(starts)
    h, w = edges.shape
    n = 0
    for y in range(h):
        starts[y] = n
        for x in range(w):
            e = edges[y, x]
            E[PAD + y, PAD + x] = e
            xs[n] = PAD + x  # kept only where e (branch-free compaction)
            n += e
    starts[h] = n
    return n


@njit(cache=True, nogil=True)
def _clear_samples(xs, starts, S, A):
    """Zero S and A at the edges listed in xs, starts: all the coder wrote there (V is read only where S is set)."""
    xs, starts, S, A = unmanaged(xs), unmanaged(starts), unmanaged(S), unmanaged(A)
    for y in range(len(starts) - 1):
        for i in range(starts[y], starts[y + 1]):
            S[PAD + y, xs[i]] = 0
            A[PAD + y, xs[i]] = 0


class ValueWorkspace:
    """The value coder's padded working images for one (h, w), kept from frame to frame: new
    multi-megabyte arrays per frame cost more in page faults and zeroing than coding a frame's
    few percent of edge pixels. Between uses S and A are zero (cleared at the last frame's
    edges); V holds stale values, which the coder reads only where S marks a sample. Not
    for concurrent use."""

    def __init__(self, height: int, width: int):
        shape = (height + 2 * PAD, width + 2 * PAD)
        self.shape = (height, width)
        self.E = np.zeros(shape, dtype=np.uint8)
        self.V = np.zeros(shape, dtype=np.int32)
        self.S = np.zeros(shape, dtype=np.int8)
        self.A = np.zeros(shape, dtype=np.int32)
        self.xs = np.empty(height * width, dtype=np.int32)
        self.starts = np.empty(height + 1, dtype=np.int64)
        self._T = None

    def temporal_values(self, prev_values) -> np.ndarray:
        """:func:`temporal_values` of ``prev_values`` in this workspace's own padded array (valid until the next call)."""
        if self._T is None:
            self._T = np.full(self.E.shape, -1, dtype=np.int32)
        return temporal_values(prev_values, *self.shape, out=self._T)


def encode_values(edges, codes, signs, regular, nearest_rows, nearest_cols, q: int, max_code: int,
                  tvalues=None, workspace: ValueWorkspace | None = None) -> tuple[bytes, np.ndarray]:
    """Code the values of the edge samples.

    edges : (h, w) bool; codes : (h, w) int true codes; signs : (h, w) int, > 0 for a positive
    Laplacian; regular : (rh, rw) decoded regular samples; nearest_rows (h,) / nearest_cols (w,) :
    index of the nearest regular sample per row / column; tvalues : from :func:`temporal_values`;
    workspace : a :class:`ValueWorkspace` of this size to work in (the encoder keeps one).
    Returns (bytes, decoded codes (h, w) int32: what the decoder will reconstruct at the edges,
    0 elsewhere; with a workspace, a view of its V, valid at the edges only and until its next use).
    """
    h, w = edges.shape
    if tvalues is None:
        tvalues = temporal_values(None, h, w)
    codes = np.ascontiguousarray(codes, dtype=np.int32)
    signs = np.ascontiguousarray(signs, dtype=np.int8)
    RG = np.ascontiguousarray(regular, dtype=np.int32)
    if workspace is None:
        workspace = ValueWorkspace(h, w)
        own = True
    else:
        if workspace.shape != (h, w):
            raise ValueError(f"workspace is for {workspace.shape}, edges are {(h, w)}")
        own = False
    ws = workspace
    n = _fill_edge_image(np.ascontiguousarray(edges, dtype=bool), ws.E, ws.xs, ws.starts)
    capacity = 2 * n + 256
    try:
        while True:
            buf = np.zeros(capacity, dtype=np.uint8)
            es, _ = _code_values(False, _NO_DATA, buf, ws.E, ws.xs, ws.starts, codes, signs, tvalues, RG,
                                 nearest_rows, nearest_cols, h, w, q, max_code, new_model(N_CONTEXTS), RATE_SHIFT,
                                 ws.V, ws.S, ws.A)
            out = encoder_bytes(es, buf)
            if out is not None:
                break
            capacity = int(es[4]) + 16
            _clear_samples(ws.xs, ws.starts, ws.S, ws.A)
    finally:
        if not own:
            _clear_samples(ws.xs, ws.starts, ws.S, ws.A)
    return out, (ws.V[PAD:-PAD, PAD:-PAD] if not own else ws.V[PAD:-PAD, PAD:-PAD].copy())


def decode_values(data, edges, regular, nearest_rows, nearest_cols, q: int, max_code: int,
                  tvalues=None, workspace: ValueWorkspace | None = None) -> tuple[np.ndarray, np.ndarray, bool]:
    """-> (codes (h, w) int32, 0 but at decoded edges, signs (h, w) int8 in {-1, 0, +1}, stream
    decoded cleanly). workspace : a :class:`ValueWorkspace` of this size to work in (the decoder keeps one)."""
    h, w = edges.shape
    if workspace is None:
        ws = ValueWorkspace(h, w)
    elif workspace.shape != (h, w):
        raise ValueError(f"workspace is for {workspace.shape}, edges are {(h, w)}")
    else:
        ws = workspace
    _fill_edge_image(np.ascontiguousarray(edges, dtype=bool), ws.E, ws.xs, ws.starts)
    if tvalues is None:
        tvalues = temporal_values(None, h, w)
    arr = as_data(data)
    codes = np.empty((h, w), dtype=np.int32)
    signs = np.empty((h, w), dtype=np.int8)
    try:
        _, ds = _code_values(True, arr, _NO_BUF, ws.E, ws.xs, ws.starts, _NO_CODES, _NO_SIGNS, tvalues,
                             np.ascontiguousarray(regular, dtype=np.int32), nearest_rows, nearest_cols, h, w, q,
                             max_code, new_model(N_CONTEXTS), RATE_SHIFT, ws.V, ws.S, ws.A)
        _unpad_decoded(ws.V, ws.S, codes, signs)
    finally:
        if workspace is not None:
            _clear_samples(ws.xs, ws.starts, ws.S, ws.A)
    return codes, signs, decoder_ok(ds, arr)
