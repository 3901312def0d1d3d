"""Edge extraction for the edge codec and its rate control."""
from __future__ import annotations

import numpy as np
import pytest

from pibr.protocol.depth import DepthQuantizer
from pibr.protocol.edgecodec.codec import EdgeEncoder
from pibr.server.edge_extract import (RateController, extract_edge_samples, perceptual_importance, significance)

from ..protocol.golden_edge import cluttered_codes

Q = DepthQuantizer(0.1, 1000.0, bits=12, min_code=1)


def _distance(codes):
    return Q.dequantize(np.asarray(codes))


def test_plane_has_no_edges_even_at_the_border():
    y, x = np.indices((40, 60))
    codes = np.round(700 + 7.3 * x - 4.1 * y).astype(int)
    s = extract_edge_samples(_distance(codes), Q)
    assert s.edges.sum() == 0


def test_step_gives_two_pixel_edges_with_opposite_signs():
    codes = np.full((20, 30), 400)
    codes[:, 15:] = 900  # nearer surface on the right
    s = extract_edge_samples(_distance(codes), Q)
    cols = np.nonzero(s.edges.any(axis=0))[0]
    assert list(cols) == [14, 15]
    assert s.edges[:, 14].all() and s.edges[:, 15].all()
    assert np.all(s.signs[:, 14] == 1)    # far side: positive Laplacian
    assert np.all(s.signs[:, 15] == -1)   # near side: negative


def test_partner_pixel_is_added_when_only_one_side_is_significant():
    codes = np.full((9, 9), 500)
    codes[4, 4] = 520  # a one-pixel bump
    codes[:, 6:] = 530
    s = extract_edge_samples(_distance(codes), Q, threshold=25.0)
    # every edge pixel's largest jump partner is an edge too
    jumps_ok = True
    for y, x in zip(*np.nonzero(s.edges)):
        nb = [(y + dy, x + dx) for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)) if 0 <= y + dy < 9 and 0 <= x + dx < 9]
        j = [abs(codes[y, x] - codes[p]) for p in nb]
        if max(j) > 25:
            jumps_ok &= bool(s.edges[nb[int(np.argmax(j))]])
    assert jumps_ok and s.edges[4, 4]


def test_sky_boundary_is_always_sampled():
    codes = np.full((16, 16), 3)
    codes[:5] = 0  # sky above a very far wall: a Laplacian of only 3
    s = extract_edge_samples(_distance(codes), Q, threshold=1e6)
    assert s.edges[4].all() and s.edges[5].all() and s.edges.sum() == 32


def test_motion_adds_edges_at_moving_object_boundaries():
    codes = np.full((32, 32), 800)
    motion = np.zeros((32, 32, 2), np.float32)
    motion[8:20, 8:20] = (3.0, 0.0)
    still = extract_edge_samples(_distance(codes), Q)
    moving = extract_edge_samples(_distance(codes), Q, motion=motion)
    assert still.edges.sum() == 0
    ring = np.zeros((32, 32), bool)
    ring[7:21, 7:21] = True
    ring[9:19, 9:19] = False
    assert moving.edges.sum() > 0 and np.all(ring[moving.edges])
    sig_m, _ = significance(codes, motion, motion_weight=0.0)
    assert np.all(sig_m == 0)


def test_perceptual_importance_follows_colour_contrast():
    flat = np.full((16, 16, 3), 128, np.uint8)
    w = perceptual_importance(flat, (64, 64))
    assert w.shape == (64, 64) and np.allclose(w, 0.25)
    checker = ((np.indices((16, 16)).sum(0) % 2) * 255).astype(np.uint8)[..., None].repeat(3, axis=2)
    assert perceptual_importance(checker, (64, 64)).min() > 0.95
    half = flat.copy()
    half[:, 8:] = 20
    w = perceptual_importance(half, (16, 16))
    assert w[:, 7:9].min() > 0.9 and w[:, :5].max() < 0.3
    with pytest.raises(ValueError):
        perceptual_importance(np.zeros((4, 4)), (4, 4))


def test_colour_weighting_drops_edges_in_flat_colour():
    codes = cluttered_codes(96, 128)
    plain = extract_edge_samples(_distance(codes), Q, threshold=8.0)
    flat = np.full((24, 32, 3), 0.5)
    weighted = extract_edge_samples(_distance(codes), Q, threshold=8.0, colour=flat)
    assert weighted.edges.sum() < plain.edges.sum()
    assert not np.any(weighted.edges & ~plain.edges)


def test_rate_controller_converges_exponentially_on_a_power_law():
    rc = RateController(50_000, threshold=3.0)
    errors = []
    for _ in range(20):
        bits = 4e5 * rc.threshold ** -0.8  # frame size falls with the threshold
        errors.append(abs(np.log(bits / 50_000)))
        rc.update(bits)
    assert errors[-1] < 1e-3 * errors[0] + 1e-3
    assert all(b <= a * 0.8 + 1e-9 for a, b in zip(errors[3:], errors[4:]))


def _curved_scene():
    """Boxes in front of curved surfaces of many frequencies: Laplacians of every size, so the
    frame size falls smoothly with the threshold."""
    boxes = cluttered_codes(128, 160, n=30)
    y, x = np.indices(boxes.shape).astype(float)
    rng = np.random.default_rng(1)
    bump = sum(rng.uniform(20, 250) * np.sin(x / rng.uniform(4, 30) + rng.uniform(0, 6)) * np.cos(y / rng.uniform(4, 30))
               for _ in range(8))
    codes = boxes + np.round(bump * (1 + x / 160)).astype(int)
    return np.where(boxes == 0, 0, np.clip(codes, 1, 4095))


def test_rate_controller_hits_a_target_with_the_real_codec():
    distance = _distance(_curved_scene())
    enc = EdgeEncoder(160, 128, 12, Q, temporal=False)
    first = enc.encode(distance, threshold=3.5).stats.total_bits
    target = 0.5 * first
    rc = RateController(target, threshold=3.5)
    sizes = []
    for _ in range(12):
        s = extract_edge_samples(distance, Q, threshold=rc.threshold)
        bits = enc.encode(distance, edges=s.edges, signs=s.signs).stats.total_bits
        sizes.append(bits)
        rc.update(bits)
    assert abs(sizes[-1] / target - 1) < 0.15
    assert rc.threshold > 3.5


def test_rate_controller_validates_and_clamps():
    with pytest.raises(ValueError):
        RateController(0)
    with pytest.raises(ValueError):
        RateController(100, threshold=0.1, min_threshold=0.5)
    rc = RateController(100, threshold=1.0, max_threshold=4.0)
    for _ in range(10):
        rc.update(1e9)
    assert rc.threshold == 4.0
    for _ in range(20):
        rc.update(0)
    assert rc.threshold == 0.5


def test_encoder_reuses_the_extracted_codes_with_identical_bytes():
    """The server hands its codes to the encoder (no second quantization): same payload and samples."""
    distance = _distance(cluttered_codes(96, 128, seed=3))
    found = extract_edge_samples(distance, Q, colour=np.full((12, 16, 3), 128, np.uint8))
    enc = EdgeEncoder(128, 96, 12, Q)
    reused = enc.encode(distance, edges=found.edges, signs=found.signs, codes=found.codes)
    fresh = enc.encode(distance, edges=found.edges, signs=found.signs)
    assert reused.payload == fresh.payload
    np.testing.assert_array_equal(reused.samples.codes, fresh.samples.codes)
    np.testing.assert_array_equal(found.codes, Q.quantize(distance).astype(np.int32))
    with pytest.raises(ValueError, match="codes must have shape"):
        enc.encode(distance, edges=found.edges, signs=found.signs, codes=found.codes[:-1])
