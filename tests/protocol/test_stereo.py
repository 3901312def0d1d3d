"""Eye poses and which eye a stereo session's frames are rendered from (protocol/stereo.py)."""
import numpy as np
import pytest

from pibr.protocol.errors import ConfigError
from pibr.protocol.pose import Pose, quat_from_axis_angle
from pibr.protocol.stereo import CENTRE, eye_pose, eye_poses, frame_eyes


def test_the_eyes_sit_half_the_ipd_along_the_heads_own_x_axis():
    turned = Pose.make((1.0, 1.6, -2.0), quat_from_axis_angle((0, 1, 0), np.pi / 2))   # looking along -x
    left, right = eye_poses(turned, 64.0)
    assert np.linalg.norm(left.p - right.p) == pytest.approx(0.064)
    # turned 90 degrees left about +y, the head's +x axis points along world -z
    np.testing.assert_allclose(left.p, [1.0, 1.6, -2.0 + 0.032], atol=1e-12)
    np.testing.assert_allclose(right.p, [1.0, 1.6, -2.0 - 0.032], atol=1e-12)
    np.testing.assert_allclose(left.q, turned.q)   # the eyes look where the head looks
    np.testing.assert_array_equal(eye_pose(turned, CENTRE).p, turned.p)


@pytest.mark.parametrize("ipd", [0, -5, 150, float("nan"), "wide"])
def test_an_impossible_ipd_is_refused_by_name(ipd):
    with pytest.raises(ConfigError, match="interpupillary distance"):
        eye_poses(Pose.identity(), ipd)


def test_which_eye_each_server_tick_renders():
    assert [frame_eyes(None, k) for k in range(3)] == [(CENTRE,)] * 3
    assert [frame_eyes("cyclops", k) for k in range(3)] == [(CENTRE,)] * 3
    assert [frame_eyes("alternate", k) for k in range(-1, 3)] == [("right",), ("left",), ("right",), ("left",)]
    assert frame_eyes("per-eye", 7) == ("left", "right")
    with pytest.raises(ConfigError, match="stereo reference"):
        frame_eyes("both", 0)
