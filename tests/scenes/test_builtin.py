"""Built-in scenes, procedural primitives and textures."""
from __future__ import annotations

import hashlib
import math

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from pibr.protocol.errors import SceneError
from pibr.scenes import primitives as prim
from pibr.scenes import textures as tex
from pibr.scenes.builtin import (BALUSTER_SPACING, BALUSTER_WIDTH, BUILTIN_SCENES, FOCUS_POINT, SPHERE_CENTER,
                                 SPHERE_RADIUS, VIEWER_ORIGIN)
from pibr.scenes.scene import Scene

#: Where the recorded people's eyes go (x, y, z boxes), which only the exhibit may occupy.
WALKING_REGION = np.array([[-1.0, 0.7, -1.8], [3.0, 1.9, 1.6]])


@pytest.fixture(scope="module")
def scenes() -> dict[str, Scene]:
    return {name: builder() for name, (_desc, builder) in BUILTIN_SCENES.items()}


@pytest.fixture(scope="module")
def room(scenes) -> Scene:
    return scenes["room"]


def _world_vertices(obj, t: float = 0.0) -> np.ndarray:
    m = obj.world_matrix(t)
    return obj.mesh.vertices.astype(np.float64) @ m[:3, :3].T + m[:3, 3]


def _scene_digest(scene: Scene) -> str:
    h = hashlib.sha256()
    for o in scene.objects:
        h.update(o.name.encode())
        h.update(o.mesh.digest().encode())
        h.update(np.ascontiguousarray(o.transform).tobytes())
        h.update(repr(o.material.base_color).encode())
        if o.material.texture is not None:
            h.update(o.material.texture.tobytes())
        h.update(repr(o.animation).encode())
    h.update(repr([(l.kind, l.color, l.intensity, l.direction, l.position, l.range) for l in scene.lights]).encode())
    return h.hexdigest()


def _components(mesh) -> list[np.ndarray]:
    """Vertex index arrays of the mesh's connected pieces (vertices at the same position are
    one, so a flat-shaded box is one piece)."""
    _, weld = np.unique(np.round(mesh.vertices.astype(np.float64), 6), axis=0, return_inverse=True)
    weld = weld.ravel()
    f = weld[mesh.faces.astype(np.int64)]
    rows = np.concatenate([f[:, 0], f[:, 1]])
    cols = np.concatenate([f[:, 1], f[:, 2]])
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(mesh.vertices),) * 2)  # welded ids < n
    n, labels = connected_components(graph, directed=False)
    used = np.zeros(len(mesh.vertices), bool)
    used[f.ravel()] = True
    vertex_labels = np.where(used[weld], labels[weld], -1)
    return [np.flatnonzero(vertex_labels == k) for k in range(n) if np.any(vertex_labels == k)]


def _winding_disagreements(mesh) -> int:
    """Faces (with area) whose CCW normal points away from their vertex normals."""
    v = mesh.vertices.astype(np.float64)
    f = mesh.faces
    cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    area = np.linalg.norm(cross, axis=1)
    along = np.einsum("ij,ij->i", cross, mesh.normals[f].astype(np.float64).sum(axis=1))
    return int(np.sum((along <= 0) & (area > 1e-12)))


# ----------------------------------------------------------------------------- the registry

def test_every_builtin_builds_with_its_metadata(scenes):
    assert set(BUILTIN_SCENES) >= {"room", "sphere", "empty"}
    for name, scene in scenes.items():
        description, _builder = BUILTIN_SCENES[name]
        assert isinstance(scene, Scene)
        assert scene.name == name
        assert scene.source == "builtin"
        assert scene.description == description and description and "\n" not in description
        assert scene.viewer_origin == VIEWER_ORIGIN
        assert 0 < scene.near < scene.far


def test_builtins_are_deterministic():
    tex.clear_cache()
    first = {name: _scene_digest(builder()) for name, (_d, builder) in BUILTIN_SCENES.items()}
    tex.clear_cache()
    second = {name: _scene_digest(builder()) for name, (_d, builder) in BUILTIN_SCENES.items()}
    assert first == second


def test_triangle_counts(scenes):
    assert 50_000 <= scenes["room"].triangle_count <= 200_000
    assert 1_000 <= scenes["sphere"].triangle_count <= 20_000
    assert scenes["empty"].triangle_count == 0 and scenes["empty"].objects == []


def test_every_mesh_is_valid(scenes):
    for scene in scenes.values():
        for o in scene.objects:
            m = o.mesh
            assert m.triangle_count > 0, o.name
            assert m.faces.max() < len(m.vertices), o.name
            assert np.allclose(np.linalg.norm(m.normals, axis=1), 1.0, atol=1e-4), o.name
            if m.uvs is not None:
                assert np.all(np.isfinite(m.uvs)), o.name
            if o.material.texture is not None:
                assert m.uvs is not None, f"{o.name} is textured but has no UVs"
                assert o.material.texture.dtype == np.uint8 and o.material.texture.shape[2] == 3
            assert all(0.0 <= c <= 1.0 for c in o.material.base_color), o.name


def test_every_face_winds_with_its_normals(scenes):
    for scene in scenes.values():
        for o in scene.objects:
            assert _winding_disagreements(o.mesh) == 0, o.name


# ----------------------------------------------------------------------------- the room

def test_room_layout_contract(room):
    lo, hi = room.bounds()
    assert lo[1] == pytest.approx(-0.6, abs=0.5)                     # hills dip just below the ground
    assert hi[1] > 20                                                 # hills
    assert room.near == pytest.approx(0.1) and room.far == pytest.approx(1000.0)
    assert room.extra_view
    region = room.viewing_region()
    assert np.all(region[0] <= VIEWER_ORIGIN.p) and np.all(VIEWER_ORIGIN.p <= region[1])
    kinds = {l.kind for l in room.lights}
    assert kinds == {"ambient", "directional", "point"} and len(room.lights) >= 3
    floor = next(o for o in room.objects if o.name == "floor_parquet")
    assert _world_vertices(floor)[:, 1] == pytest.approx(0.0)


def test_room_has_a_visible_moving_object(room):
    moving = [o for o in room.objects if o.is_dynamic]
    assert {o.animation.kind for o in moving} >= {"spin", "swing"}
    for o in moving:
        v0, v1 = _world_vertices(o, 0.0), _world_vertices(o, 0.4)
        assert np.abs(v1 - v0).max() > 0.05, f"{o.name} does not move"
        centre = v0.mean(axis=0)
        assert np.linalg.norm(centre - VIEWER_ORIGIN.p) < 5.0, f"{o.name} is too far to notice"


def test_room_spans_many_depths(room):
    nearest = {o.name: np.linalg.norm(_world_vertices(o) - VIEWER_ORIGIN.p, axis=1).min() for o in room.objects}
    depths = np.array(list(nearest.values()))
    assert np.any(depths < 2.0)
    assert np.sum((depths > 2.0) & (depths < 6.0)) >= 10
    assert np.any(depths > 50.0)
    hills = next(o for o in room.objects if o.name == "distant_hills")
    radial = np.hypot(*(_world_vertices(hills)[:, [0, 2]] - [0.5, 0.0]).T)
    assert radial.min() < 110 and radial.max() > 400


def test_room_exhibit_stands_at_the_focus(room):
    knot = next(o for o in room.objects if o.name == "exhibit_torus_knot")
    pedestal = next(o for o in room.objects if o.name == "exhibit_pedestal")
    kv, pv = _world_vertices(knot), _world_vertices(pedestal)
    assert pv[:, 1].max() == pytest.approx(1.1, abs=0.02)
    assert 1.8 < kv[:, 1].max() < 2.0
    assert np.hypot(*(kv.mean(0) - FOCUS_POINT)[[0, 2]]) < 0.1
    # the viewer origin itself is clear of the sculpture (by more than the near distance)
    assert np.linalg.norm(kv - VIEWER_ORIGIN.p, axis=1).min() > 2 * room.near


def test_room_walking_region_is_free_except_for_the_exhibit(room):
    lo, hi = WALKING_REGION
    for o in room.objects:
        if o.name.startswith("exhibit_"):
            continue
        for t in (0.0, 0.7, 1.9):
            tri = _world_vertices(o, t)[o.mesh.faces]
            overlap = np.all((tri.min(axis=1) < hi) & (tri.max(axis=1) > lo), axis=1)
            assert not overlap.any(), f"{o.name} reaches into the walking region at t={t}"


def test_room_has_thin_structures(room):
    cables = [o for o in room.objects if o.name.endswith("_cable")]
    assert cables
    for o in cables:
        size = np.ptp(_world_vertices(o), axis=0)
        assert size[0] < 0.05 and size[2] < 0.05 and size[1] > 0.5
    balusters = next(o for o in room.objects if o.name == "railing_balusters")
    pieces = _components(balusters.mesh)
    assert len(pieces) >= 40
    v = _world_vertices(balusters)
    sizes = np.array([np.ptp(v[p], axis=0) for p in pieces])
    assert np.allclose(sizes[:, [0, 2]], BALUSTER_WIDTH, atol=1e-4)
    assert np.all(sizes[:, 1] > 0.7)
    xs = np.sort([v[p, 0].mean() for p in pieces])
    gaps = np.diff(xs)
    assert np.median(gaps) == pytest.approx(BALUSTER_SPACING, abs=1e-3)
    assert BALUSTER_WIDTH <= 0.03 and 0.10 <= BALUSTER_SPACING <= 0.13


def test_room_tree_has_hundreds_of_leaves(room):
    leaves = next(o for o in room.objects if o.name == "tree_leaves")
    assert len(_components(leaves.mesh)) >= 300                      # separate leaves
    assert leaves.material.texture is not None


def test_room_floor_uvs_are_in_metres(room):
    floor = next(o for o in room.objects if o.name == "floor_parquet")
    v = _world_vertices(floor)
    uv = floor.mesh.uvs.astype(np.float64)
    # one texture repeat per 1.6 m in both directions, u along +x, v along -z
    du = np.polyfit(v[:, 0], uv[:, 0], 1)[0]
    dv = np.polyfit(v[:, 2], uv[:, 1], 1)[0]
    assert du == pytest.approx(1 / 1.6, rel=1e-4) and dv == pytest.approx(-1 / 1.6, rel=1e-4)


def test_room_object_names_are_unique_and_descriptive(room):
    names = [o.name for o in room.objects]
    assert len(names) == len(set(names))
    assert all(n and n == n.strip() and n.replace("_", "").isalnum() for n in names)


# ----------------------------------------------------------------------------- the sphere

def test_sphere_scene(scenes):
    scene = scenes["sphere"]
    assert not scene.extra_view
    (obj,) = scene.objects
    v = _world_vertices(obj)
    r = np.linalg.norm(v - SPHERE_CENTER, axis=1)
    assert r == pytest.approx(SPHERE_RADIUS, rel=1e-5) and SPHERE_RADIUS == pytest.approx(0.4)
    assert obj.material.texture is not None
    # the viewer starts well outside it, looking at it
    assert np.linalg.norm(VIEWER_ORIGIN.p - SPHERE_CENTER) > SPHERE_RADIUS + 1.0
    to_sphere = np.asarray(SPHERE_CENTER) - VIEWER_ORIGIN.p
    assert np.dot(to_sphere / np.linalg.norm(to_sphere), VIEWER_ORIGIN.forward()) > 0.95
    assert prim.signed_volume(obj.mesh) > 0


# ----------------------------------------------------------------------------- primitives

CLOSED = {
    "box": (prim.box((1.0, 2.0, 3.0), (0.5, 0.0, -1.0)), 6.0),
    "box_cells": (prim.box((1.0, 2.0, 3.0), max_cell=0.4), 6.0),
    "cylinder": (prim.cylinder(0.5, 2.0, 64), math.pi * 0.25 * 2),
    "cylinder_rings": (prim.cylinder(0.5, 2.0, 64, height_segments=5), math.pi * 0.25 * 2),
    "frustum": (prim.cylinder(0.5, 1.0, 64, top_radius=0.25), math.pi / 3 * (0.25 + 0.125 + 0.0625)),
    "cone": (prim.cone(0.5, 1.0, 64), math.pi * 0.25 / 3),
    "sphere": (prim.sphere(1.0, 64, 32), 4 / 3 * math.pi),
    "torus": (prim.torus(1.0, 0.25, 64, 24), 2 * math.pi ** 2 * 0.25 ** 2),
    "torus_knot": (prim.torus_knot(0.3, 0.04, 2, 3, 256, 16), None),
    "extrude_L": (prim.extrude([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], 1.0), 3.0),
    "extrude_L_reversed": (prim.extrude([[0, 0], [0, 2], [1, 2], [1, 1], [2, 1], [2, 0]], 1.0), 3.0),
    "lathe": (prim.lathe([[0, 0], [0.3, 0], [0.3, 0], [0.3, 1.0], [0.3, 1.0], [0, 1.0]], 64), math.pi * 0.09),
}


@pytest.mark.parametrize("name", sorted(CLOSED))
def test_closed_primitives_wind_outwards(name):
    mesh, volume = CLOSED[name]
    assert prim.signed_volume(mesh) > 0
    if volume is not None:
        assert prim.signed_volume(mesh) == pytest.approx(volume, rel=0.02)  # polygonal approximation
    assert _winding_disagreements(mesh) == 0
    assert np.allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-5)
    assert mesh.uvs is not None and np.all(np.isfinite(mesh.uvs))


def test_open_primitives_face_the_right_way():
    plane = prim.grid_plane(4.0, 3.0, 0.5, uv_scale=2.0)
    assert plane.triangle_count == 8 * 6 * 2
    assert _winding_disagreements(plane) == 0 and np.all(plane.normals[:, 1] == 1.0)
    assert np.ptp(plane.uvs[:, 0]) == pytest.approx(2.0) and np.ptp(plane.uvs[:, 1]) == pytest.approx(1.5)
    grid = prim.rect_grid([-3, -1, 0, 2], [0, 1, 5])
    assert grid.triangle_count == 12 and _winding_disagreements(grid) == 0
    tube = prim.cylinder(0.1, 1.0, 12, caps=False)
    assert tube.triangle_count == 24 and prim.signed_volume(tube) > 0


def test_leaf_is_two_sided():
    leaf = prim.leaf(0.12, 0.05, segments=4)
    assert leaf.triangle_count == 8 * 3
    n = leaf.triangle_count // 2
    front, back = leaf.faces[:n], leaf.faces[n:]
    assert np.array_equal(back - len(leaf.vertices) // 2, front[:, ::-1])
    assert _winding_disagreements(leaf) == 0
    v = leaf.vertices.astype(np.float64)
    up = np.cross(v[front[:, 1]] - v[front[:, 0]], v[front[:, 2]] - v[front[:, 0]])
    assert up[:, 1].sum() > 0                                          # the front faces +Y
    assert np.ptp(v[:, 2]) == pytest.approx(0.12) and np.ptp(v[:, 0]) <= 0.05 + 1e-6


def test_box_uvs_tile_in_metres():
    b = prim.box((2.0, 1.0, 0.5), (1.0, 0.5, 0.0), uv_scale=0.5)
    side = b.normals[:, 2] == 1.0                                      # the +Z side: u along +x, v along +y
    assert np.allclose(b.uvs[side, 0], b.vertices[side, 0] / 0.5)
    assert np.allclose(b.uvs[side, 1], b.vertices[side, 1] / 0.5)
    unit = prim.box((2.0, 1.0, 0.5))
    assert unit.uvs.min() == 0.0 and unit.uvs.max() == 1.0


def test_merge_transforms_normals_and_mirrors_winding():
    sphere = prim.sphere(1.0, 32, 16)
    stretch = prim.scaling((2.0, 1.0, 1.0))
    mirror = prim.compose(prim.translation(5.0, 0.0, 0.0), prim.scaling((-1.0, 1.0, 1.0)))
    merged = prim.merge([(sphere, stretch), (sphere, mirror), prim.box()])
    assert merged.triangle_count == 2 * sphere.triangle_count + 12
    assert prim.signed_volume(merged) == pytest.approx(3 * prim.signed_volume(sphere) + 1.0, rel=1e-5)
    assert _winding_disagreements(merged) == 0
    # normals of the stretched sphere are those of the ellipsoid x^2/4 + y^2 + z^2 = 1
    part = merged.vertices[: len(sphere.vertices)].astype(np.float64)
    expected = part / [4.0, 1.0, 1.0]
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    assert np.allclose(merged.normals[: len(sphere.vertices)], expected, atol=1e-5)
    inst = prim.instances(sphere, np.stack([stretch, mirror]))
    assert np.allclose(inst.vertices, merged.vertices[: len(inst.vertices)], atol=1e-6)
    assert np.array_equal(inst.faces, merged.faces[: len(inst.faces)])


def test_merge_fills_missing_attributes():
    colored = prim.colored(prim.box(), (255, 0, 0))
    plain = prim.transform_mesh(prim.box(), prim.translation(2, 0, 0))
    merged = prim.merge([colored, plain])
    assert merged.colors.shape == (48, 4)
    assert np.all(merged.colors[:24] == [255, 0, 0, 255]) and np.all(merged.colors[24:] == 255)
    assert merged.uvs.shape == (48, 2)
    assert prim.merge([]).triangle_count == 0


def test_primitives_reject_bad_arguments():
    with pytest.raises(SceneError):
        prim.box((1.0, -1.0, 1.0))
    with pytest.raises(SceneError):
        prim.cylinder(0.5, 1.0, segments=2)
    with pytest.raises(SceneError):
        prim.torus_knot(p=2, q=4)
    with pytest.raises(SceneError):
        prim.extrude([[0, 0], [1, 0], [2, 0]], 1.0)
    with pytest.raises(SceneError):
        prim.transform_mesh(prim.box(), np.zeros((4, 4)))


def test_rotation_matches_the_pose_convention():
    from pibr.protocol.pose import quat_from_axis_angle, quat_to_matrix

    for axis, angle in (((0, 1, 0), 0.3), ((1, 2, 3), -2.0), ((1, 0, 0), math.pi)):
        assert np.allclose(prim.rotation(axis, angle)[:3, :3], quat_to_matrix(quat_from_axis_angle(axis, angle)))
    r = prim.rotation_between((0, 1, 0), (1, 1, 0))
    assert np.allclose(r[:3, :3] @ [0, 1, 0], np.array([1, 1, 0]) / math.sqrt(2))


# ----------------------------------------------------------------------------- textures

@pytest.mark.parametrize("name", sorted(tex.TEXTURES))
def test_textures_are_deterministic_images(name):
    tex.clear_cache()
    image = tex.TEXTURES[name]()
    assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3
    assert 512 <= image.shape[0] <= 1024 and 512 <= image.shape[1] <= 1024
    assert image.std() > 3, "a texture should have visible detail"
    tex.clear_cache()
    assert np.array_equal(image, tex.TEXTURES[name]())
    image[:] = 0                                                       # callers get their own copy
    assert tex.TEXTURES[name]().max() > 0


@pytest.mark.parametrize("name", ["parquet", "wood", "plaster", "brick", "marble", "grass", "fabric"])
def test_tiling_textures_wrap_seamlessly(name):
    image = tex.TEXTURES[name]().astype(np.float64)
    inner = np.abs(np.diff(image, axis=1)).mean()
    seam = np.abs(image[:, 0] - image[:, -1]).mean()
    assert seam < 2.5 * inner + 2
    inner_v = np.abs(np.diff(image, axis=0)).mean()
    seam_v = np.abs(image[0] - image[-1]).mean()
    assert seam_v < 2.5 * inner_v + 2


@pytest.mark.gl
def test_courtyard_is_mostly_sky_with_geometry_all_round():
    from pibr.server.coverage import CoverageProbe
    from pibr.protocol.pose import Pose, quat_from_axis_angle

    scene = BUILTIN_SCENES["courtyard"][1]()
    probe = CoverageProbe(scene, (128, 128), (160, 90))
    try:
        for yaw in (0.0, 1.5, 3.0, 4.5):
            pose = Pose.make(scene.viewer_origin.p, quat_from_axis_angle([0, 1, 0], yaw))
            _, sky, _ = probe.display_points(pose, 0.0)
            assert 0.2 < sky.mean() < 0.6, (yaw, sky.mean())     # sky above colonnades on every side
    finally:
        probe.close()


# ----------------------------------------------------------------------------- the dynamic scene

def test_dynamic_scene_moves_in_every_way_and_stays_small(scenes):
    from pibr.scenes.builtin import DYNAMIC_BOUNDS

    scene = scenes["dynamic"]
    kinds = {o.name: o.animation.kind for o in scene.objects if o.is_dynamic}
    assert kinds == {"spinner": "spin", "pendulum": "swing", "cart": "travel", "ball": "orbit", "slider": "slide"}
    assert scene.triangle_count < 10_000 and scene.extra_view
    objects = {o.name: o for o in scene.objects}
    ts = np.linspace(0.0, 12.0, 961)
    centre = lambda name, t: objects[name].world_bounds(t).mean(0)
    for name in kinds:   # inside the hall at every time, and out of the walkers' way but for the spinner
        lo = np.min([objects[name].world_bounds(t)[0] for t in ts], 0)
        hi = np.max([objects[name].world_bounds(t)[1] for t in ts], 0)
        assert np.all(lo >= DYNAMIC_BOUNDS[0] - 1e-9) and np.all(hi <= DYNAMIC_BOUNDS[1] + 0.1), name
        if name != "spinner":
            overlap = np.minimum(hi, WALKING_REGION[1]) - np.maximum(lo, WALKING_REGION[0])
            assert np.any(overlap <= 0), name
    speed = lambda name: np.linalg.norm(np.diff([centre(name, t) for t in ts], axis=0), axis=1) / (ts[1] - ts[0])
    assert speed("ball").min() > 4.0                                  # fast, all the time
    cart = speed("cart")
    assert cart.max() == pytest.approx(1.8, rel=1e-6) and np.mean(cart < 1e-9) > 0.3   # starts and stops
    swing = [objects["pendulum"].animation.matrix(t)[0, 1] for t in ts]
    assert np.sum(np.diff(np.sign(np.diff(swing))) != 0) >= 8        # reverses, again and again
    # the slider passes behind the east pillar, seen from the focus point, for part of each period
    pillar = objects["pillar_east"].transform[[0, 2], 3]
    hidden = []
    for t in ts:
        a, b = np.array(FOCUS_POINT)[[0, 2]], centre("slider", t)[[0, 2]]
        s = np.clip(np.dot(pillar - a, b - a) / np.dot(b - a, b - a), 0, 1)
        hidden.append(np.linalg.norm(a + s * (b - a) - pillar) < 0.25)
    assert 0.1 < np.mean(hidden) < 0.6
