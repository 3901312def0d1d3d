"""Context-adaptive binary arithmetic coding: a range coder plus adaptive bit and integer models.

The coder is a set of numba kernels (``enc_*`` / ``dec_*`` / ``model_*`` functions below) with
its state in a tuple and the model in an array, which the edge, value, regular-sample and motion
coders call from their own compiled loops. In hot loops write ``model_p1`` -> ``enc_raw`` ->
``model_update`` out (as the edge coder's loops do): an ``enc_bit`` wrapper measured 3x slower
there (~50 instead of ~150 M symbols/s). perf shows why: a call that numba does not let LLVM
inline and that passes arrays updates their reference counts (atomic instructions) on the way in
and out, and ``inline='always'`` keeps those updates. So the integer coders (``enc_sint`` ...)
write their bins out the same way, flat.

The specification is a short, readable pure-Python reference of the same bitstream
(``RangeEncoder``, ``RangeDecoder``, ``AdaptiveBitModel``, ``encode_sint`` ... in
``tests/protocol/arith_reference.py``, beside compiled drivers of these kernels); the kernels
give identical bytes (``tests/protocol/test_edgecodec.py`` checks it), and so do they run as
plain Python (``NUMBA_DISABLE_JIT=1``), which is why they cast every array element to ``int``
before arithmetic (numpy scalars would wrap around).

**Coder.** LZMA's carry-less range coder with 32-bit range and a byte cache for carries. A bit is
coded with ``p1``, the probability that it is 1, in units of 2^-15 (1..32767): 1 takes the low
``(range >> 15) * p1`` part of the interval. The first output byte of this coder is always 0
and is not stored; the final flush's trailing zero bytes (at most 4) are not stored either: the
decoder reads zeros past the end. So the decoder reads at most 4 bytes past the end of a valid
section; more, or a code value outside the interval, is reported as corruption.

**Model** (separate from the coder). Per context two estimators of P(1), 20-bit fixed point,
updated by shifts: a fast one (rate up to 1/16) and a slow one (up to 1/128); the coding
probability is their mean. Both start at 1/2 (or a caller's prior) and begin with faster rates
(1/2, 1/4, ..., a running average) while the context's use count is small, so rare contexts
learn quickly.
The lowest probability reachable is 2^-15: a near-certain bit costs under 1e-4 bits.

**Integers** are binarised: a zero flag, a sign (signed variant), then |v| - 1 as exp-Golomb
(order 0): the exponent k in unary with one context per position, the mantissa's top bit with
one context per k, its other bits at probability 1/2. One integer *slot* is ``INT_SLOT``
consecutive contexts; callers pick a slot from their own context (e.g. local activity).
"""
from __future__ import annotations

import numpy as np
from numba import config, njit, types
from numba.core import cgutils
from numba.extending import intrinsic
from numba.np.arrayobj import make_array

PROB_BITS = 15
#: Probability 1/2 in the coder's units; also the probability of bypass bits.
HALF_P = 1 << (PROB_BITS - 1)
STATE_BITS = 20
STATE_ONE = 1 << STATE_BITS
STATE_HALF = 1 << (STATE_BITS - 1)
_MIX_SHIFT = STATE_BITS + 1 - PROB_BITS
FAST_MAX_SHIFT = 4
SLOW_MAX_SHIFT = 7
COUNT_MAX = 255
TOP = 1 << 24
MASK32 = 0xFFFFFFFF
#: The decoder may read this many zero bytes past a section's end (the stripped flush).
MAX_OVERRUN = 4

#: Exp-Golomb exponents above this are not representable (|v| < 2^(KMAX + 1)).
KMAX = 20
#: Contexts per integer slot: zero flag, sign, KMAX unary bins, KMAX + 1 mantissa top bits.
INT_SLOT = 2 + KMAX + KMAX + 1
_UNARY0 = 2
_MANT0 = 2 + KMAX

#: Adaptation shift by use count: floor(log2(n + 2)), i.e. close to a running average 1/(n + 2).
RATE_SHIFT = np.array([min(int(np.log2(n + 2)), SLOW_MAX_SHIFT) for n in range(COUNT_MAX + 1)], dtype=np.int32)


# --------------------------------------------------------------------------------------------
# numba kernels: the coder with its state in a tuple (kept in registers by LLVM)
# --------------------------------------------------------------------------------------------
#
# Encoder state ``es = (low, range, cache, cache_size, bytes written)``, output into a uint8
# buffer (bytes past its end are counted, not written: retry with a larger buffer).
# Decoder state ``ds = (code, range, read position, error flag)``. Every function returns the
# new state (and the decoded value): ``es = enc_raw(es, buf, bit, p1)``,
# ``ds, bit = dec_raw(ds, data, p1)``, ``es = enc_sint(es, buf, m, rate, base, v)``. ``m`` is a
# model from :func:`new_model`, ``rate`` is :data:`RATE_SHIFT`.

def new_model(n: int, p1=None, count: int = 0) -> np.ndarray:
    """State of ``n`` adaptive contexts for the kernels: (n, 3) int32 (fast, slow, count).

    p1 : optional (n,) initial P(1) per context in (0, 1) (a prior; default 1/2); count : the
    initial use count, i.e. how much the prior is trusted (higher: slower first updates).
    """
    m = np.empty((n, 3), dtype=np.int32)
    if p1 is None:
        m[:, 0] = STATE_HALF
        m[:, 1] = STATE_HALF
    else:
        p = np.clip(np.round(np.asarray(p1, dtype=np.float64) * STATE_ONE), 1, STATE_ONE - 1).astype(np.int32)
        m[:, 0] = p
        m[:, 1] = p
    m[:, 2] = min(max(int(count), 0), COUNT_MAX)
    return m


def encoder_bytes(es, buf: np.ndarray) -> bytes | None:
    """The finished stream of a flushed encoder, or None when ``buf`` was too small (need ``es[4]``)."""
    n = int(es[4])
    if n > len(buf):
        return None
    out = buf[1:n]
    k = len(out)
    while k > 0 and len(out) - k < MAX_OVERRUN and out[k - 1] == 0:
        k -= 1
    return out[:k].tobytes()


def as_data(data) -> np.ndarray:
    """bytes-like -> (n,) uint8 array without copying."""
    if isinstance(data, np.ndarray):
        return data
    return np.frombuffer(data, dtype=np.uint8)


def decoder_ok(ds, data: np.ndarray) -> bool:
    """True when the decoder saw no corruption and stopped where a valid stream ends."""
    n = len(data)
    return ds[3] == 0 and n <= ds[2] <= n + MAX_OVERRUN


@intrinsic
def unmanaged(typingctx, arr):
    """A view of array ``arr`` (same data, shape and strides) without its memory-info.

    Compiled functions update the reference count of every array they are passed, with an
    atomic instruction, on entry and exit; numba prunes those pairs only in call-free code,
    and a coded bit calls into the coder with the output buffer (perf: ~20 % of the value
    coder's time went to these updates). A view without memory-info has nothing to count.
    Only for kernels' local use: the caller's array must outlive the view, and the view
    must not be returned.
    """
    if not isinstance(arr, types.Array):
        return None

    def codegen(context, builder, sig, args):
        ary = make_array(arr)(context, builder, value=args[0])
        ary.meminfo = cgutils.get_null_value(ary.meminfo.type)
        ary.parent = cgutils.get_null_value(ary.parent.type)
        return ary._getvalue()

    return arr(arr), codegen


if config.DISABLE_JIT:  # the kernels run as plain Python: nothing is reference-counted
    def unmanaged(arr):  # noqa: F811
        return arr


@njit(cache=True, nogil=True)
def model_p1(m, ctx):
    p = (int(m[ctx, 0]) + int(m[ctx, 1])) >> _MIX_SHIFT
    return min(max(p, 1), 32767)


@njit(cache=True, nogil=True)
def model_update(m, ctx, bit, rate):
    n = int(m[ctx, 2])
    s = int(rate[n])
    sf = s if s < FAST_MAX_SHIFT else FAST_MAX_SHIFT
    pf = int(m[ctx, 0])
    ps = int(m[ctx, 1])
    if bit:
        pf += (STATE_ONE - pf) >> sf
        ps += (STATE_ONE - ps) >> s
    else:
        pf -= pf >> sf
        ps -= ps >> s
    m[ctx, 0] = pf
    m[ctx, 1] = ps
    if n < COUNT_MAX:
        m[ctx, 2] = n + 1


@njit(cache=True, nogil=True)
def enc_start():
    return (0, MASK32, 0, 1, 0)


@njit(cache=True, nogil=True)
def _shift_low(low, cache, csize, pos, buf):
    if low < 0xFF000000 or low > MASK32:
        carry = low >> 32
        temp = cache
        while True:
            if pos < len(buf):
                buf[pos] = (temp + carry) & 0xFF
            pos += 1
            temp = 0xFF
            csize -= 1
            if csize == 0:
                break
        cache = (low >> 24) & 0xFF
    return (low & 0x00FFFFFF) << 8, cache, csize + 1, pos


@njit(cache=True, nogil=True)
def enc_raw(es, buf, bit, p1):
    """Code one bit with probability ``p1`` (2^-15 units) of a 1, no model."""
    low, rng, cache, csize, pos = es
    bound = (rng >> PROB_BITS) * p1
    if bit:
        rng = bound
    else:
        low += bound
        rng -= bound
    while rng < TOP:
        rng <<= 8
        low, cache, csize, pos = _shift_low(low, cache, csize, pos, buf)
    return (low, rng, cache, csize, pos)


@njit(cache=True, nogil=True)
def enc_finish(es, buf):
    low, rng, cache, csize, pos = es
    for _ in range(5):
        low, cache, csize, pos = _shift_low(low, cache, csize, pos, buf)
    return (low, rng, cache, csize, pos)


@njit(cache=True, nogil=True)
def enc_sint(es, buf, m, rate, base, v):
    """Code |v| < 2^(KMAX + 1) with the integer slot at context ``base``.

    One flat function (the magnitude's bins written out here too): nested calls that pass
    the buffer and model arrays cost numba reference-count updates (atomic) per call, which
    made a coded integer ~3x dearer than its bins (measured with perf)."""
    z = 1 if v == 0 else 0
    es = enc_raw(es, buf, z, model_p1(m, base))
    model_update(m, base, z, rate)
    if z:
        return es
    neg = 1 if v < 0 else 0
    es = enc_raw(es, buf, neg, model_p1(m, base + 1))
    model_update(m, base + 1, neg, rate)
    a = abs(v)
    k = 0
    while (a >> (k + 1)) != 0:
        k += 1
    for i in range(k + 1):
        if i == KMAX:
            break
        b = 1 if i < k else 0
        c = base + _UNARY0 + i
        es = enc_raw(es, buf, b, model_p1(m, c))
        model_update(m, c, b, rate)
    r = a - (1 << k)
    for i in range(k - 1, -1, -1):
        b = (r >> i) & 1
        if i == k - 1:
            c = base + _MANT0 + k
            es = enc_raw(es, buf, b, model_p1(m, c))
            model_update(m, c, b, rate)
        else:
            es = enc_raw(es, buf, b, HALF_P)
    return es


@njit(cache=True, nogil=True)
def dec_start(data):
    code = 0
    for i in range(4):
        code = (code << 8) | (int(data[i]) if i < len(data) else 0)
    return (code, MASK32, 4, 0)


@njit(cache=True, nogil=True)
def dec_raw(ds, data, p1):
    code, rng, pos, err = ds
    bound = (rng >> PROB_BITS) * p1
    if code < bound:
        rng = bound
        bit = 1
    else:
        code -= bound
        rng -= bound
        bit = 0
    while rng < TOP:
        rng <<= 8
        b = int(data[pos]) if pos < len(data) else 0
        pos += 1
        code = ((code << 8) | b) & MASK32
    if code >= rng or pos > len(data) + MAX_OVERRUN:
        err = 1
    return (code, rng, pos, err), bit


@njit(cache=True, nogil=True)
def dec_sint(ds, data, m, rate, base):
    """Decoder of :func:`enc_sint`, as flat as it (same reason)."""
    ds, z = dec_raw(ds, data, model_p1(m, base))
    model_update(m, base, z, rate)
    if z == 1:
        return ds, 0
    ds, neg = dec_raw(ds, data, model_p1(m, base + 1))
    model_update(m, base + 1, neg, rate)
    k = 0
    while k < KMAX:
        c = base + _UNARY0 + k
        ds, b = dec_raw(ds, data, model_p1(m, c))
        model_update(m, c, b, rate)
        if b == 0:
            break
        k += 1
    r = 0
    for i in range(k - 1, -1, -1):
        if i == k - 1:
            c = base + _MANT0 + k
            ds, b = dec_raw(ds, data, model_p1(m, c))
            model_update(m, c, b, rate)
        else:
            ds, b = dec_raw(ds, data, HALF_P)
        r = (r << 1) | b
    v = r + (1 << k)
    return ds, (-v if neg == 1 else v)
