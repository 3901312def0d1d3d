"""The scene's analytic animation (server and benchmarks only; the client never has it)."""
import math

import numpy as np
import pytest

from pibr.protocol.errors import SceneError
from pibr.scenes.animation import ANIMATION_KINDS, Animation


def _is_rigid(m):
    return np.allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3)) and np.isclose(np.linalg.det(m[:3, :3]), 1.0)


@pytest.mark.parametrize("kind", ANIMATION_KINDS)
def test_every_kind_is_rigid_and_continuous(kind):
    a = Animation(kind, axis=(0, 0, 2), speed=1.5, pivot=(1, 2, 3), radius=0.7, amplitude=0.4, phase=0.1, rest=0.3)
    assert a.axis == (0.0, 0.0, 1.0)
    ts = np.linspace(-3.0, 7.0, 2001)
    ms = np.stack([a.matrix(t) for t in ts])
    assert all(_is_rigid(m) for m in ms[::50])
    # continuous: no jump between neighbouring samples beyond what the fastest motion covers
    step = np.abs(np.diff(ms, axis=0)).max()
    assert step < 2.0 * (ts[1] - ts[0]) * max(1.5, 1.5 * 0.7, 0.4 * 1.5 * 4)


def test_spin_about_its_pivot_and_swing_reverses():
    spin = Animation("spin", axis=(0, 1, 0), speed=2.0, pivot=(1, 0, 0))
    m = spin.matrix(math.pi / 4)          # a quarter turn
    np.testing.assert_allclose(m[:3, 3] + m[:3, :3] @ [1, 0, 0], [1, 0, 0], atol=1e-12)   # the pivot stays
    np.testing.assert_allclose(m[:3, :3] @ [1, 0, 0], [0, 0, -1], atol=1e-12)
    swing = Animation("swing", axis=(1, 0, 0), speed=2.0, amplitude=0.3)
    angles = [math.atan2(swing.matrix(t)[2, 1], swing.matrix(t)[1, 1]) for t in np.linspace(0, math.pi, 9)]
    assert max(angles) == pytest.approx(0.3) and min(angles) == pytest.approx(-0.3)


def test_travel_rests_moves_at_constant_speed_and_returns():
    a = Animation("travel", axis=(1, 0, 0), speed=2.0, amplitude=4.0, rest=1.0, phase=0.0)
    # cycle: rest 1 s, out 2 s, rest 1 s, back 2 s = 6 s
    x = lambda t: a.matrix(t)[0, 3]
    assert [x(t) for t in (0.0, 0.99, 1.5, 3.0, 3.5, 4.0, 5.0, 6.0, 6.5)] == \
        pytest.approx([0.0, 0.0, 1.0, 4.0, 4.0, 4.0, 2.0, 0.0, 0.0])
    assert x(-1.0) == pytest.approx(2.0)                # periodic before 0 too
    shifted = Animation("travel", axis=(1, 0, 0), speed=2.0, amplitude=4.0, rest=1.0, phase=1.5)
    assert shifted.matrix(0.0)[0, 3] == pytest.approx(1.0)   # phase: seconds into the cycle
    np.testing.assert_array_equal(a.matrix(2.0)[:3, :3], np.eye(3))


@pytest.mark.parametrize("kwargs, message", [
    ({"kind": "wobble"}, "unknown animation kind 'wobble'"),
    ({"kind": "spin", "axis": (0, 0, 0)}, "axis must be a non-zero 3-vector of finite numbers"),
    ({"kind": "spin", "pivot": (0, float("nan"), 0)}, "pivot must be a 3-vector of finite numbers"),
    ({"kind": "slide", "speed": float("inf")}, "speed must be a finite number"),
    ({"kind": "travel", "speed": 0.0, "amplitude": 1.0}, "needs a positive speed"),
    ({"kind": "travel", "speed": 1.0, "amplitude": -1.0}, "needs a positive speed"),
    ({"kind": "spin", "rest": -0.5}, "rest must be >= 0"),
])
def test_bad_values_raise_scene_errors(kwargs, message):
    with pytest.raises(SceneError, match=message):
        Animation(**kwargs)
