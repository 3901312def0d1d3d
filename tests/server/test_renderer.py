"""The renderer's wide views: culling is exact, chunks cover every face."""
import numpy as np
import pytest

from pibr.protocol.pose import Pose, quat_from_euler
from pibr.scenes.registry import load_scene
from pibr.scenes.scene import Mesh
from pibr.server.config import extra_offset_pose
from pibr.server.renderer import PEEL_TOLERANCE, chunk_boxes, visible_runs


def _poses(scene, n, seed):
    """Random eye positions in the viewing region, looking anywhere horizontally, a little up or down."""
    rng = np.random.default_rng(seed)
    lo, hi = scene.viewing_region()
    for _ in range(n):
        q = quat_from_euler([rng.uniform(-np.pi, np.pi), rng.uniform(-0.8, 0.8), rng.uniform(-0.3, 0.3)], "yxz")
        yield Pose.make(rng.uniform(lo, hi), q)


def test_chunk_boxes_contain_their_faces_and_runs_keep_order():
    rng = np.random.default_rng(0)
    v = rng.normal(size=(300, 3)).astype(np.float32)
    f = rng.integers(0, 300, size=(1000, 3))
    mesh = Mesh(v, f)
    corners = chunk_boxes(mesh, 128)
    assert corners.shape == (8, 8, 3)
    tri = v[f].astype(np.float64)
    for i in range(8):
        part = tri[i * 128:(i + 1) * 128].reshape(-1, 3)
        assert np.allclose(corners[i].min(0), part.min(0)) and np.allclose(corners[i].max(0), part.max(0))
    # A camera at +10 z looking down -z sees everything; turned around, nothing; runs are ordered.
    view = np.eye(4)
    view[2, 3] = -10.0
    assert visible_runs(corners, view, 128, 1000) == [(0, 1000)]
    back = np.diag([-1.0, 1.0, -1.0, 1.0]) @ view
    assert visible_runs(corners, back, 128, 1000) == []
    # half space through the middle: runs are sorted, disjoint, within the faces, last one clipped at 1000
    mid = np.eye(4)
    mid[2, :3] = [1.0, 0.0, 0.0]
    runs = visible_runs(corners, mid, 128, 1000)
    assert all(a + n <= b for (a, n), (b, _) in zip(runs, runs[1:]))
    assert all(n > 0 and a + n <= 1000 for a, n in runs)


@pytest.mark.gl
def test_culling_changes_no_pixel():
    """Primary (with motion) and peeled extra view, with and without culling: identical bytes."""
    from pibr.common.gl import create_context
    from pibr.server.render_target import RenderTarget
    from pibr.server.renderer import Renderer

    scene = load_scene("room")
    ctx = create_context()
    try:
        renderer = Renderer(ctx, scene, "vertex")
        primary = RenderTarget(ctx, 256, 256, motion=True)
        extra = RenderTarget(ctx, 128, 128)
        offset = extra_offset_pose(1.5, 1.8, 15.0)
        culled_some = 0
        for k, pose in enumerate(_poses(scene, 6, seed=2)):
            t = 0.37 * k   # the fan and the pendulum move
            out = {}
            for cull in (False, True):
                renderer.cull = cull
                renderer.render_wide(primary, pose, t, motion_dt=0.1)
                drawn = renderer.drawn_triangles
                renderer.render_wide(extra, pose.compose(offset), t, peel=(primary, pose, PEEL_TOLERANCE))
                out[cull] = (primary.read_color().copy(), primary.read_distance().copy(),
                             primary.read_motion()[0].copy(), extra.read_color().copy(),
                             extra.read_distance().copy(), drawn)
            for a, b in zip(out[False][:5], out[True][:5]):
                assert np.array_equal(a, b)
            culled_some += out[True][5] < out[False][5]
        assert culled_some == 6   # culling really dropped triangles in every pose
        renderer.release()
        primary.release()
        extra.release()
    finally:
        ctx.release()


@pytest.mark.gl
def test_lod_copy_keeps_every_edge_within_the_angle_from_the_eye():
    """The copy drawn for an eye spans at most the edge angle per edge, seen from that eye, and gets
    coarser (fewer triangles) as the eye moves away."""
    from pibr.common.gl import create_context
    from pibr.scenes.scene import Scene, SceneObject
    from pibr.server.renderer import Renderer

    quad = Mesh(np.array([[0, 0, 0], [0.6, 0, 0], [0.6, 0.6, 0], [0, 0.6, 0]], np.float32),
                np.array([[0, 1, 2], [0, 2, 3]]))
    place = np.eye(4)
    place[:3, 3] = [-0.3, 1.0, -2.0]
    scene = Scene("quad", [SceneObject("quad", quad, transform=place)],
                  view_region=np.array([[-1.0, 0.5, -1.0], [1.0, 1.5, 6.0]]))
    ctx = create_context()
    try:
        renderer = Renderer(ctx, scene, "vertex", max_edge_angle_deg=6.0)
        g = renderer.objects[0]
        assert len(g.tessellations[6.0]) > 2          # several bands
        rng = np.random.default_rng(1)
        faces = []
        for z in (-1.0, 0.0, 1.0, 3.0, 6.0):
            eye = np.array([rng.uniform(-1, 1), rng.uniform(0.5, 1.5), z])
            mesh = renderer._tessellated(g, None, eye, 0.0)
            faces.append(mesh.faces)
            fine = _copy_faces(renderer, g, mesh) @ place[:3, :3].T + place[:3, 3]   # (m, 3, 3) world
            lo, hi = fine.min(axis=1), fine.max(axis=1)
            dist = np.linalg.norm(np.maximum(0.0, np.maximum(lo - eye, eye - hi)), axis=1)
            edge = np.linalg.norm(fine - np.roll(fine, 1, axis=1), axis=2).max(axis=1)
            assert np.all(edge <= np.maximum(dist * np.tan(np.radians(6.0)), 0.02) * 1.001)
        assert faces[0] > faces[-1]                    # far eye: coarser copy
        renderer.release()
    finally:
        ctx.release()


def _copy_faces(renderer, g, mesh) -> np.ndarray:
    """Object-space triangles (m, 3, 3) of a pre-tessellated GPU copy, read back from its buffers."""
    from pibr.server.renderer import _VERTEX_DTYPE

    verts = np.frombuffer(mesh.vbo.read(), _VERTEX_DTYPE)["p"].astype(np.float64)
    faces = np.frombuffer(mesh.ibo.read(), np.uint32).reshape(-1, 3)
    return verts[faces]


#: The peel test as it was before it used textureGather: four clamped texelFetch calls.
_PEEL_BY_FETCHES = """    vec3 t = wa_project(p);
    vec2 texel = wa_uv(t.xy) * u_peel_size - 0.5;
    ivec2 base = ivec2(floor(texel));
    ivec2 hi = ivec2(u_peel_size) - 1;
    for (int k = 0; k < 4; ++k) {
        ivec2 q = clamp(base + ivec2(k & 1, k >> 1), ivec2(0), hi);
        float d = texelFetch(u_peel_dist, q, 0).r;
        if (d > 0.0 && abs(d - t.z) < u_peel_tolerance * t.z) return true;
    }
    return false;
}"""


@pytest.mark.gl
@pytest.mark.parametrize("mark_peeled", [True, False])
def test_peeling_by_gather_equals_peeling_by_four_fetches(monkeypatch, mark_peeled):
    import pibr.server.renderer as R
    import pibr.server.shaders as S
    from pibr.common.gl import create_context

    start = S.FRAGMENT.index("    vec3 t = wa_project(p);\n    // the 2x2")
    end = S.FRAGMENT.index("}\n#endif", start) + 1
    scene = load_scene("room")
    ctx = create_context()
    try:
        gather = R.Renderer(ctx, scene, "vertex")
        monkeypatch.setattr(S, "FRAGMENT", S.FRAGMENT[:start] + _PEEL_BY_FETCHES + S.FRAGMENT[end:])
        fetches = R.Renderer(ctx, scene, "vertex")
        primary = R.RenderTarget(ctx, 256, 256)
        extra = R.RenderTarget(ctx, 128, 128)
        offset = extra_offset_pose(1.5, 1.8, 15.0)
        peeled = 0
        for pose in _poses(scene, 5, seed=4):
            gather.render_wide(primary, pose, 0.0)
            out = []
            for r in (gather, fetches):
                r.render_wide(extra, pose.compose(offset), 0.0, peel=(primary, pose, PEEL_TOLERANCE),
                              mark_peeled=mark_peeled)
                out.append((extra.read_color().copy(), extra.read_distance().copy()))
            assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])
            gather.render_wide(extra, pose.compose(offset), 0.0)
            peeled += int(np.sum(extra.read_distance() != out[0][1]))
        assert peeled > 1000   # peeling really removed surfaces
        for r in (gather, fetches):
            r.release()
        primary.release()
        extra.release()
    finally:
        ctx.release()


def test_cube_faces_cover_the_front_hemisphere_once():
    """Every direction with p_z < 0 lies inside exactly one face's frustum (planes), and that
    face's matrix puts it inside the clip volume."""
    from pibr.server.cube_faces import FACES, face_matrix, face_planes, face_rects

    rng = np.random.default_rng(3)
    d = rng.normal(size=(2000, 3))
    d[:, 2] = -np.abs(d[:, 2]) - 1e-3
    d *= rng.uniform(0.5, 50.0, size=(2000, 1))
    inside = []
    for name in FACES:
        planes = face_planes(name, 0.1)
        ok = (d @ planes[:, :3].T + planes[:, 3] >= 0).all(axis=1)
        clip = np.c_[d, np.ones(len(d))] @ face_matrix(name, 0.1, 1000.0).T
        ndc = clip[ok, :3] / clip[ok, 3:]
        assert np.all(np.abs(ndc) <= 1 + 1e-9)
        inside.append(ok)
    assert np.all(np.sum(inside, axis=0) >= 1)
    assert np.mean(np.sum(inside, axis=0) == 1) > 0.99   # only the shared edges count twice
    rects = face_rects(8)
    assert sum(w * h for _, _, w, h in rects.values()) == 3 * 8 * 8


@pytest.mark.gl
def test_cube_projection_matches_the_vertex_projection():
    """Projection "cube" resamples five perspective faces into the same wide-angle image: colour,
    distance and motion agree with the vertex projection up to resampling blur at silhouettes."""
    from pibr.bench.metrics import psnr
    from pibr.common.gl import create_context
    from pibr.server.render_target import RenderTarget
    from pibr.server.renderer import Renderer

    scene = load_scene("room")
    ctx = create_context()
    try:
        renderer = Renderer(ctx, scene, "vertex", cube_scale=1.0)
        a = RenderTarget(ctx, 192, 192, motion=True)
        b = RenderTarget(ctx, 192, 192, motion=True)
        moving = 0
        for k, pose in enumerate(_poses(scene, 3, seed=7)):
            renderer.render_wide(a, pose, 0.5 * k, "vertex", motion_dt=0.1)
            renderer.render_wide(b, pose, 0.5 * k, "cube", motion_dt=0.1)
            assert ctx.error == "GL_NO_ERROR"
            assert psnr(a.read_color(), b.read_color()) > 24.0
            da, db = a.read_distance(), b.read_distance()
            both = (da > 0) & (db > 0)
            assert np.mean((da > 0) == (db > 0)) > 0.99
            assert np.mean(np.abs(da[both] - db[both]) < 0.02 * da[both]) > 0.9
            (ma, ka), (mb, kb) = a.read_motion(), b.read_motion()
            moving += ka.sum()
            assert np.sum(ka != kb) <= 0.2 * max(ka.sum(), 1) + 20
        assert moving > 0
        renderer.release()
        a.release()
        b.release()
    finally:
        ctx.release()


@pytest.mark.gl
def test_wide_views_sample_the_nearest_mip_and_leave_perspective_views_trilinear():
    from pibr.bench.metrics import psnr
    from pibr.common.gl import create_context
    from pibr.server.render_target import RenderTarget
    from pibr.server.renderer import Renderer

    scene = load_scene("room")
    ctx = create_context()
    try:
        renderer = Renderer(ctx, scene, "vertex")
        wide = RenderTarget(ctx, 256, 256)
        gt = RenderTarget(ctx, 128, 96)
        pose = next(_poses(scene, 1, seed=11))
        renderer.render_perspective(gt, pose, 0.0, 90.0)
        before = gt.read_color().copy()
        images = {}
        for trilinear in (False, True):
            renderer.wide_trilinear = trilinear
            renderer.render_wide(wide, pose, 0.0)
            images[trilinear] = wide.read_color().copy()
        renderer.render_perspective(gt, pose, 0.0, 90.0)
        assert np.array_equal(before, gt.read_color())      # ground truth keeps trilinear filtering
        assert not np.array_equal(images[False], images[True])
        assert psnr(images[True], images[False]) > 40.0
        renderer.release()
        wide.release()
        gt.release()
    finally:
        ctx.release()


@pytest.fixture
def ctx():
    """A context of the test's own, as the tests above make (no state shared with other tests)."""
    from pibr.common.gl import create_context

    ctx = create_context()
    yield ctx
    ctx.release()


@pytest.mark.gl
def test_specialised_programs_change_no_pixel(ctx):
    """One program per object kind (textured, moving) against one program with uniform switches:
    primary with motion, both peeled extra views, the tessellation path and a perspective view with
    moving-object indices give identical bytes, and the room really uses several kinds."""
    from pibr.server.render_target import RenderTarget
    from pibr.server.renderer import Renderer

    scene = load_scene("room")
    offset = extra_offset_pose(1.5, 1.8, 15.0)
    out = {}
    for specialise in (False, True):
        renderer = Renderer(ctx, scene, "vertex", specialise=specialise)
        primary = RenderTarget(ctx, 192, 192, motion=True)
        extra = RenderTarget(ctx, 96, 96)
        images = []
        for k, pose in enumerate(_poses(scene, 3, seed=5)):
            t = 0.41 * k   # the fan and the pendulum move
            renderer.render_wide(primary, pose, t, motion_dt=0.1)
            images += [primary.read_color().copy(), primary.read_distance().copy(), primary.read_motion()[0].copy()]
            for mark in (True, False):
                renderer.render_wide(extra, pose.compose(offset), t, peel=(primary, pose, PEEL_TOLERANCE),
                                     mark_peeled=mark)
                images += [extra.read_color().copy(), extra.read_distance().copy()]
            renderer.render_wide(extra, pose, t, "tess")
            images += [extra.read_color().copy(), extra.read_distance().copy()]
            renderer.render_perspective(primary, pose, t, 90.0)
            images += [primary.read_color().copy(), primary.read_moving_index().copy()]
        out[specialise] = images
        kinds = {key[1:] for key in renderer.programs}
        assert kinds == ({(None, None)} if not specialise else {(True, False), (False, False), (False, True)})
        primary.release()
        extra.release()
        renderer.release()
    assert len(out[True]) == len(out[False]) == 33
    for a, b in zip(out[False], out[True]):
        assert np.array_equal(a, b)
    assert (out[True][2] != 0).any()   # motion of moving objects was drawn


@pytest.mark.gl
def test_moving_motion_equals_read_motion_masked(ctx):
    """The one-pass readback equals read_motion with the motion zeroed where nothing moves, bit for
    bit, for flags around 0.5, infinities, NaN, negative zero and subnormal half motions."""
    from pibr.server.render_target import RenderTarget

    target = RenderTarget(ctx, 64, 32, motion=True)
    rng = np.random.default_rng(9)
    flags = np.array([0.0, -0.0, 0.5, np.nextafter(np.float16(0.5), np.float16(1)), 1.0, 7.0, np.inf, -np.inf,
                      np.nan, -1.0, 0.4995], np.float16)
    half = np.empty((32, 64, 4), np.float16)
    half[..., 0] = rng.normal(0.0, 40.0, (32, 64))
    half[..., 1] = rng.normal(0.0, 1e-5, (32, 64))          # many subnormal halves
    half[::5, :, 0] = -0.0
    half[..., 2] = rng.integers(0, 60, (32, 64))   # object index
    half[..., 3] = np.resize(flags, (32, 64))       # moving flag
    target.motion.write(half.tobytes())
    m, moving = target.read_motion()
    expected = np.where(moving[:, :, None], m, 0.0).astype(np.float32)
    motion, got_moving = target.read_moving_motion()
    assert np.array_equal(got_moving, moving) and 0 < moving.sum() < moving.size
    assert motion.dtype == np.float32 and motion.shape == (32, 64, 2)
    assert np.array_equal(motion.view(np.uint32), expected.view(np.uint32))
    target.release()


@pytest.mark.gl
def test_motion_pass_flags_the_moving_surfaces_and_gives_their_motion(ctx):
    """The motion attachment is drawn in a pass of its own after colour and distance (depth test for
    equality): a pixel is flagged exactly where its surface (its distance along its ray) lies on a
    moving object, with that object's index, and its motion is where that surface point was one
    frame interval ago, reprojected: checked against the scene's animation on the CPU."""
    from pibr.protocol.projection import pixel_centers, project, to_pixels, unproject
    from pibr.scenes.mesh_queries import closest_points_on_mesh
    from pibr.server.render_target import RenderTarget
    from pibr.server.renderer import Renderer

    scene = load_scene("dynamic")
    renderer = Renderer(ctx, scene)
    size, dt = 160, 0.1
    target = RenderTarget(ctx, size, size, motion=True)
    moving_ids = [k for k, o in enumerate(scene.objects) if o.is_dynamic]
    checked = 0
    for k, (t, yaw) in enumerate(((1.3, 0.0), (2.9, 0.6), (4.4, -0.5))):
        pose = Pose.make(scene.viewer_origin.position, quat_from_euler([yaw, -0.2, 0.0], "yxz"))
        renderer.render_wide(target, pose, t, motion_dt=dt)
        dist = target.read_distance().reshape(-1).astype(np.float64)
        motion, moving = target.read_moving_motion()
        index = target.read_moving_index().reshape(-1)
        motion, moving = motion.reshape(-1, 2), moving.reshape(-1)
        hit = dist > 0
        cam = unproject(pixel_centers(size, size).reshape(-1, 2), dist)
        world = cam @ pose.rotation().T + pose.p
        on = np.full((len(dist), len(scene.objects)), False)
        for i in moving_ids:
            obj = scene.objects[i]
            m = obj.world_matrix(t)
            local = (world - m[:3, 3]) @ np.linalg.inv(m[:3, :3]).T
            d, _, _ = closest_points_on_mesh(local[hit], obj.mesh.vertices, obj.mesh.faces)
            on[np.flatnonzero(hit), i] = d < 0.01 * dist[hit] + 1e-3
        on_moving = on.any(axis=1)
        assert moving.sum() > 200                                  # the objects are in view
        assert np.array_equal(moving, index >= 0)
        # flagged where a moving surface is seen, with its index (silhouette pixels aside: 1 %)
        assert np.mean(on_moving[moving]) > 0.99
        assert np.mean(on[np.flatnonzero(moving), index[moving]]) > 0.99
        # ... and every pixel whose surface lies on a moving object is flagged, but for static surfaces
        # touching one (within the tolerance) next to its outline: 1-1.3 % here, all beside a flagged pixel
        assert np.mean(moving[on_moving]) > 0.97
        flagged = moving.reshape(size, size)
        beside = flagged.copy()
        beside[1:] |= flagged[:-1]
        beside[:-1] |= flagged[1:]
        beside[:, 1:] |= flagged[:, :-1]
        beside[:, :-1] |= flagged[:, 1:]
        assert np.sum(on_moving & ~beside.reshape(-1)) <= 0.003 * on_moving.sum()
        # the motion: this pixel's surface point one frame interval ago, reprojected
        rows = np.flatnonzero(moving & on_moving)
        prev = np.empty((len(rows), 3))
        for i in moving_ids:
            sel = index[rows] == i
            obj = scene.objects[i]
            step = obj.world_matrix(t - dt) @ np.linalg.inv(obj.world_matrix(t))
            prev[sel] = world[rows[sel]] @ step[:3, :3].T + step[:3, 3]
        prev_cam = (prev - pose.p) @ pose.rotation()
        now_px = to_pixels(project(cam[rows])[0], size, size)
        prev_px = to_pixels(project(prev_cam)[0], size, size)
        err = np.linalg.norm(motion[rows] - (now_px - prev_px), axis=1)
        assert np.median(err) < 0.05 and np.percentile(err, 99) < 0.5, (np.median(err), np.percentile(err, 99))
        assert np.percentile(np.linalg.norm(motion[rows], axis=1), 90) > 1.0   # and something does move
        checked += len(rows)
    assert checked > 1000
    target.release()
    renderer.release()
