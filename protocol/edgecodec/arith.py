"""Context-adaptive binary arithmetic coding: a range coder plus adaptive bit and integer models.

Two implementations of one bitstream:

* a pure-Python reference (:class:`RangeEncoder`, :class:`RangeDecoder`, :class:`AdaptiveBitModel`,
  :func:`encode_uint` ...), short and readable, for tests and as the specification;
* numba kernels (``enc_*`` / ``dec_*`` / ``model_*`` functions below) with the coder state in a
  tuple and the model in an array, which the edge, value, regular-sample and motion coders
  call from their own compiled loops. In hot loops write ``model_p1`` -> ``enc_raw`` ->
  ``model_update`` out (as ``_encode_bits_kernel`` does): the ``enc_bit`` wrapper measured
  3x slower there (~50 instead of ~150 M symbols/s). perf shows why: a call that numba does
  not let LLVM inline and that passes arrays updates their reference counts (atomic
  instructions) on the way in and out, and ``inline='always'`` keeps those updates. So the
  integer coders (``enc_sint`` ...) write their bins out the same way, flat.

Both produce identical bytes (``tests/protocol/test_edgecodec.py`` checks it); so do the
kernels run as plain Python (``NUMBA_DISABLE_JIT=1``), which is why they cast every array
element to ``int`` before arithmetic (numpy scalars would wrap around).

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
_RATE_SHIFT_PY = [int(x) for x in RATE_SHIFT]


# --------------------------------------------------------------------------------------------
# Pure-Python reference
# --------------------------------------------------------------------------------------------

class AdaptiveBitModel:
    """Adaptive probabilities of ``n`` binary contexts (the entropy model, no coding)."""

    def __init__(self, n: int):
        self.fast = [STATE_HALF] * n
        self.slow = [STATE_HALF] * n
        self.count = [0] * n

    @classmethod
    def from_state(cls, m: np.ndarray) -> "AdaptiveBitModel":
        """The model whose state is ``m`` (n, 3), as :func:`new_model` builds it (e.g. with priors)."""
        model = cls(0)
        model.fast, model.slow, model.count = (m[:, i].astype(int).tolist() for i in range(3))
        return model

    def p1(self, ctx: int) -> int:
        """P(bit = 1) of context ``ctx`` in units of 2^-15, in 1..32767."""
        p = (self.fast[ctx] + self.slow[ctx]) >> _MIX_SHIFT
        return 1 if p < 1 else (32767 if p > 32767 else p)

    def update(self, ctx: int, bit: int) -> None:
        s = _RATE_SHIFT_PY[self.count[ctx]]
        sf = s if s < FAST_MAX_SHIFT else FAST_MAX_SHIFT
        if bit:
            self.fast[ctx] += (STATE_ONE - self.fast[ctx]) >> sf
            self.slow[ctx] += (STATE_ONE - self.slow[ctx]) >> s
        else:
            self.fast[ctx] -= self.fast[ctx] >> sf
            self.slow[ctx] -= self.slow[ctx] >> s
        if self.count[ctx] < COUNT_MAX:
            self.count[ctx] += 1


class RangeEncoder:
    """Range encoder (reference). ``encode_bit(bit, p1)``, then ``finish() -> bytes``."""

    def __init__(self):
        self.low = 0
        self.range = MASK32
        self.cache = 0
        self.cache_size = 1
        self.out = bytearray()

    def _shift_low(self) -> None:
        if self.low < 0xFF000000 or self.low > MASK32:
            carry = self.low >> 32
            temp = self.cache
            while True:
                self.out.append((temp + carry) & 0xFF)
                temp = 0xFF
                self.cache_size -= 1
                if self.cache_size == 0:
                    break
            self.cache = (self.low >> 24) & 0xFF
        self.cache_size += 1
        self.low = (self.low & 0x00FFFFFF) << 8

    def encode_bit(self, bit: int, p1: int) -> None:
        bound = (self.range >> PROB_BITS) * p1
        if bit:
            self.range = bound
        else:
            self.low += bound
            self.range -= bound
        while self.range < TOP:
            self.range <<= 8
            self._shift_low()

    def finish(self) -> bytes:
        for _ in range(5):
            self._shift_low()
        out = self.out[1:]  # the first byte is always 0
        n = len(out)
        while n > 0 and len(out) - n < MAX_OVERRUN and out[n - 1] == 0:
            n -= 1
        return bytes(out[:n])


class RangeDecoder:
    """Range decoder (reference) over ``data``; ``error`` is set on detected corruption."""

    def __init__(self, data: bytes):
        self.data = bytes(data)
        self.pos = 0
        self.range = MASK32
        self.code = 0
        self.error = False
        for _ in range(4):
            self.code = (self.code << 8) | self._byte()

    def _byte(self) -> int:
        b = self.data[self.pos] if self.pos < len(self.data) else 0
        self.pos += 1
        return b

    def decode_bit(self, p1: int) -> int:
        bound = (self.range >> PROB_BITS) * p1
        if self.code < bound:
            self.range = bound
            bit = 1
        else:
            self.code -= bound
            self.range -= bound
            bit = 0
        while self.range < TOP:
            self.range <<= 8
            self.code = ((self.code << 8) | self._byte()) & MASK32
        if self.code >= self.range or self.pos > len(self.data) + MAX_OVERRUN:
            self.error = True
        return bit

    def check_end(self) -> bool:
        """True when the stream ended where a valid stream of this length ends."""
        return not self.error and len(self.data) <= self.pos <= len(self.data) + MAX_OVERRUN


def encode_bit(enc: RangeEncoder, model: AdaptiveBitModel, ctx: int, bit: int) -> None:
    enc.encode_bit(bit, model.p1(ctx))
    model.update(ctx, bit)


def decode_bit(dec: RangeDecoder, model: AdaptiveBitModel, ctx: int) -> int:
    bit = dec.decode_bit(model.p1(ctx))
    model.update(ctx, bit)
    return bit


def _encode_magnitude(enc, model, base, m):
    """Exp-Golomb (order 0) of m >= 0 with adaptive unary and mantissa-top contexts."""
    k = (m + 1).bit_length() - 1
    for i in range(k):
        encode_bit(enc, model, base + _UNARY0 + i, 1)
    if k < KMAX:
        encode_bit(enc, model, base + _UNARY0 + k, 0)
    r = m + 1 - (1 << k)
    for i in range(k - 1, -1, -1):
        b = (r >> i) & 1
        if i == k - 1:
            encode_bit(enc, model, base + _MANT0 + k, b)
        else:
            enc.encode_bit(b, HALF_P)


def _decode_magnitude(dec, model, base):
    k = 0
    while k < KMAX and decode_bit(dec, model, base + _UNARY0 + k):
        k += 1
    r = 0
    for i in range(k - 1, -1, -1):
        b = decode_bit(dec, model, base + _MANT0 + k) if i == k - 1 else dec.decode_bit(HALF_P)
        r = (r << 1) | b
    return r + (1 << k) - 1


def encode_uint(enc: RangeEncoder, model: AdaptiveBitModel, base: int, v: int) -> None:
    """Code v in 0..2^(KMAX+1)-1 with the integer slot starting at context ``base``."""
    encode_bit(enc, model, base, 1 if v == 0 else 0)
    if v:
        _encode_magnitude(enc, model, base, v - 1)


def decode_uint(dec: RangeDecoder, model: AdaptiveBitModel, base: int) -> int:
    if decode_bit(dec, model, base):
        return 0
    return _decode_magnitude(dec, model, base) + 1


def encode_sint(enc: RangeEncoder, model: AdaptiveBitModel, base: int, v: int) -> None:
    """Code a signed v, |v| < 2^(KMAX+1), with the integer slot at ``base``."""
    encode_bit(enc, model, base, 1 if v == 0 else 0)
    if v:
        encode_bit(enc, model, base + 1, 1 if v < 0 else 0)
        _encode_magnitude(enc, model, base, abs(v) - 1)


def decode_sint(dec: RangeDecoder, model: AdaptiveBitModel, base: int) -> int:
    if decode_bit(dec, model, base):
        return 0
    neg = decode_bit(dec, model, base + 1)
    m = _decode_magnitude(dec, model, base) + 1
    return -m if neg else m


# --------------------------------------------------------------------------------------------
# numba kernels: the same coder with its state in a tuple (kept in registers by LLVM)
# --------------------------------------------------------------------------------------------
#
# Encoder state ``es = (low, range, cache, cache_size, bytes written)``, output into a uint8
# buffer (bytes past its end are counted, not written: retry with a larger buffer).
# Decoder state ``ds = (code, range, read position, error flag)``. Every function returns the
# new state (and the decoded value): ``es = enc_bit(es, buf, m, rate, ctx, bit)``,
# ``ds, bit = dec_bit(ds, data, m, rate, ctx)``. ``m`` is a model from :func:`new_model`,
# ``rate`` is :data:`RATE_SHIFT`.

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
def enc_bit(es, buf, m, rate, ctx, bit):
    es = enc_raw(es, buf, bit, model_p1(m, ctx))
    model_update(m, ctx, bit, rate)
    return es


@njit(cache=True, nogil=True)
def _enc_magnitude(es, buf, m, rate, base, mag):
    # model_p1 -> enc_raw -> model_update written out rather than enc_bit (see the module docstring)
    v = mag + 1
    k = 0
    while (v >> (k + 1)) != 0:
        k += 1
    for i in range(k + 1):
        if i == KMAX:
            break
        b = 1 if i < k else 0
        c = base + _UNARY0 + i
        es = enc_raw(es, buf, b, model_p1(m, c))
        model_update(m, c, b, rate)
    r = v - (1 << k)
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
def enc_uint(es, buf, m, rate, base, v):
    """Code 0 <= v < 2^(KMAX + 1) with the integer slot at context ``base``."""
    z = 1 if v == 0 else 0
    es = enc_raw(es, buf, z, model_p1(m, base))
    model_update(m, base, z, rate)
    if z:
        return es
    return _enc_magnitude(es, buf, m, rate, base, v - 1)


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
def dec_bit(ds, data, m, rate, ctx):
    ds, bit = dec_raw(ds, data, model_p1(m, ctx))
    model_update(m, ctx, bit, rate)
    return ds, bit


@njit(cache=True, nogil=True)
def _dec_magnitude(ds, data, m, rate, base):
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
    return ds, r + (1 << k) - 1


@njit(cache=True, nogil=True)
def dec_uint(ds, data, m, rate, base):
    ds, z = dec_raw(ds, data, model_p1(m, base))
    model_update(m, base, z, rate)
    if z == 1:
        return ds, 0
    ds, v = _dec_magnitude(ds, data, m, rate, base)
    return ds, v + 1


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


# --------------------------------------------------------------------------------------------
# Operation streams: drive either implementation with the same symbols (tests, benchmarks)
# --------------------------------------------------------------------------------------------

#: Kinds of operations in a stream: a modelled bit, a bypass bit, an unsigned and a signed integer.
OP_BIT, OP_RAW, OP_UINT, OP_SINT = 0, 1, 2, 3


def encode_ops_python(kinds, ctxs, values, n_contexts: int) -> bytes:
    """Reference: code ops (n,) of ``kinds`` with contexts (n,) (integer slot bases) and values (n,)."""
    enc, model = RangeEncoder(), AdaptiveBitModel(n_contexts)
    for kind, ctx, v in zip(kinds.tolist(), ctxs.tolist(), values.tolist()):
        if kind == OP_BIT:
            encode_bit(enc, model, ctx, v)
        elif kind == OP_RAW:
            enc.encode_bit(v, HALF_P)
        elif kind == OP_UINT:
            encode_uint(enc, model, ctx, v)
        else:
            encode_sint(enc, model, ctx, v)
    return enc.finish()


def decode_ops_python(data: bytes, kinds, ctxs, n_contexts: int) -> tuple[np.ndarray, bool]:
    """Reference decoder of :func:`encode_ops_python`: (values (n,) int64, stream ended cleanly)."""
    dec, model = RangeDecoder(data), AdaptiveBitModel(n_contexts)
    out = []
    for kind, ctx in zip(kinds.tolist(), ctxs.tolist()):
        if kind == OP_BIT:
            out.append(decode_bit(dec, model, ctx))
        elif kind == OP_RAW:
            out.append(dec.decode_bit(HALF_P))
        elif kind == OP_UINT:
            out.append(decode_uint(dec, model, ctx))
        else:
            out.append(decode_sint(dec, model, ctx))
    return np.array(out, dtype=np.int64), dec.check_end()


@njit(cache=True, nogil=True)
def _encode_ops_kernel(buf, m, rate, kinds, ctxs, values):
    es = enc_start()
    for i in range(len(kinds)):
        kind = kinds[i]
        if kind == OP_BIT:
            es = enc_bit(es, buf, m, rate, ctxs[i], values[i])
        elif kind == OP_RAW:
            es = enc_raw(es, buf, values[i], HALF_P)
        elif kind == OP_UINT:
            es = enc_uint(es, buf, m, rate, ctxs[i], values[i])
        else:
            es = enc_sint(es, buf, m, rate, ctxs[i], values[i])
    return enc_finish(es, buf)


@njit(cache=True, nogil=True)
def _decode_ops_kernel(data, m, rate, kinds, ctxs, out):
    ds = dec_start(data)
    for i in range(len(kinds)):
        kind = kinds[i]
        if kind == OP_BIT:
            ds, out[i] = dec_bit(ds, data, m, rate, ctxs[i])
        elif kind == OP_RAW:
            ds, out[i] = dec_raw(ds, data, HALF_P)
        elif kind == OP_UINT:
            ds, out[i] = dec_uint(ds, data, m, rate, ctxs[i])
        else:
            ds, out[i] = dec_sint(ds, data, m, rate, ctxs[i])
    return ds


def encode_ops_numba(kinds, ctxs, values, n_contexts: int) -> bytes:
    """Compiled twin of :func:`encode_ops_python` (identical bytes)."""
    kinds, ctxs, values = (np.ascontiguousarray(a, dtype=np.int64) for a in (kinds, ctxs, values))
    capacity = 2 * len(kinds) + 64
    while True:
        buf = np.zeros(capacity, dtype=np.uint8)
        es = _encode_ops_kernel(buf, new_model(n_contexts), RATE_SHIFT, kinds, ctxs, values)
        out = encoder_bytes(es, buf)
        if out is not None:
            return out
        capacity = int(es[4]) + 16


def decode_ops_numba(data: bytes, kinds, ctxs, n_contexts: int) -> tuple[np.ndarray, bool]:
    """Compiled twin of :func:`decode_ops_python`."""
    kinds, ctxs = (np.ascontiguousarray(a, dtype=np.int64) for a in (kinds, ctxs))
    arr = as_data(data)
    out = np.zeros(len(kinds), dtype=np.int64)
    ds = _decode_ops_kernel(arr, new_model(n_contexts), RATE_SHIFT, kinds, ctxs, out)
    return out, decoder_ok(ds, arr)


def encode_bits_python(bits, ctxs, n_contexts: int) -> bytes:
    """Reference: code binary symbols (n,) each with its context (n,)."""
    enc, model = RangeEncoder(), AdaptiveBitModel(n_contexts)
    for b, c in zip(bits.tolist(), ctxs.tolist()):
        enc.encode_bit(b, model.p1(c))
        model.update(c, b)
    return enc.finish()


@njit(cache=True, nogil=True)
def _encode_bits_kernel(buf, m, rate, bits, ctxs):
    es = enc_start()
    for i in range(len(bits)):
        c = ctxs[i]
        b = int(bits[i])
        es = enc_raw(es, buf, b, model_p1(m, c))
        model_update(m, c, b, rate)
    return enc_finish(es, buf)


@njit(cache=True, nogil=True)
def _decode_bits_kernel(data, m, rate, ctxs, out):
    ds = dec_start(data)
    for i in range(len(ctxs)):
        c = ctxs[i]
        ds, b = dec_raw(ds, data, model_p1(m, c))
        model_update(m, c, b, rate)
        out[i] = b
    return ds


def encode_bits_numba(bits, ctxs, n_contexts: int) -> bytes:
    """Compiled twin of :func:`encode_bits_python` (identical bytes)."""
    bits = np.ascontiguousarray(bits, dtype=np.uint8)
    ctxs = np.ascontiguousarray(ctxs, dtype=np.int64)
    capacity = len(bits) // 4 + 64
    while True:
        buf = np.zeros(capacity, dtype=np.uint8)
        es = _encode_bits_kernel(buf, new_model(n_contexts), RATE_SHIFT, bits, ctxs)
        out = encoder_bytes(es, buf)
        if out is not None:
            return out
        capacity = int(es[4]) + 16


def decode_bits_numba(data: bytes, ctxs, n_contexts: int) -> tuple[np.ndarray, bool]:
    """Decode :func:`encode_bits_numba` output: (bits (n,) uint8, stream ended cleanly)."""
    ctxs = np.ascontiguousarray(ctxs, dtype=np.int64)
    arr = as_data(data)
    out = np.zeros(len(ctxs), dtype=np.uint8)
    ds = _decode_bits_kernel(arr, new_model(n_contexts), RATE_SHIFT, ctxs, out)
    return out, decoder_ok(ds, arr)
