"""The depth codecs' registry: both ends have every codec, and what it says matches the codecs."""
import pytest

from pibr.protocol.depth_codecs import AUTO, DEPTH_CODECS, EDGE_BITS, depth_codec, edge_quantizer, h264_quantizer
from pibr.protocol.errors import ConfigError
from pibr.protocol.messages import PayloadKind


def test_every_codec_has_an_encoder_and_a_decoder():
    from pibr.client.depth_decoders import DEPTH_DECODERS
    from pibr.server.depth_encoders import DEPTH_ENCODERS

    assert set(DEPTH_ENCODERS) == set(DEPTH_DECODERS) == set(DEPTH_CODECS) == {"h264", "edge"}
    assert AUTO not in DEPTH_CODECS


def test_the_registry_says_what_the_codecs_do():
    from pibr.protocol.edgecodec.bitstream import MAX_BITS, MIN_BITS

    h264, edge = DEPTH_CODECS["h264"], DEPTH_CODECS["edge"]
    assert h264.in_atlas and not h264.payloads
    assert not edge.in_atlas and edge.payloads == {"primary": PayloadKind.EDGE_DEPTH,
                                                   "extra": PayloadKind.EDGE_DEPTH_EXTRA}
    assert edge.bits_range == (MIN_BITS, MAX_BITS)
    assert (h264_quantizer(0.1, 100.0).bits, h264_quantizer(0.1, 100.0).min_code) == (8, 16)
    q = edge_quantizer(0.1, 100.0)
    assert (q.bits, q.min_code) == (EDGE_BITS, 2) == (12, 2)
    assert edge_quantizer(0.1, 100.0, 10).bits == 10


def test_an_unknown_codec_is_named_with_the_choices():
    assert depth_codec("edge") is DEPTH_CODECS["edge"]
    with pytest.raises(ConfigError, match="unknown depth codec 'jpeg'; choose h264 or edge"):
        depth_codec("jpeg")
