"""Asset loading through trimesh: the assets are written on the fly into tmp_path."""
from __future__ import annotations

import logging

import numpy as np
import pytest

from pibr.protocol.errors import SceneError
from pibr.scenes.loaders import (MAX_TEXTURE_SIZE, load_asset, load_asset_scene, load_texture, texture_array,
                                 unit_scale)

trimesh = pytest.importorskip("trimesh")
Image = pytest.importorskip("PIL.Image")


def signed_volume(obj) -> float:
    """Signed volume of a closed mesh in world space: positive when its faces wind outward."""
    v = obj.mesh.vertices.astype(np.float64) @ obj.transform[:3, :3].T + obj.transform[:3, 3]
    f = obj.mesh.faces
    return float(np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6.0)


def world_vertices(obj) -> np.ndarray:
    return obj.mesh.vertices.astype(np.float64) @ obj.transform[:3, :3].T + obj.transform[:3, 3]


def write_textured_obj(tmp_path, image_size=(16, 8)):
    """box.obj + material.mtl (map_Kd) + a PNG: returns (obj path, image array)."""
    box = trimesh.creation.box((1.0, 2.0, 3.0))
    rng = np.random.default_rng(0)
    pixels = rng.integers(0, 256, (image_size[1], image_size[0], 3), dtype=np.uint8)
    material = trimesh.visual.material.SimpleMaterial(image=Image.fromarray(pixels), diffuse=[200, 200, 200, 255],
                                                      name="wood")
    box.visual = trimesh.visual.TextureVisuals(uv=rng.random((len(box.vertices), 2)), material=material)
    path = tmp_path / "box.obj"
    box.export(path)
    assert (tmp_path / "material.mtl").exists()
    return path, pixels


# ----------------------------------------------------------------------------- formats

def test_obj_with_mtl_and_texture(tmp_path):
    path, pixels = write_textured_obj(tmp_path)
    objects = load_asset(path)
    assert [o.name for o in objects] == ["box"]
    obj = objects[0]
    assert obj.mesh.triangle_count == 12
    assert obj.mesh.uvs is not None
    np.testing.assert_array_equal(obj.material.texture, pixels)
    assert obj.material.base_color == (1.0, 1.0, 1.0, 1.0)  # map_Kd replaces the placeholder Kd
    np.testing.assert_allclose(obj.world_bounds(), [[-0.5, -1, -1.5], [0.5, 1, 1.5]], atol=1e-6)


def test_large_texture_is_downscaled(tmp_path):
    path, _ = write_textured_obj(tmp_path, image_size=(4096, 64))
    texture = load_asset(path)[0].material.texture
    assert texture.shape == (32, MAX_TEXTURE_SIZE, 3) and texture.dtype == np.uint8


def test_texture_array_converts_modes():
    grey16 = Image.fromarray(np.full((4, 4), 1000, dtype=np.uint16))
    rgba = Image.fromarray(np.zeros((3, 5, 4), dtype=np.uint8), "RGBA")
    assert texture_array(grey16).shape == (4, 4, 3)
    assert texture_array(rgba).shape == (3, 5, 3)


def test_obj_with_two_materials_and_no_uvs_or_normals(tmp_path):
    (tmp_path / "two.mtl").write_text("newmtl red\nKd 1 0 0\nnewmtl green\nKd 0 1 0\nmap_Kd missing_uvs.png\n")
    Image.fromarray(np.zeros((2, 2, 3), np.uint8)).save(tmp_path / "missing_uvs.png")
    (tmp_path / "two.obj").write_text(
        "mtllib two.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 9 9 9\n"
        "usemtl red\nf 1 2 3\nusemtl green\nf 2 4 3\nf 1 1 2\nf 1 2 2\n")  # two degenerate faces
    objects = load_asset(tmp_path / "two.obj", up="y")
    by_name = {o.name: o for o in objects}
    assert set(by_name) == {"two/red", "two/green"}
    assert by_name["two/red"].material.base_color[:3] == (1.0, 0.0, 0.0)
    green = by_name["two/green"]
    assert green.material.texture is None and green.mesh.uvs is None  # a texture needs UVs
    assert green.material.base_color[:3] == (0.0, 1.0, 0.0)
    assert green.mesh.triangle_count == 1 and len(green.mesh.vertices) == 3  # degenerates, unused gone
    np.testing.assert_allclose(np.abs(green.mesh.normals), [[0, 0, 1]] * 3, atol=1e-6)  # computed


def test_glb_with_two_materials_and_node_transform(tmp_path):
    PBR = trimesh.visual.material.PBRMaterial
    box = trimesh.creation.box((1, 1, 1))
    pixels = np.full((8, 8, 3), 77, np.uint8)
    box.visual = trimesh.visual.TextureVisuals(
        uv=np.random.default_rng(1).random((len(box.vertices), 2)),
        material=PBR(name="red", baseColorFactor=[1.0, 0, 0, 1.0], baseColorTexture=Image.fromarray(pixels)))
    ball = trimesh.creation.icosphere(1, radius=0.5)
    ball.visual = trimesh.visual.TextureVisuals(material=PBR(name="blue", baseColorFactor=[0, 0, 1.0, 1.0]))
    sc = trimesh.Scene()
    sc.add_geometry(box, node_name="boxnode", geom_name="box")
    rot = trimesh.transformations.rotation_matrix(np.pi / 2, [0, 0, 1])
    node = trimesh.transformations.translation_matrix([5, 0, 0]) @ rot @ np.diag([2.0, 2.0, 2.0, 1.0])
    sc.add_geometry(ball, node_name="ballnode", geom_name="ball", transform=node)
    path = tmp_path / "pair.glb"
    sc.export(path)

    objects = {o.name: o for o in load_asset(path, up="auto")}  # glTF is +Y up: 'auto' keeps it
    assert set(objects) == {"pair/boxnode", "pair/ballnode"}
    boxo, ballo = objects["pair/boxnode"], objects["pair/ballnode"]
    assert boxo.material.base_color == (1.0, 0.0, 0.0, 1.0)
    np.testing.assert_array_equal(boxo.material.texture, pixels)
    assert ballo.material.base_color == (0.0, 0.0, 1.0, 1.0) and ballo.material.texture is None
    np.testing.assert_allclose(ballo.transform[:3, 3], [5, 0, 0], atol=1e-6)
    np.testing.assert_allclose(ballo.world_bounds(), [[4, -1, -1], [6, 1, 1]], atol=1e-6)
    np.testing.assert_allclose(boxo.world_bounds(), [[-0.5] * 3, [0.5] * 3], atol=1e-6)
    # node transform baked: rotation part of the object transform is the identity
    np.testing.assert_allclose(ballo.transform[:3, :3], np.eye(3))


def test_mirroring_node_keeps_faces_outward(tmp_path):
    sc = trimesh.Scene()
    sc.add_geometry(trimesh.creation.box((1, 1, 1)), node_name="mirrored", transform=np.diag([-1.0, 1, 1, 1]))
    path = tmp_path / "mirror.glb"
    sc.export(path)
    (obj,) = load_asset(path)
    assert signed_volume(obj) == pytest.approx(1.0, rel=1e-6)


def test_ply_with_vertex_colours(tmp_path):
    mesh = trimesh.creation.icosphere(1)
    colors = np.random.default_rng(2).integers(0, 256, (len(mesh.vertices), 4), dtype=np.uint8)
    colors[:, 3] = 255
    mesh.visual.vertex_colors = colors
    path = tmp_path / "coloured.ply"
    mesh.export(path)
    (obj,) = load_asset(path)
    assert obj.mesh.colors is not None and obj.mesh.colors.shape == (len(obj.mesh.vertices), 4)
    assert obj.material.base_color == (1.0, 1.0, 1.0, 1.0)  # colours alone give the surface colour
    # every loaded vertex keeps its own colour
    lookup = {tuple(np.round(v, 5)): tuple(c) for v, c in zip(mesh.vertices, colors)}
    for v, c in zip(world_vertices(obj), obj.mesh.colors):
        assert lookup[tuple(np.round(v, 5))] == tuple(c)


def test_ply_with_differing_face_colours_keeps_them_exact(tmp_path):
    mesh = trimesh.creation.box()
    mesh.visual.face_colors = np.random.default_rng(3).integers(0, 256, (12, 4), dtype=np.uint8)
    path = tmp_path / "faces.ply"
    mesh.export(path)
    (obj,) = load_asset(path)
    c = obj.mesh.colors[obj.mesh.faces]  # (m, 3, 4)
    assert np.all(c == c[:, :1])  # one colour per face


# ----------------------------------------------------------------------------- conventions

def write_z_up_obj(tmp_path):
    """A 1 x 1 x 2 box standing on z = 0, 2 m tall along +Z."""
    box = trimesh.creation.box((1.0, 1.0, 2.0))
    box.apply_translation([0, 0, 1.0])
    path = tmp_path / "tower.obj"
    box.export(path)
    return path


def test_z_up_obj_is_converted(tmp_path):
    path = write_z_up_obj(tmp_path)
    expected = [[-0.5, 0.0, -0.5], [0.5, 2.0, 0.5]]
    (obj,) = load_asset(path, up="z")
    np.testing.assert_allclose(obj.world_bounds(), expected, atol=1e-6)
    assert signed_volume(obj) == pytest.approx(2.0, rel=1e-6)  # a rotation: still outward
    (guessed,) = load_asset(path, up="auto")  # rests on z = 0, not on y = 0
    np.testing.assert_allclose(guessed.world_bounds(), expected, atol=1e-6)
    (default,) = load_asset(path)  # the default is auto
    np.testing.assert_allclose(default.world_bounds(), expected, atol=1e-6)
    (as_is,) = load_asset(path, up="y")  # the file taken as +Y up
    np.testing.assert_allclose(as_is.world_bounds(), [[-0.5, -0.5, 0], [0.5, 0.5, 2]], atol=1e-6)


def test_units_fit_size_center_and_scale(tmp_path):
    path = write_z_up_obj(tmp_path)
    (cm,) = load_asset(path, units="cm", up="y")
    np.testing.assert_allclose(cm.world_bounds()[1], [0.005, 0.005, 0.02], atol=1e-9)
    (inch,) = load_asset(path, units=0.0254, up="y")
    np.testing.assert_allclose(inch.world_bounds()[1, 2], 2 * 0.0254)
    (fit,) = load_asset(path, up="z", fit_size=1.0, center="base")
    np.testing.assert_allclose(fit.world_bounds(), [[-0.25, 0, -0.25], [0.25, 1.0, 0.25]], atol=1e-6)
    (centred,) = load_asset(path, up="z", center="bounds", scale=(2, 1, 1))
    np.testing.assert_allclose(centred.world_bounds(), [[-1, -1, -0.5], [1, 1, 0.5]], atol=1e-6)
    assert unit_scale("ft") == pytest.approx(0.3048)
    with pytest.raises(SceneError, match="unknown units 'furlong'"):
        load_asset(path, units="furlong")
    with pytest.raises(SceneError, match="tower.obj: up must be"):
        load_asset(path, up="x")


def test_non_watertight_mesh(tmp_path):
    box = trimesh.creation.box()
    open_box = trimesh.Trimesh(box.vertices, box.faces[:-2], process=False)
    assert not open_box.is_watertight
    path = tmp_path / "open.obj"
    open_box.export(path)
    (obj,) = load_asset(path)
    assert obj.mesh.triangle_count == 10


def test_huge_coordinates_stay_precise(tmp_path):
    box = trimesh.creation.box((2.0, 1.0, 0.5))
    box.apply_translation([1e6 + 0.25, 2e6, -3e6])
    path = tmp_path / "far.ply"
    box.export(path, encoding="ascii")  # float64 text: the file itself keeps full precision
    (obj,) = load_asset(path, up="y")
    assert obj.mesh.vertices.dtype == np.float32
    assert np.abs(obj.mesh.vertices).max() <= 1.0 + 1e-6  # re-centred: small float32
    np.testing.assert_allclose(obj.transform[:3, 3], [1e6 + 0.25, 2e6, -3e6], atol=1e-9)
    np.testing.assert_allclose(obj.world_bounds() - obj.transform[:3, 3],
                               [[-1.0, -0.5, -0.25], [1.0, 0.5, 0.25]], atol=1e-6)


def test_tiny_mesh_keeps_its_triangles(tmp_path):
    sphere = trimesh.creation.icosphere(2, radius=1.0)
    sphere.apply_scale(1e-4)
    path = tmp_path / "tiny.obj"
    sphere.export(path)
    (obj,) = load_asset(path)
    assert obj.mesh.triangle_count == len(sphere.faces)  # nothing merged or dropped as "degenerate"
    np.testing.assert_allclose(obj.world_bounds(), [[-1e-4] * 3, [1e-4] * 3], rtol=1e-5, atol=1e-10)
    norms = np.linalg.norm(obj.mesh.normals, axis=1)
    np.testing.assert_allclose(norms, 1.0, atol=1e-5)


# ----------------------------------------------------------------------------- failures

def test_point_cloud_only_file_raises(tmp_path):
    path = tmp_path / "points.ply"
    trimesh.PointCloud(np.random.default_rng(4).random((20, 3))).export(path)
    with pytest.raises(SceneError, match=r"points\.ply: the asset contains no triangles.*point cloud"):
        load_asset(path)


def test_point_cloud_next_to_mesh_is_skipped_with_warning(tmp_path, caplog):
    sc = trimesh.Scene()
    sc.add_geometry(trimesh.creation.box(), node_name="solid")
    sc.add_geometry(trimesh.PointCloud(np.random.default_rng(5).random((10, 3))), node_name="cloud")
    path = tmp_path / "mixed.glb"
    sc.export(path)
    with caplog.at_level(logging.WARNING, logger="pibr.scenes.loaders"):
        objects = load_asset(path)
    assert [o.name for o in objects] == ["mixed"]
    assert "skipping point cloud" in caplog.text and "mixed.glb" in caplog.text


def test_empty_obj_raises(tmp_path):
    path = tmp_path / "nothing.obj"
    path.write_text("# no geometry\nv 0 0 0\nv 1 0 0\n")
    with pytest.raises(SceneError, match=r"nothing\.obj: the asset contains no triangles"):
        load_asset(path)


@pytest.mark.parametrize("name, content", [
    ("corrupt.glb", b"glTF\x02\x00\x00\x00garbage that is not a GLB"),
    ("corrupt.ply", b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nend_header\n1\n"),
])
def test_corrupt_file_raises_naming_the_file(tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(SceneError) as info:
        load_asset(path)
    assert str(path) in str(info.value) and "cannot read asset" in str(info.value)


def test_missing_and_unsupported_files(tmp_path):
    with pytest.raises(SceneError, match=r"nope\.obj: asset file does not exist"):
        load_asset(tmp_path / "nope.obj")
    odd = tmp_path / "model.xyzw"
    odd.write_text("hello")
    with pytest.raises(SceneError, match=r"model\.xyzw: unsupported asset format '\.xyzw'; readable: .*obj"):
        load_asset(odd)
    with pytest.raises(SceneError, match=r"gone\.png: texture image does not exist"):
        load_texture(tmp_path / "gone.png")


# ----------------------------------------------------------------------------- as a scene

def test_load_asset_scene_places_viewer_in_front(tmp_path):
    path = write_z_up_obj(tmp_path)
    scene = load_asset_scene(path, up="z")
    assert scene.name == "tower" and scene.source == str(path)
    lo, hi = scene.bounds()
    centre = (lo + hi) / 2
    radius = np.linalg.norm(hi - lo) / 2
    eye = scene.viewer_origin.p
    np.testing.assert_allclose(eye[:2], centre[:2])
    assert eye[2] == pytest.approx(centre[2] + 2.5 * radius)
    np.testing.assert_allclose(scene.viewer_origin.forward(), [0, 0, -1], atol=1e-12)
    assert 0 < scene.near < 0.1 + 1e-12 and scene.far > 3.5 * radius
    assert len(scene.lights) >= 1 and not scene.is_dynamic
