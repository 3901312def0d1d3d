"""Depth codecs at the extremes: near 1 cm, far 10 km; all sky; all one plane; 10 km behind 1 cm.

The edge codec is lossless on its samples (q = 1), so every sample decodes to exactly the code
its quantiser gives; log depth decodes within its relative bound everywhere (Koniaris et al.'s
Eq. 13 at 16 bits: 1.05e-4 over a range of 1e6). No codec produces NaN or wraps around.
"""
import numpy as np
import pytest

from pibr.bench.codec_bench import extremes_table
from pibr.bench.depth_codecs import LogDepthDecoder, LogDepthEncoder, LogDepthQuantizer, make_pair
from pibr.client.depth_decoders import EdgeDepthStreamDecoder
from pibr.protocol.pose import Pose
from pibr.protocol.depth_codecs import edge_quantizer
from pibr.server.depth_encoders import EdgeDepthStream

NEAR, FAR = 1e-2, 1e4
H, W = 48, 64


def _maps() -> dict:
    yy, xx = np.mgrid[0:H, 0:W]
    ramp = np.geomspace(NEAR, FAR, H)[:, None] * np.ones((1, W))          # every decade, row by row
    behind = np.full((H, W), FAR * 0.999)                                 # a 10 km wall ...
    behind[(yy - 24) ** 2 + (xx - 32) ** 2 < 100] = NEAR * 1.001          # ... behind something 1 cm away
    return {"sky": np.zeros((H, W)), "plane 1 cm": np.full((H, W), NEAR), "plane 1 m": np.full((H, W), 1.0),
            "plane 10 km": np.full((H, W), FAR), "ramp 1 cm - 10 km": ramp, "10 km behind 1 cm": behind}


def _edge_round_trip(r, frames=2):
    q = edge_quantizer(NEAR, FAR)
    enc, dec = EdgeDepthStream(W, H, q, 10.0), EdgeDepthStreamDecoder(W, H, q)
    pose = Pose.identity()
    for _ in range(frames):        # the second frame is coded against the first (temporal context)
        payload, _ = enc.encode(r.astype(np.float32), pose)
        dense, samples = dec.decode(payload, pose)
    return q, dense, samples


@pytest.mark.parametrize("name", list(_maps()))
def test_edge_codec_at_the_extremes(name):
    r = _maps()[name]
    q, dense, samples = _edge_round_trip(r)
    assert dense.shape == (H, W) and np.all(np.isfinite(dense))
    want = q.quantize(r).astype(np.int64)
    valid = samples.valid
    assert valid.any()
    assert np.array_equal(samples.codes[valid].astype(np.int64), want[valid])    # lossless on its samples
    exact = q.dequantize(want)
    if name != "ramp 1 cm - 10 km":
        # piecewise constant: the reconstruction is the quantisation itself, sky stays sky
        assert np.array_equal(dense, exact)
    else:
        # between samples it diffuses: decoded distances stay within the representable range
        assert dense.min() >= exact.min() * (1 - 1e-6) and dense.max() <= exact.max() * (1 + 1e-6)
        assert np.all(dense > 0)


def test_ten_km_behind_one_cm_in_the_edge_codec_decodes_to_its_farthest_code():
    """The edge codec's 12-bit disparity cannot tell 10 km from 82 m at near = 1 cm (its
    documented resolution limit); the 1 cm object keeps its distance within a code step."""
    r = _maps()["10 km behind 1 cm"]
    q, dense, _ = _edge_round_trip(r)
    assert dense[0, 0] == pytest.approx(NEAR * 2 * 4093, rel=1e-6)
    assert dense[24, 32] == pytest.approx(NEAR * 1.001, rel=1.0 / 4093)


@pytest.mark.parametrize("name", list(_maps()))
def test_log_codec_at_the_extremes(name):
    r = _maps()[name]
    q = LogDepthQuantizer(NEAR, FAR, 16)
    enc, dec = LogDepthEncoder(W, H, q, block=16), LogDepthDecoder(W, H, q)
    for _ in range(2):
        back = dec.decode(enc.encode(r)).astype(np.float64)
        assert np.array_equal(dec.codes, q.quantize(r))
    assert np.all(np.isfinite(back))
    geo = r > 0
    assert np.all(back[~geo] == 0)
    rel = np.abs(back[geo] - r[geo]) / r[geo]
    assert np.all(rel <= q.max_relative_error() + 2 ** -23)     # + float32 rounding of the decoded distance


def test_log_quantizer_bound_at_every_distance_and_monotone():
    q = LogDepthQuantizer(NEAR, FAR, 16)
    r = np.geomspace(NEAR, FAR, 200001)
    codes = q.quantize(r).astype(np.int64)
    back = q.dequantize(codes).astype(np.float64)
    assert codes[0] == 2 and codes[-1] == q.max_code
    assert np.all(np.diff(codes) >= 0) and np.all(np.diff(back) >= 0)
    assert np.all(np.abs(back - r) / r <= q.max_relative_error() + 2 ** -23)
    assert q.max_relative_error() == pytest.approx(np.expm1(np.log(1e6) / (2 * 65533)))
    assert q.max_relative_error() < 1.1e-4


@pytest.mark.parametrize("codec", ["h264-8bit", "h264-10bit", "zstd"])
def test_other_codecs_stay_finite_and_keep_sky(codec):
    for name, r in _maps().items():
        enc, dec = make_pair(codec, W, H, NEAR, FAR, 10.0, 2000.0)
        back = dec.decode(enc.encode(r.astype(np.float32)))
        assert np.all(np.isfinite(back)) and np.all(back >= 0), name
        if name == "sky":
            assert np.all(back == 0)
        else:
            assert np.all(back > 0), name


def test_extremes_table():
    t = extremes_table(NEAR, FAR, per_decade=2)
    assert len(t["distances_m"]) == 13 and t["distances_m"][0] == pytest.approx(NEAR)
    qs = t["quantizers"]
    assert set(qs) == {"8bit-disparity", "edge-12bit-disparity", "log16"}
    assert all(v["monotone"] and v["finite"] for v in qs.values())
    assert qs["log16"]["max_relative_error"] <= qs["log16"]["bound"]["relative_error_max"] + 2 ** -23
    eight = qs["8bit-disparity"]
    assert eight["farthest_decoded_m"] == pytest.approx(eight["bound"]["resolves_up_to_m"])
    assert qs["edge-12bit-disparity"]["farthest_decoded_m"] == pytest.approx(4093 * 2 * NEAR, rel=1e-6)
    # linear disparity loses the far end entirely; log depth does not
    assert qs["8bit-disparity"]["relative_error"][-1] > 0.99 and qs["log16"]["relative_error"][-1] < 1.1e-4


def test_rendered_10_km_wall_behind_a_1_cm_speck():
    """A scene with near 1 cm and far 10 km: a 1 cm speck 2 cm in front of the camera, a wall 9 km
    away. The renderer's radial distances match the geometry at every pixel (no NaN, the far
    sphere clips the wall to sky where it lies beyond 10 km), and the codecs keep to their bounds.
    (Drawn with the ``tess`` projection: the default ``vertex`` projection's pre-tessellation never
    splits edges below 2 cm (``levels_for_view_region``'s ``min_edge``), so the 1 cm speck 2 cm
    from the eye is rasterised with straight 28-degree chords: 0.19 % off in distance, more than
    the 0.14 % a 6-degree chord allows. The wall is split into 500 m cells as built-in scenes split
    large surfaces: tessellation levels are capped, and a 30 km wall of 12 triangles 90 m away
    comes out up to 85 % too far.)"""
    from pibr.protocol.atlas import build_layout
    from pibr.protocol.depth_codecs import h264_quantizer
    from pibr.common.gl import create_context
    from pibr.protocol.projection import pixel_centers, unproject
    from pibr.scenes.primitives import box
    from pibr.scenes.scene import Scene, SceneObject
    from pibr.server.producer import FrameProducer, ProducerSpec
    from pibr.server.renderer import MAX_EDGE_ANGLE_DEG, Renderer

    speck_z, wall_z = 0.0195, 8995.0
    wall = box((30000.0, 30000.0, 10.0), (0, 0, -wall_z - 5.0), max_cell=500.0)
    scene = Scene("extremes", [SceneObject("speck", box((0.01, 0.01, 0.001), (0, 0, -speck_z - 0.0005))),
                               SceneObject("wall", wall)],
                  near=NEAR, far=FAR, extra_view=False)
    size = 64
    ctx = create_context()
    renderer = Renderer(ctx, scene, "tess")
    producer = FrameProducer(ctx, renderer, ProducerSpec((size, size), build_layout((size, size), None, True),
                                                         h264_quantizer(NEAR, FAR), "tess", keep_distance=True))
    try:
        r = producer.produce(Pose.identity(), 0.0).distances["primary"].astype(np.float64)
    finally:
        producer.release()
        renderer.release()
        ctx.release()
    assert np.all(np.isfinite(r)) and r.min() >= 0
    dz = -unproject(pixel_centers(size, size).reshape(-1, 2))[:, 2].reshape(size, size)
    speck, wall = (r > 0) & (r < 1.0), r > 1.0
    assert speck.sum() >= 16 and wall.sum() >= 200     # the wall is within 10 km up to 26 degrees off axis
    # a straight edge spanning the renderer's 6 degrees lies up to 1 - cos(3 deg) nearer than the surface
    chord = 1 - np.cos(np.radians(MAX_EDGE_ANGLE_DEG / 2))
    assert np.all(np.abs(r[speck] - speck_z / dz[speck]) <= chord * r[speck])
    assert np.all(np.abs(r[wall] - wall_z / dz[wall]) <= chord * r[wall])
    assert np.all(wall_z / dz[r == 0] > FAR * (1 - chord))         # sky only beyond the far sphere
    # 16-bit log depth keeps both within its bound; the edge codec keeps the speck within a code
    # step and puts the wall at its farthest code (82 m), as its 12-bit disparity documents
    q = LogDepthQuantizer(NEAR, FAR, 16)
    back = LogDepthDecoder(size, size, q).decode(LogDepthEncoder(size, size, q).encode(r))
    geo = r > 0
    assert np.all(np.abs(back[geo] - r[geo]) / r[geo] <= q.max_relative_error() + 2 ** -23)
    qe = edge_quantizer(NEAR, FAR)
    enc, dec = EdgeDepthStream(size, size, qe, 10.0), EdgeDepthStreamDecoder(size, size, qe)
    dense, samples = dec.decode(enc.encode(r.astype(np.float32), Pose.identity())[0], Pose.identity())
    assert np.all(np.isfinite(dense))
    valid = samples.valid
    assert np.array_equal(samples.codes[valid].astype(np.int64), qe.quantize(r)[valid].astype(np.int64))
    # between its samples the speck's face is diffused: within one code step of disparity
    # the speck's face: its samples within half a code step of disparity (the quantisation), the few
    # pixels diffused between them (its corners) within two
    d_err = np.abs(NEAR / np.where(dense > 0, dense, 1.0) - NEAR / np.where(r > 0, r, 1.0)) * 4093
    assert np.all(d_err[speck & valid] <= 0.5 + 1e-3) and np.all(d_err[speck] <= 2.0)
    assert (speck & valid).sum() >= speck.sum() * 3 // 4
    assert np.all(dense[wall] == pytest.approx(NEAR * 2 * 4093, rel=1e-6))
    assert np.all(dense[r == 0] == 0)
