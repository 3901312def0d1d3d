"""gridwarp (Schollmeyer et al. 2017): the surface-estimation quadtree and adaptive grid on
synthetic distance maps, then the GL method against ground truth in one process."""
import math

import numpy as np
import pytest

from pibr.client.frame_textures import DEPTH_SLACK_CODES
from pibr.client.surface_grid import (ALL_CONNECTED, E, W, _classify, _connectivity, _direction, build_surface_grid,
                                      check_tile, pixel_directions)
from pibr.protocol.depth import DepthQuantizer
from pibr.protocol.depth_codecs import h264_quantizer
from pibr.protocol.projection import pixel_centers, unproject

NEAR, FAR = 0.1, 1000.0
SKY = 900.0
H264 = h264_quantizer(NEAR, FAR)
FINE = DepthQuantizer(NEAR, FAR, bits=12, min_code=1)   # the edge codec's quantisation


def _transport(q: DepthQuantizer, codec: str) -> dict:
    return {"code_scale": NEAR * (q.max_code - q.min_code), "slack_codes": DEPTH_SLACK_CODES[codec]}


H264_ARGS = _transport(H264, "h264")
FINE_ARGS = _transport(FINE, "edge")


def _h264(r):
    return H264.dequantize(H264.quantize(r))


def _directions(w, h):
    return unproject(pixel_centers(w, h).reshape(-1, 2)).reshape(h, w, 3)


def _plane(w, h, normal, offset):
    """Distances to the plane n . p = offset (points with n . u > 0.05 only; 0 elsewhere)."""
    nd = _directions(w, h) @ np.asarray(normal, np.float64)
    return np.where(nd > 0.05, offset / np.maximum(nd, 1e-9), 0.0)


def _coverage(grid):
    cover = np.zeros((grid.height, grid.width), int)
    for x0, y0, x1, y1 in grid.cells:
        cover[y0:y1, x0:x1] += 1
    return cover


def _cells_per_tile(grid, tile):
    counts = np.zeros((-(-grid.height // tile), -(-grid.width // tile)), int)
    for x0, y0, _, _ in grid.cells:
        counts[y0 // tile, x0 // tile] += 1
    return counts


def _corner_directions(w, h):
    """(h + 1, w + 1, 3) unit camera-space directions of the pixel corners, from the grid kernels'
    own formula (surface_grid._direction, which places the grid's corners)."""
    return np.array([[_direction(float(x), float(y), w, h) for x in range(w + 1)] for y in range(h + 1)])


def _pixel_connectivity(distance, epsilon, code_scale, slack_codes, sky_distance=None, void_margin=1):
    """(h, w) uint8: each pixel's connectedness to its 8 neighbours, as build_surface_grid computes
    it (bit d: ``DIRECTIONS[d]``; neighbours outside the image count as connected)."""
    d = np.ascontiguousarray(distance, dtype=np.float64)
    sky = -1.0 if sky_distance is None else float(sky_distance)
    kind, code = _classify(d, sky, int(void_margin) if sky_distance is None else 0, float(code_scale))
    return _connectivity(kind, code, pixel_directions(d.shape[1], d.shape[0]), float(epsilon), float(slack_codes))


# -- the quadtree and grid on the CPU ---------------------------------------------------------


def test_kernel_directions_are_the_protocols():
    w, h = 40, 24
    x = np.arange(w + 1) / w * 2 - 1
    y = 1 - np.arange(h + 1) / h * 2
    t = np.stack(np.meshgrid(x, y), axis=-1).reshape(-1, 2)
    np.testing.assert_allclose(_corner_directions(w, h), unproject(t).reshape(h + 1, w + 1, 3), atol=1e-12)


def _codes(distance):
    """Distances as (fractional) 8-bit disparity codes above the minimum."""
    return H264_ARGS["code_scale"] / np.asarray(distance, np.float64)


def test_constant_distance_is_one_cell_per_tile():
    """A sphere around the camera: flat enough across a tile at 512 pixels (11 degrees)."""
    g = build_surface_grid(_h264(np.full((512, 512), 3.0)), 32, 0.02, **H264_ARGS, sky_distance=SKY)
    assert g.count == 256
    assert (g.cells[:, 2] - g.cells[:, 0] == 32).all() and (g.cells[:, 3] - g.cells[:, 1] == 32).all()
    assert (g.bits == ALL_CONNECTED).all()
    codes = _codes(np.linalg.norm(g.vertices, axis=2))
    assert np.abs(codes - _codes(_h264(3.0))).max() < 0.5      # within half a depth code
    assert (_coverage(g) == 1).all()


@pytest.mark.parametrize("name,normal,offset", [("floor", (0.0, -1.0, 0.0), 1.6), ("wall", (0.6, 0.0, -0.8), 2.0)])
@pytest.mark.parametrize("quantizer,args", [(FINE, FINE_ARGS), (H264, H264_ARGS)], ids=["edge", "h264"])
def test_slanted_plane_keeps_its_tiles_whole(name, normal, offset, quantizer, args):
    """A true 3D plane seen in the wide-angle projection: its distance varies across every tile
    by more than the transport's error (a min/max-depth quadtree splits nearly all of them), yet
    almost every tile is one cell."""
    r = _plane(256, 256, normal, offset)
    d = quantizer.dequantize(quantizer.quantize(r))
    g = build_surface_grid(d, 32, 0.02, **args, sky_distance=SKY)
    counts = _cells_per_tile(g, 32)
    whole, minmax_splits = [], 0
    for i in range(8):
        for j in range(8):
            tile = d[32 * i:32 * i + 32, 32 * j:32 * j + 32]
            if (r[32 * i:32 * i + 32, 32 * j:32 * j + 32] > 0).all():
                whole.append(counts[i, j] == 1)
                minmax_splits += tile.max() - tile.min() > args["slack_codes"] * quantizer.step_at(tile.min())
    assert len(whole) >= 24
    assert minmax_splits >= 0.75 * len(whole)
    assert np.mean(whole) >= 0.85


def test_depth_step_splits_cells_and_detaches_the_sides():
    w, h, step = 512, 512, 300
    r = np.full((h, w), 5.0)
    r[:, :step] = 2.0
    d = _h264(r)
    g = build_surface_grid(d, 32, 0.02, **H264_ARGS, sky_distance=SKY)
    x0, x1 = g.cells[:, 0], g.cells[:, 2]
    assert not ((x0 < step) & (x1 > step)).any()          # no cell straddles the step
    left, right = x1 <= step, x0 >= step
    codes = _codes(np.linalg.norm(g.vertices, axis=2))
    # Each side keeps its own depth, also at the corners on the step: no rubber sheet.
    assert np.abs(codes[left] - _codes(d[0, 0])).max() < 0.5
    assert np.abs(codes[right] - _codes(d[0, -1])).max() < 0.5
    assert (g.bits[x1 == step] & (1 << E) == 0).all()
    assert (g.bits[x0 == step] & (1 << W) == 0).all()
    assert (g.bits[(x1 < step) | (x0 > step)] == ALL_CONNECTED).all()
    assert (g.levels[(x1 == step) | (x0 == step)] <= 2).all()   # small cells along the step,
    assert g.count < 0.01 * w * h                               # few elsewhere
    conn = _pixel_connectivity(d, 0.02, **H264_ARGS, sky_distance=SKY)
    assert (conn[:, step - 1] & (1 << E) == 0).all() and (conn[:, step] & (1 << W) == 0).all()


def test_noise_leaves_every_pixel_its_own_cell():
    rng = np.random.default_rng(0)
    h, w = 70, 100
    parity = np.add.outer(np.arange(h), np.arange(w)) % 2
    codes = 20 + 40 * parity + rng.uniform(0, 20, (h, w))       # neighbours 20..60 codes apart
    g = build_surface_grid(H264.dequantize(np.round(codes + 16).astype(np.uint8)), 32, 0.02, **H264_ARGS,
                           sky_distance=SKY)
    assert g.count == w * h and (g.levels == 0).all()
    rng_d = rng.uniform(1.0, 10.0, (h, w))                     # unquantised noise, no slack
    g = build_surface_grid(rng_d, 32, 0.02, code_scale=FINE_ARGS["code_scale"], slack_codes=0.0, sky_distance=SKY)
    assert g.count == w * h


def test_sky_is_a_far_surface_of_its_own_in_the_primary_view():
    h, w = 512, 512
    r = np.full((h, w), 4.0)
    r[:160] = 0.0                                          # sky above row 160
    d = _h264(r)
    g = build_surface_grid(d, 32, 0.02, **H264_ARGS, sky_distance=SKY)
    assert (_coverage(g) == 1).all()
    sky = g.cells[:, 3] <= 160
    ground = g.cells[:, 1] >= 160
    assert (sky | ground).all()                            # no cell mixes sky and ground
    np.testing.assert_allclose(np.linalg.norm(g.vertices[sky], axis=2), SKY, rtol=1e-3)
    assert np.abs(_codes(np.linalg.norm(g.vertices[ground], axis=2)) - _codes(d[-1, 0])).max() < 0.5
    assert (_cells_per_tile(g, 32)[:5] == 1).all()         # the all-sky tiles are one cell each
    assert (g.bits[sky & (g.cells[:, 3] == 160)] & (1 << 2) == 0).all()   # cut from the ground below


def test_empty_pixels_of_the_extra_view_are_not_drawn():
    h, w = 64, 96
    r = np.full((h, w), 3.0)
    r[20:30, 40:60] = 0.0                                  # peeled away
    g = build_surface_grid(_h264(r), 16, 0.02, **H264_ARGS, sky_distance=None, void_margin=1)
    cover = _coverage(g)
    assert (cover[19:31, 39:61] == 0).all()                # the hole and a margin of one pixel
    outside = np.ones((h, w), bool)
    outside[19:31, 39:61] = False
    assert (cover[outside] == 1).all()


@pytest.mark.parametrize("w,h,tile,cells,distance", [(1000, 700, 32, 704, 3.0), (100, 70, 32, 12, 0.0),
                                                     (20, 12, 64, 1, 0.0), (33, 5, 16, 3, 0.0)])
def test_views_that_are_not_a_multiple_of_the_tile(w, h, tile, cells, distance):
    """Clipped cells at the right and bottom; views smaller than a tile are one cell. (The small
    views are all sky: a view of 20 x 12 pixels spans 9 degrees per pixel, where no surface at
    constant distance is flat.)"""
    g = build_surface_grid(_h264(np.full((h, w), distance)), tile, 0.02, **H264_ARGS, sky_distance=SKY)
    assert g.count == cells
    assert (_coverage(g) == 1).all()
    assert g.cells[:, 2].max() == w and g.cells[:, 3].max() == h


def test_t_junctions_lie_on_the_larger_cells_side():
    """A smooth bump in a flat surface makes small cells next to large ones; every corner of a
    small cell inside a large cell's side is moved onto that side, so no cracks open."""
    h = w = 128
    yy, xx = np.mgrid[0:h, 0:w]
    r = 3.0 - 0.4 * np.exp(-((xx - 50) ** 2 + (yy - 60) ** 2) / (2 * 6.0 ** 2))
    d = FINE.dequantize(FINE.quantize(r))
    g = build_surface_grid(d, 32, 0.01, **FINE_ARGS, sky_distance=SKY)
    assert (g.bits == ALL_CONNECTED).all()                 # one connected surface
    assert len(set(g.levels.tolist())) >= 3
    corners = ((0, 1), (2, 3), (0, 2), (1, 3))             # sides: top, bottom, left, right
    checked = 0
    for i, (x0, y0, x1, y1) in enumerate(g.cells):
        for k in range(4):
            cx, cy = (x1 if k & 1 else x0), (y1 if k >> 1 else y0)
            for j, (a0, b0, a1, b1) in enumerate(g.cells):
                if g.levels[j] <= g.levels[i]:
                    continue
                on_h = cy in (b0, b1) and a0 < cx < a1
                on_v = cx in (a0, a1) and b0 < cy < b1
                if not (on_h or on_v):
                    continue
                ka, kb = corners[(0 if cy == b0 else 1) if on_h else (2 if cx == a0 else 3)]
                p, q = g.vertices[j, ka].astype(np.float64), g.vertices[j, kb].astype(np.float64)
                v = g.vertices[i, k].astype(np.float64)
                off = np.linalg.norm(np.cross(v - p, q - p)) / np.linalg.norm(q - p)
                assert off < 1e-5 * np.linalg.norm(v)
                checked += 1
    assert checked >= 8


def test_bad_inputs_are_refused():
    with pytest.raises(ValueError, match="tile"):
        check_tile(24)
    with pytest.raises(ValueError, match="shape"):
        build_surface_grid(np.ones(5), 32, 0.02, **H264_ARGS)
    with pytest.raises(ValueError, match="code_scale"):
        build_surface_grid(np.ones((4, 4)), 32, 0.02, code_scale=0.0, slack_codes=1.0)


# -- the method on the GPU ----------------------------------------------------------------------

gl = pytest.mark.gl


def _fill(ctx, image):
    """HoleFill of an (h, w, 4) float32 image (rgb, distance; 0 = hole) -> (h, w, 4) uint8."""
    from pibr.client.hole_fill import HoleFill

    h, w = image.shape[:2]
    src = ctx.texture((w, h), 4, dtype="f4")
    src.write(np.ascontiguousarray(image, np.float32).tobytes())
    out = ctx.texture((w, h), 4)
    fbo = ctx.framebuffer(color_attachments=[out])
    hf = HoleFill(ctx, w, h)
    try:
        fbo.use()
        hf.fill(src)
        return np.frombuffer(fbo.read(components=4), np.uint8).reshape(h, w, 4).copy()
    finally:
        for r in (hf, fbo, out, src):
            r.release()


@gl
def test_hole_filling_takes_the_background_not_the_occluder(gl_ctx):
    """A strip disoccluded beside a near object is filled from the far background; were the
    object as far as the background, its colour would bleed in (the depth decides)."""
    h, w = 48, 64
    fills = {}
    for occluder in (2.0, 10.0):
        img = np.zeros((h, w, 4), np.float32)
        img[..., 2], img[..., 3] = 1.0, 10.0                  # blue background, 10 m
        img[14:34, 16:32] = (1.0, 0.0, 0.0, occluder)          # red object
        img[14:34, 32:40] = 0.0                                # the strip it uncovered
        out = _fill(gl_ctx, img)
        hole = np.zeros((h, w), bool)
        hole[14:34, 32:40] = True
        assert (out[hole, 3] == 0).all() and (out[~hole, 3] == 255).all()
        np.testing.assert_array_equal(out[~hole, :3], np.round(255 * img[~hole, :3]).astype(np.uint8))
        fills[occluder] = out[hole, :3].astype(float).mean(axis=0)
    assert fills[2.0][2] > 240 and fills[2.0][0] < 15
    assert fills[10.0][0] > 40
    empty = _fill(gl_ctx, np.zeros((9, 13, 4), np.float32))
    assert (empty == 0).all()


@pytest.fixture(scope="module")
def sim():
    from pibr.bench.simulation import Simulation, bench_server_config
    from pibr.scenes.registry import load_scene

    s = Simulation(load_scene("room"), bench_server_config((256, 256)), (320, 180))
    yield s
    s.close()
    s.ctx.release()


def _grid(sim, **knobs):
    from pibr.client.methods.grid_warp import GridWarp

    return GridWarp(sim.ctx, sim.output, sim.session, **knobs)


def _show(sim, method, pose, frame):
    rgb, holes, _ = sim.display(method, pose, frame, 0.0)
    return rgb, holes


def _read_warp(m):
    """The grid warp's last image before hole filling, (h, w, 4) float32 (rgb, distance; 0 = hole),
    row 0 first as stored (a method with hole filling)."""
    w, h = m.target.size
    return np.frombuffer(m.target.read(), np.float32).reshape(h, w, 4).copy()


def _moved(pose, right=0.15, back=0.05):
    from pibr.protocol.pose import Pose

    r = pose.rotation()
    return Pose.make(pose.p + right * r[:, 0] + back * r[:, 2], pose.q)


@gl
def test_at_zero_displacement_it_matches_the_frame(sim):
    """Measured (room, 256-pixel views, 320 x 180): none 25.95 dB, gridwarp 25.15 dB (meshwarp
    25.18); silhouettes differ by the nearest-texel band and the cell edges."""
    from pibr.bench.metrics import psnr

    pose = sim.scene.viewer_origin
    frame = sim.frame_at(0.0, pose)
    gt = sim.ground_truth(pose, 0.0)
    none = sim.make_method("none")
    reference, _ = _show(sim, none, pose, frame)
    none.release()
    m = _grid(sim)
    rgb, holes = _show(sim, m, pose, frame)
    m.release()
    assert holes < 1e-3
    assert psnr(gt, rgb) >= psnr(gt, reference) - 1.0


@gl
def test_a_small_translation_beats_rotation_and_meshwarp(sim):
    """Measured DSSIM: rotation 0.267, meshwarp 0.154, gridwarp 0.127."""
    from pibr.bench.metrics import dssim, ssim

    pose = sim.scene.viewer_origin
    frame = sim.frame_at(0.0, pose)
    moved = _moved(pose)
    gt = sim.ground_truth(moved, 0.0)
    scores = {}
    for name in ("rotation", "meshwarp", "gridwarp"):
        m = _grid(sim) if name == "gridwarp" else sim.make_method(name)
        rgb, _ = _show(sim, m, moved, frame)
        m.release()
        scores[name] = dssim(ssim(gt, rgb))
    assert scores["gridwarp"] < scores["rotation"] - 0.1
    assert scores["gridwarp"] < scores["meshwarp"] - 0.01


@gl
def test_hole_filling_lowers_the_error_and_keeps_holes_counted(sim):
    """Measured: 16.4 dB unfilled, 21.1 dB filled; the same 7 % of pixels alpha 0 in both."""
    from pibr.bench.metrics import psnr

    pose = sim.scene.viewer_origin
    frame = sim.frame_at(0.0, pose)
    moved = _moved(pose)
    gt = sim.ground_truth(moved, 0.0)
    images = {}
    for fill in (True, False):
        m = _grid(sim, fill=fill)
        sim.target.begin()
        m.render(moved, frame, sim.textures, 0.0)
        images[fill] = sim.target.read().copy()
        m.release()
    holes = images[False][:, :, 3] == 0
    assert 0.01 < holes.mean() < 0.2
    assert ((images[True][:, :, 3] == 0) == holes).all()
    assert (images[False][holes, :3] == 0).all()
    assert psnr(gt, images[True][:, :, :3]) > psnr(gt, images[False][:, :, :3]) + 3.0
    err = {f: np.abs(images[f][holes, :3].astype(float) - gt[holes].astype(float)).mean() for f in images}
    assert err[True] < 0.5 * err[False]


@gl
@pytest.mark.parametrize("yaw,pitch", [(90.0, 0.0), (180.0, 0.0), (0.0, 89.0), (30.0, -89.0)])
def test_turned_away_from_the_frame(sim, yaw, pitch):
    """Grid vertices behind the output camera and at the hemisphere's rim and poles: no NaN."""
    from pibr.protocol.pose import Pose, quat_from_euler

    pose = sim.scene.viewer_origin
    frame = sim.frame_at(0.0, pose)
    turned = Pose.make(_moved(pose).p, quat_from_euler([math.radians(yaw), math.radians(pitch), 0.0], "yxz"))
    m = _grid(sim)
    try:
        rgb, holes = _show(sim, m, turned, frame)
        warp = _read_warp(m)
    finally:
        m.release()
    assert np.isfinite(warp).all()
    assert (warp[:, :, 3] >= 0).all()
    assert sim.ctx.error == "GL_NO_ERROR"
    if yaw == 180.0:
        assert holes > 0.9 and (warp[:, :, 3] == 0).mean() > 0.9   # nothing of the frame is behind
    else:
        assert holes < 0.9


@gl
def test_the_grid_is_built_once_per_frame(sim):
    pose = sim.scene.viewer_origin
    m = _grid(sim)
    try:
        frame = sim.frame_at(0.0, pose)
        for _ in range(2):
            _show(sim, m, pose, frame)
        assert m.builds == 1
        assert m.last_primitives == 2 * sum(g.cells for g in m.grids) > 0
        assert len(m.grids) == 2                            # the room sends an extra view
        frame = sim.frame_at(0.1, _moved(pose))
        _show(sim, m, pose, frame)
        assert m.builds == 2
    finally:
        m.release()


def _gl_objects(obj, seen=None):
    """Every moderngl object reachable from a method's attributes (not the context)."""
    import moderngl

    seen = set() if seen is None else seen
    found = []
    if id(obj) in seen or isinstance(obj, (moderngl.Context, str, bytes, int, float, np.ndarray)):
        return found
    seen.add(id(obj))
    if hasattr(obj, "mglo"):
        return [obj]
    children = obj.values() if isinstance(obj, dict) else obj if isinstance(obj, (list, tuple)) else \
        vars(obj).values() if hasattr(obj, "__dict__") and type(obj).__module__.startswith("pibr.client") else ()
    for child in children:
        found += _gl_objects(child, seen)
    return found


@gl
@pytest.mark.parametrize("fill", [True, False])
def test_release_frees_every_gl_object(sim, fill):
    pose = sim.scene.viewer_origin
    frame = sim.frame_at(0.0, pose)
    for _ in range(2):
        m = _grid(sim, fill=fill)
        _show(sim, m, pose, frame)
        objects = _gl_objects(m)
        assert len(objects) >= (8 if fill else 7)
        m.release()
        assert all(type(o.mglo).__name__ == "InvalidObject" for o in objects)
    assert sim.ctx.error == "GL_NO_ERROR"


@gl
@pytest.mark.parametrize("knobs,word", [({"tile": 24}, "tile"), ({"tile": 512}, "tile"), ({"tile": True}, "tile"),
                                        ({"epsilon": 0.0}, "epsilon"), ({"epsilon": float("nan")}, "epsilon"),
                                        ({"fill": "yes"}, "fill")])
def test_bad_knobs_are_config_errors(sim, knobs, word):
    from pibr.protocol.errors import ConfigError

    with pytest.raises(ConfigError, match=f"gridwarp {word}"):
        _grid(sim, **knobs)
