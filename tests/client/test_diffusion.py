"""Push-pull diffusion of the edge codec's samples into dense depth."""
from __future__ import annotations

import numpy as np
import pytest

from pibr.client.diffusion import codes_to_distance, diffuse, diffuse_plain, push_pull_fast, reconstruct_depth
from pibr.protocol.edgecodec.codec import EdgeDecoder, EdgeEncoder, laplacian

from ..protocol.golden_edge import QUANTIZER, cluttered_codes, piecewise_planar_codes
from .diffusion_reference import push_pull_numpy


def _psnr(a, b, peak=4095.0):
    return 10 * np.log10(peak ** 2 / np.mean((np.asarray(a, float) - b) ** 2))


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (9, 1), (2, 3), (7, 5), (33, 17), (64, 48)])
def test_numpy_and_numba_push_pull_agree(shape):
    rng = np.random.default_rng(sum(shape))
    for density in (0.02, 0.3, 1.0):
        v = rng.random(shape) * 1000
        m = rng.random(shape) < density
        m.flat[rng.integers(m.size)] = True
        a = push_pull_numpy(v, m)
        b = push_pull_fast(v, m)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(a[m], v[m])  # samples are never overwritten


def test_push_pull_special_cases():
    assert np.all(push_pull_numpy(np.ones((4, 5)), np.zeros((4, 5), bool)) == 0)
    assert np.all(push_pull_fast(np.ones((4, 5)), np.zeros((4, 5), bool)) == 0)
    m = np.zeros((30, 40), bool)
    m[7, 9] = True
    np.testing.assert_allclose(push_pull_numpy(np.full((30, 40), 12.5), m), 12.5)
    with pytest.raises(ValueError):
        push_pull_numpy(np.ones((3, 3)), np.ones((3, 4), bool))


def test_planes_are_reproduced_from_sparse_samples_and_the_border():
    y, x = np.indices((70, 90)).astype(float)
    plane = 3.0 * y - 2.0 * x + 500.0
    m = np.zeros(plane.shape, bool)
    m[::11, ::13] = True
    m[-1, ::13] = m[::11, -1] = True
    m[-1, -1] = True
    err = np.abs(push_pull_fast(plane, m, iterations=8) - plane)
    assert err.max() < 0.02 * np.ptp(plane)


def _samples(codes, **kw):
    h, w = codes.shape
    distance = QUANTIZER.dequantize(codes)
    out = EdgeEncoder(w, h, 12, QUANTIZER, **kw).encode(distance)
    return EdgeDecoder(w, h, 12, QUANTIZER).decode(out.payload)


def _near_discontinuities(codes, samples, width=4):
    big = np.abs(laplacian(codes)) > 50
    band = big.copy()
    for _ in range(width):
        grown = band.copy()
        grown[1:] |= band[:-1]
        grown[:-1] |= band[1:]
        grown[:, 1:] |= band[:, :-1]
        grown[:, :-1] |= band[:, 1:]
        band = grown
    return band & ~samples.valid


@pytest.mark.parametrize("make", [piecewise_planar_codes, cluttered_codes])
def test_edge_aware_diffusion_reconstructs_piecewise_planar_depth(make):
    codes = make(192, 256)
    s = _samples(codes)
    aware = diffuse(s)
    plain = diffuse_plain(s)
    np.testing.assert_array_equal(aware[s.valid], codes[s.valid])
    np.testing.assert_array_equal(plain[s.valid], codes[s.valid])
    assert _psnr(aware, codes) > 54.0
    assert _psnr(aware, codes) > _psnr(plain, codes) + 15.0
    band = _near_discontinuities(codes, s)
    err_aware = np.abs(aware - codes)[band]
    err_plain = np.abs(plain - codes)[band]
    assert err_aware.mean() < 0.1 * err_plain.mean()
    assert err_aware.max() < 0.25 * err_plain.max()


def test_diffusion_keeps_a_thin_wall_sharp():
    codes = np.full((64, 64), 300)
    codes[:, 30:34] = 2000  # a 4-pixel pole in front
    s = _samples(codes)
    aware = diffuse(s)
    assert np.abs(aware - codes).max() < 1.0
    assert np.abs(diffuse_plain(s) - codes).max() > 30


def test_sky_is_zero_distance_and_samples_map_back_exactly():
    codes = cluttered_codes(96, 128)
    s = _samples(codes)
    depth = reconstruct_depth(s, QUANTIZER)
    sky = codes == 0
    assert sky.any()
    assert np.all(depth[sky] == 0)
    np.testing.assert_array_equal(depth[s.valid], QUANTIZER.dequantize(codes)[s.valid])
    assert np.all(codes_to_distance(np.array([0.0, 0.49, 0.51]), QUANTIZER)[:2] == 0)
    assert codes_to_distance(np.array([0.51]), QUANTIZER)[0] > 0
    plain = reconstruct_depth(s, QUANTIZER, edge_aware=False)
    assert plain.shape == depth.shape == codes.shape and depth.dtype == np.float32


def test_no_edges_at_all_uses_the_regular_samples():
    codes = np.full((80, 100), 1234)
    s = _samples(codes)
    assert not s.edges.any()
    np.testing.assert_allclose(diffuse(s), 1234.0)


@pytest.mark.parametrize("shape", [(2, 700), (700, 2), (3, 400), (32, 32), (33, 32), (32, 33), (45, 61), (64, 48)])
def test_compacted_sweeps_equal_the_plain_red_black_sweeps(shape):
    """The colour-compacted Gauss-Seidel sweeps compute exactly what the straightforward ones do."""
    from pibr.client.diffusion import _smooth_nb, _smooth_simple

    rng = np.random.default_rng(shape[0] * 1000 + shape[1])
    for density in (0.0, 0.05, 0.5, 1.0):
        u = rng.random(shape) * 4000
        m = (rng.random(shape) < density).astype(np.uint8)
        for iterations in (1, 4, 9):
            a, b = u.copy(), u.copy()
            _smooth_simple(a, m, iterations)
            _smooth_nb(b, m, iterations)
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("density", [0.0, 0.2, 0.4, 0.55, 0.7, 1.0])
def test_region_labels_boxes_and_sizes(density):
    """Regions are the 4-connected components of non-edge pixels, numbered in raster order of their
    first pixel (as scipy numbers them), with their bounding boxes and pixel counts."""
    from scipy import ndimage

    from pibr.client.diffusion import _label_regions

    rng = np.random.default_rng(int(density * 100))
    for shape in [(1, 1), (1, 13), (11, 1), (37, 53), (64, 64)]:
        edges = rng.random(shape) < density
        labels = np.zeros(shape, np.int32)
        n, boxes, sizes = _label_regions(edges.view(np.uint8), labels)
        expected, n_expected = ndimage.label(~edges)
        assert n == n_expected
        np.testing.assert_array_equal(labels, expected)
        for c in range(1, n + 1):
            ys, xs = np.nonzero(labels == c)
            assert list(boxes[c]) == [ys.min(), ys.max(), xs.min(), xs.max()] and sizes[c] == len(ys)


def test_a_reused_workspace_gives_the_same_depth():
    """One workspace across frames of different content and size: every result equals a fresh run."""
    from pibr.client.diffusion import DiffusionWorkspace

    ws = DiffusionWorkspace()
    for codes in (cluttered_codes(96, 128, seed=1), piecewise_planar_codes(61, 93), cluttered_codes(96, 128, seed=2),
                  cluttered_codes(40, 30, seed=3)):
        s = _samples(codes)
        np.testing.assert_array_equal(diffuse(s, workspace=ws), diffuse(s))
