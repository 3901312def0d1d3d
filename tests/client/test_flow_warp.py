"""``flow`` extrapolation (client/flow_warp.py): moving pixels forward-warped along their flow to
the display time, the background made up behind them, bounded like the per-object extrapolation."""
import numpy as np
import pytest

from pibr.client.flow_warp import FILL_RING, FlowFrame
from pibr.client.object_motion import DEFAULT_HORIZON_FRAMES

H, W = 64, 96
BOX = (slice(20, 30), slice(10, 20))


def _frame(flow_value=(3.0, 1.0), box_distance=2.0, slack=0.0, **kw):
    """A wall at 5 m with a 10 x 10 box at ``box_distance`` moving by ``flow_value`` px per 0.1 s."""
    y = np.full((H, W), 50, np.uint8)
    u = np.full((H // 2, W // 2), 100, np.uint8)
    v = np.full((H // 2, W // 2), 150, np.uint8)
    dist = np.full((H, W), 5.0, np.float32)
    moving = np.zeros((H, W), bool)
    moving[BOX] = True
    y[BOX] = 200
    u[10:15, 5:10] = 30
    dist[BOX] = box_distance
    flow = np.zeros((H, W, 2), np.float32)
    flow[moving] = flow_value
    return FlowFrame(y, u, v, dist, flow, moving, scene_t=1.0, interval=0.1, depth_slack=slack, **kw), (y, u, v, dist)


def _full(ext, planes):
    """The whole view with the extrapolated rectangle pasted in: (y, u, v, distance)."""
    y, u, v, dist = (p.copy() for p in planes)
    x0, y0, w, h = ext.rect
    y[y0:y0 + h, x0:x0 + w] = ext.y
    u[y0 // 2:(y0 + h) // 2, x0 // 2:(x0 + w) // 2] = ext.u
    v[y0 // 2:(y0 + h) // 2, x0 // 2:(x0 + w) // 2] = ext.v
    dist[y0:y0 + h, x0:x0 + w] = ext.distance
    return y, u, v, dist


@pytest.mark.parametrize("steps, shift", [(1.0, (3, 1)), (2.0, (6, 2)), (2.5, (8, 3))])
def test_an_object_translating_by_a_known_flow_lands_where_expected(steps, shift):
    f, planes = _frame()
    ext = f.extrapolate(steps)
    y, u, v, dist = _full(ext, planes)
    # round half up: 2.5 * (3, 1) = (7.5, 2.5) -> (8, 3)
    expected = np.zeros((H, W), bool)
    expected[20 + shift[1]:30 + shift[1], 10 + shift[0]:20 + shift[0]] = True
    np.testing.assert_array_equal(y == 200, expected)
    np.testing.assert_array_equal(dist == 2.0, expected)
    # the vacated pixels show the wall behind, in colour and distance
    vacated = np.zeros((H, W), bool)
    vacated[BOX] = True
    vacated &= ~expected
    assert np.all(y[vacated] == 50) and np.allclose(dist[vacated], 5.0)
    assert np.all(u[~_dilated_blocks(expected)] == 100)
    # the moved pixels are the ones a point is drawn for, with their distance
    got = np.zeros((H, W), bool)
    got[ext.moved[:, 1], ext.moved[:, 0]] = True
    np.testing.assert_array_equal(got, expected)
    assert np.all(ext.moved_distance == 2.0)
    # outside the rectangle and away from the object nothing changed
    assert not ext.changed[_crop(ext, ~(expected | _dilate(vacated | expected, FILL_RING)))].any()


def _dilate(mask, r):
    out = mask.copy()
    for _ in range(r):
        g = out.copy()
        g[1:] |= out[:-1]
        g[:-1] |= out[1:]
        g[:, 1:] |= g[:, :-1].copy()
        g[:, :-1] |= g[:, 1:].copy()
        out = g
    return out


def _dilated_blocks(mask):
    """Chroma blocks (h / 2, w / 2) touching a dilated mask: where chroma may be mixed."""
    m = _dilate(mask, FILL_RING + 2)
    return m.reshape(H // 2, 2, W // 2, 2).any(axis=(1, 3))


def _crop(ext, mask):
    x0, y0, w, h = ext.rect
    return mask[y0:y0 + h, x0:x0 + w]


def test_zero_flow_or_no_time_changes_nothing():
    f, _ = _frame(flow_value=(0.0, 0.0))
    assert f.count == 0 and f.extrapolate(2.0) is None
    # an object at rest beside one that moves: its pixels and its surroundings stay as decoded
    y, u, v, dist = _frame()[1]
    moving = np.zeros((H, W), bool)
    moving[BOX] = True
    moving[40:50, 60:70] = True
    flow = np.zeros((H, W, 2), np.float32)
    flow[BOX] = (3.0, 1.0)
    ext = FlowFrame(y, u, v, dist, flow, moving, 1.0, 0.1).extrapolate(2.0)
    x0, y0, w, h = ext.rect
    assert y0 + h <= 38      # the resting object is outside what changed
    g, _ = _frame()
    assert g.count > 0
    assert g.extrapolate(0.0) is None and g.extrapolate(g.steps(1.0)) is None and g.steps(0.5) == 0.0


def test_extrapolation_over_many_intervals_stays_bounded():
    """A frame 10 intervals old is extrapolated at most 1.5 horizons (4.5 intervals), never further."""
    f, planes = _frame(flow_value=(2.0, 0.0))
    assert f.steps(1.0 + 0.3) == pytest.approx(3.0)           # full speed up to the horizon
    late = [f.steps(1.0 + k * 0.1) for k in (4, 6, 10, 100)]
    assert all(a < b for a, b in zip(late, late[1:]))            # still slowing down ...
    assert late[-1] <= 1.5 * DEFAULT_HORIZON_FRAMES + 1e-9       # ... towards 4.5 intervals
    ext = f.extrapolate(f.steps(1.0 + 100 * 0.1))
    y = _full(ext, planes)[0]
    cols = np.nonzero((y == 200).any(axis=0))[0]
    assert cols.min() - 10 <= 2.0 * 1.5 * DEFAULT_HORIZON_FRAMES + 0.5


def test_a_static_occluder_in_front_stays_in_front_and_the_made_up_background_yields():
    f, planes = _frame(flow_value=(6.0, 0.0))
    y, u, v, dist = planes
    # a pillar at 1 m (in front of the box at 2 m) right of the box
    pillar = (slice(0, H), slice(24, 27))
    y2, d2 = y.copy(), dist.copy()
    y2[pillar], d2[pillar] = 10, 1.0
    moving = np.zeros((H, W), bool)
    moving[BOX] = True
    flow = np.zeros((H, W, 2), np.float32)
    flow[moving] = (6.0, 0.0)
    g = FlowFrame(y2, u, v, d2, flow, moving, 1.0, 0.1)
    out = _full(g.extrapolate(1.0), (y2, u, v, d2))[0]
    assert np.all(out[pillar] == 10)                             # the pillar hides the box's far end
    assert np.all(out[20:30, 16:24] == 200)                      # the rest of the box moved


def test_within_the_depth_transports_error_the_moving_object_wins():
    """With 8-bit disparity an object 2 % in front of the wall looks no nearer than it: the slack
    lets it cover the wall; without slack the wall (nearer by noise) would hide it."""
    y = np.full((H, W), 50, np.uint8)
    u = np.full((H // 2, W // 2), 128, np.uint8)
    dist = np.full((H, W), 4.9, np.float32)      # the wall, read nearer than the object by noise
    moving = np.zeros((H, W), bool)
    moving[BOX] = True
    y[BOX] = 200
    dist[BOX] = 5.0
    flow = np.zeros((H, W, 2), np.float32)
    flow[moving] = (8.0, 0.0)
    shown = {}
    for slack in (0.0, 0.01):
        f = FlowFrame(y, u, u, dist, flow, moving, 1.0, 0.1, depth_slack=slack)
        shown[slack] = _full(f.extrapolate(1.0), (y, u, u, dist))[0][20:30, 22:28]   # past the ring
    assert np.all(shown[0.01] == 200) and np.all(shown[0.0] == 50)


def test_a_stretching_object_has_no_cracks():
    """A flow that grows across the object by 1.5 px per pixel leaves one-pixel gaps between its
    splatted pixels; they are closed."""
    y = np.full((H, W), 50, np.uint8)
    u = np.full((H // 2, W // 2), 128, np.uint8)
    dist = np.full((H, W), 5.0, np.float32)
    moving = np.zeros((H, W), bool)
    moving[20:30, 10:20] = True
    y[moving] = 200
    dist[moving] = 2.0
    flow = np.zeros((H, W, 2), np.float32)
    xs = np.indices((H, W))[1]
    flow[..., 0] = np.where(moving, 0.5 * (xs - 9), 0.0)    # one step: pixel 9 + k goes to 9 + 1.5 k
    f = FlowFrame(y, u, u, dist, flow, moving, 1.0, 0.1)
    out = _full(f.extrapolate(1.0), (y, u, u, dist))[0]
    assert np.all(out[20:30, 11:25] == 200)


def test_bad_shapes_are_refused():
    y = np.zeros((H, W), np.uint8)
    u = np.zeros((H // 2, W // 2), np.uint8)
    with pytest.raises(ValueError, match="must match the luma"):
        FlowFrame(y, u, u, np.zeros((H, W)), np.zeros((H, W, 3)), np.zeros((H, W), bool), 0.0, 0.1)
    with pytest.raises(ValueError, match="size must be even"):
        FlowFrame(y[:-1], u, u, np.zeros((H - 1, W)), np.zeros((H - 1, W, 2)), np.zeros((H - 1, W), bool), 0.0, 0.1)
    with pytest.raises(ValueError, match="positive interval"):
        FlowFrame(y, u, u, np.zeros((H, W)), np.zeros((H, W, 2)), np.zeros((H, W), bool), 0.0, 0.0)
