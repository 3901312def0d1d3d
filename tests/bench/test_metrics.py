import math

import numpy as np
import pytest

from pibr.bench.metrics import (PSNR_CAP, dssim, error_image, flip, frame_metrics, masked_metrics, pixels_per_degree,
                                psnr, ssim)
from pibr.protocol.errors import ConfigError


def _img(seed=0, shape=(64, 96, 3)):
    return np.random.default_rng(seed).integers(0, 256, shape, dtype=np.uint8)


def test_identical_images_are_perfect_and_finite():
    a = _img()
    assert psnr(a, a) == PSNR_CAP
    assert ssim(a, a) == pytest.approx(1.0)
    assert dssim(ssim(a, a)) == pytest.approx(0.0)
    assert flip(a, a, 20.0) == pytest.approx(0.0, abs=1e-6)


def test_known_psnr():
    a = np.full((10, 10, 3), 100, np.uint8)
    b = a.copy()
    b[...] = 110  # MSE 100
    assert psnr(a, b) == pytest.approx(10 * math.log10(255 ** 2 / 100))


def test_worse_images_score_worse():
    a = _img(1)
    slight = np.clip(a.astype(int) + 5, 0, 255).astype(np.uint8)
    other = _img(2)
    m1, m2 = frame_metrics(a, slight, 20.0), frame_metrics(a, other, 20.0)
    assert m1["psnr"] > m2["psnr"] and m1["ssim"] > m2["ssim"] and m1["flip"] < m2["flip"]
    assert 0 <= m2["dssim"] <= 1


def test_shape_mismatch_is_named():
    with pytest.raises(ValueError, match="one shape"):
        psnr(_img(), _img(shape=(64, 95, 3)))


def test_pixels_per_degree_and_error_image():
    assert pixels_per_degree(960, 90) == pytest.approx(480 * math.pi / 180)
    e = error_image(_img(1), _img(2))
    assert e.shape == (64, 96, 3) and e.dtype == np.uint8


def test_evaluate_needs_a_recording(tmp_path):
    from pibr.bench.evaluate import evaluate_run

    with pytest.raises(ConfigError, match="no session.json"):
        evaluate_run(str(tmp_path))


def test_summary_warns_of_frames_that_say_little():
    from pibr.bench.evaluate import summary_table

    row = {"psnr_mean": 49.9, "ssim_mean": 1.0, "dssim_mean": 0.0, "flip_mean": 0.0, "geometric_holes_mean": 0.0,
           "hole_fraction_mean": 0.0, "client_ms_median": 3.0, "age_ms_mean": 200.0, "frames": 30}
    quiet = summary_table({"methods": {"none": row}, "nearly_uniform_frames": 0})
    assert "warning" not in quiet
    loud = summary_table({"methods": {"none": row}, "nearly_uniform_frames": 28})
    assert "warning: 28 of 30 ground-truth frames are nearly one colour" in loud


def test_masked_metrics():
    rng = np.random.default_rng(0)
    a = rng.integers(0, 255, (40, 60, 3), dtype=np.uint8)
    b = a.copy()
    mask = np.zeros((40, 60), bool)
    mask[10:30, 20:40] = True
    b[mask] = 255 - b[mask]
    m = masked_metrics(a, b, {"object": mask, "rest": ~mask, "tiny": np.eye(40, 60, dtype=bool)[:, :60] & mask})
    assert m["psnr_rest"] == 100.0 and m["dssim_rest"] < m["dssim_object"]
    assert m["psnr_object"] < m["psnr"] < 100.0
    assert math.isnan(m["psnr_tiny"]) and math.isnan(m["dssim_tiny"])   # fewer than MIN_PIXELS


def _scene_like_pair(seed: int, shape=(96, 160, 3)):
    """A smooth image with edges and its noisy, shifted copy: SSIM well inside (0, 1)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    base = np.stack([(xx * 1.5) % 256, (yy * 2.5) % 256, ((xx + yy) // 16 % 2) * 200 + 20], axis=2)
    test = np.roll(base, 2, axis=1) + rng.normal(0, 12, shape)
    return base.astype(np.uint8), np.clip(test, 0, 255).astype(np.uint8)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_shared_reference_ssim_is_scikit_images_to_the_bit(seed):
    from skimage.metrics import structural_similarity

    from pibr.bench.metrics import SsimReference

    ref, test = _scene_like_pair(seed)
    rng = np.random.default_rng(seed)
    noise = rng.integers(0, 256, ref.shape, dtype=np.uint8)
    reference = SsimReference(ref)
    for other in (test, noise, ref, 255 - ref):
        assert reference.ssim(other) == float(structural_similarity(ref, other, channel_axis=2, data_range=255))
    assert 0.2 < reference.ssim(test) < 0.95


def test_tick_metrics_are_the_libraries_metrics_of_each_image():
    """tick_metrics and frame_metrics (compiled SSIM and PSNR, the reference's share computed
    once) equal scikit-image's SSIM, numpy's PSNR and flip-evaluator's FLIP of each image."""
    from skimage.metrics import structural_similarity

    from pibr.bench.metrics import tick_metrics

    from .test_flip_metric import library_flip

    ref, test = _scene_like_pair(3)
    images = [test, np.roll(test, 5, axis=0), ref]
    for with_flip in (True, False):
        got = tick_metrics(ref, images, 30.0, with_flip)
        single = [frame_metrics(ref, img, 30.0, with_flip) for img in images]
        libraries = [float(structural_similarity(ref, img, channel_axis=2, data_range=255)) for img in images]
        want = [{"psnr": psnr(ref, img), "ssim": s, "dssim": dssim(s),
                 "flip": library_flip(ref, img, 30.0)[1] if with_flip else math.nan}
                for img, s in zip(images, libraries)]
        for g, one, w in zip(got, single, want):
            assert g.keys() == one.keys() == w.keys()
            for k in g:
                assert g[k] == one[k] == w[k] or (k == "flip" and not with_flip and math.isnan(g[k])
                                                  and math.isnan(one[k])), k
        assert got[0]["ssim"] < 0.95 and got[2]["ssim"] == 1.0


def test_error_image_is_the_magma_of_the_mean_difference():
    from matplotlib import colormaps

    ref, test = _scene_like_pair(4)
    diff = np.abs(ref.astype(np.int16) - test.astype(np.int16)).mean(axis=2) / 255.0
    lut = (colormaps["magma"](np.linspace(0, 1, 256))[:, :3] * 255).astype(np.uint8)
    for gain in (1.0, 4.0):
        assert np.array_equal(error_image(ref, test, gain), lut[np.clip(diff * gain * 255, 0, 255).astype(np.uint8)])


@pytest.mark.parametrize("shape", [(64, 96, 3), (35, 51, 3), (36, 49, 3)])
@pytest.mark.parametrize("scale", [1, 2, 3])
def test_side_by_side_frame_is_the_full_mosaic_subsampled(shape, scale):
    """The video frame is made from subsampled tiles; it must equal subsampling the full-size
    mosaic (shown | truth | error per row), at every phase odd sizes give the tiles."""
    from pibr.bench.evaluate import _side_by_side

    pairs = [(_img(seed, shape), _img(seed + 10, shape)) for seed in range(3)]
    mosaic = np.concatenate([np.concatenate([shown, ref, error_image(ref, shown)], axis=1) for shown, ref in pairs],
                            axis=0)[::scale, ::scale]
    h, w = mosaic.shape[:2]
    want = mosaic[: h - h % 2, : w - w % 2]
    got = _side_by_side(pairs, scale)
    assert got.flags.c_contiguous
    assert np.array_equal(got, want)


@pytest.mark.parametrize("shape", [(7, 7, 3), (8, 13, 3), (61, 37, 3)])
def test_compiled_ssim_and_psnr_are_the_libraries_numbers_at_any_size(shape):
    """SSIM's compiled box filters (reflected borders on short lines too) and PSNR's exact sum
    give scikit-image's and numpy's bits, on sizes down to SSIM's window."""
    from skimage.metrics import structural_similarity

    from pibr.bench.metrics import SsimReference

    for seed in range(4):
        ref = _img(seed, shape)
        reference = SsimReference(ref)
        near = np.clip(ref.astype(np.int16) + np.random.default_rng(seed).integers(-9, 10, shape), 0, 255)
        for test in (near.astype(np.uint8), _img(seed + 50, shape), ref):
            assert reference.ssim(test) == float(structural_similarity(ref, test, channel_axis=2, data_range=255))
            mse = np.mean((ref.astype(np.float64) - test.astype(np.float64)) ** 2)
            assert psnr(ref, test) == (PSNR_CAP if mse == 0 else min(PSNR_CAP, 10 * math.log10(255.0 ** 2 / mse)))
        assert ssim(ref, near.astype(np.uint8)) == reference.ssim(near.astype(np.uint8))
    with pytest.raises(ValueError, match="uint8"):
        SsimReference(ref.astype(np.float32))


def test_nearly_uniform_counts_as_numpy_does():
    """The compiled count equals numpy's element-wise test, at the fraction's edge too."""
    from pibr.bench.metrics import nearly_uniform

    rng = np.random.default_rng(5)
    for share in (0.90, 0.949, 0.951, 0.99):
        img = np.full((60, 80, 3), 120, np.uint8)
        img += rng.integers(-2, 3, img.shape).astype(np.uint8)          # within the tolerance
        off = rng.random(img.shape[:2]) > share
        img[off] = rng.integers(0, 256, (int(off.sum()), 3), dtype=np.uint8)
        flat = img.reshape(-1, 3).astype(np.int16)
        mode = np.median(flat[:: max(1, len(flat) // 4096)], axis=0)
        want = bool(np.all(np.abs(flat - mode) <= 2, axis=1).mean() > 0.95)
        assert nearly_uniform(img) == want
        assert nearly_uniform(img[:, ::-1]) == want   # any strides
    assert nearly_uniform(np.full((8, 8, 3), 9, np.uint8)) and not nearly_uniform(_img(3))
