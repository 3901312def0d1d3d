import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pibr.protocol import projection as P


def _front_points(n, rng, rmin=1e-3, rmax=1e3):
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[:, 2] = -np.abs(d[:, 2])
    r = np.exp(rng.uniform(np.log(rmin), np.log(rmax), n))
    return d * r[:, None]


def test_round_trip_front_hemisphere():
    p = _front_points(10000, np.random.default_rng(1))
    t, r, valid = P.project(p)
    assert valid.all()
    assert np.all(np.abs(t) <= 1.0)
    err = np.linalg.norm(P.unproject(t, r) - p, axis=1)
    assert np.all(err <= 1e-9 * r)


def test_matches_paper_formula_away_from_poles():
    p = _front_points(1000, np.random.default_rng(2))
    r = np.linalg.norm(p, axis=1)
    tx, ty = p[:, 0] / r, p[:, 1] / r
    keep = np.abs(ty) < 0.999
    t, _, _ = P.project(p)
    np.testing.assert_allclose(t[keep, 0], (tx / np.sqrt(1 - ty ** 2))[keep], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(t[:, 1], ty, atol=1e-12)


@pytest.mark.parametrize("eps", [1e-3, 1e-8, 1e-15, 0.0])
def test_poles_are_finite_and_invert(eps):
    # |t_y| -> 1: straight up and down, approached from several azimuths.
    az = np.linspace(-np.pi / 2, np.pi / 2, 7)
    for sign in (1.0, -1.0):
        p = np.stack([eps * np.sin(az), np.full_like(az, sign), -eps * np.cos(az)], axis=1)
        t, r, valid = P.project(p)
        assert np.all(np.isfinite(t)) and np.all(np.abs(t) <= 1.0)
        np.testing.assert_allclose(t[:, 1], sign, atol=1e-6)
        back = P.unproject(t, r)
        np.testing.assert_allclose(back, p, atol=1e-6)


def test_camera_centre_and_tiny_distances():
    t, r, valid = P.project(np.zeros((1, 3)))
    assert np.all(np.isfinite(t)) and r[0] == 0.0 and not valid[0]
    p = np.array([[1e-300, 2e-300, -3e-300], [0.0, 0.0, -1e-320]])
    t, r, valid = P.project(p)
    assert valid.all() and np.all(np.isfinite(t))
    np.testing.assert_allclose(P.unproject(t, r) / np.abs(p).max(axis=1, keepdims=True),
                               p / np.abs(p).max(axis=1, keepdims=True), atol=1e-9)


def test_huge_distances_keep_direction():
    p = np.array([[3e200, -4e200, -5e200], [1e308, 0.0, -1e308], [0.0, 0.0, -np.finfo(float).max]])
    t, r, valid = P.project(p)
    assert valid.all() and np.all(np.isfinite(t)) and np.all(np.isfinite(r))
    d = p / np.linalg.norm(p / 1e300, axis=1, keepdims=True) / 1e300
    np.testing.assert_allclose(P.unproject(t), d, atol=1e-12)


def test_points_behind_camera_are_invalid_but_finite():
    p = np.array([[0.0, 0.0, 1.0], [1.0, 0.5, 0.01], [-2.0, 0.0, 5.0], [0.0, 1.0, 1e-9]])
    t, r, valid = P.project(p)
    assert not valid.any()
    assert np.all(np.isfinite(t)) and np.all(np.abs(t) <= 1.0)


def test_nonfinite_input_is_invalid():
    t, r, valid = P.project(np.array([[np.nan, 0, -1], [np.inf, 0, -1], [0, 0, -np.inf]]))
    assert not valid.any() and np.all(np.isfinite(t))


def test_extended_projection_continues_past_the_rim():
    # Azimuth sweeps from the front through the side (x' = 1) to straight behind (x' = 2).
    az = np.radians(np.linspace(0, 179.9, 500))
    p = np.stack([np.sin(az), np.zeros_like(az), -np.cos(az)], axis=1)
    tx, ty, r = P.FORWARD_EXTENDED.numpy(px=p[:, 0], py=p[:, 1], pz=p[:, 2])
    assert np.all(np.diff(tx) > 0)
    assert abs(tx[0]) < 1e-12 and abs(tx[-1] - 2) < 2e-3
    i = np.argmin(np.abs(az - np.pi / 2))
    assert abs(tx[i] - 1) < 1e-2


def test_pixel_centres_and_uv_convention():
    t = P.pixel_centers(4, 2)
    assert t.shape == (2, 4, 2)
    np.testing.assert_allclose(t[0, 0], [-0.75, 0.5])   # top-left pixel: left, up
    np.testing.assert_allclose(t[1, 3], [0.75, -0.5])
    px = P.to_pixels(t.reshape(-1, 2), 4, 2)
    np.testing.assert_allclose(px[0], [0.5, 0.5])


@settings(max_examples=300, deadline=None)
@given(st.floats(-1, 1), st.floats(-1, 1), st.floats(1e-6, 1e6))
def test_inverse_then_forward_is_identity(x, y, r):
    t = np.array([[x, y]])
    p = P.unproject(t, np.array([r]))
    t2, r2, valid = P.project(p)
    assert valid[0]
    np.testing.assert_allclose(r2, r, rtol=1e-9)
    # At the pole row every x' names the same direction; elsewhere x' must come back.
    if abs(y) < 1 - 1e-6:
        np.testing.assert_allclose(t2[0, 0], x, atol=1e-6 / np.sqrt(1 - y * y))
    np.testing.assert_allclose(t2[0, 1], y, atol=1e-12)


@pytest.mark.gl
def test_glsl_agrees_with_numpy(gl_ctx):
    rng = np.random.default_rng(3)
    pts = np.concatenate([
        _front_points(2000, rng, 1e-2, 1e3),
        rng.normal(size=(500, 3)) * 10,                      # behind too (extended projection)
        np.array([[0, 1, 0], [0, -1, 0], [1e-7, 1, -1e-7], [0, 0, -1e-20], [0, 0, 0]]),
    ]).astype(np.float32)
    vs = "#version 410\n" + P.GLSL + """
in vec3 in_p;
out vec3 out_f;
out vec3 out_e;
out vec3 out_i;
void main() {
    out_f = wa_project(in_p);
    out_e = wa_project_extended(in_p);
    out_i = wa_unproject(clamp(out_f.xy, -1.0, 1.0));
}
"""
    prog = gl_ctx.program(vertex_shader=vs, varyings=["out_f", "out_e", "out_i"])
    src = gl_ctx.buffer(pts.tobytes())
    dst = gl_ctx.buffer(reserve=len(pts) * 9 * 4)
    vao = gl_ctx.vertex_array(prog, [(src, "3f", "in_p")])
    fbo = gl_ctx.simple_framebuffer((1, 1))  # a standalone context has no default framebuffer
    fbo.use()
    gl_ctx.error  # reading the flag clears anything left by earlier users of the context
    vao.transform(dst, vertices=len(pts))
    out = np.frombuffer(dst.read(), np.float32).reshape(len(pts), 3, 3)
    assert gl_ctx.error == "GL_NO_ERROR"
    p64 = pts.astype(np.float64)
    tx, ty, r = P.FORWARD.numpy(px=p64[:, 0], py=p64[:, 1], pz=p64[:, 2])
    ex, ey, er = P.FORWARD_EXTENDED.numpy(px=p64[:, 0], py=p64[:, 1], pz=p64[:, 2])
    np.testing.assert_allclose(out[:, 0, 0], tx, atol=2e-5)
    np.testing.assert_allclose(out[:, 0, 1], ty, atol=2e-5)
    np.testing.assert_allclose(out[:, 0, 2], r, rtol=1e-5, atol=1e-30)
    np.testing.assert_allclose(out[:, 1, 0], ex, atol=2e-5)
    d = np.stack(P.INVERSE.numpy(vx=np.clip(tx, -1, 1), vy=np.clip(ty, -1, 1)), axis=1)
    np.testing.assert_allclose(out[:, 2], d, atol=1e-3)
    for o in (vao, src, dst, prog, fbo):
        o.release()
