"""The ``MOTION_FLOW`` payload of a ``Frame``: the primary view's motion flow of moving objects.

Per pixel of the primary view, how far the surface there moved on screen over the last server
frame interval by itself (pixels, x right, y down): the flow the server renders for moving
objects (the camera's own motion is known from the poses, so static surfaces have none).
Frames of a scene that moves carry it whatever the depth transport; a static scene's frames
carry none. Two coders, chosen by the server (``pibr serve --flow-coder``):

* ``blocks`` (:mod:`.edgecodec.motion`): the moving mask, losslessly, and one non-linearly
  quantized mean vector per 8 x 8 block with a moving pixel; the decoded flow is the block's
  vector on its moving pixels, 0 elsewhere;
* ``edges`` (:mod:`.edgecodec.flow`, Pajak et al. 2011's way): edge samples of the quantized
  flow, regular samples and their values; the client diffuses them (``pibr.client.motion_flow``).

Layout (little-endian)::

    u8  coder: 0 nothing moves in this view (no section), 1 blocks, 2 edges
    u16 width, u16 height of the view (must be the session's primary view)
    the coder's section (nothing for coder 0)

A frame in which no moving pixel is visible costs the 5 bytes of the head.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from .errors import CodecError

_HEAD = struct.Struct("<BHH")
HEAD_BYTES = _HEAD.size
_NONE = 0   # the head's coder byte when nothing moves in the view


@dataclass
class DecodedFlow:
    """A payload as parsed: ``dense`` (flow (h, w, 2) float32, moving (h, w) bool) from the
    ``blocks`` coder or when nothing moves, or ``samples`` (:class:`FlowSamples`) from the
    ``edges`` coder, which the client diffuses."""

    coder: str
    width: int
    height: int
    dense: tuple | None = None
    samples: object = None   # edgecodec.flow.FlowSamples


# The coders' kernels are compiled (numba) and imported when a coder runs, so that naming the
# coders (command lines, settings) costs nothing.

def _encode_blocks(flow, moving, scale, decoded, **options) -> tuple[bytes, dict]:
    from .edgecodec.motion import encode_motion

    section, dense, mov = encode_motion(flow, moving, scale, decoded=decoded, **options)   # reads moving pixels only
    return section, {"dense": (dense, mov)}


def _decode_blocks(section, w: int, h: int) -> dict:
    from .edgecodec.motion import decode_motion

    try:
        return {"dense": decode_motion(section, h, w)}
    except CodecError as exc:   # the block coder's messages name the edge codec it lives in
        raise CodecError(f"motion flow: {exc}".replace("edge codec: ", "")) from None


def _encode_edges(flow, moving, scale, decoded, **options) -> tuple[bytes, dict]:
    from .edgecodec.flow import encode_flow_edges

    flow = np.where(moving[..., None], np.nan_to_num(np.asarray(flow, dtype=np.float64)), 0.0)
    section, samples = encode_flow_edges(flow, moving, scale, **options)
    return section, {"samples": samples}


def _decode_edges(section, w: int, h: int) -> dict:
    from .edgecodec.flow import decode_flow_edges

    return {"samples": decode_flow_edges(section, h, w)}


@dataclass(frozen=True)
class FlowCoder:
    """One way the flow travels: its ``id`` in the payload's head, ``encode(flow, moving, scale,
    decoded, **options) -> (section, DecodedFlow fields)`` and ``decode(section, w, h) -> fields``."""

    name: str
    id: int
    encode: object
    decode: object


#: The flow coders by name (``pibr serve --flow-coder``).
FLOW_CODERS: dict[str, FlowCoder] = {c.name: c for c in (
    FlowCoder("blocks", 1, _encode_blocks, _decode_blocks),
    FlowCoder("edges", 2, _encode_edges, _decode_edges),
)}
DEFAULT_FLOW_CODER = "blocks"
_BY_ID = {c.id: c for c in FLOW_CODERS.values()}


def encode_motion_flow(flow, moving, coder: str = DEFAULT_FLOW_CODER, scale: int = 8, decoded: bool = True,
                       **options) -> tuple[bytes, DecodedFlow | None]:
    """flow (h, w, 2) float pixels, moving (h, w) bool -> (payload, what the decoder will see, or
    None unless ``decoded``: the server sends the payload only).

    options go to the coder (``blocks``: block_log2; ``edges``: threshold, spacing_log2, q)."""
    moving = np.asarray(moving, dtype=bool)
    h, w = moving.shape
    if coder not in FLOW_CODERS:
        raise ValueError(f"unknown flow coder {coder!r}; choose from {', '.join(FLOW_CODERS)}")
    if not (1 <= w <= 0xFFFF and 1 <= h <= 0xFFFF):
        raise ValueError(f"view size {w}x{h} outside 1..65535")
    flow = np.asarray(flow)
    if flow.shape != (h, w, 2):
        raise ValueError(f"flow must have shape ({h}, {w}, 2), got {flow.shape}")
    if not moving.any():
        return _HEAD.pack(_NONE, w, h), _still(w, h) if decoded else None
    spec = FLOW_CODERS[coder]
    section, fields = spec.encode(flow, moving, scale, decoded, **options)
    return _HEAD.pack(spec.id, w, h) + section, DecodedFlow(coder, w, h, **fields) if decoded else None


def _still(w, h) -> DecodedFlow:
    return DecodedFlow("none", w, h, dense=(np.zeros((h, w, 2), np.float32), np.zeros((h, w), bool)))


def decode_motion_flow(payload, width: int, height: int) -> DecodedFlow:
    """Payload -> :class:`DecodedFlow` for a primary view of ``width`` x ``height``. Raises CodecError."""
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        raise CodecError(f"motion flow: payload must be bytes, got {type(payload).__name__}")
    view = memoryview(payload).cast("B")
    if len(view) < _HEAD.size:
        raise CodecError(f"motion flow: payload of {len(view)} bytes is shorter than its {_HEAD.size}-byte head")
    coder, w, h = _HEAD.unpack_from(view, 0)
    if (w, h) != (width, height):
        raise CodecError(f"motion flow: payload is {w}x{h}, the primary view {width}x{height}")
    section = view[_HEAD.size:]
    if coder == _NONE:
        if len(section):
            raise CodecError(f"motion flow: {len(section)} bytes after a head that says nothing moves")
        return _still(w, h)
    if coder not in _BY_ID:
        raise CodecError(f"motion flow: unknown coder {coder}")
    spec = _BY_ID[coder]
    return DecodedFlow(spec.name, w, h, **spec.decode(section, w, h))
