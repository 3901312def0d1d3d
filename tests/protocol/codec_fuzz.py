"""What every decoder's property tests check of arbitrary bytes: a result or the codec's own error."""
from __future__ import annotations

import time

from pibr.protocol.errors import CodecError


def decode_or_codec_error(decode, payload: bytes, prefix: str):
    """``decode(payload)``, or None when it raises a CodecError whose message starts with ``prefix``;
    any other exception propagates, and a decode may not take a second (a hang guard)."""
    t0 = time.perf_counter()
    try:
        out = decode(payload)
    except CodecError as exc:
        assert str(exc).startswith(prefix), exc
        out = None
    assert time.perf_counter() - t0 < 1.0
    return out
