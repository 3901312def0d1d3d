"""``--motion flow`` in the methods that re-project the primary view: moving objects come closer to
where the ground truth shows them, nothing changes without motion or time, and the frame's
textures are restored for the methods that show it as decoded."""
from __future__ import annotations

import numpy as np
import pytest

from pibr.bench.metrics import masked_metrics
from pibr.bench.simulation import Simulation, bench_server_config, load_proxies
from pibr.protocol.pose import Pose
from pibr.scenes.registry import load_scene

pytestmark = pytest.mark.gl

FLOW_METHODS = ("none", "rotation", "homography", "splat", "coarse-meshwarp", "gridwarp", "proxy")


@pytest.fixture(scope="module")
def sim():
    scene = load_scene("dynamic")
    proxies, _ = load_proxies(scene)
    s = Simulation(scene, bench_server_config((512, 512)), (192, 108), fov_deg=45.0, proxies=proxies, flow_frames=True,
                   moving_truth=True)
    yield s
    s.close()
    s.ctx.release()


def _pendulum_pose(scene, t: float) -> Pose:
    o = next(o for o in scene.objects if o.name == "pendulum")
    return Pose.look_at(scene.viewer_origin.p, o.world_bounds(t).mean(axis=0))


def _show(sim, name, options, pose, frame, t):
    m = sim.make_method(name, **options)
    try:
        return sim.display(m, pose, frame, t)[0]
    finally:
        m.release()


@pytest.mark.parametrize("name", FLOW_METHODS)
def test_flow_brings_the_moving_object_closer_to_the_truth(sim, name):
    """The pendulum mid-swing (fastest), shown 2 frame intervals after the frame: with flow, the
    pixels where the ground truth shows it, and the whole view, are nearer the truth."""
    scene = sim.scene
    swing = next(o for o in scene.objects if o.name == "pendulum").animation
    t_frame = (np.pi - swing.phase) / swing.speed     # the bob passes the bottom, at full speed
    pose = _pendulum_pose(scene, t_frame)
    frame = sim.frame_at(t_frame, pose)
    t_show = t_frame + 0.2
    gt = sim.ground_truth(pose, t_show)
    index = next(i for i, o in enumerate(scene.objects) if o.name == "pendulum")
    mask = {"object": sim.ground_truth_moving() == index}
    assert mask["object"].sum() > 200
    score = {motion: masked_metrics(gt, _show(sim, name, {"motion": motion}, pose, frame, t_show), mask)
             for motion in ("static", "flow")}
    assert score["flow"]["psnr_object"] > score["static"]["psnr_object"] + 1.0, score
    assert score["flow"]["psnr"] > score["static"]["psnr"], score


@pytest.mark.parametrize("name", ("rotation", "gridwarp", "proxy"))
def test_without_time_or_motion_flow_changes_nothing(sim, name):
    scene = sim.scene
    pose = _pendulum_pose(scene, 3.0)
    frame = sim.frame_at(3.0, pose)
    for t in (3.0, 2.9):    # at the frame's own time, and before it (never back in time)
        np.testing.assert_array_equal(_show(sim, name, {"motion": "flow"}, pose, frame, t),
                                      _show(sim, name, {"motion": "static"}, pose, frame, t))
    assert sim.textures.flow is not None and sim.textures.flow.count > 0


def test_the_textures_are_restored_for_the_methods_that_show_the_frame_as_decoded(sim):
    scene = sim.scene
    pose = _pendulum_pose(scene, 4.0)
    frame = sim.frame_at(4.0, pose)
    before = np.frombuffer(sim.textures.y.read(alignment=1), np.uint8).copy()
    static = sim.make_method("rotation")
    flow = sim.make_method("rotation", motion="flow")
    try:
        reference = sim.display(static, pose, frame, 4.2)[0]
        moved = sim.display(flow, pose, frame, 4.2)[0]
        assert sim.textures.extrapolated is not None
        assert not np.array_equal(moved, reference)
        np.testing.assert_array_equal(sim.display(static, pose, frame, 4.2)[0], reference)
        assert sim.textures.extrapolated is None
        np.testing.assert_array_equal(np.frombuffer(sim.textures.y.read(alignment=1), np.uint8), before)
    finally:
        static.release()
        flow.release()


def test_proxy_flow_points_carve_as_when_carving_every_pixel(sim):
    """The moved pixels drawn as points with the proxies: the default carving gives carve_all's
    image (the path it replaced), bit for bit, colour and alpha."""
    scene = sim.scene
    swing = next(o for o in scene.objects if o.name == "pendulum").animation
    t_frame = (np.pi - swing.phase) / swing.speed
    pose = _pendulum_pose(scene, t_frame)
    frame = sim.frame_at(t_frame, pose)
    images = {}
    for carve_all in (False, True):
        m = sim.make_method("proxy", motion="flow", carve_all=carve_all)
        try:
            sim.target.begin()
            m.render(pose, frame, sim.textures, t_frame + 0.2)
            images[carve_all] = sim.target.read().copy()
            assert m.last_points > 0
        finally:
            m.release()
    np.testing.assert_array_equal(images[False], images[True])
