"""A session's depth decoder, chosen by the session's depth codec (protocol/depth_codecs.py).

Every decoder has ``decode(frame, reconstruct=True) -> {view: distance (h, w) float32} | None``
and ``close()``:

* ``h264``: :class:`AtlasDepthDecoder`, nothing to decode (the textures read the disparity from the atlas);
* ``edge``: :class:`EdgeDepthDecoder`, the edge codec's streams decoded into dense maps (Pajak et al.).

Each edge view's decoder warps its previous decoded samples to the new frame's pose exactly as
the server's encoder did, decodes, and diffuses the sparse samples into a dense map.
"""
from __future__ import annotations

import concurrent.futures

import numpy as np

from pibr.common.priority import background_executor
from pibr.protocol.depth import DepthQuantizer
from pibr.protocol.depth_codecs import DEPTH_CODECS
from pibr.protocol.edgecodec.codec import DecodedSamples, EdgeDecoder, warp_samples
from pibr.protocol.errors import CodecError
from pibr.protocol.messages import Frame
from pibr.protocol.pose import Pose

from .diffusion import DiffusionWorkspace, reconstruct_depth


class EdgeDepthStreamDecoder:
    """One view's depth stream."""

    def __init__(self, width: int, height: int, quantizer: DepthQuantizer, edge_aware: bool = True):
        self.quantizer, self.edge_aware = quantizer, edge_aware
        self.decoder = EdgeDecoder(width, height, quantizer.bits, quantizer)
        self.workspace = DiffusionWorkspace()  # this stream's: the streams decode on threads of their own
        self._prev: tuple[DecodedSamples, Pose] | None = None

    def decode(self, payload: bytes, pose: Pose, reconstruct: bool = True) -> tuple[np.ndarray | None, DecodedSamples]:
        """-> (dense distance (h, w) float32, 0 = sky; the decoded samples). ``reconstruct`` False:
        the samples only (the next frame is coded against them), no diffusion: distance None."""
        warped = warp_samples(self._prev[0], self._prev[1], pose, self.quantizer) if self._prev else None
        samples = self.decoder.decode(payload, None if warped is None else warped.edges,
                                      None if warped is None else warped.values)
        self._prev = (samples, pose)
        if not reconstruct:
            return None, samples
        return reconstruct_depth(samples, self.quantizer, self.edge_aware, self.workspace), samples


class EdgeDepthDecoder:
    """All depth streams of a session; ``decode(frame)`` -> {view: distance (h, w) float32}."""

    def __init__(self, session, edge_aware: bool = True):
        q = DepthQuantizer(session.near, session.far, bits=session.depth_bits, min_code=session.depth_min_code)
        kinds = DEPTH_CODECS["edge"].payloads
        self.streams = {"primary": (EdgeDepthStreamDecoder(session.primary.width, session.primary.height, q,
                                                           edge_aware), kinds["primary"])}
        if session.extra is not None:
            self.streams["extra"] = (EdgeDepthStreamDecoder(session.extra.width, session.extra.height, q, edge_aware),
                                     kinds["extra"])
        self.motion = None
        # The views' streams are independent and their kernels release the GIL: the extra
        # view decodes on this helper thread while the caller's decodes the primary.
        self._helper = (background_executor("pibr-depth")
                        if "extra" in self.streams else None)

    def close(self) -> None:
        if self._helper is not None:
            self._helper.shutdown(wait=True)
            self._helper = None

    def decode(self, frame: Frame, reconstruct: bool = True) -> dict | None:
        """-> {view: distance}, or None when not ``reconstruct`` (samples decoded for the next frames only)."""
        poses = {"primary": frame.primary_pose, "extra": frame.extra_pose}
        jobs = {}
        for name, (stream, kind) in self.streams.items():
            payload = frame.payload(kind)
            if payload is None or poses[name] is None:
                raise CodecError(f"frame {frame.frame_id} lacks the {name} view's edge-coded depth")
            jobs[name] = (stream, payload, poses[name], reconstruct)
        extra = self._helper.submit(jobs["extra"][0].decode, *jobs["extra"][1:]) if "extra" in jobs else None
        out = {}
        try:
            out["primary"], samples = jobs["primary"][0].decode(*jobs["primary"][1:])
            self.motion = samples.motion
        finally:  # never leave the extra stream's decode running into the next frame's
            if extra is not None:
                concurrent.futures.wait([extra])
        if extra is not None:
            out["extra"] = extra.result()[0]
        return out if reconstruct else None


class AtlasDepthDecoder:
    """Depth in the H.264 atlas: the frame textures read it from the decoded image, nothing to decode here."""

    motion = None

    def __init__(self, session, edge_aware: bool = True):
        pass

    def decode(self, frame: Frame, reconstruct: bool = True) -> None:
        return None

    def close(self) -> None:
        pass


#: The client's decoder of each depth codec (protocol/depth_codecs.py), by name.
DEPTH_DECODERS = {"h264": AtlasDepthDecoder, "edge": EdgeDepthDecoder}


def make_depth_decoder(session, edge_aware: bool = True):
    """The depth decoder of ``session`` (its ``depth_codec``)."""
    return DEPTH_DECODERS[session.depth_codec](session, edge_aware)
