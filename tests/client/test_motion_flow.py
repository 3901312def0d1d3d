"""The client's motion flow: both coders decode to a dense flow of the primary view; the edge
samples (Pajak et al.) diffuse into each moving region without leaking into the background."""
import numpy as np
import pytest

from pibr.client.motion_flow import MotionFlowDecoder
from pibr.protocol.edgecodec.motion import MAX_MOTION
from pibr.protocol.errors import CodecError
from pibr.protocol.motion_flow import encode_motion_flow

from ..protocol.golden_motion_flow import HEIGHT, WIDTH, golden_payload, moving_field
from ..protocol.test_motion_flow import quantisation_bound


@pytest.mark.parametrize("coder", ["blocks", "edges"])
def test_both_coders_decode_to_the_moving_mask_and_a_close_flow(coder):
    flow, moving = moving_field(96, 128)
    payload, _ = encode_motion_flow(flow, moving, coder)
    got, got_moving = MotionFlowDecoder(128, 96).decode(payload)
    np.testing.assert_array_equal(got_moving, moving)
    assert np.all(got[~moving] == 0)            # the background stays exactly still
    epe = np.linalg.norm(got - flow, axis=-1)[moving]
    assert epe.mean() < {"blocks": 0.5, "edges": 0.15}[coder], epe.mean()


def test_edge_samples_follow_a_turning_object_better_than_block_means():
    """A disc turning about its centre has a flow affine in the pixel: diffusion between the
    samples reproduces it; 8 x 8 block means are off by up to half a block's flow gradient."""
    y, x = np.indices((96, 128), dtype=np.float64)
    disc = (x - 60) ** 2 + (y - 50) ** 2 < 35 ** 2
    flow = np.zeros((96, 128, 2), np.float32)
    flow[disc, 0] = -0.2 * (y[disc] - 50)
    flow[disc, 1] = 0.2 * (x[disc] - 60)
    err = {}
    for coder in ("blocks", "edges"):
        got, _ = MotionFlowDecoder(128, 96).decode(encode_motion_flow(flow, disc, coder)[0])
        err[coder] = np.linalg.norm(got - flow, axis=-1)[disc].mean()
    assert err["edges"] < 0.5 * err["blocks"], err


@pytest.mark.parametrize("v", [(MAX_MOTION, -MAX_MOTION), (1.0 / 256, -1.0 / 64), (0.49, 17.3)])
def test_diffused_flow_at_the_quantisers_limits_stays_within_the_documented_error(v):
    flow = np.zeros((HEIGHT, WIDTH, 2), np.float32)
    moving = np.zeros((HEIGHT, WIDTH), bool)
    moving[10:30, 12:40] = True
    flow[moving] = v
    got, got_moving = MotionFlowDecoder(WIDTH, HEIGHT).decode(encode_motion_flow(flow, moving, "edges")[0])
    np.testing.assert_array_equal(got_moving, moving)
    sent = np.asarray(v, np.float32).astype(np.float64)
    err = np.abs(got[moving].astype(np.float64) - sent)
    assert np.all(err <= quantisation_bound(sent) + 1e-6 * np.abs(sent))


def test_a_bad_payload_raises_codec_error():
    decoder = MotionFlowDecoder(WIDTH, HEIGHT)
    good = golden_payload("motion_flow_edges")
    with pytest.raises(CodecError, match="^motion flow: "):
        decoder.decode(good[:-7])
    with pytest.raises(CodecError, match="the primary view 32x32"):
        MotionFlowDecoder(32, 32).decode(good)
