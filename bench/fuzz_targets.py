"""The parsers ``pibr bench fuzz`` attacks: their valid seed inputs and how pibr runs them.

Each :class:`Target` builds its seeds in-process from pibr's own writers and encoders, runs
one input the way pibr does, and names the errors that input may raise (its documented
errors); anything else a run raises is a bug.

=========  ==========================================================  ===================
parser     runs                                                        documented errors
=========  ==========================================================  ===================
wire       ``Connection.receive_data`` (any chunking) and ``receive_   any ProtocolError
           eof`` on framed messages of every type; every Welcome's     (recorded by the
           config through ``SessionConfig.from_json``, as the client   connection, which
           does. ``receive_data`` itself must never raise.             never raises)
edge       ``EdgeDecoder.decode`` of edge-codec payloads (intra, raster,  CodecError
           lossy, motion, temporal with the encoder's warped context)
quadtree   ``decode_quadtrees`` of frame quadtree payloads (mutated     CodecError
           zstd frames, and mutated bodies compressed again)
proxy      ``decode_bundle`` (raw), ``decompress_bundle`` + decode      MalformedMessage (and
           (zstd, within a session's announced size), and ProxyChunk    any ProtocolError of
           frames through a Connection and ``BundleAssembler``; each    the chunks' frames)
           object's world matrix must be finite
trace      ``load_trace`` (canonical / pred6dof by header),             TraceError
           ``import_pred6dof``, ``import_csv`` (Euler with a header;
           indices without one), ``parse_columns`` of a ``--columns``
           text; then ``summary()`` and a canonical write -> read that
           must give the same trace back
scene      ``load_description`` of JSON and TOML scene descriptions     SceneError
=========  ==========================================================  ===================
"""
from __future__ import annotations

import io
import json
import os
import random
import tempfile
from dataclasses import dataclass, field

import numpy as np

import struct

from .fuzz_mutate import dump_json, dump_toml, havoc, mutate_tree, overwrite_fields


@dataclass
class Seed:
    """One valid input: ``kind`` tells the target how to run it, ``tree`` (JSON/TOML seeds)
    enables structure-aware mutations, ``text`` the text mutations."""

    kind: str
    data: bytes
    tree: object = None
    text: bool = False
    parts: object = None    # a target's own structure of the seed (the wire's messages)
    fields: tuple = ()      # (offset, size, "u" | "f") of a binary format's counts, sizes and values


@dataclass
class Target:
    """A parser under test. Subclasses fill ``seeds`` (:meth:`build`) and implement :meth:`run`."""

    name: str = ""
    documented: tuple = ()
    suffix: str = ".bin"
    seeds: list = field(default_factory=list)

    def build(self) -> None:
        """Make the seeds (in the parent, once)."""

    def setup(self, workdir: str) -> None:
        """Prepare a worker (after it starts): files the inputs refer to, decoders."""
        self.workdir = workdir

    def run(self, kind: str, data: bytes) -> None:
        """Run one input; raise only :attr:`documented` errors."""
        raise NotImplementedError

    def mutate(self, rng: random.Random, seed: Seed) -> bytes:
        others = [s.data for s in self.seeds if s.kind == seed.kind and s is not seed] or [seed.data]
        if seed.tree is not None and rng.random() < 0.55:
            tree = mutate_tree(rng, seed.tree)
            if rng.random() < 0.3:
                tree = mutate_tree(rng, tree)
            data = dump_toml(tree) if isinstance(tree, dict) and seed.kind == "toml" else dump_json(tree)
            return havoc(rng, data, others, text=True) if rng.random() < 0.15 else data
        if seed.fields and rng.random() < 0.35:
            data = overwrite_fields(rng, seed.data, seed.fields)
            return havoc(rng, data, others) if rng.random() < 0.2 else data
        return havoc(rng, seed.data, others, text=seed.text)


def _message_fields(mtype: int, payload: bytes) -> tuple:
    """The integer and float fields of a binary message payload (Pose, Frame, ProxyChunk, Error)."""
    from pibr.protocol.messages import _FRAME_HEAD, _PAYLOAD_HEAD, Error, Frame, PoseMsg, ProxyChunk

    if mtype == PoseMsg.TYPE:
        return ((0, 4, "u"), (4, 8, "u")) + tuple((12 + 8 * k, 8, "f") for k in range(7))
    if mtype == ProxyChunk.TYPE:
        return ((0, 4, "u"), (4, 4, "u"), (8, 4, "u"))
    if mtype == Error.TYPE:
        return ((0, 2, "u"),)
    if mtype != Frame.TYPE or len(payload) < _FRAME_HEAD.size:
        return ()
    fields = [(0, 4, "u"), (4, 8, "u"), (12, 8, "u"), (20, 4, "u"), (24, 8, "u"), (32, 4, "u"), (180, 1, "u")]
    fields += [(36 + 8 * k, 8, "f") for k in range(16)]
    pos = _FRAME_HEAD.size
    for _ in range(payload[180]):
        fields += [(pos, 1, "u"), (pos + 1, 4, "u")]
        pos += _PAYLOAD_HEAD.size + struct.unpack_from("<I", payload, pos + 1)[0]
    return tuple(fields)


# ============================================================================ wire

class WireTarget(Target):
    """Framed message streams in both directions, and every message type alone."""

    def __init__(self):
        from pibr.protocol.errors import ProtocolError

        super().__init__("wire", (ProtocolError,))

    def build(self) -> None:
        from pibr.protocol.framing import encode_frame
        from pibr.protocol.messages import (Bye, Clock, Error, Frame, Hello, OutputConfig, PayloadKind, PoseMsg,
                                            ProxyChunk, Stats, Welcome)
        from pibr.protocol.pose import Pose

        pose = Pose.make((0.5, 1.6, -2.0), (0.9238795325112867, 0.0, 0.3826834323650898, 0.0))
        extra = Pose.make((0.5, 3.4, -3.5), (0.9914448613738104, -0.13052619222005157, 0.0, 0.0))
        edge = EdgeTarget.payloads()
        quadtree = QuadtreeTarget.payloads()[0]
        welcomes = [Welcome("pibr-server/0.1", 7, c, setup_us=1234) for c in _session_configs()]
        hellos = [Hello(client="fuzz", scene="room", clock="virtual", output=OutputConfig(960, 540, 90.0, 60.0),
                        want_proxies=True, depth_codec="h264"),
                  Hello(client="fuzz", clock="real", depth_codec="edge", quadtree_threshold=0.05)]
        frames = [Frame(3, 300_000, 216_667, 13, 300_000, pose, extra, 0.1, 1000.0, (12.5, 1.25, 3.0, 6.5),
                        ((PayloadKind.H264_ATLAS, b"\x00\x00\x00\x01\x67" + bytes(range(40))),
                         (PayloadKind.EDGE_DEPTH, edge["intra"]), (PayloadKind.QUADTREE, quadtree)), keyframe=True),
                  Frame(4, 400_000, 316_667, 19, 400_000, pose, None, 0.05, 50.0,
                        payloads=((PayloadKind.EDGE_DEPTH, edge["motion"]),
                                  (PayloadKind.EDGE_MOTION, b"\x01\x02")))]
        singles = hellos + welcomes + frames + [
            PoseMsg(42, 700_000, pose), Clock(), ProxyChunk(1, 3, 10, b"zstd"),
            Stats({"frames_received": 12.0, "missed_deadlines": 0.0, "frames_decoded": 3.0}), Bye("done"),
            Error(6, "Pose: invalid pose: quaternion norm below 1e-06")]
        streams = [[(m, 1000 * i) for i, m in enumerate(singles[k:k + 1])] for k in range(len(singles))]
        # A server's session as the client reads it, and a client's as the server reads it.
        streams.append([(welcomes[0], 0), (ProxyChunk(0, 2, 8, b"abcd"), 0), (ProxyChunk(1, 2, 8, b"efgh"), 0),
                        (frames[0], 148_000), (Clock(), 150_000), (Stats({"dropped": 1.0}), 150_000),
                        (frames[1], 248_000), (Bye("end"), 300_000)])
        streams.append([(hellos[0], 0)] + [(PoseMsg(i, 16_667 * i, pose), 16_667 * i + 64_000) for i in range(4)]
                       + [(Clock(), 130_000), (Stats({"frames_decoded": 2.0}), 140_000), (Bye(""), 150_000)])
        self.seeds = [Seed(streams_kind(s), b"".join(encode_frame(m.TYPE, m.serialize(), vt) for m, vt in s),
                           parts=[(m.TYPE, m.serialize(), vt) for m, vt in s]) for s in streams]

    def mutate(self, rng, seed) -> bytes:
        from pibr.protocol.framing import encode_frame

        frames = list(seed.parts)
        r = rng.random()
        if r < 0.5:   # one message's payload mutated, the framing kept valid: the message parsers see it
            i = rng.randrange(len(frames))
            mtype, payload, vt = frames[i]
            fields = _message_fields(mtype, payload)
            if payload[:1] == b"{" and rng.random() < 0.6:
                payload = dump_json(mutate_tree(rng, json.loads(payload)))
            elif fields and rng.random() < 0.5:
                payload = overwrite_fields(rng, payload, fields)
            else:
                others = [p for _, p, _ in frames if p] or [payload]
                payload = havoc(rng, payload, others, text=payload[:1] == b"{")
            if rng.random() < 0.1:
                mtype = rng.choice((1, 2, 3, 4, 5, 6, 7, 8, 9, 0, 10, 255))
            frames[i] = (mtype, payload, vt)
            return b"".join(encode_frame(t, p, v) for t, p, v in frames)
        stream = b"".join(encode_frame(t, p, v) for t, p, v in frames)
        return havoc(rng, stream, [s.data for s in self.seeds])

    def run(self, kind, data) -> None:
        from pibr.protocol.connection import Connection
        from pibr.protocol.messages import Welcome
        from pibr.protocol.session import SessionConfig

        conn = Connection()
        cuts = sorted(random.Random(len(data)).sample(range(len(data) + 1), min(3, len(data) + 1)))
        try:
            for a, b in zip([0] + cuts, cuts + [len(data)]):
                conn.receive_data(data[a:b])
            conn.receive_eof()
        except Exception as exc:   # documented never to raise: any exception here is the bug
            raise RuntimeError(f"Connection.receive_data raised {type(exc).__name__}: {exc}") from exc
        for env in conn.events_received():
            if isinstance(env.message, Welcome):
                SessionConfig.from_json(env.message.config)
        if conn.error is not None:
            raise conn.error


def streams_kind(stream) -> str:
    return "+".join(m.NAME for m, _ in stream[:3]) + ("+..." if len(stream) > 3 else "")


def _session_configs() -> list[dict]:
    """Welcome configs as the server plans them: the room scene with the h264 atlas and an
    extra view, the edge codec with motion and a quadtree, a single-view session."""
    from pibr.protocol.messages import Hello
    from pibr.protocol.proxy import BundleInfo
    from pibr.scenes.registry import load_scene
    from pibr.server.config import ServerConfig
    from pibr.server.session_plan import plan_session

    sphere = load_scene("sphere")
    out = []
    for cfg, hello in ((ServerConfig(view_size=(64, 64), extra_view="on"), Hello()),
                       (ServerConfig(view_size=(96, 64), extra_view="on", depth_codec="edge"),
                        Hello(depth_codec="edge", quadtree_threshold=0.1)),
                       (ServerConfig(view_size=(64, 32), extra_view="off"), Hello(clock="real"))):
        config, _ = plan_session(cfg, sphere, hello, BundleInfo(1, 1000, 2000, 1024, {"proxy": 12}).to_json())
        out.append(config.to_json())
    return out


# ============================================================================ edge codec

_EDGE_SIZE = (64, 48)


def _depth_scene(width: int, height: int, shift: int = 0) -> np.ndarray:
    """(h, w) float32 radial distance of a small synthetic room: a far wall, a floor, a box
    in front (step edges), a tilted square (diagonal edges) and a patch of sky."""
    y, x = np.indices((height, width), dtype=np.float64)
    u, v = x / (width - 1), y / (height - 1)
    d = 6.0 - 0.8 * u - 0.5 * v
    d = np.where(v > 0.62, 1.5 + 3.0 * (1 - v), d)
    box = (np.abs(x - (0.3 * width + shift)) < 0.12 * width) & (np.abs(y - 0.45 * height) < 0.2 * height)
    d = np.where(box, 1.2 + 0.2 * u, d)
    tilt = np.abs(x - 0.72 * width - shift) + np.abs(y - 0.35 * height) < 0.25 * min(width, height)
    d = np.where(tilt, 0.8 + 0.3 * u - 0.2 * v, d)
    d = np.where((x < 0.2 * width) & (y < 0.25 * height), 0.0, d)
    return d.astype(np.float32)


class EdgeTarget(Target):
    """Edge-codec payloads of small synthetic frames (every coding mode), decoded as the client does."""

    def __init__(self):
        from pibr.protocol.errors import CodecError

        super().__init__("edge", (CodecError,))

    @staticmethod
    def _encoded() -> dict:
        """kind -> (payload, warped previous samples or None)."""
        from pibr.protocol.depth import DepthQuantizer
        from pibr.protocol.edgecodec.codec import EdgeEncoder, warp_samples
        from pibr.protocol.pose import Pose

        w, h = _EDGE_SIZE
        q = DepthQuantizer(0.1, 100.0, bits=12, min_code=2)
        d0, d1 = _depth_scene(w, h), _depth_scene(w, h, shift=2)
        motion = np.zeros((h, w, 2), np.float32)
        motion[16:32, 12:28] = (1.5, -0.25)
        out = {"intra": (EdgeEncoder(w, h, 12, q).encode(d0).payload, None),
               "raster": (EdgeEncoder(w, h, 12, q, passes=1).encode(d0).payload, None),
               "lossy": (EdgeEncoder(w, h, 12, q, q=4).encode(d0).payload, None),
               "motion": (EdgeEncoder(w, h, 12, q).encode(d0, motion=motion).payload, None)}
        enc = EdgeEncoder(w, h, 12, q)
        first = enc.encode(d0)
        pose0 = Pose.make((0.0, 1.6, 0.0))
        pose1 = Pose.make((0.05, 1.6, -0.02), (0.9998, 0.0, 0.02, 0.0))
        warped = warp_samples(first.samples, pose0, pose1, q)
        out["temporal"] = (enc.encode(d1, warped.edges, warped.values).payload, warped)
        return out

    @classmethod
    def payloads(cls) -> dict:
        return {k: p for k, (p, _) in cls._encoded().items()}

    #: Header fields of the edge bitstream (protocol/edgecodec/bitstream.py): flags, size, bits,
    #: spacing, min_code, q, edge count and the four section lengths.
    FIELDS = ((4, 1, "u"), (5, 1, "u"), (6, 2, "u"), (8, 2, "u"), (10, 1, "u"), (11, 1, "u"), (12, 2, "u"),
              (14, 2, "u"), (16, 4, "u"), (20, 4, "u"), (24, 4, "u"), (28, 4, "u"), (32, 4, "u"))

    def build(self) -> None:
        encoded = self._encoded()
        self.seeds = [Seed(k, p, fields=self.FIELDS) for k, (p, _) in encoded.items()]
        self._warped = {k: w for k, (_, w) in encoded.items()}

    def mutate(self, rng, seed) -> bytes:
        """Half the time one arithmetic-coded section is mutated and the header's lengths kept
        consistent, so the section decoders (not the length check) see the damage."""
        from pibr.protocol.edgecodec.bitstream import HEADER_SIZE

        if rng.random() >= 0.5:
            return super().mutate(rng, seed)
        lengths = list(struct.unpack_from("<4I", seed.data, 20))
        sections, pos = [], HEADER_SIZE
        for n in lengths:
            sections.append(seed.data[pos:pos + n])
            pos += n
        k = rng.choice([i for i, n in enumerate(lengths) if n] or [0])
        others = [s.data[HEADER_SIZE:] for s in self.seeds]
        sections[k] = havoc(rng, sections[k], others)
        head = bytearray(seed.data[:HEADER_SIZE])
        struct.pack_into("<4I", head, 20, *(len(s) for s in sections))
        data = bytes(head) + b"".join(sections)
        return overwrite_fields(rng, data, self.FIELDS[:9]) if rng.random() < 0.15 else data

    def setup(self, workdir) -> None:
        from pibr.protocol.depth import DepthQuantizer
        from pibr.protocol.edgecodec.codec import EdgeDecoder

        super().setup(workdir)
        self.decoder = EdgeDecoder(*_EDGE_SIZE, 12, DepthQuantizer(0.1, 100.0, bits=12, min_code=2))

    def run(self, kind, data) -> None:
        warped = self._warped[kind]
        self.decoder.decode(data, None if warped is None else warped.edges, None if warped is None else warped.values)


# ============================================================================ quadtree

class QuadtreeTarget(Target):
    """Quadtree payloads of one and two views; bodies mutated before compression, and the zstd frames."""

    SIZES = ((64, 48), (32, 24))

    def __init__(self):
        from pibr.protocol.errors import CodecError

        super().__init__("quadtree", (CodecError,))

    @classmethod
    def payloads(cls) -> list[bytes]:
        from pibr.server.quadtree import quadtree_payload

        primary, extra = (_depth_scene(w, h) for w, h in cls.SIZES)
        return [quadtree_payload({"primary": primary, "extra": extra}, 0.05, 16),
                quadtree_payload({"primary": primary}, 0.2, 8)]

    def build(self) -> None:
        import zstandard

        two, one = self.payloads()
        d = zstandard.ZstdDecompressor()
        bodies = [d.decompress(two), d.decompress(one)]
        self.seeds = [Seed("two", two), Seed("one", one)] + [
            Seed(f"{kind}-body", body, fields=_quadtree_fields(body)) for kind, body in zip(("two", "one"), bodies)]

    def run(self, kind, data) -> None:
        import zstandard

        from pibr.protocol.quadtree import decode_quadtrees

        if kind.endswith("-body"):
            data = zstandard.ZstdCompressor(level=1, write_content_size=True).compress(data)
        decode_quadtrees(data, self.SIZES if kind.startswith("two") else self.SIZES[:1])


def _quadtree_fields(body: bytes) -> tuple:
    """Version, view count, and each view's index, size, root tile and bit count."""
    fields, pos = [(0, 1, "u"), (1, 1, "u")], 2
    for _ in range(body[1]):
        fields += [(pos, 1, "u"), (pos + 1, 2, "u"), (pos + 3, 2, "u"), (pos + 5, 2, "u"), (pos + 7, 4, "u")]
        pos += 11 + (struct.unpack_from("<I", body, pos + 7)[0] + 7) // 8
    return tuple(fields)


# ============================================================================ proxy bundle

#: The chunk size of the fuzzed bundles' ProxyChunk seeds.
_PROXY_CHUNK_BYTES = 4096


class ProxyTarget(Target):
    """The proxy bundle of the built-in sphere scene (its encaging LoD) plus a spinning box."""

    def __init__(self):
        from pibr.protocol.errors import ProtocolError

        super().__init__("proxy", (ProtocolError,))

    def build(self) -> None:
        from pibr.protocol.framing import encode_frame
        from pibr.protocol.messages import ProxyChunk
        from pibr.protocol.proxy import BundleInfo, ProxyObject, compress_bundle, encode_bundle, split_chunks
        from pibr.scenes.lod import simplify_encaging
        from pibr.scenes.primitives import box as box_mesh
        from pibr.scenes.registry import load_scene

        objects = []
        for obj in load_scene("sphere").objects:
            lod = simplify_encaging(obj.mesh, resolution=12)
            objects.append(ProxyObject(obj.name, obj.transform, obj.is_dynamic, obj.mesh.bounds().astype("f8"),
                                       (obj.mesh.vertices, obj.mesh.faces), (lod.proxy.vertices, lod.proxy.faces)))
        box = box_mesh((0.4, 0.4, 0.4))
        transform = np.eye(4)
        transform[:3, 3] = (1.0, 0.5, 0.0)
        objects.append(ProxyObject("box", transform, True, box.bounds().astype("f8"), (box.vertices, box.faces),
                                   (box.vertices, box.faces)))
        small = encode_bundle(objects[1:])
        raw = encode_bundle(objects)
        packed = compress_bundle(raw)
        chunked = b"".join(encode_frame(ProxyChunk.TYPE, ProxyChunk(i, n, len(packed), p).serialize())
                           for parts in [split_chunks(packed, _PROXY_CHUNK_BYTES)] for n in [len(parts)]
                           for i, p in enumerate(parts))
        # What a Welcome announced for each kind of input: the client assembles and inflates within it.
        self.announced = {"zstd": (len(raw), len(objects)), "zstd-small": (len(small), len(objects) - 1),
                          "chunks": BundleInfo(len(objects), len(packed), len(raw), _PROXY_CHUNK_BYTES, {})}
        self.seeds = [Seed("raw", raw, fields=_bundle_fields(raw)), Seed("raw", small, fields=_bundle_fields(small)),
                      Seed("zstd", packed), Seed("zstd-small", compress_bundle(small)),
                      Seed("chunks", chunked, fields=_chunk_fields(chunked))]

    def run(self, kind, data) -> None:
        from pibr.protocol.connection import Connection
        from pibr.protocol.messages import ProxyChunk
        from pibr.protocol.proxy import BundleAssembler, decode_bundle, decompress_bundle

        if kind == "chunks":
            info = self.announced["chunks"]
            conn = Connection()
            conn.receive_data(data)
            conn.receive_eof()
            assembler = BundleAssembler(info)
            for env in conn.events_received():
                if isinstance(env.message, ProxyChunk) and not assembler.complete:
                    assembler.add(env.message)
            if conn.error is not None:
                raise conn.error
            data = decompress_bundle(assembler.data(), info.raw_bytes, info.objects)
        elif kind != "raw":
            data = decompress_bundle(data, *self.announced[kind])
        for obj in decode_bundle(data):
            if not (np.all(np.isfinite(obj.transform)) and isinstance(obj.moving, bool)):
                raise AssertionError(f"decoded object {obj.name!r} has a non-finite transform or a moving flag "
                                     f"{obj.moving!r}")


def _bundle_fields(raw: bytes) -> tuple:
    """Object count; per object the name length, transform, moving flag, bounds, and
    both meshes' vertex and face counts, a vertex and a face index (protocol/proxy.py layout)."""
    fields, pos = [(4, 4, "u")], 8
    for _ in range(struct.unpack_from("<I", raw, 4)[0]):
        (n,) = struct.unpack_from("<H", raw, pos)
        fields.append((pos, 2, "u"))
        pos += 2 + n
        fields += [(pos + 8 * k, 8, "f") for k in range(16)] + [(pos + 128, 1, "u")]
        pos += 129
        fields += [(pos + 8 * k, 8, "f") for k in range(6)]
        pos += 48
        for _mesh in range(2):
            nv, nf = struct.unpack_from("<II", raw, pos)
            fields += [(pos, 4, "u"), (pos + 4, 4, "u"), (pos + 8, 8, "u"), (pos + 8 + 12 * nv, 4, "u")]
            pos += 8 + 12 * nv + 12 * nf
    return tuple(fields)


def _chunk_fields(stream: bytes) -> tuple:
    """Each ProxyChunk frame's length and its index, count and total size."""
    from pibr.protocol.framing import HEADER_SIZE

    fields, pos = [], 0
    while pos < len(stream):
        length = struct.unpack_from("<I", stream, pos + 16)[0]
        fields += [(pos + 16, 4, "u"), (pos + 20, 4, "u"), (pos + 24, 4, "u"), (pos + 28, 4, "u")]
        pos += HEADER_SIZE + length
    return tuple(fields)


# ============================================================================ head traces

class TraceTarget(Target):
    """Every trace format pibr imports, and the ``--columns`` text."""

    def __init__(self):
        from pibr.protocol.errors import TraceError

        super().__init__("trace", (TraceError,), suffix=".csv")

    _COLUMNS = {
        "csv-euler": dict(columns={"t": "time", "px": "px", "py": "py", "pz": "pz", "yaw": "yaw", "pitch": "pitch",
                                   "roll": "roll"}, rotation="euler", time_unit="ms", recentre="yaw"),
        "csv-index": dict(columns={"t": 0, "p": 1, "q": 4}, quat_order="xyzw", handedness="left", time_unit="ns",
                          delimiter=None, positions="columns"),
    }
    _COLUMNS_TEXT = b"t=t,px=px,py=py,pz=pz,qw=qw,qx=qx,qy=qy,qz=qz"

    def build(self) -> None:
        from importlib import resources

        from pibr.common.traces.canonical import write_canonical_csv
        from pibr.common.traces.synthesis import synthesize

        trace = synthesize("mixed", 0.3, rate_hz=60.0, seed=3)
        with tempfile.TemporaryDirectory() as tmp:
            canonical = os.path.join(tmp, "canonical.csv")
            write_canonical_csv(trace, canonical)
            with open(canonical, "rb") as f:
                canonical_bytes = f.read()
        ref = resources.files("pibr.common.traces").joinpath("data/pred6dof/1.csv")
        pred = b"\n".join(ref.read_bytes().splitlines()[:20]) + b"\n"
        euler = ["time;px;py;pz;yaw;pitch;roll"] + [
            f"{1000 + 16.7 * i:.1f},{0.01 * i:.4f},{1.6 + 0.001 * i:.4f},{-0.02 * i:.4f},{2.0 * i:.2f},{-1.0 * i:.2f},0"
            for i in range(15)]
        index = [f"{1_700_000_000_000_000_000 + 16_666_667 * i} {0.01 * i} 1.6 {-0.01 * i} 0 {0.01 * i} 0 1"
                 for i in range(15)]
        self.canonical_bytes = canonical_bytes
        self.seeds = [Seed("canonical", canonical_bytes, text=True), Seed("pred6dof", pred, text=True),
                      Seed("csv-euler", "\n".join(euler).encode() + b"\n", text=True),
                      Seed("csv-index", "\n".join(index).encode() + b"\n", text=True),
                      Seed("columns", self._COLUMNS_TEXT, text=True)]

    def setup(self, workdir) -> None:
        super().setup(workdir)
        self.path = os.path.join(workdir, "trace.csv")
        self.fixed = os.path.join(workdir, "fixed.csv")
        self.out = os.path.join(workdir, "out.csv")
        with open(self.fixed, "wb") as f:
            f.write(self.canonical_bytes)

    def run(self, kind, data) -> None:
        from pibr.common.traces.canonical import read_canonical_csv, write_canonical_csv
        from pibr.common.traces.loading import load_trace
        from pibr.common.traces.importers import import_csv, import_pred6dof, parse_columns

        if kind == "columns":
            trace = import_csv(self.fixed, parse_columns(data.decode("utf-8", "surrogateescape")))
        else:
            with open(self.path, "wb") as f:
                f.write(data)
            if kind == "canonical":
                trace = load_trace(self.path)
            elif kind == "pred6dof":
                trace = import_pred6dof(self.path)
            else:
                trace = import_csv(self.path, **self._COLUMNS[kind])
        json.dumps(trace.summary(), allow_nan=False)
        write_canonical_csv(trace, self.out)
        back = read_canonical_csv(self.out)
        if not (np.array_equal(back.t, trace.t) and np.array_equal(back.positions, trace.positions)
                and np.array_equal(back.orientations, trace.orientations)):
            raise AssertionError("the canonical file written from the trace reads back different")


# ============================================================================ scene descriptions

_SCENE_JSON = {
    "name": "fuzz", "description": "every key a description has", "units": "m", "up": "y", "near": 0.05,
    "far": 200.0, "sky_color": [0.6, 0.7, 0.9], "extra_view": True, "view_region": [[-3, 1.0, -3], [3, 2.2, 6]],
    "viewer_origin": {"position": [0, 1.6, 5], "yaw_deg": 10, "pitch_deg": -10},
    "extra_view_offset": {"forward": 1.5, "up": 1.8, "tilt_deg": 15},
    "lights": [{"kind": "ambient", "intensity": 0.3}, {"kind": "directional", "direction": [-0.4, -1, -0.3],
                                                       "color": [1.0, 0.95, 0.9], "intensity": 0.9},
               {"kind": "point", "position": [0, 3, 0], "range": 12, "intensity": 1.5}],
    "objects": [
        {"name": "floor", "builtin": "plane", "size": [20, 20], "texture": "tex.png", "uv_scale": 10},
        {"builtin": "box", "size": [1, 2, 0.5], "position": [1, 1, 0], "rotation_deg": [30, 0, 5],
         "scale": [1, 1.5, 1], "color": [0.9, 0.2, 0.1, 1.0]},
        {"name": "ball", "builtin": "sphere", "radius": 0.3, "segments": 10, "position": [2, 1, 0],
         "animation": {"kind": "orbit", "axis": [0, 1, 0], "radius": 1.5, "speed": 0.5}},
        {"builtin": "cylinder", "radius": 0.2, "height": 1.0, "segments": 8, "quaternion": [1, 0, 0.2, 0],
         "animation": {"kind": "swing", "axis": [1, 0, 0], "amplitude": 0.3, "speed": 2.0, "pivot": [0, 0.5, 0],
                       "phase": 0.1}},
    ],
}

_SCENE_TOML = {
    "name": "fuzz-toml", "units": "cm", "up": "z", "near": 0.1, "far": 1000.0,
    "viewer_origin": {"position": [0, 1.6, 4], "quaternion": [1, 0, 0, 0]},
    "objects": [
        {"name": "statue", "asset": "tetra.obj", "units": "mm", "up": "y", "fit_size": 1.5, "center": "base",
         "position": [0, 0, 0], "scale": 1.0, "texture": "tex.png", "split": 0},
        {"builtin": "box", "size": [0.5, 0.5, 0.5], "animation": {"kind": "slide", "axis": [1, 0, 0],
                                                                  "amplitude": 0.4, "speed": 1.0}},
        {"builtin": "sphere", "radius": 0.25, "segments": 6, "position": [0, 0.5, 1],
         "animation": {"kind": "spin", "axis": [0, 1, 0], "speed": 1.0}},
    ],
}

#: A textured tetrahedron, the asset the TOML seed places.
_TETRA_OBJ = b"""v 0 0 0
v 1000 0 0
v 0 1000 0
v 0 0 1000
vt 0 0
vt 1 0
vt 0 1
f 1/1 3/3 2/2
f 1/1 2/2 4/3
f 1/1 4/3 3/2
f 2/1 3/2 4/3
"""


class SceneTarget(Target):
    """JSON and TOML scene descriptions using every key (primitives, an asset, a texture)."""

    def __init__(self):
        from pibr.protocol.errors import SceneError

        super().__init__("scene", (SceneError,), suffix=".txt")

    def build(self) -> None:
        self.seeds = [Seed("json", json.dumps(_SCENE_JSON, indent=1).encode(), _SCENE_JSON, text=True),
                      Seed("toml", dump_toml(_SCENE_TOML), _SCENE_TOML, text=True)]

    def setup(self, workdir) -> None:
        from PIL import Image

        super().setup(workdir)
        with open(os.path.join(workdir, "tetra.obj"), "wb") as f:
            f.write(_TETRA_OBJ)
        buf = io.BytesIO()
        Image.fromarray((np.indices((8, 8)).sum(0) % 2 * 255).astype(np.uint8)).convert("RGB").save(buf, "PNG")
        with open(os.path.join(workdir, "tex.png"), "wb") as f:
            f.write(buf.getvalue())

    def run(self, kind, data) -> None:
        from pibr.protocol.errors import MalformedMessage
        from pibr.protocol.messages import Hello
        from pibr.protocol.session import SessionConfig
        from pibr.scenes.description import load_description
        from pibr.server.config import ServerConfig
        from pibr.server.session_plan import plan_session

        path = os.path.join(self.workdir, "scene." + kind)
        with open(path, "wb") as f:
            f.write(data)
        scene = load_description(path)
        # The scene must make a Welcome the server can write and its clients accept.
        config, _ = plan_session(ServerConfig(view_size=(64, 64)), scene, Hello())
        try:
            SessionConfig.from_json(json.loads(json.dumps(config.to_json(), allow_nan=False)))
        except MalformedMessage as exc:
            raise AssertionError(f"the scene's Welcome is refused: {exc}") from exc


# ============================================================================ registry

TARGETS = {"wire": WireTarget, "edge": EdgeTarget, "quadtree": QuadtreeTarget, "proxy": ProxyTarget,
           "trace": TraceTarget, "scene": SceneTarget}

