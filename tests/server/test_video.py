"""The H.264 encoder: x264's undershoot of its target goes back to the colour (issue 26, item 3)."""
import numpy as np

from pibr.client.video import H264Decoder
from pibr.server.video import TARGET_FACTOR_RANGE, H264Encoder

W, H, FPS, KEYINT = 256, 192, 10.0, 10


def _panning_noise(n: int) -> list[np.ndarray]:
    """``n`` yuv420p frames of blurred noise panning 3 px down and 2 px right a frame: content that
    costs bits every frame, on which x264 under pibr's tight VBV stays ~12 % under its target."""
    rng = np.random.default_rng(3)
    big = rng.integers(0, 256, (H + 4 * n + 5, W + 4 * n + 5)).astype(np.float32)
    c = np.cumsum(np.cumsum(np.pad(big, ((1, 0), (1, 0))), 0), 1)
    k = 5
    big = (c[k:, k:] - c[:-k, k:] - c[k:, :-k] + c[:-k, :-k]) / (k * k)
    frames = []
    for i in range(n):
        yuv = np.full((H * 3 // 2, W), 128, np.uint8)
        yuv[:H] = np.clip((big[3 * i:3 * i + H, 2 * i:2 * i + W] - 128) * 3 + 128, 0, 255)
        frames.append(yuv)
    return frames


def _group_rates(sizes: list[int], kbps: float) -> list[float]:
    bits = np.array(sizes) * 8.0
    return [bits[k:k + KEYINT].mean() * FPS / 1000 / kbps for k in range(0, len(bits), KEYINT)]


def test_the_bits_x264_leaves_unspent_go_back_to_the_colour(monkeypatch):
    import pibr.server.video as video

    kbps, frames = 400.0, _panning_noise(6 * KEYINT)
    encoder = H264Encoder(W, H, FPS, kbps, KEYINT, "ultrafast", deterministic=True)
    out = [encoder.encode(f) for f in frames]
    rates = _group_rates([len(d) for d, _ in out], kbps)
    # measured 0.96-1.01 of the target in every group, 0.98 on average
    assert np.mean(rates) > 0.95 and min(rates) > 0.9, rates
    assert max(rates) < 1.08, rates   # given back, not overshot
    assert encoder.target_factor > 1.05
    # without the correction x264 keeps to 0.86-0.89 of the target on the same frames
    monkeypatch.setattr(video, "INITIAL_TARGET_FACTOR", 1.0)
    monkeypatch.setattr(video, "UNDERSHOOT_GAIN", 0.0)
    plain = H264Encoder(W, H, FPS, kbps, KEYINT, "ultrafast", deterministic=True)
    assert np.mean(_group_rates([len(plain.encode(f)[0]) for f in frames], kbps)) < 0.92
    # keyframes only where x264 places them anyway, and the stream decodes across every new encoder
    assert [i for i, (_, key) in enumerate(out) if key] == list(range(0, 6 * KEYINT, KEYINT))
    decoder = H264Decoder(W, H)
    images = [decoder.decode(d) for d, _ in out]
    assert all(im.width == W and im.height == H for im in images)
    assert abs(float(images[-1].y.astype(np.float32).mean()) - float(_panning_noise(6 * KEYINT)[-1][:H].mean())) < 4


def test_a_forced_keyframe_starts_a_group_and_content_that_needs_nothing_asks_for_bounded_more():
    encoder = H264Encoder(W, H, FPS, 400.0, KEYINT, "ultrafast", deterministic=True)
    flat = np.full((H * 3 // 2, W), 128, np.uint8)   # a grey screen: x264 sends next to nothing
    keys = [encoder.encode(flat, force_keyframe=(i == 14))[1] for i in range(5 * KEYINT)]
    assert [i for i, key in enumerate(keys) if key] == [0, 10, 14, 24, 34, 44]
    assert encoder.target_factor == TARGET_FACTOR_RANGE[1]
