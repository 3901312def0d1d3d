"""The edge codec's frame format: a fixed header, then up to four arithmetic-coded sections.

Layout (little-endian)::

    offset size  field
     0      4    magic b"PIBE"
     4      1    version (2: the edge image starts with a block occupancy map; 1 coded every pixel)
     5      1    flags: bit 0 temporal context, bit 1 four interleaved passes (else one raster
                 pass), bit 2 motion section present; other bits must be 0
     6      2    width   (1..MAX_SIZE)
     8      2    height  (1..MAX_SIZE)
    10      1    bits of a sample code (MIN_BITS..MAX_BITS)
    11      1    log2 of the regular-sample spacing (MIN_SPACING_LOG2..MAX_SPACING_LOG2)
    12      2    min_code of the depth quantizer (1..2^bits - 2)
    14      2    q, the residual quantization step (1..2^bits - 1; 1 = lossless)
    16      4    number of edge samples (0..width*height)
    20     16    byte lengths of the sections: edge image, regular samples, edge values, motion
    36           the sections, in that order, back to back (nothing after them)

Every size read from a payload is checked against a bound derived from the header (and the
header against the decoder's configuration) before anything is allocated; a failed check
raises :class:`~pibr.protocol.errors.CodecError` naming the field.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass, replace

from ..errors import CodecError
from .arith import INT_SLOT
from .edges import BLOCK_LOG2

MAGIC = b"PIBE"
VERSION = 2
MAX_SIZE = 8192
#: 8 bits lets the codec be compared with 8-bit H.264 depth at equal precision (issue 26).
MIN_BITS, MAX_BITS = 8, 16
MIN_SPACING_LOG2, MAX_SPACING_LOG2 = 2, 7

FLAG_TEMPORAL = 1
FLAG_FOUR_PASSES = 2
FLAG_MOTION = 4
_KNOWN_FLAGS = FLAG_TEMPORAL | FLAG_FOUR_PASSES | FLAG_MOTION

_HEADER = struct.Struct("<4sBBHHBBHHI4I")
HEADER_SIZE = _HEADER.size
SECTIONS = ("edges", "regular", "values", "motion")

#: A coded binary symbol never costs more than 15 bits: 2 bytes is a safe bound per symbol.
_BYTES_PER_BIN = 2
#: Bins of one integer at most (zero flag, sign, unary, mantissa) — see arith.INT_SLOT.
_BINS_PER_INT = INT_SLOT
#: Slack per section for the coder's flush.
_SLACK = 16


def grid_shape(width: int, height: int, spacing_log2: int) -> tuple[int, int]:
    """(rows, cols) of the regular-sample grid: one sample per 2^spacing_log2 square, rounded up."""
    s = 1 << spacing_log2
    return (height + s - 1) // s, (width + s - 1) // s


def motion_bound(width: int, height: int) -> int:
    """Largest motion section a ``width`` x ``height`` frame may carry (bytes)."""
    blocks = ((width + 7) // 8) * ((height + 7) // 8)  # the smallest block size motion.py allows
    return 8 + _BYTES_PER_BIN * (width * height + 2 * _BINS_PER_INT * blocks) + _SLACK


@dataclass(frozen=True)
class FrameHeader:
    width: int
    height: int
    bits: int
    min_code: int
    q: int
    n_edges: int
    temporal: bool = False
    four_passes: bool = True
    motion: bool = False
    spacing_log2: int = 5
    lengths: tuple = (0, 0, 0, 0)

    @property
    def flags(self) -> int:
        return ((FLAG_TEMPORAL if self.temporal else 0) | (FLAG_FOUR_PASSES if self.four_passes else 0)
                | (FLAG_MOTION if self.motion else 0))

    def section_bounds(self) -> tuple[int, int, int, int]:
        """Upper bounds of the four section lengths (bytes), from the header's sizes alone."""
        rh, rw = grid_shape(self.width, self.height, self.spacing_log2)
        pixels = self.width * self.height
        blocks = grid_shape(self.width, self.height, BLOCK_LOG2)
        return (_BYTES_PER_BIN * (pixels + blocks[0] * blocks[1]) + _SLACK,
                _BYTES_PER_BIN * _BINS_PER_INT * rh * rw + _SLACK,
                _BYTES_PER_BIN * (1 + _BINS_PER_INT) * self.n_edges + _SLACK,
                motion_bound(self.width, self.height) if self.motion else 0)

    def validate(self) -> None:
        """Raise :class:`CodecError` naming the first field out of range."""
        if not (1 <= self.width <= MAX_SIZE and 1 <= self.height <= MAX_SIZE):
            raise CodecError(f"edge codec: size {self.width}x{self.height} outside 1..{MAX_SIZE}")
        if not (MIN_BITS <= self.bits <= MAX_BITS):
            raise CodecError(f"edge codec: bits {self.bits} outside {MIN_BITS}..{MAX_BITS}")
        max_code = (1 << self.bits) - 1
        if not (1 <= self.min_code < max_code):
            raise CodecError(f"edge codec: min_code {self.min_code} outside 1..{max_code - 1}")
        if not (1 <= self.q <= max_code):
            raise CodecError(f"edge codec: q {self.q} outside 1..{max_code}")
        if not (MIN_SPACING_LOG2 <= self.spacing_log2 <= MAX_SPACING_LOG2):
            raise CodecError(f"edge codec: regular spacing 2^{self.spacing_log2} outside "
                             f"2^{MIN_SPACING_LOG2}..2^{MAX_SPACING_LOG2}")
        if not (0 <= self.n_edges <= self.width * self.height):
            raise CodecError(f"edge codec: {self.n_edges} edge samples in a {self.width}x{self.height} frame")
        for name, n, bound in zip(SECTIONS, self.lengths, self.section_bounds()):
            if not (0 <= n <= bound):
                raise CodecError(f"edge codec: {name} section of {n} bytes exceeds its bound of {bound}")

    def pack(self, sections: tuple[bytes, bytes, bytes, bytes]) -> bytes:
        """Header + sections -> payload (the lengths come from ``sections``)."""
        lengths = tuple(len(s) for s in sections)
        head = replace(self, lengths=lengths)
        head.validate()
        return _HEADER.pack(MAGIC, VERSION, head.flags, head.width, head.height, head.bits, head.spacing_log2,
                            head.min_code, head.q, head.n_edges, *lengths) + b"".join(sections)


def parse(payload) -> tuple[FrameHeader, dict]:
    """payload -> (validated header, {section name: memoryview}). Raises CodecError."""
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        raise CodecError(f"edge codec: payload must be bytes, got {type(payload).__name__}")
    view = memoryview(payload).cast("B")
    if len(view) < HEADER_SIZE:
        raise CodecError(f"edge codec: payload of {len(view)} bytes is shorter than the {HEADER_SIZE}-byte header")
    (magic, version, flags, width, height, bits, spacing_log2, min_code, q, n_edges,
     *lengths) = _HEADER.unpack_from(view, 0)
    if magic != MAGIC:
        raise CodecError(f"edge codec: bad magic {bytes(magic)!r}, expected {MAGIC!r}")
    if version != VERSION:
        raise CodecError(f"edge codec: unsupported version {version}, expected {VERSION}")
    if flags & ~_KNOWN_FLAGS:
        raise CodecError(f"edge codec: unknown flags 0x{flags:02x}")
    head = FrameHeader(width=width, height=height, bits=bits, min_code=min_code, q=q, n_edges=n_edges,
                       temporal=bool(flags & FLAG_TEMPORAL), four_passes=bool(flags & FLAG_FOUR_PASSES),
                       motion=bool(flags & FLAG_MOTION), spacing_log2=spacing_log2, lengths=tuple(lengths))
    head.validate()
    total = HEADER_SIZE + sum(lengths)
    if total != len(view):
        what = "truncated" if total > len(view) else "has trailing bytes"
        raise CodecError(f"edge codec: payload {what}: header announces {total} bytes, got {len(view)}")
    sections, pos = {}, HEADER_SIZE
    for name, n in zip(SECTIONS, lengths):
        sections[name] = view[pos:pos + n]
        pos += n
    return head, sections
