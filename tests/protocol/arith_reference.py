"""The arithmetic coder's reference and test drivers (pibr/protocol/edgecodec/arith.py), moved here
from arith.py because nothing in pibr calls them; the tests hold arith's kernels to them.

* A pure-Python reference of the bitstream (:class:`RangeEncoder`, :class:`RangeDecoder`,
  :class:`AdaptiveBitModel`, :func:`encode_uint` ...): short, readable, the specification.
* Compiled twins of its single bits and unsigned integers (``enc_bit`` / ``enc_uint`` /
  ``dec_bit`` / ``dec_uint``), built on arith's kernels like the codecs' own loops (which code
  bits inline and signed integers with ``enc_sint`` / ``dec_sint``).
* Operation streams: drive either implementation with the same symbols (``*_python`` against
  ``*_numba``: identical bytes).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from pibr.protocol.edgecodec.arith import (_MANT0, _MIX_SHIFT, _UNARY0, COUNT_MAX, FAST_MAX_SHIFT, HALF_P, KMAX,
                                           MASK32, MAX_OVERRUN, PROB_BITS, RATE_SHIFT, STATE_HALF, STATE_ONE, TOP,
                                           as_data, dec_raw, dec_sint, dec_start, decoder_ok, enc_finish, enc_raw,
                                           enc_sint, enc_start, encoder_bytes, model_p1, model_update, new_model)

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
# numba twins of the reference's bits and unsigned integers (on arith's kernels)
# --------------------------------------------------------------------------------------------

@njit(cache=True, nogil=True)
def enc_bit(es, buf, m, rate, ctx, bit):
    es = enc_raw(es, buf, bit, model_p1(m, ctx))
    model_update(m, ctx, bit, rate)
    return es


@njit(cache=True, nogil=True)
def _enc_magnitude(es, buf, m, rate, base, mag):
    # model_p1 -> enc_raw -> model_update written out rather than enc_bit (see arith's docstring)
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



# --------------------------------------------------------------------------------------------
# Operation streams: drive either implementation with the same symbols
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
