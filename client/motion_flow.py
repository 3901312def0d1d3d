"""Decoding a frame's ``MOTION_FLOW`` payload into a dense flow of the primary view.

The ``blocks`` coder's payload decodes to the dense flow directly. The ``edges`` coder's
(Pajak et al. 2011) carries samples, which are diffused per component with the depth's
edge-aware push-pull (:func:`pibr.client.diffusion.diffuse`): each region between edge
samples is filled from its own samples only, so the background, whose samples are all 0,
stays exactly 0 and the moving mask is where the diffused flow is not.
"""
from __future__ import annotations

import numpy as np

from pibr.protocol.edgecodec.codec import DecodedSamples
from pibr.protocol.edgecodec.flow import FlowSamples
from pibr.protocol.motion_flow import decode_motion_flow

from .diffusion import DiffusionWorkspace, diffuse

_NO_GRID = np.zeros(0, dtype=np.int64)


def diffuse_flow(samples: FlowSamples, workspace: DiffusionWorkspace | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Samples -> (flow (h, w, 2) float32 pixels, moving (h, w) bool)."""
    h, w = samples.shape
    flow = np.zeros((h, w, 2), dtype=np.float32)
    for k in range(2):
        component = DecodedSamples(edges=samples.edges, signs=samples.signs[..., k],
                                   codes=np.ascontiguousarray(samples.flow[..., k]), valid=samples.valid,
                                   regular=np.zeros((0, 0), np.uint16), regular_rows=_NO_GRID,
                                   regular_cols=_NO_GRID, bits=16, min_code=1)
        flow[..., k] = diffuse(component, workspace=workspace)
    return flow, np.any(flow != 0.0, axis=-1)


class MotionFlowDecoder:
    """The motion flow of one session's primary view (``width`` x ``height``); one per stream
    (its diffusion memory is reused from frame to frame, on the thread that decodes)."""

    def __init__(self, width: int, height: int):
        self.width, self.height = int(width), int(height)
        self.workspace = DiffusionWorkspace()

    def decode(self, payload) -> tuple[np.ndarray, np.ndarray]:
        """Payload -> (flow (h, w, 2) float32 pixels per frame interval, moving (h, w) bool).
        Raises CodecError when it does not decode."""
        parsed = decode_motion_flow(payload, self.width, self.height)
        if parsed.dense is not None:
            return parsed.dense
        return diffuse_flow(parsed.samples, self.workspace)
