"""How a session's depth travels, by name: the depth codecs both ends build their streams from.

A session announces its codec in ``SessionConfig.depth_codec`` with the quantization it uses
(``depth_bits``, ``depth_min_code``). Each codec says here what that means on the wire: whether
the views' disparity sits in the H.264 atlas beside the colour, or travels as payloads of its
own, which payload kinds, and its default quantization. The server's encoders
(``pibr.server.depth_encoders``) and the client's decoders (``pibr.client.depth_decoders``) are
chosen by these names, so a codec added here must be added at both ends (a test checks it).

* ``h264``: 8-bit disparity in the luma of the H.264 atlas (Reinert et al. 2016, Sec. 4);
* ``edge``: the edge codec's payloads per view (Pajak et al. 2011; :mod:`.edgecodec`), 12 bits.
"""
from __future__ import annotations

from dataclasses import dataclass

from .depth import DepthQuantizer
from .errors import ConfigError
from .messages import PayloadKind


@dataclass(frozen=True)
class DepthCodec:
    """One way depth travels.

    name        : as on the wire and on command lines
    in_atlas    : the views' quantized disparity sits in the H.264 atlas (no payloads of its own)
    payloads    : view -> the payload kind carrying that view's depth (empty when ``in_atlas``)
    bits, min_code : its default quantization (codes below ``min_code`` mark sky and peeled pixels)
    bits_range  : the depths (bits) it can carry, inclusive
    noun        : how error messages name it
    summary     : one line for help texts
    """

    name: str
    in_atlas: bool
    payloads: dict
    bits: int
    min_code: int
    bits_range: tuple
    noun: str
    summary: str

    def quantizer(self, near: float, far: float, bits: int | None = None) -> DepthQuantizer:
        """The codec's quantizer for a scene's clip spheres (``bits``: another depth than its default)."""
        return DepthQuantizer(near, far, bits=self.bits if bits is None else bits, min_code=self.min_code)


#: Bits of the edge codec's disparity codes (sky = code 0, peeled = 1, surfaces from 2).
EDGE_BITS = 12

DEPTH_CODECS: dict[str, DepthCodec] = {c.name: c for c in (
    DepthCodec("h264", True, {}, 8, 16, (1, 16), "depth in the H.264 atlas", "8-bit disparity in the H.264 atlas"),
    # the edge bitstream's range (edgecodec/bitstream.py MIN_BITS..MAX_BITS; a test keeps them equal)
    DepthCodec("edge", False, {"primary": PayloadKind.EDGE_DEPTH, "extra": PayloadKind.EDGE_DEPTH_EXTRA},
               EDGE_BITS, 2, (8, 16), "the edge codec", "the edge codec (Pajak et al. 2011), 12-bit disparity"),
)}

#: What a server or client may ask for: a codec by name, or ``auto`` (the server decides for the bandwidth).
AUTO = "auto"


def depth_codec(name: str) -> DepthCodec:
    """The codec called ``name``; ConfigError naming the choices otherwise."""
    try:
        return DEPTH_CODECS[name]
    except (KeyError, TypeError):
        raise ConfigError(f"unknown depth codec {name!r}; choose {' or '.join(DEPTH_CODECS)}") from None


def h264_quantizer(near: float, far: float) -> DepthQuantizer:
    """The 8-bit disparity carried in the luma of the H.264 atlas."""
    return DEPTH_CODECS["h264"].quantizer(near, far)


def edge_quantizer(near: float, far: float, bits: int = EDGE_BITS) -> DepthQuantizer:
    """The edge codec's depth quantizer: ``bits`` of disparity, sky = code 0, peeled (the extra
    view's pixels the primary already shows) = 1, surfaces from 2."""
    return DEPTH_CODECS["edge"].quantizer(near, far, bits)
