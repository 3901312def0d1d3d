"""``proxy`` drawing both eyes of a stereo pair at once (render_pair): the images of each eye
drawn alone, one LoD selection for the pair's union frustum, and the client using it."""
import json

import numpy as np
import pytest

from pibr.bench.simulation import Simulation, bench_server_config, load_proxies
from pibr.client.lod_select import LodSelector
from pibr.protocol.frustum import eye_tangents
from pibr.protocol.messages import OutputConfig
from pibr.protocol.pose import Pose, quat_from_axis_angle
from pibr.protocol.proxy import ProxyObject, closed_box
from pibr.protocol.stereo import eye_pose
from pibr.scenes.registry import load_scene

pytestmark = pytest.mark.gl

W, H = 320, 180


@pytest.fixture(scope="module")
def sim():
    scene = load_scene("room")
    proxies, _ = load_proxies(scene, progress=False)
    s = Simulation(scene, bench_server_config((512, 512)), (W, H), proxies=proxies)
    yield s
    s.close()
    s.ctx.release()


def _poses(sim):
    """(head at display, head the frame was rendered at) for a few displacements, turns included."""
    o = sim.scene.viewer_origin
    turn = Pose.make(o.p, quat_from_axis_angle([0.0, 1.0, 0.0], 0.3))
    return [(o, o), (Pose.make(o.p + [0.15, 0.02, -0.1], o.q), o), (turn.compose(Pose.make((0.05, 0.0, 0.1))), turn)]


@pytest.mark.parametrize("options", [{}, {"lod_level": "proxy"}, {"inpaint": False}])
def test_a_pair_drawn_at_once_is_each_eye_drawn_alone(sim, options):
    """Each half of render_pair's image is that eye's render, but for pixels the two rasterisations
    round differently (the pair's clip space is squeezed into half the target): measured here at
    most 0.07 % of pixels, by at most 2/255 (the records' uv precision); at 960x540 0.02 %, a few
    of them at a silhouette. An object one eye may draw without its back faces and the other not
    is drawn for each eye apart (before, 1 % of pixels differed at the proxy level)."""
    m = sim.make_method("proxy", pair_at_once=True, **options)
    try:
        for head, rendered_at in _poses(sim):
            frame = sim.frame_at(0.0, rendered_at)
            left, right = eye_pose(head, "left", 64.0), eye_pose(head, "right", 64.0)
            assert m.shares_pair(left, right)
            (pair_l, holes_l), (pair_r, holes_r) = sim.display_pair_timed(m, left, right, frame, 0.0)[0]
            pair_primitives = m.last_primitives
            alone_l, own_l, _ = sim.display(m, left, frame, 0.0)
            primitives_l = m.last_primitives
            alone_r, own_r, _ = sim.display(m, right, frame, 0.0)
            for pair, alone in ((pair_l, alone_l), (pair_r, alone_r)):
                differ = np.abs(pair.astype(np.int16) - alone).max(axis=2)
                assert np.mean(differ > 0) < 0.002 and np.mean(differ > 8) < 0.0005
            assert abs(holes_l - own_l) < 0.002 and abs(holes_r - own_r) < 0.002
            assert not np.array_equal(pair_l, pair_r)   # two eyes, two images
            # the union frustum draws at least what either eye does, both eyes per proxy
            assert pair_primitives >= 2 * max(primitives_l, m.last_primitives) - 1e-9
    finally:
        m.release()


def test_which_pairs_are_drawn_at_once(sim):
    head = sim.scene.viewer_origin
    left, right = eye_pose(head, "left"), eye_pose(head, "right")
    m = sim.make_method("proxy", pair_at_once=True)
    try:
        assert m.shares_pair(left, right)
        assert not m.shares_pair(right, left)   # the left eye must be on the left
        assert not m.shares_pair(left, right.compose(Pose.make((0.0, 0.0, 0.0), quat_from_axis_angle([0, 1, 0], 0.01))))
        assert not m.shares_pair(left, head.compose(Pose.make((0.032, 0.02, 0.0))))   # not along x
        m.look_through(eye_tangents("left", (52.0, 42.0, 30.0, 33.0)))   # an eye's own frustum: one by one
        assert not m.shares_pair(left, right)
        m.look_through(None)
        assert m.shares_pair(left, right)
    finally:
        m.release()
    for options in ({"carve_all": True, "pair_at_once": True}, {"carve": False, "pair_at_once": True}, {}):
        other = sim.make_method("proxy", **options)   # the default: each eye alone
        try:
            assert not other.shares_pair(left, right)
        finally:
            other.release()


def _cube(centre, half: float) -> ProxyObject:
    lo, hi = np.asarray(centre, np.float64) - half, np.asarray(centre, np.float64) + half
    v, f = closed_box(lo, hi)
    return ProxyObject("cube", np.eye(4), False, np.stack([lo, hi]), (v, f), (v, f))


def test_the_union_frustum_holds_what_either_eye_sees():
    """At 90 degrees a side plane is x = z: a cube just right of the centre's frustum, inside the
    right eye's (whose plane is 5 cm further right), is drawn for the pair; one past the right
    eye's, for neither. Each object at the nearer eye's distance."""
    out = OutputConfig(320, 180, 90.0, 30.0)
    half = 0.05
    inside_right, beyond = _cube([4.025, 0.0, -4.0], 0.005), _cube([4.1, 0.0, -4.0], 0.005)
    sel = LodSelector([inside_right, beyond], out)
    centre = Pose.identity()
    right = centre.compose(Pose.make((half, 0.0, 0.0)))
    assert [s.index for s in sel.select(centre)] == []
    assert [s.index for s in sel.select(right)] == [0]
    union = sel.select(centre, half_baseline=half)
    assert [s.index for s in union] == [0]
    assert union[0].distance == pytest.approx(sel.select(right)[0].distance)
    # turned the other way, the left eye's side of the union
    mirrored = LodSelector([_cube([-4.025, 0.0, -4.0], 0.005)], out)
    assert [s.index for s in mirrored.select(centre, half_baseline=half)] == [0]
    assert mirrored.select(centre) == []


async def test_a_cyclops_client_draws_each_pair_at_once(tmp_path):
    """``--stereo cyclops --pair-at-once`` with proxy: both eyes drawn in one render_pair a tick
    (the pair's ms shared out evenly, so each tick's two records carry the same ms), each half
    recorded as its eye: every recorded image is nearer its own eye's ground truth than the other
    eye's."""
    from pibr.bench.evaluate import _frames
    from pibr.bench.groundtruth import GroundTruth
    from pibr.client.app import run_client
    from pibr.client.config import ClientConfig
    from pibr.client.recorder import read_records
    from pibr.server.config import ServerConfig

    from ..loopback import running_server

    out = tmp_path / "run"
    async with running_server(ServerConfig(port=0, scene="room", view_size=(192, 192), bitrate_kbps=3000)) as (
            _, host, port):
        result = await run_client(ClientConfig(host=host, port=port, trace="pred6dof-1", start_s=12.0, duration_s=0.5,
                                               rate_hz=30.0, methods=("proxy",), out_dir=str(out), width=160,
                                               height=96, progress="none", stereo="cyclops", ipd_mm=64.0,
                                               options={"pair_at_once": True}))
    assert result.ticks == 15
    info = json.load(open(out / "session.json"))
    assert info["methods"]["proxy"]["pair_drawn_at_once"] is True
    records = {eye: read_records(out / f"proxy.{eye}.records.csv") for eye in ("left", "right")}
    images = {eye: list(_frames(str(out / f"proxy.{eye}.lossless.avi"))) for eye in ("left", "right")}
    assert len(records["left"]) == len(records["right"]) == len(images["left"]) == 15
    gt = GroundTruth(load_scene("room"), 160, 96, 90.0)
    try:
        for k, (a, b) in enumerate(zip(records["left"], records["right"])):
            assert a["client_ms"] == b["client_ms"] and a["frame_id"] == b["frame_id"]
            if a["frame_id"] < 0:
                continue
            for eye, other, rec in (("left", "right", a), ("right", "left", b)):
                shown = images[eye][k].astype(np.float64)
                err = {}
                for name, r in ((eye, rec), (other, b if rec is a else a)):
                    pose = Pose.make([r["px"], r["py"], r["pz"]], [r["qw"], r["qx"], r["qy"], r["qz"]])
                    err[name] = np.mean(np.abs(gt.render(pose, r["scene_t"]) - shown))
                assert err[eye] < err[other]
    finally:
        gt.close()
