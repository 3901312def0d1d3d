"""The proxy bundle: every object's levels of detail, sent once before the first frame.

Per object: a name, its rest transform, whether it moves, its bounding box, and two
meshes — the original and the simplified *encaging* proxy (the third level, the box, is
the bounding box). Positions only: the client rasterises proxies for depth and
back-projection; colour comes from the transmitted views.

Layout (little-endian), then zstd-compressed and cut into ``ProxyChunk`` messages::

    b"PXB1" u32 object_count
    per object:
        u16 name_len, name (UTF-8)
        16 f64 transform (row-major), u8 moving (0 or 1)
        6 f64 bounds (min xyz, max xyz; object space)
        2 x mesh: u32 vertex_count, u32 face_count, f32 vertices (n, 3), u32 faces (m, 3)

Every count is checked against limits and the bytes left before anything is allocated.

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
        """The bounding box as (8, 3) vertices and (12, 3) outward-wound faces."""
        lo, hi = self.bounds
        v = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])],
                     np.float32)
        f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]], np.uint32)
        return v, f

    def level(self, name: str) -> tuple:
        return {"original": self.original, "proxy": self.proxy}.get(name) or self.box_mesh()


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
    def __init__(self, data: bytes):
        self.data, self.pos = data, 0

    def take(self, n: int, what: str) -> bytes:
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
    return v.astype(np.float32), f.astype(np.uint32)


def decode_bundle(data: bytes) -> list[ProxyObject]:
    r = _Reader(data)
    if r.take(4, "magic") != MAGIC:
        raise MalformedMessage("proxy bundle: bad magic")
    (count,) = r.unpack("<I", "object count")
    if count > MAX_OBJECTS:
        raise MalformedMessage(f"proxy bundle: {count} objects exceed the limit of {MAX_OBJECTS}")
    objects = []
    for i in range(count):
        (n,) = r.unpack("<H", f"object {i} name length")
        try:
            name = r.take(n, f"object {i} name").decode("utf-8")
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


def decompress_bundle(data: bytes, max_size: int = MAX_BUNDLE_BYTES) -> bytes:
    """zstd frame -> raw bundle, refusing output larger than ``max_size``."""
    import zstandard

    try:
        params = zstandard.get_frame_parameters(data)
        if params.content_size > max_size:
            raise MalformedMessage(f"proxy bundle: {params.content_size} bytes uncompressed exceed {max_size}")
        return zstandard.ZstdDecompressor().decompress(data, max_output_size=max_size)
    except zstandard.ZstdError as exc:
        raise MalformedMessage(f"proxy bundle: zstd: {exc}") from None


def split_chunks(data: bytes, chunk_bytes: int = CHUNK_BYTES) -> list[bytes]:
    return [data[i:i + chunk_bytes] for i in range(0, len(data), chunk_bytes)] or [b""]


class BundleAssembler:
    """Collects ``ProxyChunk`` messages in order; :attr:`complete` when all arrived."""

    def __init__(self, max_size: int = MAX_BUNDLE_BYTES):
        self.max_size = max_size
        self._parts: list[bytes] = []
        self.count = None
        self.total = None

    def add(self, chunk) -> None:
        if self.count is None:
            self.count, self.total = chunk.count, chunk.total_size
            if self.total > self.max_size:
                raise MalformedMessage(f"proxy bundle of {self.total} bytes exceeds the limit of {self.max_size}")
        if (chunk.count, chunk.total_size) != (self.count, self.total):
            raise MalformedMessage("ProxyChunk: count or total size changed between chunks")
        if chunk.index != len(self._parts):
            raise MalformedMessage(f"ProxyChunk: expected chunk {len(self._parts)}, got {chunk.index}")
        self._parts.append(chunk.data)
        if sum(len(p) for p in self._parts) > self.total:
            raise MalformedMessage("ProxyChunk: more data than the announced total size")

    @property
    def complete(self) -> bool:
        return self.count is not None and len(self._parts) == self.count

    def data(self) -> bytes:
        data = b"".join(self._parts)
        if len(data) != self.total:
            raise MalformedMessage(f"proxy bundle: {len(data)} bytes received, {self.total} announced")
        return data
