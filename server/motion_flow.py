"""Each frame's ``MOTION_FLOW`` payload: the primary view's motion flow of moving objects.

The renderer writes the flow of moving objects over the last frame interval beside colour and
distance (server/renderer.py); it is coded here with the session's flow coder
(protocol/motion_flow.py), in the encoder pool, whatever the depth transport.
"""
from __future__ import annotations

from pibr.protocol.motion_flow import encode_motion_flow


def motion_flow_payload(produced, coder: str) -> bytes:
    """The MOTION_FLOW payload of a :class:`~pibr.server.pipeline.ProducedFrame` rendered with motion."""
    if produced.motion is None or produced.moving is None:
        raise ValueError("the frame was rendered without motion (ProducerSpec.motion_dt)")
    return encode_motion_flow(produced.motion, produced.moving, coder, decoded=False)[0]
