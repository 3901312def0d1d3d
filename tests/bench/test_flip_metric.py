"""The compiled FLIP gives NVIDIA flip-evaluator's maps and means to the bit."""
import flip_evaluator   # the test extra's: the reference implementation
import numpy as np
import pytest

from pibr.bench.flip_metric import FlipReference


def library_flip(ref, test, ppd):
    """flip-evaluator's (H, W) float32 map and mean of two (H, W, 3) uint8 sRGB images."""
    error, mean, _ = flip_evaluator.evaluate(ref.astype(np.float32) / 255.0, test.astype(np.float32) / 255.0, "LDR",
                                             inputsRGB=True, applyMagma=False, computeMeanError=True,
                                             parameters={"ppd": float(ppd)})
    return np.asarray(error).reshape(ref.shape[:2]), float(mean)


def _scene_like(seed, shape):
    """A smooth image with edges and flat areas, and a shifted, noisy, partly blacked-out copy."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    base = np.stack([(xx * 3.1) % 256, (yy * 1.7) % 256, ((xx // 9 + yy // 7) % 2) * 180 + 30], axis=2)
    test = np.roll(base, 3, axis=1) + rng.normal(0, 8, shape)
    test[: shape[0] // 4, : shape[1] // 3] = 0   # a hole
    return base.astype(np.uint8), np.clip(test, 0, 255).astype(np.uint8)


@pytest.mark.parametrize("shape,ppd", [((64, 96, 3), 30.0), ((135, 240, 3), 8.377580409572783),
                                       ((37, 51, 3), 67.0), ((9, 5, 3), 67.0), ((120, 80, 3), 3.0),
                                       ((48, 64, 3), 20.5), ((36, 64, 3), 0.5585053606381855),
                                       ((18, 32, 3), 0.2)])
def test_maps_and_means_are_flip_evaluators_to_the_bit(shape, ppd):
    rng = np.random.default_rng(len(shape) + int(ppd))
    ref, shifted = _scene_like(int(ppd), shape)
    reference = FlipReference(ref, ppd)
    noisy = np.clip(ref.astype(np.int16) + rng.integers(-25, 26, shape), 0, 255).astype(np.uint8)
    for test in (shifted, noisy, 255 - ref, rng.integers(0, 256, shape, dtype=np.uint8), ref):
        want_map, want_mean = library_flip(ref, test, ppd)
        got_map, got_mean = reference.map_and_mean(test)
        assert got_map.dtype == np.float32 and got_map.shape == shape[:2]
        # at a few pixels per degree FLIP's filter weights hold a 0/0 (a NaN its Max() then drops)
        assert np.array_equal(got_map, want_map, equal_nan=True), f"{int((got_map != want_map).sum())} pixels differ"
        assert got_mean == want_mean
    assert reference.mean(ref) == 0.0 and reference.mean(shifted) > 0.01


def test_flip_of_every_grey_level_pair_is_the_librarys():
    """Every 8-bit level against every other (the sRGB table's 256 entries, flat and at edges)."""
    levels = np.arange(256, dtype=np.uint8)
    ref = np.repeat(np.repeat(levels.reshape(16, 16), 3, axis=0), 3, axis=1)
    ref = np.stack([ref, ref.T, 255 - ref], axis=2)
    for shift in (1, 7, 100):
        test = np.roll(ref, shift, axis=(0, 1))
        want_map, want_mean = library_flip(ref, test, 10.0)
        got_map, got_mean = FlipReference(ref, 10.0).map_and_mean(test)
        assert np.array_equal(got_map, want_map) and got_mean == want_mean


def test_bad_images_are_refused():
    ref = np.zeros((8, 8, 3), np.uint8)
    with pytest.raises(ValueError, match="uint8"):
        FlipReference(ref.astype(np.float32), 30.0)
    with pytest.raises(ValueError, match="uint8"):
        FlipReference(ref, 30.0).mean(np.zeros((8, 9, 3), np.uint8))
