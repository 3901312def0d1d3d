"""Bringing a smaller view to size on the CPU: bilinear colour as GL samples it, nearest distance."""
import numpy as np
import pytest

from pibr.server.view_upsample import ViewUpsampler


def _bilinear_reference(low: np.ndarray, height: int, width: int) -> np.ndarray:
    """GL's LINEAR filter at the whole view's pixel centres, clamped at the edges, in float64."""
    h, w = low.shape[:2]

    def taps(n_low, n_high):
        u = (np.arange(n_high) + 0.5) * n_low / n_high - 0.5
        first = np.floor(u)
        return (np.clip(first, 0, n_low - 1).astype(int), np.clip(first + 1, 0, n_low - 1).astype(int), u - first)

    xa, xb, fx = taps(w, width)
    ya, yb, fy = taps(h, height)
    f = low[:, :, :3].astype(np.float64)
    rows = f[:, xa] * (1 - fx)[None, :, None] + f[:, xb] * fx[None, :, None]
    out = rows[ya] * (1 - fy)[:, None, None] + rows[yb] * fy[:, None, None]
    return out


@pytest.mark.parametrize("low_shape, shape", [((43, 43), (128, 128)), ((64, 48), (128, 96)), ((30, 17), (90, 51))])
def test_colour_is_gl_bilinear_and_distance_the_nearest_pixel(low_shape, shape):
    rng = np.random.default_rng(1)
    low = rng.integers(0, 256, low_shape + (4,), dtype=np.uint8)
    out = np.zeros(shape + (4,), np.uint8)
    up = ViewUpsampler()
    up.colour(low, out)
    reference = _bilinear_reference(low, *shape)
    assert np.max(np.abs(out[:, :, :3] - reference)) <= 0.5 + 1e-3     # float32 arithmetic, rounded
    assert np.all(out[:, :, 3] == 255)

    dist = rng.random(low_shape, dtype=np.float32) * 10
    whole = up.distance(dist, np.empty(shape, np.float32))
    yn = np.minimum(((np.arange(shape[0]) + 0.5) * low_shape[0] / shape[0]).astype(int), low_shape[0] - 1)
    xn = np.minimum(((np.arange(shape[1]) + 0.5) * low_shape[1] / shape[1]).astype(int), low_shape[1] - 1)
    assert np.array_equal(whole, dist[yn][:, xn])
    motion = rng.random(low_shape + (2,), dtype=np.float32)
    assert np.array_equal(up.nearest(motion, shape[::-1]), motion[yn][:, xn])
    flags = rng.random(low_shape) > 0.5
    assert np.array_equal(up.nearest(flags, shape[::-1]), flags[yn][:, xn])


def test_a_flat_view_stays_flat_and_a_ramp_stays_a_ramp():
    up = ViewUpsampler()
    flat = np.full((20, 20, 4), 77, np.uint8)
    assert np.all(up.colour(flat, np.zeros((60, 60, 4), np.uint8))[:, :, :3] == 77)
    ramp = np.zeros((1, 32, 4), np.uint8)
    ramp[0, :, 0] = np.arange(32) * 8
    out = up.colour(ramp, np.zeros((1, 64, 4), np.uint8))[0, :, 0].astype(int)
    assert np.all(np.diff(out) >= 0) and out[0] == 0 and out[-1] == 248
    # interior pixels halfway between two low pixels' centres: the mean of the two
    assert np.array_equal(out[1:-1:2], np.arange(31) * 8 + 2) and np.array_equal(out[2:-1:2], np.arange(31) * 8 + 6)
