"""Colour at a quarter of the pixels, rebuilt whole on the client (client/colour_rebuild.py):
exact on a still view after four frames, reprojected when the head turns, new samples only where
the previous frame did not see the point. Frames are packed by the server's packer without video
coding, so the rebuild alone is measured."""
from types import SimpleNamespace

import numpy as np
import pytest

from pibr.client.colour_rebuild import RebuildSettings, rebuilt_layout
from pibr.client.frame_textures import FrameTextures, rect_uniform
from pibr.client.video import YUVImage
from pibr.protocol.atlas import COLOUR_JITTER, build_layout, colour_jitter
from pibr.protocol.pose import Pose, quat_from_euler
from pibr.protocol.projection import pixel_centers, unproject
from pibr.protocol.session import SessionConfig, ViewConfig
from pibr.server.packer import CpuAtlasPacker

pytestmark = pytest.mark.gl

SIZE = (96, 64)


def _config(colour_scale=0.5, extra=False):
    e = (SIZE[0] // 2, SIZE[1] // 2) if extra else None
    return SessionConfig(scene={"name": "t", "near": 0.1, "far": 100.0, "viewer_origin": [0, 1.6, 0, 1, 0, 0, 0]},
                         clock="virtual", server_fps=10.0, server_delay_us=20_000, primary=ViewConfig(*SIZE),
                         extra=ViewConfig(*e) if e else None, extra_offset=Pose.identity() if e else None,
                         atlas=build_layout(SIZE, e, False, colour_scale), video_bitrate_kbps=1000.0, keyint=30,
                         depth_codec="edge", depth_bits=12, depth_min_code=2, colour_scale=colour_scale)


@pytest.fixture
def ctx(gl_current):
    return gl_current


def _pattern(directions: np.ndarray) -> np.ndarray:
    """World directions (h, w, 3) -> RGBA (h, w, 4) uint8: detail finer than two pixels, in colour."""
    x, y, z = directions[..., 0], directions[..., 1], directions[..., 2]
    rgb = np.stack([0.5 + 0.45 * np.sin(40.0 * x + 13.0 * y), 0.5 + 0.45 * np.sin(37.0 * y - 11.0 * z),
                    0.5 + 0.45 * np.sin(43.0 * z + 7.0 * x)], axis=-1)
    out = np.full(directions.shape[:2] + (4,), 255, np.uint8)
    out[..., :3] = np.round(255.0 * rgb)
    return out


def _whole_view(pose: Pose) -> np.ndarray:
    """The primary view of the pattern on the sky from ``pose``, (h, w, 4) uint8."""
    w, h = SIZE
    dirs = unproject(pixel_centers(w, h).reshape(-1, 2)) @ pose.rotation().T
    return _pattern(dirs.reshape(h, w, 3))


def _upload(textures, config, rgba, frame_id, pose, distance):
    packer = CpuAtlasPacker(config.atlas, None)
    jitter = colour_jitter(frame_id) if config.colour_scale != 1.0 else None
    yuv = packer.pack({"primary.color": rgba}, {}, jitter).copy()
    h = config.atlas.height
    q = (config.atlas.width // 2) * (h // 2)
    chroma = yuv[h:].reshape(-1)
    image = YUVImage(yuv[:h], chroma[:q].reshape(h // 2, -1), chroma[q:].reshape(h // 2, -1))
    frame = SimpleNamespace(frame_id=frame_id, primary_pose=pose, extra_pose=None)
    textures.upload(image, frame, {"primary": distance.astype(np.float32)})


def _whole_yuv(rgba) -> tuple:
    """What the server sends at colour scale 1: luma per pixel, chroma per 2x2 block -> (Y, U, V) per pixel."""
    cfg = _config(1.0)
    yuv = CpuAtlasPacker(cfg.atlas, None).pack({"primary.color": rgba}, {}).copy()
    h, w = cfg.atlas.height, cfg.atlas.width
    chroma = yuv[h:].reshape(-1)
    u = chroma[:(w // 2) * (h // 2)].reshape(h // 2, w // 2)
    v = chroma[(w // 2) * (h // 2):].reshape(h // 2, w // 2)
    up = lambda c: np.repeat(np.repeat(c, 2, 0), 2, 1)[:SIZE[1], :SIZE[0]].astype(np.float64)
    return yuv[:SIZE[1], :SIZE[0]].astype(np.float64), up(u), up(v)


def _errors(textures, rgba) -> np.ndarray:
    """|rebuilt - what scale 1 sends| of Y, U, V in code units, (h, w, 3)."""
    got = textures.rebuild.read("primary")[..., :3] * 255.0
    return np.abs(got - np.stack(_whole_yuv(rgba), axis=-1))


def test_the_jitter_visits_every_pixel_of_a_block_once_in_four_frames():
    assert sorted(colour_jitter(k) for k in range(4)) == [(0, 0), (0, 1), (1, 0), (1, 1)]
    assert [colour_jitter(k) for k in range(8)] == list(COLOUR_JITTER) * 2
    assert colour_jitter(1) == (1, 1)      # the diagonal second: both rows and columns after two frames


def test_the_methods_read_the_rebuilt_colour(ctx):
    cfg = _config(extra=True)
    layout = rebuilt_layout(cfg)
    assert layout == {"primary": (0, 0, 96, 64), "extra": (96, 0, 48, 32), "size": (144, 64)}
    assert rect_uniform(cfg, "extra.color") == (96.0, 0.0, 48.0, 32.0)
    assert rect_uniform(cfg, "extra.depth") == (0.0, 0.0, 0.0, 0.0)     # depth is not in the atlas
    assert cfg.atlas.rect("extra.color") == (48, 0, 24, 16)
    assert rect_uniform(_config(1.0), "primary.color") == (0.0, 0.0, 96.0, 64.0)
    textures = FrameTextures(ctx, cfg)
    try:
        with pytest.raises(ValueError, match="needs its whole colour"):
            textures.upload(None, SimpleNamespace(frame_id=0), None, flow=object())
    finally:
        textures.release()


def _still(ctx, settings, frames=6):
    """Y, U, V errors (frames, h, w, 3) of a still view rebuilt frame after frame."""
    cfg = _config()
    pose = Pose.make([0.0, 1.6, 0.0], quat_from_euler([0.3, 0.1, 0.0], "yxz"))
    rgba = _whole_view(pose)
    sky = np.zeros(SIZE[::-1])
    textures = FrameTextures(ctx, cfg, settings)
    try:
        errors = []
        for k in range(frames):
            _upload(textures, cfg, rgba, k, pose, sky)
            errors.append(_errors(textures, rgba))
        assert ctx.error == "GL_NO_ERROR"
    finally:
        textures.release()
    return np.stack(errors)


def test_a_released_framebuffer_left_bound_by_others_does_not_break_an_upload(ctx):
    """The rebuild binds the caller's framebuffer back afterwards: one that code elsewhere released
    while bound (the shared context of a process) must not make the upload fail."""
    cfg = _config()
    pose = Pose.make([0.0, 1.6, 0.0], quat_from_euler([0.3, 0.1, 0.0], "yxz"))
    textures = FrameTextures(ctx, cfg, RebuildSettings())
    other = ctx.simple_framebuffer((8, 8))
    try:
        other.use()
        other.release()
        _upload(textures, cfg, _whole_view(pose), 0, pose, np.zeros(SIZE[::-1]))
        assert textures.rebuild.frames == 1
    finally:
        textures.release()


def test_a_still_view_is_whole_after_four_frames(ctx):
    """With the interpolations between samples given next to no weight, four frames rebuild the
    whole colour exactly: every pixel's luma and every block's chroma was sent once."""
    worst = _still(ctx, RebuildSettings(sample_sigma=0.15)).max(axis=(1, 2))
    # one frame is a quarter of the pixels: the rest interpolated, far off on this pattern
    assert worst[0][0] > 20 and worst[0][1:].max() > 10
    for k in (3, 4, 5):      # half-float storage and the interpolations' 1e-4 weight: < 1 code
        assert worst[k].max() < 1.0, (k, worst[k])
    assert worst[2].max() > 10     # ... and not before the fourth


def test_the_default_weights_converge_on_a_still_view(ctx):
    """The defaults trust the interpolations more (a moving head gains, RebuildSettings): a still
    view still converges, to within a few codes on this pattern of full-contrast detail."""
    rms = np.sqrt(np.mean(_still(ctx, RebuildSettings(), frames=8) ** 2, axis=(1, 2)))
    # measured RMS codes of Y, U, V: 29.6 / 36.4 / 40.5 after one frame, 4.4 / 6.4 / 7.3 after
    # four (the interpolations keep some weight each frame), the same after eight
    assert rms[0].min() > 25
    assert np.all(rms[3] < 0.25 * rms[0]), rms
    assert np.all(rms[7] < 1.2 * rms[3]), rms       # and stays there


def test_a_turning_head_keeps_what_reprojects(ctx):
    """Converged at one pose, then the head turns by 2 degrees: the previous result reprojected
    keeps the detail the new quarter of the pixels alone cannot give."""
    cfg = _config()
    a = Pose.make([0.0, 1.6, 0.0], quat_from_euler([0.3, 0.1, 0.0], "yxz"))
    b = a.compose(Pose.make([0.0, 0.0, 0.0], quat_from_euler([np.radians(2.0), 0.0, 0.0], "yxz")))
    sky = np.zeros(SIZE[::-1])
    textures = FrameTextures(ctx, cfg)
    try:
        for k in range(4):
            _upload(textures, cfg, _whole_view(a), k, a, sky)
        _upload(textures, cfg, _whole_view(b), 4, b, sky)
        with_history = _errors(textures, _whole_view(b))[..., 0]
        textures.rebuild.reset()
        _upload(textures, cfg, _whole_view(b), 4, b, sky)
        alone = _errors(textures, _whole_view(b))[..., 0]
    finally:
        textures.release()
    inner = (slice(4, -4), slice(8, -8))      # the edge the turn brought into view has no history
    rms = lambda e: float(np.sqrt(np.mean(e[inner] ** 2)))
    assert rms(with_history) < 0.5 * rms(alone), (rms(with_history), rms(alone))


def test_what_the_previous_frame_did_not_see_comes_from_the_new_samples(ctx):
    """A still view whose middle is suddenly nearer (something moved in, in a flat colour): the
    history there belongs to another surface and is not used. (Interpolations given next to no
    weight, so that what is kept is kept exactly.)"""
    cfg = _config()
    pose = Pose.make([0.0, 1.6, 0.0], quat_from_euler([0.3, 0.1, 0.0], "yxz"))
    far = np.full(SIZE[::-1], 5.0)
    rgba = _whole_view(pose)
    textures = FrameTextures(ctx, cfg, RebuildSettings(sample_sigma=0.15))
    try:
        for k in range(4):
            _upload(textures, cfg, rgba, k, pose, far)
        near, inside = far.copy(), rgba.copy()
        near[16:48, 24:72] = 2.0
        inside[16:48, 24:72, :3] = (200, 60, 30)
        _upload(textures, cfg, inside, 4, pose, near)
        errors = _errors(textures, inside)
    finally:
        textures.release()
    # inside the square, two pixels from its edge: its flat colour, not the pattern it replaced
    assert errors[18:46, 26:70].max() < 1.0
    # outside, more than two pixels away: still the whole colour of the pattern
    outside = np.ones(SIZE[::-1], bool)
    outside[14:50, 22:74] = False
    assert errors[outside].max() < 1.0
