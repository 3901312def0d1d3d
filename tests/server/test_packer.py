"""The CPU atlas packer makes the GL packing passes' bytes: on colours and distances where float32
rounding decides, and on rendered room frames through the frame producer."""
import numpy as np
import pytest

from pibr.protocol.atlas import AtlasLayout, build_layout
from pibr.protocol.depth import PEELED
from pibr.protocol.depth_codecs import h264_quantizer
from pibr.server.packer import AtlasPacker, CpuAtlasPacker



@pytest.fixture
def ctx(gl_current):
    """The shared context, made current (tests/conftest.py)."""
    return gl_current


def _both(ctx, layout, quantizer, colors: dict, distances: dict):
    """(GL passes' yuv420p, CPU packer's yuv420p) of the same (h, w, 4) uint8 / (h, w) float32 views."""
    textures = {name: ctx.texture((v.shape[1], v.shape[0]), 4, v.tobytes()) for name, v in colors.items()}
    textures.update({name: ctx.texture((v.shape[1], v.shape[0]), 1, v.tobytes(), dtype="f4")
                     for name, v in distances.items()})
    gpu = AtlasPacker(ctx, layout, quantizer)
    try:
        gpu.pack(textures)
        reference = gpu.read().copy()
    finally:
        gpu.release()
        for t in textures.values():
            t.release()
    return reference, CpuAtlasPacker(layout, quantizer).pack(colors, distances).copy()


def _square(rgb: np.ndarray, side: int) -> np.ndarray:
    """(n, 3) uint8 colours -> (side, side, 4) RGBA, padded by repeating them."""
    out = np.empty((side * side, 4), np.uint8)
    out[:, :3] = np.resize(rgb, (side * side, 3))
    out[:, 3] = 255
    return out.reshape(side, side, 4)


def _luma_ties() -> np.ndarray:
    """Every 8-bit colour whose exact luma 0.299 r + 0.587 g + 0.114 b lies within 0.001 of
    k + 0.5, where only float32 rounding decides which way floor(y + 0.5) goes (about 50k)."""
    g, b = np.meshgrid(np.arange(256), np.arange(256), indexing="ij")
    found = []
    for r in range(256):
        m = (299 * r + 587 * g + 114 * b) % 1000
        near = (m >= 499) & (m <= 501)
        found.append(np.stack([np.full(near.sum(), r), g[near], b[near]], axis=1))
    return np.concatenate(found).astype(np.uint8)


def _chroma_tie_blocks(rng, count: int) -> np.ndarray:
    """(count, 2, 2, 3) uint8 blocks whose exact U or V (from the 4-texel sums) lies within
    50 / 125000 of k + 0.5; the sums are split into four texels at random."""
    sums = rng.integers(0, 1021, size=(3_000_000, 3), dtype=np.int32)
    num_u = -168736 * sums[:, 0] - 331264 * sums[:, 1] + 500000 * sums[:, 2]
    num_v = 500000 * sums[:, 0] - 418688 * sums[:, 1] - 81312 * sums[:, 2]
    near = np.zeros(len(sums), bool)
    for num in (num_u, num_v):   # value = num / 4e6 + 128, a tie where num = 2e6 mod 4e6
        near |= np.abs((num % 4_000_000) - 2_000_000) <= 32 * 50
    sums = sums[near][:count]
    assert len(sums) == count
    # four texels in 0..255 adding up to each sum: the first three random where room allows
    parts = np.zeros((count, 4, 3), np.int32)
    left = sums.copy()
    for k in range(3):
        lo = np.maximum(0, left - 255 * (3 - k))
        hi = np.minimum(255, left)
        parts[:, k] = lo + (rng.random(left.shape) * (hi - lo + 1)).astype(np.int32)
        left -= parts[:, k]
    parts[:, 3] = left
    assert parts.min() >= 0 and parts.max() <= 255 and np.array_equal(parts.sum(1), sums)
    return parts.reshape(count, 2, 2, 3).astype(np.uint8)


@pytest.mark.gl
def test_luma_and_chroma_equal_the_passes_where_rounding_decides(ctx):
    rng = np.random.default_rng(7)
    ties = _luma_ties()
    assert 40_000 < len(ties) < 60_000
    corners = np.array([[a, b, c] for a in (0, 1, 127, 128, 254, 255) for b in (0, 1, 127, 128, 254, 255)
                        for c in (0, 1, 127, 128, 254, 255)], np.uint8)
    luma = _square(np.concatenate([corners, ties, rng.integers(0, 256, (10_000, 3))]), 256)
    blocks = np.concatenate([_chroma_tie_blocks(rng, 4096),
                             rng.integers(0, 256, (128 * 128 - 4096, 2, 2, 3), dtype=np.uint8)])
    chroma = np.full((256, 256, 4), 255, np.uint8)
    chroma[:, :, :3] = blocks.reshape(128, 128, 2, 2, 3).transpose(0, 2, 1, 3, 4).reshape(256, 256, 3)
    layout = AtlasLayout(512, 256, {"primary.color": (0, 0, 256, 256), "extra.color": (256, 0, 256, 256)})
    reference, packed = _both(ctx, layout, None, {"primary.color": luma, "extra.color": chroma}, {})
    assert np.array_equal(packed, reference)


@pytest.mark.gl
def test_depth_codes_equal_the_pass_on_every_boundary_and_special_value(ctx):
    q = h264_quantizer(0.1, 1000.0)
    # the distances where each code starts, in float64, and 200 float32 steps either side of each
    span = q.max_code - q.min_code
    starts = q.near * span / (np.arange(span) + 0.5)
    around = np.float32(starts)[:, None].view(np.int32) + np.arange(-200, 200)[None, :]
    # (no subnormals: whether llvmpipe flushes them to zero depends on its threads' state; the
    # renderer never writes one, and the CPU packer codes them as sky)
    tiny = np.finfo(np.float32).tiny
    special = np.array([0.0, -0.0, PEELED, -1e-30, tiny, -tiny, 1e-30, q.near, q.far,
                        np.nextafter(np.float32(q.far), np.float32(np.inf)), np.nextafter(np.float32(q.near), 0),
                        np.inf, -np.inf, np.finfo(np.float32).max], np.float32)
    rng = np.random.default_rng(3)
    values = np.concatenate([around.reshape(-1).view(np.float32), special,
                             np.exp(rng.uniform(np.log(0.05), np.log(2000.0), 100_000)).astype(np.float32)])
    side = int(np.ceil(np.sqrt(len(values)) / 16)) * 16
    distance = np.resize(values, side * side).reshape(side, side).astype(np.float32)
    layout = AtlasLayout(side, side, {"primary.depth": (0, 0, side, side)})
    reference, packed = _both(ctx, layout, q, {}, {"primary.depth": distance})
    assert np.array_equal(packed, reference)
    assert set(np.unique(packed[:side])) == set(range(q.min_code, 256)) | {0, 8}   # every code and sky, peeled


@pytest.mark.gl
def test_rendered_room_frames_equal_through_the_producer(ctx):
    """Dual view with depth in the atlas (and the distances, low colour and motion the producer
    hands out), then the edge-depth layout: identical with the GL passes and on the CPU."""
    from pibr.scenes.registry import load_scene
    from pibr.server.config import extra_offset_pose
    from pibr.server.producer import FrameProducer, ProducerSpec
    from pibr.server.renderer import Renderer
    from pibr.protocol.pose import Pose, quat_from_euler

    scene = load_scene("room")
    renderer = Renderer(ctx, scene, "vertex")
    q = h264_quantizer(scene.near, scene.far)
    offset = extra_offset_pose(1.5, 1.8, 15.0)
    specs = [ProducerSpec((256, 256), build_layout((256, 256), (128, 128), True), q, extra_size=(128, 128),
                          extra_offset=offset, keep_distance=True, low_colour=4, motion_dt=0.1),
             ProducerSpec((256, 256), build_layout((256, 256), (128, 128), False), None, extra_size=(128, 128),
                          extra_offset=offset, keep_distance=True)]
    try:
        for spec in specs:
            cpu = FrameProducer(ctx, renderer, spec)
            gpu = FrameProducer(ctx, renderer, ProducerSpec(**{**spec.__dict__, "gpu_pack": True}))
            assert isinstance(cpu.packer, CpuAtlasPacker) and isinstance(gpu.packer, AtlasPacker)
            for k, pose in enumerate(_poses(scene, Pose, quat_from_euler)):
                a, b = cpu.produce(pose, 0.37 * k), gpu.produce(pose, 0.37 * k)
                assert np.array_equal(a.yuv, b.yuv)
                assert a.distances.keys() == b.distances.keys() == {"primary", "extra"}
                for name in a.distances:
                    assert np.array_equal(a.distances[name], b.distances[name])
                for x, y in ((a.low_colour, b.low_colour), (a.motion, b.motion), (a.moving, b.moving)):
                    assert (x is None and y is None) or np.array_equal(x, y)
                if spec.quantizer is not None:   # a real frame: many colours, depth codes, peeled pixels
                    y_plane = a.yuv[:256]
                    assert len(np.unique(y_plane[:, :256])) > 100 and len(np.unique(y_plane[:, 256:512])) > 10
                    assert (y_plane[:128, 512:] == 8).any() or (y_plane[128:, 512:] == 8).any()
            cpu.release()
            gpu.release()
    finally:
        renderer.release()


def _poses(scene, Pose, quat_from_euler):
    """Two eyes in the viewing region looking different ways."""
    lo, hi = scene.viewing_region()
    for f, yaw in ((0.3, 0.4), (0.7, 2.5)):
        yield Pose.make(lo + f * (hi - lo), quat_from_euler([yaw, 0.1, 0.0], "yxz"))


def test_bad_sources_and_layouts_are_refused():
    layout = build_layout((64, 64), None, True)
    packer = CpuAtlasPacker(layout, h264_quantizer(0.1, 100.0))
    with pytest.raises(ValueError, match="primary.color needs a C-contiguous"):
        packer.pack({"primary.color": np.zeros((64, 64, 3), np.uint8)}, {})
    with pytest.raises(ValueError, match="primary.depth needs a C-contiguous"):
        packer.pack({}, {"primary.depth": np.zeros((64, 64), np.float64)})
    with pytest.raises(ValueError, match="primary.color needs a C-contiguous"):
        packer.pack({"primary.color": np.zeros((64, 128, 4), np.uint8)[:, ::2]}, {})
    with pytest.raises(ValueError, match="needs a depth quantizer"):
        CpuAtlasPacker(layout, None).pack({}, {"primary.depth": np.zeros((64, 64), np.float32)})
    with pytest.raises(ValueError, match="even corners"):
        CpuAtlasPacker(AtlasLayout(64, 64, {"primary.color": (1, 0, 32, 32)}), None)


def test_a_colour_scaled_pack_sends_the_jitters_pixels_and_blocks():
    """At colour scale 0.5 the rectangle holds the luma of the pixels (2 i + jx, 2 j + jy) and the
    chroma of the view's 2x2 blocks (2 i + jx, 2 j + jy): the bytes the whole view's pack has there."""
    from pibr.protocol.atlas import COLOUR_JITTER

    rng = np.random.default_rng(3)
    view = rng.integers(0, 256, (64, 96, 4), dtype=np.uint8)
    whole = CpuAtlasPacker(build_layout((96, 64), None, False), None).pack({"primary.color": view}, {}).copy()
    wy, wu, wv = _planes(whole, 96, 64)
    layout = build_layout((96, 64), None, False, colour_scale=0.5)
    assert layout.rect("primary.color") == (0, 0, 48, 32)
    seen = np.zeros((64, 96), int)
    for jx, jy in COLOUR_JITTER:
        packed = CpuAtlasPacker(layout, None).pack({"primary.color": view}, {}, (jx, jy)).copy()
        y, u, v = _planes(packed, layout.width, layout.height)
        assert np.array_equal(y[:32, :48], wy[jy::2, jx::2])
        assert np.array_equal(u[:16, :24], wu[jy::2, jx::2]) and np.array_equal(v[:16, :24], wv[jy::2, jx::2])
        seen[jy::2, jx::2] += 1
    assert np.all(seen == 1)     # four frames: every pixel once
    with pytest.raises(ValueError, match=r"needs a C-contiguous \(64, 96, 4\)"):
        CpuAtlasPacker(layout, None).pack({"primary.color": view[::2, ::2].copy()}, {}, (0, 0))


def _planes(yuv, width, height):
    chroma = yuv[height:].reshape(-1)
    q = (width // 2) * (height // 2)
    return yuv[:height], chroma[:q].reshape(height // 2, width // 2), chroma[q:].reshape(height // 2, width // 2)
