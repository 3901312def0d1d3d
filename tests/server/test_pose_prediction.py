"""Head-pose predictors (server/pose_prediction.py) on motions each should follow exactly."""
import math

import numpy as np
import pytest

from pibr.protocol.errors import ConfigError
from pibr.protocol.pose import Pose, quat_angle, quat_from_axis_angle
from pibr.server.pose_prediction import MAX_EXTRAPOLATION_S, make_predictor


def _pose(t, accel=0.0, spin=1.0):
    """Moving along x at 0.5 m/s (plus ``accel`` m/s^2), turning about y at ``spin`` rad/s."""
    return Pose.make((0.5 * t + 0.5 * accel * t * t, 1.6, 0.0), quat_from_axis_angle((0, 1, 0), spin * t))


def _feed(name, times, **kw):
    p = make_predictor(name)
    for t in times:
        p.update(t, _pose(t, **kw))
    return p


def _error(guess, truth):
    return float(np.linalg.norm(guess.p - truth.p)), float(quat_angle(guess.q, truth.q))


@pytest.mark.parametrize("name", ["velocity", "accel", "kalman"])
def test_constant_velocity_is_followed(name):
    times = np.arange(0, 2, 1 / 30)
    p = _feed(name, times)
    pos, ang = _error(p.predict(0.128), _pose(times[-1] + 0.128))
    assert pos < 1e-3 and ang < math.radians(0.1)
    none_pos, none_ang = _error(_feed("none", times).predict(0.128), _pose(times[-1] + 0.128))
    assert none_pos > 0.06 and none_ang > math.radians(7)   # 0.5 m/s and 57 deg/s for 128 ms


def test_constant_acceleration_needs_the_second_order():
    times = np.arange(0, 2, 1 / 30)
    truth = _pose(times[-1] + 0.2, accel=2.0)
    accel = _error(_feed("accel", times, accel=2.0).predict(0.2), truth)[0]
    velocity = _error(_feed("velocity", times, accel=2.0).predict(0.2), truth)[0]
    assert accel < 1e-6 and velocity > 0.03


def test_the_kalman_filter_takes_q_and_minus_q_as_one_rotation():
    times = np.arange(0, 2, 1 / 30)
    p = make_predictor("kalman")
    for k, t in enumerate(times):
        pose = _pose(t)
        if k % 2:   # every other quaternion sent with the opposite sign: the same rotation
            pose = Pose.make(pose.p, -np.asarray(pose.q))
        p.update(t, pose)
    assert _error(p.predict(0.1), _pose(times[-1] + 0.1))[1] < math.radians(0.1)


def test_limits_and_names():
    p = _feed("velocity", [0.0, 0.1])
    assert p.predict(10.0).p[0] == pytest.approx(0.5 * (0.1 + MAX_EXTRAPOLATION_S))
    with pytest.raises(ValueError, match="no pose"):
        make_predictor("kalman").predict(0.1)
    with pytest.raises(ConfigError, match="unknown pose predictor 'psychic'"):
        make_predictor("psychic")


@pytest.mark.parametrize("name", ["velocity", "kalman"])
def test_an_earlier_time_starts_a_new_timeline(name):
    """A real-clock client's warm-up poses and its ticks' poses count time from different zeros:
    a pose earlier than the last starts the history over instead of being dropped for good."""
    p = _feed(name, np.arange(10, 12, 1 / 30))
    later = np.arange(0, 1, 1 / 30)
    for t in later:
        p.update(t, _pose(t))
    pos, ang = _error(p.predict(0.1), _pose(later[-1] + 0.1))
    assert pos < 1e-3 and ang < math.radians(0.1)
