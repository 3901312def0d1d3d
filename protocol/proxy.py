"""The proxy bundle: every object's levels of detail, sent once before the first frame.

Per object: a name, its rest transform, whether it moves, its bounding box, and two
meshes — the original and the simplified *encaging* proxy (the third level, the box, is
the bounding box). Positions only: the client rasterises proxies for depth and
back-projection; colour comes from the transmitted views.

Layout (little-endian), then zstd-compressed and cut into ``ProxyChunk`` messages, all
``chunk_bytes`` long but the last (see :class:`BundleInfo`, what the ``Welcome`` announces)::

    b"PXB2" u32 object_count
    per object:
        u16 name_len, name (UTF-8)
        16 f64 transform (row-major), u8 moving (0 or 1)
        6 f64 bounds (min xyz, max xyz; object space)
        2 x mesh: u32 vertex_count, u32 face_count, f32 vertices (n, 3), u32 faces (m, 3)

Every count is checked against limits and the bytes left before anything is allocated;
decompression never produces more than the announced uncompressed size.

A moving object's animation does not travel: the client learns where it is from the
transforms every ``Frame`` carries (protocol/object_poses.py), as a real engine's client
would, never where it will be. Format 2 (``PXB2``) dropped format 1's motion model.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from .errors import MalformedMessage

MAGIC = b"PXB2"
MAX_OBJECTS = 100_000
MAX_VERTICES = 20_000_000
MAX_BUNDLE_BYTES = 1 << 30
CHUNK_BYTES = 1 << 20
#: Smallest chunk a bundle may be cut into, and most chunks one bundle may take.
MIN_CHUNK_BYTES = 1 << 10
MAX_CHUNKS = 1 << 16
#: The magic and the object count, checked before the rest is decompressed.
HEADER_BYTES = 8
#: Most bytes decompressed in one step.
DECOMPRESS_STEP = 1 << 20
#: The longest zstd frame header (magic, descriptor, window, dictionary id, content size).
ZSTD_FRAME_HEADER_MAX = 18
LEVELS = ("original", "proxy", "box")


@dataclass
class ProxyObject:
    """One object's levels of detail. vertices (n, 3) float32, faces (m, 3) uint32 per mesh.

    transform : (4, 4) object-to-world at rest; a ``moving`` object's frames say where it is.
    """

    name: str
    transform: np.ndarray
    moving: bool
    bounds: np.ndarray
    original: tuple
    proxy: tuple

    def box_mesh(self) -> tuple:
        """The bounding box as (8, 3) vertices and (12, 3) outward-wound faces (:func:`closed_box`)."""
        return closed_box(*self.bounds)

    def level(self, name: str) -> tuple:
        return {"original": self.original, "proxy": self.proxy}.get(name) or self.box_mesh()


def closed_box(lo, hi) -> tuple:
    """The axis-aligned box from corner ``lo`` (3,) to ``hi`` (3,) as a proxy's box level: (8, 3)
    float32 vertices shared by its sides (vertex index 4 * (x is hi) + 2 * (y is hi) + (z is hi))
    and (12, 3) uint32 faces wound counter-clockwise seen from outside, so it bounds a volume."""
    v = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], np.float32)
    f = np.array([[0, 1, 3], [0, 3, 2],      # -X
                  [4, 6, 7], [4, 7, 5],      # +X
                  [0, 4, 5], [0, 5, 1],      # -Y
                  [2, 3, 7], [2, 7, 6],      # +Y
                  [0, 2, 6], [0, 6, 4],      # -Z
                  [1, 5, 7], [1, 7, 3]], np.uint32)     # +Z
    return v, f


def is_closed(faces: np.ndarray) -> bool:
    """Whether (m, 3) faces bound a volume: every directed edge occurs as often as its reverse
    (no boundary, consistent orientation; non-manifold edges allowed). Winding numbers are then
    integers away from the surface, so "inside" is well defined."""
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return False
    e = f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    n = int(f.max()) + 1
    fwd, fwd_count = np.unique(e[:, 0] * n + e[:, 1], return_counts=True)
    rev, rev_count = np.unique(e[:, 1] * n + e[:, 0], return_counts=True)
    return bool(np.array_equal(fwd, rev) and np.array_equal(fwd_count, rev_count))


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Signed volume of a closed (n, 3) / (m, 3) mesh: positive when its faces wind outward
    (counter-clockwise seen from outside)."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return 0.0
    return float(np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6.0)


def winds_outward(vertices: np.ndarray, faces: np.ndarray) -> bool:
    """Whether a (n, 3) / (m, 3) mesh, its vertices merged where they lie within a millionth of
    its size of each other (meshes split them along uv seams and creases, and a seam's two ends
    may differ by rounding), is closed and none of its connected parts is wound inward (negative
    volume; a two-sided sheet, volume 0, is fine). Then the winding number is never negative,
    so from any point outside the mesh's box every back face lies behind a front face of the
    same mesh: what makes culling back faces safe."""
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(f) == 0:
        return False
    step = 1e-6 * max(float(np.max(np.ptp(v, axis=0))), 1e-9)
    # (two positions either side of a rounding boundary stay apart: the mesh then counts as open)
    _, first, merged = np.unique(np.round(v / step), axis=0, return_index=True, return_inverse=True)
    points = v[first]
    f = merged.reshape(-1)[f]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0])]   # sliver faces merged away
    if not is_closed(f):
        return False
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(points)
    edges = f[:, [0, 1, 1, 2]].reshape(-1, 2)
    graph = coo_matrix((np.ones(len(edges), np.int8), (edges[:, 0], edges[:, 1])), shape=(n, n))
    parts, label = connected_components(graph, directed=False)
    part = label[f[:, 0]]
    volume = np.bincount(part, np.einsum("ij,ij->i", points[f[:, 0]], np.cross(points[f[:, 1]], points[f[:, 2]])) / 6.0,
                         minlength=parts)
    lo = np.full((parts, 3), np.inf)
    hi = np.full((parts, 3), -np.inf)
    np.minimum.at(lo, label, points)
    np.maximum.at(hi, label, points)
    box = np.prod(np.maximum(hi - lo, 1e-9), axis=1)
    return bool(np.all(volume >= -1e-6 * box) and volume.sum() > 0.0)


def _pack_mesh(parts: list, vertices, faces) -> None:
    v = np.ascontiguousarray(vertices, dtype="<f4").reshape(-1, 3)
    f = np.ascontiguousarray(faces, dtype="<u4").reshape(-1, 3)
    parts.append(struct.pack("<II", len(v), len(f)))
    parts.append(v.tobytes())
    parts.append(f.tobytes())


def encode_bundle(objects: list[ProxyObject]) -> bytes:
    """Uncompressed bundle bytes."""
    parts = [MAGIC, struct.pack("<I", len(objects))]
    for o in objects:
        name = o.name.encode("utf-8")[:65535]
        parts.append(struct.pack("<H", len(name)) + name)
        parts.append(np.asarray(o.transform, "<f8").reshape(16).tobytes())
        parts.append(struct.pack("<B", bool(o.moving)))
        parts.append(np.asarray(o.bounds, "<f8").reshape(6).tobytes())
        _pack_mesh(parts, *o.original)
        _pack_mesh(parts, *o.proxy)
    return b"".join(parts)


class _Reader:
    """Reads a bundle without copying it: ``take`` hands out views of ``data``."""

    def __init__(self, data):
        self.data, self.pos = memoryview(data).cast("B"), 0

    def take(self, n: int, what: str) -> memoryview:
        if n < 0 or n > len(self.data) - self.pos:
            raise MalformedMessage(f"proxy bundle: {what} needs {n} bytes, {len(self.data) - self.pos} left")
        out = self.data[self.pos:self.pos + n]
        self.pos += n
        return out

    def unpack(self, fmt: str, what: str):
        return struct.unpack(fmt, self.take(struct.calcsize(fmt), what))


def _read_mesh(r: _Reader, where: str) -> tuple:
    nv, nf = r.unpack("<II", f"{where} counts")
    if nv > MAX_VERTICES or nf > MAX_VERTICES:
        raise MalformedMessage(f"proxy bundle: {where} has {nv} vertices / {nf} faces, over the limit {MAX_VERTICES}")
    v = np.frombuffer(r.take(nv * 12, f"{where} vertices"), "<f4").reshape(nv, 3)
    f = np.frombuffer(r.take(nf * 12, f"{where} faces"), "<u4").reshape(nf, 3)
    if not np.all(np.isfinite(v)):
        raise MalformedMessage(f"proxy bundle: {where} has non-finite vertices")
    if nf and int(f.max()) >= nv:
        raise MalformedMessage(f"proxy bundle: {where} face index {int(f.max())} >= vertex count {nv}")
    # Views of a writable bundle (decompress_bundle's bytearray): the meshes are the bundle, no
    # second copy of it; an immutable bundle's are copied, so every mesh can be written to.
    v, f = v.astype(np.float32, copy=False), f.astype(np.uint32, copy=False)
    if not v.flags.writeable:
        v, f = v.copy(), f.copy()
    return v, f


def decode_bundle(data) -> list[ProxyObject]:
    """A raw bundle (bytes, or the bytearray :func:`decompress_bundle` returns: then its meshes are
    views of it, no copy) -> its objects."""
    r = _Reader(data)
    if bytes(r.take(4, "magic")) != MAGIC:
        raise MalformedMessage("proxy bundle: bad magic")
    (count,) = r.unpack("<I", "object count")
    if count > MAX_OBJECTS:
        raise MalformedMessage(f"proxy bundle: {count} objects exceed the limit of {MAX_OBJECTS}")
    objects = []
    for i in range(count):
        (n,) = r.unpack("<H", f"object {i} name length")
        try:
            name = bytes(r.take(n, f"object {i} name")).decode("utf-8")
        except UnicodeDecodeError:
            raise MalformedMessage(f"proxy bundle: object {i} name is not UTF-8") from None
        transform = np.frombuffer(r.take(128, f"object {i} transform"), "<f8").reshape(4, 4).copy()
        (moving,) = r.unpack("<B", f"object {i} moving flag")
        if moving > 1:
            raise MalformedMessage(f"proxy bundle: object {i} moving flag is {moving}, not 0 or 1")
        bounds = np.frombuffer(r.take(48, f"object {i} bounds"), "<f8").reshape(2, 3).copy()
        if not (np.all(np.isfinite(transform)) and np.all(np.isfinite(bounds))):
            raise MalformedMessage(f"proxy bundle: object {i} has a non-finite transform or bounds")
        original = _read_mesh(r, f"object {i} original mesh")
        proxy = _read_mesh(r, f"object {i} proxy mesh")
        objects.append(ProxyObject(name, transform, bool(moving), bounds, original, proxy))
    if r.pos != len(data):
        raise MalformedMessage(f"proxy bundle: {len(data) - r.pos} trailing bytes")
    return objects


def compress_bundle(raw: bytes, level: int = 9) -> bytes:
    import zstandard

    return zstandard.ZstdCompressor(level=level).compress(raw)


def _check_header(head: bytes, objects: int | None) -> None:
    """The first 8 uncompressed bytes: magic and object count (against the announcement)."""
    if head[:4] != MAGIC:
        raise MalformedMessage(f"proxy bundle: bad magic {bytes(head[:4])!r} in the first decompressed bytes")
    (count,) = struct.unpack("<I", head[4:8])
    if count > MAX_OBJECTS:
        raise MalformedMessage(f"proxy bundle: {count} objects exceed the limit of {MAX_OBJECTS}")
    if objects is not None and count != objects:
        raise MalformedMessage(f"proxy bundle: holds {count} objects, the Welcome announced {objects}")


class _ChunkStream:
    """A file-like reader over chunks of bytes, in order (the compressed bundle as received,
    never joined into one copy)."""

    def __init__(self, chunks):
        self._chunks, self._i, self._pos = list(chunks), 0, 0

    def read(self, n: int = -1) -> bytes:
        out = []
        while self._i < len(self._chunks) and (n < 0 or n > 0):
            chunk = self._chunks[self._i]
            take = len(chunk) - self._pos if n < 0 else min(n, len(chunk) - self._pos)
            out.append(bytes(chunk[self._pos:self._pos + take]))
            self._pos += take
            n -= take if n >= 0 else 0
            if self._pos == len(chunk):
                self._i, self._pos = self._i + 1, 0
        return b"".join(out)


def decompress_bundle(data, raw_size: int, objects: int | None = None) -> bytearray:
    """zstd frame (bytes, or a list of its chunks in order) -> raw bundle of exactly ``raw_size``
    bytes (what the Welcome announced), as a bytearray that :func:`decode_bundle` decodes in place.

    Streaming, with ``raw_size`` as the ceiling: the zstd header's content size and window
    must fit it, the magic and object count are checked in the first 8 decompressed bytes,
    and decompression stops as soon as the output would pass ``raw_size``, so a small frame
    that inflates to gigabytes costs no more than the announced size. The output is the only
    allocation of that size (peak: the announced size plus the compressed chunks)."""
    import zstandard

    chunks = [data] if isinstance(data, (bytes, bytearray, memoryview)) else list(data)
    if not chunks or not any(len(c) for c in chunks):
        raise MalformedMessage("proxy bundle: no compressed data")
    data = _ChunkStream(chunks).read(ZSTD_FRAME_HEADER_MAX)   # what get_frame_parameters reads

    if not HEADER_BYTES <= raw_size <= MAX_BUNDLE_BYTES:
        raise MalformedMessage(f"proxy bundle: announced size {raw_size} is outside [{HEADER_BYTES}, "
                               f"{MAX_BUNDLE_BYTES}]")
    try:
        params = zstandard.get_frame_parameters(data)
        if params.content_size != zstandard.CONTENTSIZE_UNKNOWN and params.content_size != raw_size:
            raise MalformedMessage(f"proxy bundle: the zstd header declares {params.content_size} bytes "
                                   f"uncompressed, the Welcome announced {raw_size}")
        # The decoder's window (its largest allocation) need not exceed the whole bundle.
        window = min(1 << 27, max(1 << 10, 1 << (raw_size - 1).bit_length()))
        if params.window_size > window:
            raise MalformedMessage(f"proxy bundle: the zstd frame asks for a {params.window_size}-byte window, "
                                   f"more than the {raw_size} bytes the Welcome announced need")
        reader = zstandard.ZstdDecompressor(max_window_size=window).stream_reader(_ChunkStream(chunks))
        head = reader.read(HEADER_BYTES)
        if len(head) != HEADER_BYTES:
            raise MalformedMessage(f"proxy bundle: decompresses to fewer than {HEADER_BYTES} bytes")
        _check_header(head, objects)
        out = bytearray(raw_size)   # only now: the header matches the announcement
        out[:HEADER_BYTES] = head
        view, pos = memoryview(out), HEADER_BYTES
        while pos < raw_size:
            n = reader.readinto(view[pos:pos + DECOMPRESS_STEP])
            if not n:
                raise MalformedMessage(f"proxy bundle: decompresses to {pos} bytes, the Welcome announced "
                                       f"{raw_size}")
            pos += n
        view.release()
        if reader.read(1):
            raise MalformedMessage(f"proxy bundle: decompresses to more than the {raw_size} bytes the Welcome "
                                   f"announced")
    except zstandard.ZstdError as exc:
        raise MalformedMessage(f"proxy bundle: zstd: {exc}") from None
    return out


def split_chunks(data: bytes, chunk_bytes: int = CHUNK_BYTES) -> list[bytes]:
    """Cut the compressed bundle into chunks: every one ``chunk_bytes`` long but the last,
    none empty (a zstd frame is never empty)."""
    if not data:
        raise ValueError("a compressed proxy bundle is never empty")
    return [data[i:i + chunk_bytes] for i in range(0, len(data), chunk_bytes)]


def _field(o: dict, key: str, lo: int, hi: int, path: str) -> int:
    v = o.get(key)
    if isinstance(v, bool) or not isinstance(v, int):
        raise MalformedMessage(f"{path}: field {key!r} must be an integer, got {v!r:.40}")
    if not lo <= v <= hi:
        raise MalformedMessage(f"{path}: field {key!r} = {v} is outside [{lo}, {hi}]")
    return v


@dataclass(frozen=True)
class BundleInfo:
    """What a Welcome announces about the proxy bundle that follows it (``SessionConfig.proxies``).

    objects     : objects in the bundle
    bytes       : compressed size, the sum of the chunks' data
    raw_bytes   : uncompressed size, the decompression ceiling
    chunk_bytes : data bytes of every chunk but the last (which holds the rest, at least 1)
    triangles   : level -> total triangles (informational)

    The chunk count is implied: ceil(bytes / chunk_bytes), at most ``MAX_CHUNKS``.
    """

    objects: int
    bytes: int
    raw_bytes: int
    chunk_bytes: int
    triangles: dict

    def __post_init__(self):
        if not (0 <= self.objects <= MAX_OBJECTS and 1 <= self.bytes <= MAX_BUNDLE_BYTES
                and HEADER_BYTES <= self.raw_bytes <= MAX_BUNDLE_BYTES
                and MIN_CHUNK_BYTES <= self.chunk_bytes <= MAX_BUNDLE_BYTES):
            raise ValueError(f"proxy bundle of {self.objects} objects, {self.bytes} bytes ({self.raw_bytes} "
                             f"uncompressed) in chunks of {self.chunk_bytes} bytes is out of range")
        if self.chunks > MAX_CHUNKS:
            raise ValueError(f"proxy bundle of {self.bytes} bytes needs {self.chunks} chunks of {self.chunk_bytes} "
                             f"bytes, more than the limit of {MAX_CHUNKS}")

    @property
    def chunks(self) -> int:
        return -(-self.bytes // self.chunk_bytes)

    def chunk_size(self, index: int) -> int:
        """Data bytes chunk ``index`` must carry."""
        return self.chunk_bytes if index < self.chunks - 1 else self.bytes - (self.chunks - 1) * self.chunk_bytes

    def to_json(self) -> dict:
        return {"objects": self.objects, "bytes": self.bytes, "raw_bytes": self.raw_bytes,
                "chunk_bytes": self.chunk_bytes, "chunks": self.chunks, "triangles": dict(self.triangles)}

    @classmethod
    def from_json(cls, o, path: str = "Welcome.config.proxies") -> "BundleInfo":
        if not isinstance(o, dict):
            raise MalformedMessage(f"{path}: must be an object")
        objects = _field(o, "objects", 0, MAX_OBJECTS, path)
        size = _field(o, "bytes", 1, MAX_BUNDLE_BYTES, path)
        raw = _field(o, "raw_bytes", HEADER_BYTES, MAX_BUNDLE_BYTES, path)
        chunk_bytes = _field(o, "chunk_bytes", MIN_CHUNK_BYTES, MAX_BUNDLE_BYTES, path)
        chunks = _field(o, "chunks", 1, MAX_CHUNKS, path)
        if chunks != -(-size // chunk_bytes):
            raise MalformedMessage(f"{path}: {chunks} chunks do not carry {size} bytes in chunks of {chunk_bytes}")
        triangles = o.get("triangles", {})
        if not isinstance(triangles, dict) or len(triangles) > len(LEVELS):
            raise MalformedMessage(f"{path}: field 'triangles' must map at most {len(LEVELS)} levels to counts")
        for level in triangles:
            _field(triangles, level, 0, MAX_VERTICES * MAX_OBJECTS, f"{path}.triangles")
        return cls(objects, size, raw, chunk_bytes, triangles)


class BundleAssembler:
    """Collects the ``ProxyChunk`` messages of an announced bundle; :attr:`complete` when all arrived.

    Each chunk must match the announcement (count, total size, its own exact size), arrive
    once and carry data; chunks are kept as they come and joined once, so assembly is linear."""

    def __init__(self, info: BundleInfo):
        self.info = info
        self._parts: list[bytes | None] = [None] * info.chunks
        self.received = 0

    @property
    def count(self) -> int:
        return self.info.chunks

    def add(self, chunk) -> None:
        info = self.info
        if chunk.count != info.chunks:
            raise MalformedMessage(f"ProxyChunk: count {chunk.count} differs from the {info.chunks} chunks the "
                                   f"Welcome announced")
        if chunk.total_size != info.bytes:
            raise MalformedMessage(f"ProxyChunk: total size {chunk.total_size} differs from the {info.bytes} bytes "
                                   f"the Welcome announced")
        if not 0 <= chunk.index < info.chunks:
            raise MalformedMessage(f"ProxyChunk: index {chunk.index} is outside 0..{info.chunks - 1}")
        if self._parts[chunk.index] is not None:
            raise MalformedMessage(f"ProxyChunk: chunk {chunk.index} arrived twice")
        if not chunk.data:
            raise MalformedMessage(f"ProxyChunk: chunk {chunk.index} is empty")
        if len(chunk.data) != info.chunk_size(chunk.index):
            raise MalformedMessage(f"ProxyChunk: chunk {chunk.index} carries {len(chunk.data)} bytes, the "
                                   f"announcement implies {info.chunk_size(chunk.index)}")
        self._parts[chunk.index] = chunk.data
        self.received += 1

    @property
    def complete(self) -> bool:
        return self.received == self.info.chunks

    def data(self) -> bytes:
        """The compressed bundle in one piece (a copy: :meth:`chunks` avoids it)."""
        return b"".join(self.chunks())

    def chunks(self) -> list:
        """The compressed bundle's chunks, in order."""
        if not self.complete:
            raise MalformedMessage(f"proxy bundle: {self.received} of {self.info.chunks} chunks received")
        return list(self._parts)

    def release(self) -> None:
        """Forget the chunks (once decompressed)."""
        self._parts = [None] * len(self._parts)
