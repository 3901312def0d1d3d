"""A session's depth encoder, chosen by the session's depth codec (protocol/depth_codecs.py).

Every encoder takes a :class:`~pibr.server.pipeline.ProducedFrame` and gives the frame's depth
payloads, ``encode(produced) -> [(PayloadKind, bytes)]``, and has ``close()``:

* ``h264``: :class:`AtlasDepthEncoder`, nothing of its own (the packer put the disparity in the atlas);
* ``edge``: :class:`EdgeDepthEncoder`, the edge codec's streams (Pajak et al.), one per view.

Per frame and view, the edge codec codes the edge samples of the distance map
(``edge_extract``) against the previous frame's decoded samples warped to the new pose (both
ends warp identically), with the significance threshold steered towards a bitrate when one is
set. Every ``intra_every`` frames a view is coded without the temporal context, as H.264 sends
keyframes.
"""
from __future__ import annotations

import numpy as np

from pibr.protocol.depth import DepthQuantizer
from pibr.protocol.depth_codecs import DEPTH_CODECS, edge_quantizer
from pibr.protocol.edgecodec.codec import DEFAULT_THRESHOLD, EdgeEncoder, EncodeStats, warp_samples
from pibr.protocol.pose import Pose

from .config import EdgeSettings
from .edge_extract import RateController, extract_edge_samples


class EdgeDepthStream:
    """One view's depth stream."""

    def __init__(self, width: int, height: int, quantizer: DepthQuantizer, fps: float, kbps: float = 0.0,
                 temporal: bool = True, intra_every: int = 30, q: int = 1, passes: int = 4,
                 threshold: float = DEFAULT_THRESHOLD, perceptual: bool = False):
        self.quantizer = quantizer
        self.encoder = EdgeEncoder(width, height, bits=quantizer.bits, quantizer=quantizer, q=q, temporal=temporal,
                                   passes=passes)
        self.rate = RateController(kbps * 1000.0 / fps, threshold) if kbps > 0 else None
        self._cap_bits = None if self.rate is None else self.rate.target   # the configured cap per frame
        self._mean_bits: float | None = None   # bits per frame while the stream has its whole rate
        self._shared = False                    # coding at a share of its rate (set_share)
        self.threshold = threshold
        self.intra_every = max(1, intra_every)
        self.perceptual = perceptual
        self._prev = None
        self.frames = 0

    def set_share(self, share: float) -> None:
        """Code at ``share`` of the stream's rate (the stream adaptation, server/stream_adaptation.py):
        of its cap, or without one of the bits per frame it spent with its whole rate; 1 restores it."""
        base = self._cap_bits if self._cap_bits is not None else self._mean_bits
        self._shared = share < 1.0 and base is not None
        if not self._shared:
            base, share = self._cap_bits, 1.0   # the cap again, or no rate control at all
        if base is None:
            self.rate = None
        elif self.rate is None:
            self.rate = RateController(max(1.0, base * share), self.threshold)
        else:
            self.rate.target = max(1.0, base * share)

    def encode(self, distance: np.ndarray, pose: Pose, motion=None, moving=None,
               colour=None) -> tuple[bytes, EncodeStats]:
        """distance (h, w) float32 -> (payload, stats). motion (h, w, 2) pixels and moving (h, w) bool
        of moving objects, or None; colour a low-resolution (hl, wl, 3) image for perceptual
        weighting (used when ``perceptual``)."""
        warped = None
        if self._prev is not None and self.frames % self.intra_every:
            warped = warp_samples(self._prev[0], self._prev[1], pose, self.quantizer)
        threshold = self.rate.threshold if self.rate is not None else self.threshold
        found = extract_edge_samples(distance, self.quantizer, threshold, motion,
                                     colour if self.perceptual else None)
        enc = self.encoder.encode(distance, None if warped is None else warped.edges,
                                  None if warped is None else warped.values, edges=found.edges, signs=found.signs,
                                  codes=found.codes, motion=motion, moving=moving)
        if self.rate is not None:
            self.rate.update(enc.stats.total_bits)
        if self._cap_bits is None and not self._shared:
            bits = float(enc.stats.total_bits)
            self._mean_bits = bits if self._mean_bits is None else 0.9 * self._mean_bits + 0.1 * bits
        self._prev = (enc.samples, pose)
        self.frames += 1
        return enc.payload, enc.stats


class EdgeDepthEncoder:
    """A session's depth encoding: the primary view's stream and the extra view's. ``encode(produced)`` gives the Frame's payloads."""

    sends_payloads = True

    def __init__(self, session, fps: float, settings: EdgeSettings = EdgeSettings()):
        q = edge_quantizer(session.near, session.far, session.depth_bits)
        kinds = DEPTH_CODECS["edge"].payloads
        views = {"primary": (session.primary, kinds["primary"])}
        if session.extra is not None:
            views["extra"] = (session.extra, kinds["extra"])
        # Split a bitrate target by pixel count.
        pixels = {k: v.width * v.height for k, (v, _) in views.items()}
        total = sum(pixels.values())
        self.streams = {
            name: (EdgeDepthStream(view.width, view.height, q, fps, settings.kbps * pixels[name] / total,
                                   settings.temporal, settings.intra_every, perceptual=settings.perceptual), kind)
            for name, (view, kind) in views.items()}
        self.last_stats: dict = {}

    def set_share(self, share: float) -> None:
        """Every view's stream at ``share`` of its rate (EdgeDepthStream.set_share)."""
        for stream, _ in self.streams.values():
            stream.set_share(share)

    def encode(self, produced) -> list[tuple[int, bytes]]:
        payloads = []
        poses = {"primary": produced.primary_pose, "extra": produced.extra_pose}
        for name, (stream, kind) in self.streams.items():
            # the motion flow travels as its own payload (MOTION_FLOW), with either depth codec
            data, stats = stream.encode(produced.distances[name], poses[name], colour=produced.low_colour)
            payloads.append((kind, data))
            self.last_stats[name] = stats
        return payloads

    def close(self) -> None:
        pass


class AtlasDepthEncoder:
    """Depth in the H.264 atlas: the packer already wrote it, so a frame gets no payload of its own."""

    sends_payloads = False

    def __init__(self, session, fps: float, settings: EdgeSettings = EdgeSettings()):
        pass

    def set_share(self, share: float) -> None:
        pass   # depth is in the atlas: it follows the colour's target

    def encode(self, produced) -> list[tuple[int, bytes]]:
        return []

    def close(self) -> None:
        pass


#: The server's encoder of each depth codec (protocol/depth_codecs.py), by name.
DEPTH_ENCODERS = {"h264": AtlasDepthEncoder, "edge": EdgeDepthEncoder}


def make_depth_encoder(session, fps: float, settings: EdgeSettings = EdgeSettings()):
    """The depth encoder of ``session`` (its ``depth_codec``), at ``fps`` frames a second."""
    return DEPTH_ENCODERS[session.depth_codec](session, fps, settings)
