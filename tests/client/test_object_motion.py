"""Client-side extrapolation of moving objects from the transforms the frames carried, at its
numerical extremes: reversals, stops, half-turns per frame, lost frames."""
import math

import numpy as np
import pytest

from pibr.client.object_motion import (ACCEL_LIMIT, ObjectPlacer, PoseHistory, damped_horizon, extrapolate, rotation_exp,
                                       rotation_log)
from pibr.protocol.errors import ConfigError
from pibr.protocol.object_poses import ObjectPoses
from pibr.protocol.pose import quat_from_axis_angle, quat_to_matrix
from pibr.scenes.animation import Animation

DT = 0.1                 # frame interval, seconds
HORIZON = 3 * DT


def _rigid(angle=0.0, axis=(0, 1, 0), position=(0, 0, 0)) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = quat_to_matrix(quat_from_axis_angle(axis, angle))
    m[:3, 3] = position
    return m


def _track(motion, times) -> list:
    return [(t, motion(t)) for t in times]


def _angle_between(a, b) -> float:
    return float(np.linalg.norm(rotation_log(a[:3, :3] @ b[:3, :3].T)))


def test_rotation_log_and_exp_at_zero_and_near_pi():
    for angle in (0.0, 1e-9, 1e-4, 1.0, math.pi - 1e-6, math.pi - 1e-12, math.pi):
        for axis in ((0, 1, 0), (1, -2, 0.5)):
            r = quat_to_matrix(quat_from_axis_angle(axis, angle))
            w = rotation_log(r)
            assert np.linalg.norm(w) == pytest.approx(angle, abs=2e-8)
            np.testing.assert_allclose(rotation_exp(w), r, atol=1e-12)
            if 1e-6 < angle < math.pi - 1e-6:   # the axis is determined (at pi up to its sign)
                np.testing.assert_allclose(w / angle, np.array(axis) / np.linalg.norm(axis), atol=1e-6)


def test_constant_velocity_and_spin_are_extrapolated_exactly():
    """An object spinning about an off-centre pivot while its centre travels in a line: velocity
    (about the object's centre) is exact; static lags by what moved."""
    centre = np.array([1.0, 0.5, -2.0])

    def motion(t):
        m = _rigid(1.3 * t, (0.3, 1, 0.2))
        m[:3, 3] = centre + np.array([2.0, 0.0, -1.0]) * t - m[:3, :3] @ centre   # centre moves linearly
        return m

    track = _track(motion, [0.0, DT, 2 * DT])
    for t in (2 * DT, 2.5 * DT, 4.5 * DT):
        got = extrapolate(track, t, "velocity", HORIZON, centre)
        np.testing.assert_allclose(got, motion(t), atol=1e-12)
    static = extrapolate(track, 4.5 * DT, "static", HORIZON, centre)
    np.testing.assert_array_equal(static, motion(2 * DT))
    accel = extrapolate(track, 4.5 * DT, "accel", HORIZON, centre)
    np.testing.assert_allclose(accel, motion(4.5 * DT), atol=1e-12)


def test_second_order_follows_a_constant_acceleration_within_its_limit():
    """A steady acceleration is followed exactly while its correction stays within ACCEL_LIMIT of
    the first order's displacement; from rest (all acceleration) it is limited to that."""
    def motion(t):
        return _rigid(position=(4.0 * t + 1.5 * t * t, 0, 0))

    track = _track(motion, [0.0, DT, 2 * DT])
    t = 2 * DT + 0.25
    assert extrapolate(track, t, "accel", HORIZON)[0, 3] == pytest.approx(motion(t)[0, 3], abs=1e-12)
    assert extrapolate(track, t, "velocity", HORIZON)[0, 3] < motion(t)[0, 3] - 0.1

    def from_rest(t):
        return _rigid(position=(10.0 * t * t, 0, 0))

    track = _track(from_rest, [0.0, DT, 2 * DT])
    x_new, first = from_rest(2 * DT)[0, 3], extrapolate(track, t, "velocity", HORIZON)[0, 3]
    got = extrapolate(track, t, "accel", HORIZON)[0, 3]
    assert got == pytest.approx(x_new + (1.0 + ACCEL_LIMIT) * (first - x_new))   # limited
    assert first < got < from_rest(t)[0, 3]


def test_a_reversal_between_frames_overshoots_by_at_most_the_capped_horizon():
    """Moving +x at 2 m/s until t = 0.2, then back at the same speed: the frames at 0.1 and 0.2
    say +x, so velocity overshoots -- but never by more than 1.5 horizons of travel."""
    def x(t):
        return 2.0 * t if t <= 0.2 else 0.4 - 2.0 * (t - 0.2)

    track = _track(lambda t: _rigid(position=(x(t), 0, 0)), [0.1, 0.2])
    for t in (0.25, 0.45, 0.8, 5.0):
        got = extrapolate(track, t, "velocity", HORIZON)[0, 3]
        assert 0.4 < got <= 0.4 + 2.0 * 1.5 * HORIZON + 1e-12
    # once the next frame shows the way back, velocity follows it
    track = _track(lambda t: _rigid(position=(x(t), 0, 0)), [0.1, 0.2, 0.3])
    assert extrapolate(track, 0.35, "velocity", HORIZON)[0, 3] < x(0.3)


def test_a_stop_between_frames_and_a_start():
    """The travel animation: after a stop, velocity overshoots for a frame and then holds
    exactly still; on a start it lags one frame and then tracks exactly."""
    travel = Animation("travel", axis=(1, 0, 0), speed=2.0, amplitude=1.0, rest=1.0)   # stops at t = 1.5
    times = [1.3, 1.4, 1.5]        # the last frame lands right on the stop
    over = extrapolate(_track(travel.matrix, times), 1.75, "velocity", HORIZON)[0, 3]
    assert over == pytest.approx(1.0 + 2.0 * 0.25)                               # still moving, bounded
    still = extrapolate(_track(travel.matrix, [1.4, 1.5, 1.6]), 1.8, "velocity", HORIZON)[0, 3]
    assert still == pytest.approx(1.0, abs=1e-12) == travel.matrix(1.8)[0, 3]
    # the second order sees a huge deceleration there; limited, it does not throw the cart back
    for t in (1.7, 1.8, 2.0, 5.0):
        assert extrapolate(_track(travel.matrix, [1.4, 1.5, 1.6]), t, "accel", HORIZON)[0, 3] == \
            pytest.approx(1.0, abs=1e-12)
    # starting at t = 2.5: frames at 2.4 and 2.5 are at rest, then it tracks from two moving frames on
    assert extrapolate(_track(travel.matrix, [2.4, 2.5]), 2.7, "velocity", HORIZON)[0, 3] == pytest.approx(1.0)
    np.testing.assert_allclose(extrapolate(_track(travel.matrix, [2.6, 2.7]), 2.9, "velocity", HORIZON),
                               travel.matrix(2.9), atol=1e-12)
    # right after the start the second order overshoots, by at most ACCEL_LIMIT of the way
    x = extrapolate(_track(travel.matrix, [2.4, 2.5, 2.6]), 2.8, "accel", HORIZON)[0, 3]
    assert travel.matrix(2.8)[0, 3] > x >= 0.8 - (1.0 + ACCEL_LIMIT) * 2.0 * 0.2 - 1e-12


@pytest.mark.parametrize("turn", [0.9 * math.pi, 0.99 * math.pi, math.pi - 1e-7])
def test_rotation_near_half_a_turn_per_frame(turn):
    """Spinning by nearly pi per frame interval: the relative rotation is read the right way
    round and the spin continues correctly 2.5 intervals on."""
    spin = Animation("spin", axis=(0.2, 1.0, -0.1), speed=turn / DT, pivot=(0.5, 0, 0))
    centre = np.array([0.5, 0.0, 0.0])
    track = _track(spin.matrix, [0.0, DT])
    got = extrapolate(track, 2.5 * DT, "velocity", HORIZON, centre)
    assert _angle_between(got, spin.matrix(2.5 * DT)) < 1e-6
    np.testing.assert_allclose(got[:3, 3], spin.matrix(2.5 * DT)[:3, 3], atol=1e-6)


def test_rotation_past_half_a_turn_per_frame_aliases_but_stays_a_rotation():
    """1.1 pi per frame looks exactly like 0.9 pi the other way (sampling cannot tell them
    apart): extrapolated as that, a valid rigid motion, bounded by the horizon."""
    fast = Animation("spin", axis=(0, 1, 0), speed=1.1 * math.pi / DT)
    backwards = Animation("spin", axis=(0, 1, 0), speed=-0.9 * math.pi / DT)
    got = extrapolate(_track(fast.matrix, [0.0, DT]), 2.5 * DT, "velocity", HORIZON)
    assert _angle_between(got, backwards.matrix(2.5 * DT)) < 1e-6
    np.testing.assert_allclose(got[:3, :3] @ got[:3, :3].T, np.eye(3), atol=1e-12)


@pytest.mark.parametrize("mode", ["velocity", "accel"])
def test_lost_frames_never_fly_off(mode):
    """The newest frame is 3 to 200 intervals old: the extrapolation slows after the horizon and
    stays within 1.5 horizons of travel of the last place, and finite, however long it waits."""
    def motion(t):   # 5 m/s and accelerating, spinning 6 rad/s
        m = _rigid(6.0 * t, (0, 0, 1))
        m[:3, 3] = (5.0 * t + 20.0 * t * t, 0, 0)
        return m

    track = _track(motion, [0.0, DT, 2 * DT])
    last = motion(2 * DT)[0, 3]
    speed = 5.0 + 40.0 * 2 * DT            # the speed at the last frame
    xs = [extrapolate(track, 2 * DT + k * DT, mode, HORIZON)[0, 3] for k in (3, 4, 6, 10, 50, 200)]
    assert np.all(np.isfinite(xs)) and np.all(np.diff(xs) >= -1e-12)   # slowing, never turning back
    bound = 1.5 * HORIZON * speed if mode == "velocity" else 1.5 * HORIZON * (speed + 40.0 * 1.5 * HORIZON)
    assert xs[-1] - last <= bound
    assert xs[-1] - xs[-2] < 1e-9                                     # come to rest
    assert damped_horizon(1e9, HORIZON) == pytest.approx(1.5 * HORIZON)
    assert damped_horizon(-5.0, HORIZON) == -HORIZON
    assert damped_horizon(0.2, HORIZON) == 0.2


def test_history_keeps_the_newest_per_object_and_restarts_on_a_new_timeline():
    rest = np.stack([np.eye(4), _rigid(position=(1, 2, 3))])
    bounds = np.array([[[0, 0, 0], [1, 1, 1]], [[-1, -1, -1], [1, 1, 1]]], float)
    h = PoseHistory(rest, bounds, depth=3)
    np.testing.assert_allclose(h.centre(0), [0.5, 0.5, 0.5])
    np.testing.assert_allclose(h.centre(1), [1, 2, 3])
    for k in range(5):
        h.add(k * DT, ObjectPoses.from_matrices([1], [_rigid(position=(k, 0, 0))]))
    assert [t for t, _ in h.track(1)] == pytest.approx([0.2, 0.3, 0.4]) and h.track(0) == []
    h.add(0.4, ObjectPoses.from_matrices([1], [_rigid(position=(9, 9, 9))]))      # a repeat is ignored
    assert h.track(1)[-1][1][0, 3] == 4
    h.add(0.05, ObjectPoses.from_matrices([1], [_rigid()]))                       # time went back
    assert [t for t, _ in h.track(1)] == [0.05] and h.newest_time == 0.05


def test_placer_modes_and_the_oracle_only_with_a_model():
    h = PoseHistory()
    h.add(0.0, ObjectPoses.from_matrices([0], [_rigid(position=(0, 0, 0))]))
    h.add(DT, ObjectPoses.from_matrices([0], [_rigid(position=(1, 0, 0))]))
    assert ObjectPlacer(h, "velocity", DT).motions([0, 3], 0.15)[0][0, 3] == pytest.approx(1.5)
    assert 3 not in ObjectPlacer(h, "velocity", DT).motions([0, 3], 0.15)   # nothing received: at rest
    assert ObjectPlacer(h, "static", DT).motions([0], 0.15)[0][0, 3] == 1.0
    oracle = ObjectPlacer(h, "oracle", DT, oracle=lambda i, t: _rigid(position=(10 * t, 0, 0)))
    assert oracle.motions([0], 0.15)[0][0, 3] == pytest.approx(1.5)
    with pytest.raises(ConfigError, match="only the benchmarks have"):
        ObjectPlacer(h, "oracle", DT)
    with pytest.raises(ConfigError, match="unknown motion extrapolation 'warp'"):
        ObjectPlacer(h, "warp", DT)
