"""Per-frame depth quadtrees of the transmitted views (the ``quadtree`` payload of a ``Frame``).

Quadtree warping (Reinert et al. 2016, Section 6.2, after Didyk et al. 2010) draws each leaf
of a quadtree over a view's distance map as one quad. The server builds the trees (it has
the exact distances; ``pibr.server.quadtree``); this module is the bitstream both ends agree
on. A view is cut into square *root tiles* of ``tile`` pixels (a power of two) in row-major
order, the last row and column of tiles clipped by the image; each tile is a quadtree whose
leaves are ``(x, y, size)`` squares, ``x`` and ``y`` multiples of ``size``. A leaf may reach
past the image's right or bottom edge (only its part inside counts).

Payload: one zstd frame (content size in its header) of::

    offset size  field
     0      1    version (1)
     1      1    number of views n (1..MAX_VIEWS)
     2           n views, back to back, nothing after them; each:
       +0   1    view index (0 primary, 1 extra); each index at most once
       +1   2    width   (must equal the size the session announced for that view)
       +3   2    height
       +5   2    root tile size (a power of two, 1..MAX_TILE)
       +7   4    number of split bits b
      +11        ceil(b / 8) bytes: the bits, most significant first, padding bits 0

Little-endian. The split bits are the tiles' nodes in pre-order (children top-left,
top-right, bottom-left, bottom-right), 1 = split into four, 0 = leaf. Nodes of one pixel are
always leaves and nodes wholly outside the image do not exist: neither carries a bit. The
bits must be used up exactly.

Decoding checks every field against the view sizes the session announced before allocating
(so a payload never costs more memory than those views allow) and raises only
:class:`~pibr.protocol.errors.CodecError`, naming the problem. Golden payloads pin the format
in ``tests/protocol/golden/quadtree_*.bin``.
"""
from __future__ import annotations

import struct
from typing import Sequence

import numpy as np
from numba import njit

from .errors import CodecError

VERSION = 1
MAX_VIEWS = 2
#: Largest root tile a payload may announce (a power of two).
MAX_TILE = 4096
#: Largest view side (as the session's views).
MAX_SIZE = 8192
ZSTD_LEVEL = 3

_HEAD = struct.Struct("<BB")
_VIEW = struct.Struct("<BHHHI")

# Error codes of the kernels.
_OK, _OUT_OF_BITS, _GAP, _TOO_MANY_LEAVES = 0, -1, -2, -3


def _levels(tile: int) -> int:
    return int(tile).bit_length() - 1


def max_split_bits(width: int, height: int, tile: int = MAX_TILE) -> int:
    """An upper bound on the split bits of a ``width`` x ``height`` view: every node of two
    pixels or more that reaches into the image, at every level up to ``tile``."""
    total = 0
    for k in range(1, _levels(tile) + 1):
        s = 1 << k
        total += (-(-width // s)) * (-(-height // s))
    return total


def root_tiles(width: int, height: int, tile: int) -> int:
    return (-(-width // tile)) * (-(-height // tile))


# ------------------------------------------------------------------ kernels

@njit(cache=True, nogil=True)
def _fill_sizes(leaves, sizes):
    """sizes[y, x] = size of the leaf whose corner is (x, y); -> 0, or the index + 1 of a duplicate."""
    for i in range(leaves.shape[0]):
        x, y, s = leaves[i, 0], leaves[i, 1], leaves[i, 2]
        if sizes[y, x] != 0:
            return i + 1
        sizes[y, x] = s
    return 0


@njit(cache=True, nogil=True)
def _bits_from_sizes(sizes, width, height, tile, bits):
    """Pre-order split bits of the tree whose leaves ``sizes`` marks -> (bits written, leaves
    reached, error code)."""
    depth = 1
    t = tile
    while t > 1:
        t //= 2
        depth += 1
    stack = np.empty((3 * depth + 1, 3), np.int64)
    n = 0
    reached = 0
    for ty in range(0, height, tile):
        for tx in range(0, width, tile):
            sp = 0
            stack[0, 0], stack[0, 1], stack[0, 2] = tx, ty, tile
            sp = 1
            while sp > 0:
                sp -= 1
                x, y, s = stack[sp, 0], stack[sp, 1], stack[sp, 2]
                if x >= width or y >= height:
                    continue
                v = sizes[y, x]
                if s == 1:
                    if v != 1:
                        return n, reached, _GAP
                    reached += 1
                    continue
                if v == s:
                    bits[n] = 0
                    n += 1
                    reached += 1
                    continue
                bits[n] = 1
                n += 1
                h = s // 2
                stack[sp, 0], stack[sp, 1], stack[sp, 2] = x + h, y + h, h
                stack[sp + 1, 0], stack[sp + 1, 1], stack[sp + 1, 2] = x, y + h, h
                stack[sp + 2, 0], stack[sp + 2, 1], stack[sp + 2, 2] = x + h, y, h
                stack[sp + 3, 0], stack[sp + 3, 1], stack[sp + 3, 2] = x, y, h
                sp += 4
    return n, reached, _OK


@njit(cache=True, nogil=True)
def _leaves_from_bits(bits, nbits, width, height, tile, leaves):
    """Walk the pre-order bits -> (leaves written, bits used, error code)."""
    depth = 1
    t = tile
    while t > 1:
        t //= 2
        depth += 1
    stack = np.empty((3 * depth + 1, 3), np.int64)
    n = 0
    used = 0
    cap = leaves.shape[0]
    for ty in range(0, height, tile):
        for tx in range(0, width, tile):
            stack[0, 0], stack[0, 1], stack[0, 2] = tx, ty, tile
            sp = 1
            while sp > 0:
                sp -= 1
                x, y, s = stack[sp, 0], stack[sp, 1], stack[sp, 2]
                if x >= width or y >= height:
                    continue
                split = False
                if s > 1:
                    if used >= nbits:
                        return n, used, _OUT_OF_BITS
                    split = bits[used] != 0
                    used += 1
                if not split:
                    if n >= cap:
                        return n, used, _TOO_MANY_LEAVES
                    leaves[n, 0], leaves[n, 1], leaves[n, 2] = x, y, s
                    n += 1
                    continue
                h = s // 2
                stack[sp, 0], stack[sp, 1], stack[sp, 2] = x + h, y + h, h
                stack[sp + 1, 0], stack[sp + 1, 1], stack[sp + 1, 2] = x, y + h, h
                stack[sp + 2, 0], stack[sp + 2, 1], stack[sp + 2, 2] = x + h, y, h
                stack[sp + 3, 0], stack[sp + 3, 1], stack[sp + 3, 2] = x, y, h
                sp += 4
    return n, used, _OK


# ------------------------------------------------------------------ one tree

def _check_tile(tile: int) -> int:
    if not (isinstance(tile, (int, np.integer)) and 1 <= tile <= MAX_TILE and tile & (tile - 1) == 0):
        raise ValueError(f"root tile size must be a power of two in 1..{MAX_TILE}, got {tile!r}")
    return int(tile)


def split_bits(leaves, width: int, height: int, tile: int) -> np.ndarray:
    """Leaves (n, 3) int (x, y, size) of a quadtree over a ``width`` x ``height`` view ->
    its pre-order split bits (b,) uint8 (0 or 1).

    Raises ValueError unless the leaves are exactly the leaves of such a tree: each size a
    power of two up to ``tile``, corners multiples of their size inside the image, no
    overlaps and no gaps.
    """
    tile = _check_tile(tile)
    if not (1 <= width <= MAX_SIZE and 1 <= height <= MAX_SIZE):
        raise ValueError(f"view size must be in 1..{MAX_SIZE}, got {width}x{height}")
    a = np.asarray(leaves)
    if a.ndim != 2 or a.shape[1] != 3 or not np.issubdtype(a.dtype, np.integer):
        raise ValueError(f"leaves must be an (n, 3) integer array (x, y, size), got {a.dtype} {a.shape}")
    a = a.astype(np.int64)
    x, y, s = a[:, 0], a[:, 1], a[:, 2]
    bad = (s < 1) | (s > tile) | ((s & (s - 1)) != 0) | (x < 0) | (y < 0) | (x >= width) | (y >= height)
    bad |= (x % np.maximum(s, 1) != 0) | (y % np.maximum(s, 1) != 0)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"leaf {i} {tuple(int(v) for v in a[i])} is not a quadtree node of a "
                         f"{width}x{height} view with {tile}-pixel root tiles")
    sizes = np.zeros((height, width), np.int32)
    dup = _fill_sizes(a, sizes)
    if dup:
        raise ValueError(f"leaf {dup - 1} {tuple(int(v) for v in a[dup - 1])} appears twice")
    bits = np.empty(max(max_split_bits(width, height, tile), 1), np.uint8)
    n, reached, err = _bits_from_sizes(sizes, width, height, tile, bits)
    if err == _GAP:
        raise ValueError("the leaves leave a gap in the image")
    if reached != len(a):
        raise ValueError(f"{len(a) - reached} leaves overlap others")
    return bits[:n].copy()


def leaves_from_bits(bits, width: int, height: int, tile: int) -> np.ndarray:
    """Pre-order split bits (b,) -> leaves (n, 3) int32 (x, y, size) in pre-order, tiles in
    row-major order. Raises CodecError unless the bits describe exactly one tree per tile."""
    bits = np.ascontiguousarray(bits, dtype=np.uint8)
    tiles = root_tiles(width, height, tile)
    cap = tiles + 3 * int(np.count_nonzero(bits))   # every split adds at most 3 leaves
    leaves = np.empty((cap, 3), np.int32)
    n, used, err = _leaves_from_bits(bits, len(bits), width, height, tile, leaves)
    if err == _OUT_OF_BITS:
        raise CodecError(f"quadtree: the {len(bits)} split bits of a {width}x{height} view run out "
                         f"before its {tiles} root tiles are complete")
    if err != _OK:   # cannot happen: cap bounds the leaves
        raise CodecError(f"quadtree: more leaves than {cap}")
    if used != len(bits):
        raise CodecError(f"quadtree: {len(bits) - used} split bits left over after the last root tile "
                         f"of a {width}x{height} view")
    return leaves[:n].copy()


# ------------------------------------------------------------------ payload

def encode_quadtrees(views: Sequence[tuple], level: int = ZSTD_LEVEL) -> bytes:
    """views: (view index, width, height, root tile size, leaves (n, 3)) per view -> payload bytes.

    Raises ValueError if a view's leaves do not form its quadtree (see :func:`split_bits`)."""
    import zstandard

    if not 1 <= len(views) <= MAX_VIEWS:
        raise ValueError(f"a quadtree payload holds 1..{MAX_VIEWS} views, got {len(views)}")
    indices = [int(v[0]) for v in views]
    if len(set(indices)) != len(indices) or not all(0 <= i < MAX_VIEWS for i in indices):
        raise ValueError(f"view indices must be distinct and in 0..{MAX_VIEWS - 1}, got {indices}")
    parts = [_HEAD.pack(VERSION, len(views))]
    for index, width, height, tile, leaves in views:
        bits = split_bits(leaves, int(width), int(height), tile)
        parts.append(_VIEW.pack(index, width, height, tile, len(bits)))
        parts.append(np.packbits(bits).tobytes())
    return zstandard.ZstdCompressor(level=level, write_content_size=True).compress(b"".join(parts))


def max_body_size(sizes: Sequence[tuple[int, int]]) -> int:
    """The largest uncompressed payload views of these (width, height) can need."""
    return _HEAD.size + sum(_VIEW.size + (max_split_bits(w, h) + 7) // 8 for w, h in sizes)


def _decompress(data: bytes, limit: int) -> bytes:
    import zstandard

    data = bytes(data)
    try:
        params = zstandard.get_frame_parameters(data)
    except zstandard.ZstdError as exc:
        raise CodecError(f"quadtree: not a zstd frame ({exc})") from None
    size = params.content_size
    if size in (zstandard.CONTENTSIZE_UNKNOWN, zstandard.CONTENTSIZE_ERROR):
        raise CodecError("quadtree: the zstd frame does not state its content size")
    if size > limit:
        raise CodecError(f"quadtree: {size} bytes uncompressed exceed the {limit} the session's views allow")
    try:
        raw = zstandard.ZstdDecompressor().decompress(data, max_output_size=limit)
        # The frame decoded within the limit; now make sure nothing follows it.
        dobj = zstandard.ZstdDecompressor().decompressobj()
        dobj.decompress(data)
    except zstandard.ZstdError as exc:
        raise CodecError(f"quadtree: zstd: {exc}") from None
    if dobj.unused_data:
        raise CodecError(f"quadtree: {len(dobj.unused_data)} bytes after the zstd frame")
    if len(raw) != size:
        raise CodecError(f"quadtree: zstd frame holds {len(raw)} bytes, its header says {size}")
    return raw


def decode_quadtrees(data: bytes, sizes: Sequence[tuple[int, int]]) -> list[np.ndarray]:
    """Payload -> leaves (n, 3) int32 (x, y, size) of every view, in view index order.

    ``sizes``: (width, height) of views 0, 1, ... as the session announced them; the payload
    must hold a tree for each of them, of exactly that size. Raises CodecError otherwise."""
    if not 1 <= len(sizes) <= MAX_VIEWS:
        raise ValueError(f"expected 1..{MAX_VIEWS} view sizes, got {len(sizes)}")
    sizes = [(int(w), int(h)) for w, h in sizes]
    raw = _decompress(data, max_body_size(sizes))
    if len(raw) < _HEAD.size:
        raise CodecError(f"quadtree: {len(raw)} bytes are shorter than the {_HEAD.size}-byte header")
    version, count = _HEAD.unpack_from(raw, 0)
    if version != VERSION:
        raise CodecError(f"quadtree: version {version}, this end reads version {VERSION}")
    if count != len(sizes):
        raise CodecError(f"quadtree: {count} views in the payload, the session has {len(sizes)}")
    pos = _HEAD.size
    out: list = [None] * len(sizes)
    for i in range(count):
        if len(raw) - pos < _VIEW.size:
            raise CodecError(f"quadtree: view {i}'s header is truncated")
        index, width, height, tile, nbits = _VIEW.unpack_from(raw, pos)
        pos += _VIEW.size
        if index >= len(sizes):
            raise CodecError(f"quadtree: view index {index} is not one of the session's {len(sizes)} views")
        if out[index] is not None:
            raise CodecError(f"quadtree: view {index} appears twice")
        if (width, height) != sizes[index]:
            raise CodecError(f"quadtree: view {index} is {width}x{height}, the session announced "
                             f"{sizes[index][0]}x{sizes[index][1]}")
        if not (1 <= tile <= MAX_TILE and tile & (tile - 1) == 0):
            raise CodecError(f"quadtree: view {index}'s root tile size {tile} is not a power of two in 1..{MAX_TILE}")
        bound = max_split_bits(width, height, tile)
        if nbits > bound:
            raise CodecError(f"quadtree: view {index} claims {nbits} split bits, a {width}x{height} view "
                             f"with {tile}-pixel tiles has at most {bound}")
        nbytes = (nbits + 7) // 8
        if len(raw) - pos < nbytes:
            raise CodecError(f"quadtree: view {index}'s {nbits} split bits are truncated")
        packed = np.frombuffer(raw, np.uint8, nbytes, pos)
        pos += nbytes
        if nbits % 8 and int(packed[-1]) & ((1 << (8 - nbits % 8)) - 1):
            raise CodecError(f"quadtree: view {index}'s padding bits are not zero")
        bits = np.unpackbits(packed)[:nbits]
        out[index] = leaves_from_bits(bits, width, height, tile)
    if pos != len(raw):
        raise CodecError(f"quadtree: {len(raw) - pos} bytes after the last view")
    return out
