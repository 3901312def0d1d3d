"""Every method draws through an eye's asymmetric frustum (Method.look_through), and back."""
import numpy as np
import pytest

from pibr.bench.simulation import Simulation, bench_server_config, load_proxies
from pibr.client.methods import method_names
from pibr.protocol.frustum import eye_tangents, symmetric
from pibr.protocol.pose import Pose
from pibr.scenes.registry import load_scene

pytestmark = pytest.mark.gl

W, H = 160, 90
LEFT_EYE = eye_tangents("left", (52.0, 38.0, 40.0, 50.0))


@pytest.fixture(scope="module")
def sim():
    scene = load_scene("room")
    proxies, _ = load_proxies(scene, progress=False)
    s = Simulation(scene, bench_server_config((256, 256)), (W, H), proxies=proxies, keep_distances=True)
    yield s
    s.close()
    s.ctx.release()


def _psnr(a, b) -> float:
    mse = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return 10 * np.log10(255.0 ** 2 / max(mse, 1e-9))


@pytest.mark.parametrize("name", method_names())
def test_every_method_draws_through_an_eyes_frustum_and_back(sim, name):
    """Shown from the frame's own pose, each method's image is the ground truth through the frustum
    it was told to look through, far closer to it than to the symmetric view (measured: 7-16 dB
    closer); told None again, it is the symmetric one's."""
    o = sim.scene.viewer_origin
    pose = Pose.make(o.p, o.q)
    frame = sim.frame_at(0.0, pose)
    through, straight = sim.ground_truth(pose, 0.0, LEFT_EYE), sim.ground_truth(pose, 0.0)
    m = sim.make_method(name)
    try:
        before, _, _ = sim.display(m, pose, frame, 0.0)
        m.look_through(LEFT_EYE)
        shown, _, _ = sim.display(m, pose, frame, 0.0)
        assert _psnr(shown, through) > _psnr(shown, straight) + 4.0
        m.look_through(None)
        back, _, _ = sim.display(m, pose, frame, 0.0)
        assert np.array_equal(back, before)
        assert _psnr(back, straight) > _psnr(back, through) + 4.0
    finally:
        m.release()


def test_the_symmetric_frustum_given_as_tangents_draws_the_same_image(sim):
    """One camera model: the symmetric frustum written out as tangents is the output's own
    (its projection from the tangents, not the field of view: at most a rounding apart)."""
    o = sim.scene.viewer_origin
    frame = sim.frame_at(0.0, o)
    pose = Pose.make(o.p + np.array([0.1, 0.0, -0.05]), o.q)
    for name in ("proxy", "gridwarp", "rotation"):
        m = sim.make_method(name)
        try:
            a, _, _ = sim.display(m, pose, frame, 0.0)
            m.look_through(symmetric(90.0, W, H))
            b, _, _ = sim.display(m, pose, frame, 0.0)
        finally:
            m.release()
        differ = np.abs(a.astype(np.int16) - b).max(axis=2)
        assert np.mean(differ > 2) < 0.002, name
