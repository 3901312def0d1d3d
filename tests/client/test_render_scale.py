"""Quality levels on the GL thread: a method drawn at a lower resolution and upsampled, and
every level of the methods the deadline controller runs."""
import numpy as np
import pytest

from pibr.bench.metrics import psnr
from pibr.bench.simulation import Simulation, bench_server_config, load_proxies
from pibr.client.deadline import levels_for
from pibr.common.quality import Level
from pibr.client.render_scale import make_level, scaled_output
from pibr.common.link import SessionSchedule
from pibr.common.replay import display_samples
from pibr.protocol.messages import OutputConfig
from pibr.scenes.registry import load_scene

pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def sim():
    scene = load_scene("room")
    proxies, _ = load_proxies(scene)
    s = Simulation(scene, bench_server_config((256, 256)), (192, 108), proxies=proxies)
    yield s
    s.close()
    s.ctx.release()


@pytest.fixture(scope="module")
def sample(sim):
    return display_samples(sim.scene, "pred6dof-1", 31.0, 1.0, SessionSchedule.round_trip(30.0))[20]


def _draw(sim, sample, level):
    t_disp, display, t_render, rendered = sample
    frame = sim.frame_at(t_render, rendered)
    method = make_level(sim.ctx, level, sim.output, sim.session, sim.proxies, poses=sim.poses)
    try:
        rgb, holes, _ = sim.display(method, display, frame, t_disp)
        alpha = sim.target.read()[:, :, 3]
    finally:
        method.release()
    assert sim.ctx.error == "GL_NO_ERROR"
    return rgb, holes, alpha


def test_a_scaled_output_keeps_the_field_of_view():
    out = scaled_output(OutputConfig(960, 540, 90.0, 30.0), 1 / 3)
    assert (out.width, out.height, out.fov_deg, out.rate_hz) == (320, 180, 90.0, 30.0)
    assert (scaled_output(OutputConfig(32, 18, 60.0, 60.0), 0.25).width,) == (16,)


def test_a_scaled_level_draws_through_an_eyes_frustum(sim, sample):
    """A level drawn smaller looks through the eye's frustum too (the scaled output keeps its
    tangents, and look_through reaches the method inside)."""
    from pibr.protocol.frustum import eye_tangents

    eye = eye_tangents("left", (52.0, 42.0, 30.0, 33.0))
    assert scaled_output(OutputConfig(960, 540, 90.0, 30.0, eye), 0.5).frustum == eye
    t_disp, display, t_render, rendered = sample
    frame = sim.frame_at(t_render, rendered)
    truth = sim.ground_truth(display, t_disp, eye)
    for level in (Level("full", "proxy"), Level("1/2", "proxy", 0.5)):
        method = make_level(sim.ctx, level, sim.output, sim.session, sim.proxies, poses=sim.poses)
        try:
            straight, _, _ = sim.display(method, display, frame, t_disp)
            method.look_through(eye)
            through, _, _ = sim.display(method, display, frame, t_disp)
        finally:
            method.release()
        assert psnr(truth, through) > psnr(truth, straight) + 4.0, level.name


def test_half_resolution_upsampled_looks_like_full_resolution(sim, sample):
    full, full_holes, _ = _draw(sim, sample, Level("full", "rotation"))
    half, half_holes, alpha = _draw(sim, sample, Level("1/2", "rotation", 0.5))
    assert half.shape == full.shape == (108, 192, 3)
    assert set(np.unique(alpha)) <= {0, 255}           # coverage stays yes or no
    assert psnr(full, half) > 26.0                     # blurred, but the same picture (29.7 dB)
    assert abs(full_holes - half_holes) < 0.02
    noise = np.random.default_rng(0).integers(0, 256, full.shape, dtype=np.uint8)
    assert psnr(full, noise) < 12.0                    # (what another picture scores)


def test_the_cheapest_proxy_level_is_still_closer_to_proxy_than_rotation_is(sim, sample):
    levels = levels_for("proxy")
    top, _, _ = _draw(sim, sample, levels[0])
    low, _, _ = _draw(sim, sample, levels[-2])          # 1/4 scale, coarse proxies
    rotation, _, _ = _draw(sim, sample, levels[-1])     # the fallback
    assert psnr(top, low) > psnr(top, rotation) > 15.0  # 25.9 and 24.9 dB here


@pytest.mark.parametrize("method", ["proxy", "rotation", "none", "gridwarp"])
def test_every_level_draws(sim, sample, method):
    for level in levels_for(method):
        rgb, holes, _ = _draw(sim, sample, level)
        assert rgb.shape == (108, 192, 3) and 0.0 <= holes <= 1.0
        assert rgb.reshape(-1, 3).std(axis=0).max() > 5.0     # a picture, not a blank


def test_a_scaled_level_draws_its_lod_coarser_by_its_scale(sim):
    """The LoD target is an angle (client/lod_select.py); a level at half the pixels takes a
    target twice as coarse, its own or the user's, as the levels were measured with at 960x540."""
    from pibr.client.lod_select import switch_distances

    for options, target in (({}, 6.0), ({"lod_target_px": 4.0}, 4.0)):
        method = make_level(sim.ctx, Level("1/2", "proxy", 0.5), sim.output, sim.session, sim.proxies,
                            poses=sim.poses, **options)
        try:
            np.testing.assert_allclose(method.method.selector.thresholds, switch_distances(sim.proxies, 2 * target))
        finally:
            method.release()
        whole = make_level(sim.ctx, Level("full", "proxy"), sim.output, sim.session, sim.proxies, poses=sim.poses,
                           **options)
        try:
            np.testing.assert_allclose(whole.selector.thresholds, switch_distances(sim.proxies, target))
        finally:
            whole.release()
