"""Proxy-guided IBR and LoD selection against ground truth, in one process."""
import numpy as np
import pytest

from pibr.bench.coverage import LatencyModel, display_samples
from pibr.bench.ibr_bench import Simulation, _load_proxies
from pibr.bench.metrics import psnr
from pibr.client.lod_select import LodSelector
from pibr.protocol.messages import OutputConfig
from pibr.protocol.pose import Pose, quat_from_euler
from pibr.scenes.registry import load_scene

pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def room():
    scene = load_scene("room")
    proxies, _ = _load_proxies(scene, progress=False)
    return scene, proxies


def test_lod_selection_by_distance_and_frustum(room):
    scene, proxies = room
    out = OutputConfig(320, 180, 90.0, 30.0)
    sel = LodSelector(proxies, out, target_px=6.0)
    pose = scene.viewer_origin
    chosen = sel.select(pose, 0.0)
    assert 0 < len(chosen) < len(proxies)                   # something is culled, something drawn
    back = Pose.make(pose.p, quat_from_euler([np.pi, 0, 0], "yxz"))
    assert {c.index for c in sel.select(back, 0.0)} != {c.index for c in chosen}
    levels = {c.level for c in chosen}
    assert levels <= {"original", "proxy", "box"}
    # Coarser targets pick coarser levels; distances decide, per object.
    rank = {"original": 0, "proxy": 1, "box": 2}
    coarse = {c.index: c.level for c in LodSelector(proxies, out, target_px=200.0).select(pose, 0.0)}
    assert all(rank[coarse[c.index]] >= rank[c.level] for c in chosen)
    far = [c for c in chosen if c.distance > 50]
    assert all(c.level != "original" for c in far)
    boxes = LodSelector(proxies, out, force_level="box").select(pose, 0.0)
    assert {c.level for c in boxes} == {"box"}


@pytest.fixture(scope="module")
def sim(room):
    scene, proxies = room
    s = Simulation(scene, (512, 512), (320, 180), proxies=proxies)
    yield s
    s.close()
    s.ctx.release()


def _run(sim, name, pose, t_render_pose, t=0.0, **options):
    frame = sim.frame_at(round(t, 6), t_render_pose)
    m = sim.make_method(name, **options)
    try:
        rgb, holes, ms = sim.display(m, pose, frame, t)
    finally:
        m.release()
    return rgb, holes


def test_proxy_matches_ground_truth_without_latency(sim):
    pose = sim.scene.viewer_origin
    gt = sim.ground_truth(pose, 0.0)
    rgb, holes = _run(sim, "proxy", pose, pose)
    assert holes < 0.03
    assert psnr(gt, rgb) > 24


def test_proxy_beats_rotation_when_the_head_moves(sim):
    scene = sim.scene
    samples = display_samples(scene, "pred6dof-1", 20.0, 2.0, 30.0, LatencyModel(rate_hz=30.0))[::10]
    better = 0
    for t_disp, display, t_render, rendered in samples:
        gt = sim.ground_truth(display, t_disp)
        frame = sim.frame_at(t_render, rendered)
        scores = {}
        for name in ("rotation", "proxy"):
            m = sim.make_method(name)
            rgb, _, _ = sim.display(m, display, frame, t_disp)
            m.release()
            scores[name] = psnr(gt, rgb)
        better += scores["proxy"] > scores["rotation"]
    assert better >= len(samples) // 2


@pytest.mark.parametrize("level", ["box", "proxy", "original"])
def test_every_level_renders_and_carves(sim, level):
    pose = sim.scene.viewer_origin
    gt = sim.ground_truth(pose, 0.0)
    rgb, holes = _run(sim, "proxy", pose, pose, lod_level=level)
    assert np.isfinite(rgb).all() and 0 <= holes <= 1
    assert psnr(gt, rgb) > 18   # even boxes give usable images: carving keeps silhouettes


def test_camera_inside_a_proxy_and_at_extremes(sim):
    # Inside the exhibit's encaging proxy, looking up at the pole and down.
    for yaw, pitch in ((0.0, 0.0), (0.5, 1.5), (0.0, -1.5)):
        pose = Pose.make((0.3, 1.6, -0.2), quat_from_euler([yaw, pitch, 0.0], "yxz"))
        rgb, holes = _run(sim, "proxy", pose, pose)
        assert np.isfinite(rgb).all() and 0 <= holes <= 1
