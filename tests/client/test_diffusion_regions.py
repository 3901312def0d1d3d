"""The edge-aware diffusion equals, bit for bit, the box-by-box diffusion it replaced
(tests/client/diffusion_reference.py): on rendered room frames and on random edge maps; so does
the plain push-pull."""
from __future__ import annotations

import numpy as np
import pytest

from pibr.client.diffusion import DiffusionWorkspace, _label_regions, _label_runs, diffuse, push_pull_fast
from pibr.protocol.edgecodec.codec import DecodedSamples, EdgeDecoder, EdgeEncoder

from ..protocol.golden_edge import QUANTIZER, cluttered_codes, piecewise_planar_codes
from .diffusion_reference import reference_diffuse, reference_push_pull


def _decoded(edges, valid, codes):
    return DecodedSamples(edges=edges, signs=np.zeros(edges.shape, np.int8), codes=codes.astype(np.uint16),
                          valid=valid, regular=np.zeros((0, 0), np.uint16), regular_rows=np.zeros(0, np.int64),
                          regular_cols=np.zeros(0, np.int64), bits=12, min_code=1)


def _random_samples(rng, shape, edge_density, edge_valid, regular_density):
    edges = rng.random(shape) < edge_density
    valid = (edges & (rng.random(shape) < edge_valid)) | (rng.random(shape) < regular_density)
    codes = np.where(valid, rng.integers(1, 4096, shape), 0)
    return _decoded(edges, valid, codes)


@pytest.mark.parametrize("density", [0.0, 0.2, 0.4, 0.55, 0.7, 1.0])
def test_region_runs_are_the_labelled_regions(density):
    """_label_runs finds _label_regions' regions: the same numbers, boxes and sizes, and its runs
    (grouped by region, in raster order) paint the label image exactly."""
    rng = np.random.default_rng(int(density * 100) + 1)
    for shape in [(1, 1), (1, 13), (11, 1), (37, 53), (64, 64), (40, 200)]:
        edges = (rng.random(shape) < density).view(np.uint8)
        labels = np.zeros(shape, np.int32)
        n, boxes, sizes = _label_regions(edges, labels)
        max_runs = shape[0] * ((shape[1] + 1) // 2)
        runs = np.full((2 * max_runs, 3), -7, np.int32)
        n_runs, boxes_runs, sizes_runs, run_start = _label_runs(edges, runs, np.full(max_runs, -7, np.int32))
        assert n_runs == n
        np.testing.assert_array_equal(boxes_runs[1:], boxes[1:n + 1])
        np.testing.assert_array_equal(sizes_runs[1:], sizes[1:n + 1])
        painted = np.zeros(shape, np.int32)
        for c in range(1, n + 1):
            group = runs[run_start[c]:run_start[c + 1]]
            assert len(group) and np.all(np.diff(group[:, 0] * shape[1] + group[:, 1]) > 0)
            for y, a, b in group:
                assert np.all(painted[y, a:b + 1] == 0)
                painted[y, a:b + 1] = c
        np.testing.assert_array_equal(painted, labels)


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (9, 1), (2, 2), (3, 50), (50, 3), (37, 53), (64, 64), (97, 130)])
def test_random_edge_maps_diffuse_as_the_reference(shape):
    """Regions of every size and shape, touching the border or not, with edge pixels that are not all
    samples (so some of a region's neighbours take pulled values) and regions without samples."""
    rng = np.random.default_rng(shape[0] * 7 + shape[1])
    ws = DiffusionWorkspace()
    for edge_density in (0.0, 0.15, 0.35, 0.6):
        for edge_valid in (1.0, 0.7):
            s = _random_samples(rng, shape, edge_density, edge_valid, regular_density=0.03)
            for iterations in (0, 1, 4, 7):
                expected = reference_diffuse(s, iterations=iterations)
                np.testing.assert_array_equal(diffuse(s, iterations=iterations, workspace=ws), expected)
                np.testing.assert_array_equal(diffuse(s, iterations=iterations), expected)


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (9, 1), (2, 2), (2, 3), (3, 3), (4, 7), (7, 5), (33, 17), (64, 48),
                                   (65, 130)])
def test_plain_push_pull_equals_the_reference(shape):
    """Every level's interior and border, odd and even sizes; values that are not samples are NaN
    (never read)."""
    rng = np.random.default_rng(shape[0] * 1000 + shape[1])
    for density in (0.02, 0.3, 0.9, 1.0):
        m = rng.random(shape) < density
        m.flat[rng.integers(m.size)] = True
        v = np.where(m, rng.random(shape) * 4000, np.nan)
        for iterations in (0, 1, 4):
            np.testing.assert_array_equal(push_pull_fast(v, m, iterations), reference_push_pull(v, m, iterations))


def test_a_workspace_reused_across_frame_sizes_gives_the_reference():
    """Stamps and scratch left by a larger or a smaller frame never leak into the next one."""
    rng = np.random.default_rng(11)
    ws = DiffusionWorkspace()
    for shape in [(90, 120), (20, 30), (60, 80), (90, 121), (5, 7), (60, 80)]:
        s = _random_samples(rng, shape, 0.25, 0.9, 0.03)
        np.testing.assert_array_equal(diffuse(s, workspace=ws), reference_diffuse(s))


def test_the_work_budget_falls_back_as_the_reference():
    rng = np.random.default_rng(5)
    s = _random_samples(rng, (80, 120), 0.2, 0.9, 0.02)
    for max_work in (0.0, 0.3, 1.0, 16.0):
        np.testing.assert_array_equal(diffuse(s, max_work=max_work), reference_diffuse(s, max_work=max_work))


@pytest.mark.parametrize("make", [piecewise_planar_codes, cluttered_codes])
def test_coded_scenes_diffuse_as_the_reference(make):
    for shape in [(192, 256), (61, 93)]:
        codes = make(*shape)
        out = EdgeEncoder(shape[1], shape[0], 12, QUANTIZER).encode(QUANTIZER.dequantize(codes))
        s = EdgeDecoder(shape[1], shape[0], 12, QUANTIZER).decode(out.payload)
        np.testing.assert_array_equal(diffuse(s), reference_diffuse(s))


@pytest.mark.gl
def test_room_frames_diffuse_as_the_reference(tmp_path, gl_ctx):
    """Rendered room frames along a real head trace, edge-coded and decoded as the client does."""
    from pibr.bench.codec_speed import render_frames
    from pibr.bench.windows import EVALUATION_WINDOWS, Window
    from pibr.server import edge_extract
    from pibr.protocol.depth_codecs import EDGE_BITS, edge_quantizer

    path = str(tmp_path / "frames.npz")
    windows = tuple(Window(w.trace, w.start_s, 0.1) for w in EVALUATION_WINDOWS[:3])
    n = render_frames(path, "room", windows, 10.0, (512, 512), progress=False)
    data = np.load(path)
    quantizer = edge_quantizer(float(data["near"]), float(data["far"]), EDGE_BITS)
    encoder = EdgeEncoder(512, 512, EDGE_BITS, quantizer)
    decoder = EdgeDecoder(512, 512, EDGE_BITS, quantizer)
    ws = DiffusionWorkspace()
    for i in range(n):
        found = edge_extract.extract_edge_samples(data["distance"][i], quantizer)
        enc = encoder.encode(data["distance"][i], edges=found.edges, signs=found.signs, codes=found.codes)
        s = decoder.decode(enc.payload)
        labels = np.zeros(s.shape, np.int32)
        n_regions, boxes, sizes = _label_regions(s.edges.view(np.uint8), labels)
        assert n_regions > 20 and sizes[1:n_regions + 1].max() > s.valid.size // 10  # real, cluttered frames
        np.testing.assert_array_equal(diffuse(s, workspace=ws), reference_diffuse(s))
