import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pibr.protocol.errors import InvalidPose
from pibr.protocol.pose import (Pose, quat_from_axis_angle, quat_from_euler, quat_from_matrix, quat_multiply,
                                quat_normalize, quat_rotate, quat_slerp, quat_to_matrix)

from .pose_reference import left_handed_to_right_handed

quats = st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(lambda q: np.linalg.norm(q) > 1e-3)


def test_normalise_makes_unit_and_canonical_sign():
    q = quat_normalize([-2.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(q, [1, 0, 0, 0])
    q = quat_normalize(np.array([[0.0, 3.0, 4.0, 0.0], [-1.0, 1.0, 1.0, 1.0]]))
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0)
    assert np.all(q[:, 0] >= 0)


@pytest.mark.parametrize("bad", [[0, 0, 0, 0], [1e-9, 0, 0, 0], [np.nan, 0, 0, 1], [np.inf, 0, 0, 0]])
def test_zero_or_nonfinite_quaternion_rejected(bad):
    with pytest.raises(InvalidPose):
        quat_normalize(bad)
    with pytest.raises(InvalidPose):
        Pose.make((0, 0, 0), bad)


def test_nan_position_rejected():
    with pytest.raises(InvalidPose, match="NaN"):
        Pose.make((0, np.nan, 0))


@settings(max_examples=200, deadline=None)
@given(quats)
def test_matrix_round_trip(q):
    q = quat_normalize(q)
    m = quat_to_matrix(q)
    np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(m) == pytest.approx(1.0)
    back = quat_from_matrix(m)
    # q and -q are the same rotation; the sign is canonical except where w is ~0
    assert min(np.abs(back - q).max(), np.abs(back + q).max()) < 1e-9


def test_axis_angle_right_hand_rule():
    q = quat_from_axis_angle((0, 1, 0), np.pi / 2)  # yaw left by 90 degrees
    np.testing.assert_allclose(quat_rotate(q, [0, 0, -1]), [-1, 0, 0], atol=1e-12)


def test_euler_yaw_pitch():
    q = quat_from_euler(np.radians([90, 0, 0]), "yxz")
    np.testing.assert_allclose(quat_rotate(q, [0, 0, -1]), [-1, 0, 0], atol=1e-12)
    q = quat_from_euler(np.radians([0, 30, 0]), "yxz")  # pitch up
    f = quat_rotate(q, [0, 0, -1])
    assert f[1] == pytest.approx(np.sin(np.radians(30)))


def test_slerp_midpoint_and_ends():
    a = quat_from_axis_angle((0, 1, 0), 0.0)
    b = quat_from_axis_angle((0, 1, 0), 1.0)
    np.testing.assert_allclose(quat_slerp(a, b, 0.5), quat_from_axis_angle((0, 1, 0), 0.5), atol=1e-12)
    np.testing.assert_allclose(quat_slerp(a, b, 0.0), a, atol=1e-12)
    np.testing.assert_allclose(quat_slerp(a, -b, 1.0), b, atol=1e-12)  # short way round
    np.testing.assert_allclose(quat_slerp(a, a, 0.3), a, atol=1e-12)   # identical ends


def test_pose_compose_inverse_and_view_matrix():
    rng = np.random.default_rng(0)
    for _ in range(20):
        a = Pose.make(rng.normal(size=3), rng.normal(size=4))
        b = Pose.make(rng.normal(size=3), rng.normal(size=4))
        np.testing.assert_allclose(a.compose(b).matrix(), a.matrix() @ b.matrix(), atol=1e-12)
        np.testing.assert_allclose(a.compose(a.inverse()).matrix(), np.eye(4), atol=1e-12)
        np.testing.assert_allclose(a.view_matrix() @ a.matrix(), np.eye(4), atol=1e-12)


def test_look_at_points_minus_z_at_target():
    p = Pose.look_at((1, 2, 3), (4, 2, 3))
    np.testing.assert_allclose(p.forward(), [1, 0, 0], atol=1e-12)
    up = Pose.look_at((0, 0, 0), (0, 5, 0))  # straight up: any roll, still valid
    np.testing.assert_allclose(up.forward(), [0, 1, 0], atol=1e-12)


def test_left_handed_conversion():
    # A Unity camera at (1, 2, 3) with yaw +90 degrees (turning right in Unity: +Z forward -> +X).
    half = np.radians(90) / 2
    unity_q = np.array([np.cos(half), 0, np.sin(half), 0])  # (w, x, y, z) about +Y, left-handed
    p, q = left_handed_to_right_handed([1, 2, 3], unity_q)
    np.testing.assert_allclose(p, [1, 2, -3])
    # Unity forward is +Z rotated to +X; in pibr the camera looks along -Z: it must look along +X too.
    np.testing.assert_allclose(quat_rotate(quat_normalize(q), [0, 0, -1]), [1, 0, 0], atol=1e-12)
    # Handedness flips are involutions.
    p2, q2 = left_handed_to_right_handed(p, q)
    np.testing.assert_allclose(p2, [1, 2, 3])
    np.testing.assert_allclose(q2, unity_q)


def test_pose_array_round_trip_and_shape_errors():
    a = Pose.make((1, 2, 3), (0.5, 0.5, 0.5, 0.5))
    assert Pose.from_array(a.as_array()) == a
    with pytest.raises(InvalidPose, match=r"shape \(7,\)"):
        Pose.from_array(np.zeros(6))
    with pytest.raises(InvalidPose, match=r"shape \(3,\)"):
        Pose.make((1, 2))
    assert quat_multiply([1, 0, 0, 0], [0, 1, 0, 0]).tolist() == [0, 1, 0, 0]


def test_normalise_survives_components_whose_squares_overflow():
    q = quat_normalize([1.0, 0.0, 1e308, 0.0])
    assert np.allclose(q, [0.0, 0.0, 1.0, 0.0]) and np.all(np.isfinite(q))
    batch = quat_normalize([[1e308, 1e308, 0.0, 0.0], [0.0, 2.0, 0.0, 0.0]])
    assert np.allclose(batch, [[np.sqrt(0.5), np.sqrt(0.5), 0, 0], [0, 1, 0, 0]])
    assert Pose.make((0, 0, 0), (-1e308, 0, 0, 0)).orientation == (1.0, 0.0, 0.0, 0.0)
