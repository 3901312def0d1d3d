"""An eye's asymmetric frustum (protocol/frustum.py): rays, pixels and the GL projection agree,
the symmetric one is today's camera, and bad angles or tangents are refused by name."""
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pibr.protocol import frustum
from pibr.protocol.errors import ConfigError, MalformedMessage
from pibr.protocol.messages import Hello, OutputConfig
from pibr.server.coverage import camera_rays

QUEST_LIKE = (52.0, 42.0, 45.0, 52.0)   # outer, inner, up, down degrees: a headset's left eye

angles = st.floats(min_value=5.0, max_value=frustum.MAX_EDGE_DEG)


@settings(max_examples=60, deadline=None)
@given(outer=angles, inner=angles, up=angles, down=angles, w=st.integers(16, 64), h=st.integers(16, 64),
       eye=st.sampled_from(["left", "right"]))
def test_each_pixels_ray_lands_on_its_centre_and_the_projection_agrees(outer, inner, up, down, w, h, eye):
    t = frustum.eye_tangents(eye, (outer, inner, up, down))
    rays = frustum.rays(t, w, h) * 3.0      # points 3 m along each pixel's ray
    col, row = frustum.to_pixels(rays, t, w, h)
    gx, gy = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    assert np.allclose(col, gx.ravel(), atol=1e-6) and np.allclose(row, gy.ravel(), atol=1e-6)
    clip = np.c_[rays, np.ones(len(rays))] @ frustum.projection(t, 0.1, 100.0).T
    ndc = clip[:, :3] / clip[:, 3:]
    assert np.allclose((ndc[:, 0] + 1) * 0.5 * w, col, atol=1e-6)
    assert np.allclose((1 - ndc[:, 1]) * 0.5 * h, row, atol=1e-6)   # images top row first
    assert np.all(np.abs(ndc[:, 2]) < 1)


def test_the_symmetric_frustum_is_todays_camera():
    t = frustum.symmetric(90.0, 320, 180)
    assert t == (-1.0 * math.tan(math.pi / 4), math.tan(math.pi / 4), -math.tan(math.pi / 4) * 180 / 320,
                 math.tan(math.pi / 4) * 180 / 320)
    # the rays as the camera made them before frustums (tangents of half the field of view)
    tan_x = math.tan(math.pi / 4)
    tan_y = tan_x * 180 / 320
    xs = ((np.arange(320) + 0.5) / 320 * 2 - 1) * tan_x
    ys = (1 - (np.arange(180) + 0.5) / 180 * 2) * tan_y
    gx, gy = np.meshgrid(xs, ys)
    d = np.stack([gx, gy, -np.ones_like(gx)], axis=-1).reshape(-1, 3)
    assert np.array_equal(camera_rays(320, 180, 90.0), d / np.linalg.norm(d, axis=1, keepdims=True))
    assert np.array_equal(frustum.rays(t, 320, 180), camera_rays(320, 180, 90.0))
    # ... and its projection matrix, to the bit
    before = np.zeros((4, 4))
    before[0, 0], before[1, 1] = 1 / tan_x, 1 / tan_y
    before[2, 2], before[2, 3], before[3, 2] = (100.0 + 0.1) / (0.1 - 100.0), 2 * 100.0 * 0.1 / (0.1 - 100.0), -1.0
    assert np.array_equal(frustum.projection(t, 0.1, 100.0), before)
    assert frustum.equivalent_fov_deg(t) == pytest.approx(90.0)
    assert OutputConfig(320, 180, 90.0).tangents() == t


def test_the_right_eye_mirrors_the_left():
    left, right = (frustum.eye_tangents(e, QUEST_LIKE) for e in ("left", "right"))
    assert left[0] == -right[1] and left[1] == -right[0] and left[2:] == right[2:]
    assert left[0] == pytest.approx(-math.tan(math.radians(52.0)))   # the left eye sees further left
    assert left[3] == pytest.approx(math.tan(math.radians(45.0))) and left[2] == pytest.approx(-math.tan(math.radians(52)))
    (hx, _), (cx, cy) = frustum.half_and_centre(left)
    assert cx < 0 and cy < 0 and hx == pytest.approx(0.5 * (math.tan(math.radians(52)) + math.tan(math.radians(42))))


@pytest.mark.parametrize("values, message", [
    ("52,42,45", "four angles"), ("52,42,45,x", "four angles"), ("0,42,45,52", "outer angle must be in (0, 80]"),
    ((52, 42, 90, 52), "up angle must be in"), ((52, 42, 45, float("nan")), "down angle must be in"),
])
def test_bad_eye_angles_are_named(values, message):
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[")):
        frustum.check_eye_fov_deg(values)
    with pytest.raises(ConfigError, match="belongs to an eye"):
        frustum.eye_tangents("centre", QUEST_LIKE)


def test_an_outputs_frustum_goes_over_the_wire_and_bad_ones_are_refused():
    t = frustum.eye_tangents("left", QUEST_LIKE)
    out = OutputConfig(320, 180, 90.0, 60.0, t)
    hello = Hello.parse(Hello(output=out).serialize())
    assert hello.output == out and hello.output.tangents() == t
    assert "frustum" not in OutputConfig().to_json()          # a symmetric output's JSON is as before
    for bad, message in (([1.0, -1.0, -0.5, 0.5], "left < right"), ([-1, 1, -0.5], "four numbers"),
                         ([-1, 1, -0.5, True], "four numbers"), ([-1, 1, -0.5, 1e300], "within 80 degrees"),
                         ([-1, 1, -0.5, 10 ** 400], "frustum")):
        body = json.loads(Hello(output=out).serialize())
        body["output"]["frustum"] = bad
        with pytest.raises(MalformedMessage, match=message):
            Hello.parse(json.dumps(body).encode())
