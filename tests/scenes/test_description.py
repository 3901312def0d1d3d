"""Scene description files (TOML / JSON), the scene registry and ``pibr scenes``."""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import types

import numpy as np
import pytest

from pibr.protocol.errors import SceneError
from pibr.scenes import registry
from pibr.scenes.description import build_scene, load_description
from pibr.scenes.scene import Mesh, Scene, SceneObject

trimesh = pytest.importorskip("trimesh")
Image = pytest.importorskip("PIL.Image")


@pytest.fixture(autouse=True)
def fresh_registry_cache():
    registry.clear_cache()
    yield
    registry.clear_cache()


@pytest.fixture
def assets(tmp_path):
    """models/tower.obj (1 x 1 x 2 m box along +Z, resting on z = 0) and textures/tiles.png."""
    (tmp_path / "models").mkdir()
    (tmp_path / "textures").mkdir()
    box = trimesh.creation.box((100.0, 100.0, 200.0))  # centimetres
    box.apply_translation([0, 0, 100.0])
    box.export(tmp_path / "models" / "tower.obj")
    Image.fromarray(np.full((4, 4, 3), 200, np.uint8)).save(tmp_path / "textures" / "tiles.png")
    return tmp_path


VALID_TOML = """
name = "courtyard"
description = "a tower on a tiled floor, a ball circling it"
units = "cm"
up = "z"
near = 0.05
far = 200.0
sky_color = [0.1, 0.2, 0.3]
extra_view = false

[viewer_origin]
position = [0, 1.6, 5]
yaw_deg = 90
pitch_deg = -10

[extra_view_offset]
forward = 1.5
up = 1.8
tilt_deg = 15

[[lights]]
kind = "ambient"
intensity = 0.3

[[lights]]
kind = "directional"
direction = [0, -2, 0]
color = [1.0, 0.9, 0.8]

[[objects]]
name = "floor"
builtin = "plane"
size = [20, 10]
texture = "textures/tiles.png"
uv_scale = 10

[[objects]]
name = "tower"
asset = "models/tower.obj"
position = [3, 0, 0]
rotation_deg = [90, 0, 0]
center = "base"

[[objects]]
name = "ball"
builtin = "sphere"
radius = 0.3
segments = 12
position = [2, 1, 0]
color = [0.9, 0.2, 0.1]
[objects.animation]
kind = "spin"
speed = 0.5

[[objects]]
builtin = "box"
size = [1, 2, 3]
scale = [2, 1, 1]
quaternion = [1, 0, 0, 0]
[objects.animation]
kind = "orbit"
radius = 1.5

[[objects]]
builtin = "cylinder"
radius = 0.2
height = 1.0
position = [-3, 0.5, 0]
"""


def test_valid_toml_builds_the_scene(assets):
    path = assets / "courtyard.toml"
    path.write_text(VALID_TOML)
    scene = load_description(path)
    assert isinstance(scene, Scene)
    assert scene.name == "courtyard" and scene.source == str(path)
    assert (scene.near, scene.far, scene.sky_color, scene.extra_view) == (0.05, 200.0, (0.1, 0.2, 0.3), False)
    objects = {o.name: o for o in scene.objects}
    assert list(objects) == ["floor", "tower", "ball", "box", "cylinder"]

    floor = objects["floor"]
    np.testing.assert_allclose(floor.world_bounds(), [[-10, 0, -5], [10, 0, 5]], atol=1e-6)
    assert floor.material.texture.shape == (4, 4, 3)
    assert floor.mesh.uvs.max() == pytest.approx(10.0)

    # 1 x 1 x 2 m Z-up tower in cm, stood on its base, yawed 90 degrees, placed at x = 3
    np.testing.assert_allclose(objects["tower"].world_bounds(), [[2.5, 0, -0.5], [3.5, 2, 0.5]], atol=1e-6)

    ball = objects["ball"]
    assert ball.material.base_color == (0.9, 0.2, 0.1, 1.0)
    assert ball.animation.kind == "spin" and ball.animation.pivot == (2.0, 1.0, 0.0)  # spins in place
    np.testing.assert_allclose(ball.world_bounds(t=1.0).mean(0), [2, 1, 0], atol=1e-6)
    box = objects["box"]  # scale baked into the mesh; position is the orbit's centre
    np.testing.assert_allclose(box.mesh.bounds(), [[-1, -1, -1.5], [1, 1, 1.5]], atol=1e-6)
    np.testing.assert_allclose(box.transform, np.eye(4))
    assert box.animation.kind == "orbit" and scene.is_dynamic
    centres = [box.world_bounds(t).mean(0) for t in np.linspace(0, 2 * np.pi, 5)]
    np.testing.assert_allclose(np.linalg.norm(centres, axis=1), 1.5, atol=1e-6)
    np.testing.assert_allclose(objects["cylinder"].world_bounds(), [[-3.2, 0, -0.2], [-2.8, 1, 0.2]], atol=1e-6)

    assert [lt.kind for lt in scene.lights] == ["ambient", "directional"]
    np.testing.assert_allclose(scene.lights[1].direction, [0, -1, 0])
    v = scene.viewer_origin
    np.testing.assert_allclose(v.p, [0, 1.6, 5])
    c = math.cos(math.radians(10))
    np.testing.assert_allclose(v.forward(), [-c, -math.sin(math.radians(10)), 0], atol=1e-9)  # yaw 90: left
    off = scene.extra_view_offset
    np.testing.assert_allclose(off.p, [0, 1.8, -1.5])
    assert off.forward()[1] < 0  # tilted down


def test_valid_json_with_defaults(assets):
    path = assets / "mini.json"
    path.write_text(json.dumps({
        "objects": [
            {"asset": "models/tower.obj", "units": "cm", "up": "z", "fit_size": 1.0, "color": [0, 1, 0]},
            {"asset": "models/tower.obj", "units": 0.01},
        ],
    }))
    scene = load_description(path)
    assert scene.name == "mini"
    assert [o.name for o in scene.objects] == ["tower", "tower~2"]  # default names stay unique
    tower = scene.objects[0]
    assert tower.material.base_color == (0.0, 1.0, 0.0, 1.0)
    np.testing.assert_allclose(tower.world_bounds()[1] - tower.world_bounds()[0], [0.5, 1.0, 0.5], atol=1e-6)
    # no viewer_origin: in front of the scene (+Z), looking along -Z
    lo, hi = scene.bounds()
    assert scene.viewer_origin.p[2] > hi[2]
    np.testing.assert_allclose(scene.viewer_origin.forward(), [0, 0, -1], atol=1e-12)
    assert len(scene.lights) == 2  # Scene's defaults


def test_animation_object_with_asset_parts_moves_together(assets):
    scene = build_scene({"objects": [{"asset": "models/tower.obj", "animation": {"kind": "slide", "amplitude": 1.0,
                                                                                 "axis": [1, 0, 0], "speed": 1.0}}]},
                        assets / "inline.toml")
    (obj,) = scene.objects
    shift = obj.world_bounds(t=math.pi / 2) - obj.world_bounds(t=0.0)
    np.testing.assert_allclose(shift, [[1, 0, 0], [1, 0, 0]], atol=1e-9)


def test_travel_animation_starts_and_stops(assets):
    """The starts-and-stops kind from a description: rest, travel at constant speed, rest, back."""
    scene = build_scene({"objects": [{"builtin": "box", "position": [1, 0, 0], "animation": {
        "kind": "travel", "axis": [0, 0, 2], "speed": 2.0, "amplitude": 3.0, "rest": 0.5}}]}, assets / "inline.toml")
    (obj,) = scene.objects
    z = [obj.world_matrix(t)[2, 3] for t in (0.0, 0.5, 1.0, 2.0, 2.5, 3.0, 4.0, 4.5)]
    np.testing.assert_allclose(z, [0.0, 0.0, 1.0, 3.0, 3.0, 2.0, 0.0, 0.0], atol=1e-12)


INVALID = [
    ('objcts = []', "objcts: unknown key; allowed here: name, description"),
    ('near = 1.0\nfar = 0.5', "far: must be greater than near (1.0), got 0.5"),
    ('sky_color = [1, 2]', "sky_color: expected 3 numbers, got [1, 2]"),
    ('units = "furlong"', "units: unknown units 'furlong'"),
    ('up = "x"', "up: expected one of y, z, auto"),
    ('extra_view = "yes"', "extra_view: expected true or false"),
    ('[viewer_origin]\nyaw_deg = 3', "viewer_origin.position: required"),
    ('[viewer_origin]\nposition = [0, 0, 0]\nyaw_deg = 3\nquaternion = [1, 0, 0, 0]',
     "viewer_origin.quaternion: give either quaternion or yaw_deg/pitch_deg"),
    ('[viewer_origin]\nposition = [0, 0, 0]\nquaternion = [0, 0, 0, 0]', "viewer_origin.quaternion: quaternion norm"),
    ('[extra_view_offset]\nforward = 1', "extra_view_offset.up: required"),
    ('[[lights]]\nkind = "spot"', "lights[0].kind: expected one of ambient, directional, point, got \"spot\""),
    ('[[lights]]\nkind = "ambient"\ndirection = [0, -1, 0]', "lights[0].direction: unknown key"),
    ('[[lights]]\nkind = "directional"\ndirection = [0, 0, 0]', "lights[0].direction: must not be zero"),
    ('[[objects]]\nbuiltin = "box"\n[[objects]]\nbuiltin = "box"\n[[objects]]\nbuiltin = "box"\nposition = [1, 2]',
     "objects[2].position: expected 3 numbers, got [1, 2]"),
    ('[[objects]]\nbuiltin = "cone"', "objects[0].builtin: expected one of box, sphere, cylinder, plane"),
    ('[[objects]]\nbuiltin = "box"\nasset = "models/tower.obj"', "objects[0]: needs exactly one of 'asset'"),
    ('[[objects]]\nposition = [0, 0, 0]', "objects[0]: needs exactly one of 'asset'"),
    ('[[objects]]\nasset = "models/missing.obj"', "objects[0].asset: file"),
    ('[[objects]]\nbuiltin = "box"\nradius = 2', "objects[0].radius: unknown key; allowed here:"),
    ('[[objects]]\nbuiltin = "box"\nsize = [1, 0, 1]', "objects[0].size: must be positive"),
    ('[[objects]]\nbuiltin = "sphere"\nsegments = 2', "objects[0].segments: expected an integer in 3..1024, got 2"),
    ('[[objects]]\nbuiltin = "box"\nscale = -1', "objects[0].scale: must be positive, got -1"),
    ('[[objects]]\nbuiltin = "box"\ncolor = [2, 0, 0]', "objects[0].color: values must lie in [0, 1]"),
    ('[[objects]]\nbuiltin = "box"\nrotation_deg = [1, 2, 3]\nquaternion = [1, 0, 0, 0]',
     "objects[0].quaternion: give either quaternion or rotation_deg, not both"),
    ('[[objects]]\nbuiltin = "box"\ntexture = "nope.png"', "objects[0].texture: file"),
    ('[[objects]]\nasset = "models/tower.obj"\ntexture = "textures/tiles.png"',
     "objects[0].texture: asset 'tower.obj' has no texture coordinates"),
    ('[[objects]]\nname = "a"\nbuiltin = "box"\n[[objects]]\nname = "a"\nbuiltin = "sphere"',
     "objects[1].name: 'a' is already used by objects[0]"),
    ('[[objects]]\nbuiltin = "box"\n[objects.animation]\nkind = "wobble"', "objects[0].animation.kind: expected one of"),
    ('[[objects]]\nbuiltin = "box"\n[objects.animation]\nkind = "spin"\naxis = [0, 0, 0]',
     "objects[0].animation: animation axis must be a non-zero 3-vector"),
    ('[[objects]]\nbuiltin = "box"\n[objects.animation]\nspeed = 1', "objects[0].animation.kind: required"),
    ('[[objects]]\nbuiltin = "box"\n[objects.animation]\nkind = "travel"\nspeed = 1',
     "objects[0].animation: a travel animation needs a positive speed (m/s) and amplitude (m)"),
    ('[[objects]]\nbuiltin = "box"\n[objects.animation]\nkind = "travel"\namplitude = 1\nrest = -1',
     "objects[0].animation: animation rest must be >= 0 seconds, got -1.0"),
    ('objects = 3', "objects: expected a list of tables, got 3"),
    ('name = "x"\nname2 = ', "invalid TOML"),
]


@pytest.mark.parametrize("text, message", INVALID, ids=[m.split(":")[0] for _, m in INVALID])
def test_invalid_toml_names_file_and_key(assets, text, message):
    path = assets / "bad.toml"
    path.write_text(text)
    with pytest.raises(SceneError) as info:
        load_description(path)
    assert str(info.value).startswith(f"{path}: ")
    assert message in str(info.value)


def test_invalid_json_and_wrong_shapes(assets):
    path = assets / "bad.json"
    path.write_text('{"objects": [')
    with pytest.raises(SceneError, match=r"bad\.json: invalid JSON"):
        load_description(path)
    path.write_text('[1, 2]')
    with pytest.raises(SceneError, match=r"bad\.json: expected a table, got \[1, 2\]"):
        load_description(path)
    path.write_text(json.dumps({"objects": [{"builtin": "box", "position": [0, True, 0]}]}))
    with pytest.raises(SceneError, match=r"objects\[0\]\.position: expected 3 numbers"):
        load_description(path)
    with pytest.raises(SceneError, match=r"missing\.toml: scene description does not exist"):
        load_description(assets / "missing.toml")


def test_corrupt_asset_error_names_both_files(assets):
    (assets / "models" / "broken.glb").write_bytes(b"not a glb at all")
    path = assets / "scene.toml"
    path.write_text('[[objects]]\nasset = "models/broken.glb"\n')
    with pytest.raises(SceneError) as info:
        load_description(path)
    text = str(info.value)
    assert text.startswith(f"{path}: objects[0].asset: ") and "broken.glb: cannot read asset" in text


# ----------------------------------------------------------------------------- registry

def _tiny_scene(name):
    mesh = Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32), np.array([[0, 1, 2]]))
    return Scene(name=name, objects=[SceneObject("tri", mesh)])


@pytest.fixture
def fake_builtins(monkeypatch):
    """A stand-in for pibr.scenes.builtin, counting builds."""
    builds = []

    def builder(name):
        def build():
            builds.append(name)
            return _tiny_scene(name)
        return build

    module = types.ModuleType("pibr.scenes.builtin")
    module.BUILTIN_SCENES = {"room": ("a furnished room", builder("room")),
                             "sphere": ("one sphere", builder("sphere")),
                             "empty": ("nothing", builder("empty"))}
    monkeypatch.setitem(sys.modules, "pibr.scenes.builtin", module)
    return builds


def test_registry_builtins_and_cache(fake_builtins):
    assert registry.available_scenes() == {"room": "a furnished room", "sphere": "one sphere", "empty": "nothing"}
    assert registry.DEFAULT_SCENE in registry.available_scenes()
    first = registry.load_scene("sphere")
    assert first.name == "sphere" and registry.load_scene("sphere") is first
    assert fake_builtins == ["sphere"]


def test_registry_unknown_name_lists_builtins(fake_builtins):
    with pytest.raises(SceneError, match=r"unknown scene 'castle'; built-in scenes: empty, room, sphere"):
        registry.load_scene("castle")
    with pytest.raises(SceneError, match=r"scene file 'castle\.toml' does not exist"):
        registry.load_scene("castle.toml")


def test_registry_files_are_cached_by_mtime(fake_builtins, assets):
    path = assets / "one.toml"
    path.write_text('[[objects]]\nbuiltin = "box"\n')
    first = registry.load_scene(str(path))
    assert registry.load_scene(str(path)) is first
    path.write_text('[[objects]]\nbuiltin = "box"\n[[objects]]\nbuiltin = "sphere"\n')
    os.utime(path, ns=(os.stat(path).st_atime_ns, os.stat(path).st_mtime_ns + 10**9))
    second = registry.load_scene(str(path))
    assert second is not first and len(second.objects) == 2
    asset = registry.load_scene(str(assets / "models" / "tower.obj"))
    assert asset.name == "tower" and asset.triangle_count == 12


def test_real_builtin_scenes():
    scenes = registry.available_scenes()
    assert {"room", "sphere", "empty"} <= set(scenes)
    assert registry.DEFAULT_SCENE == "room"
    assert all(isinstance(d, str) and d for d in scenes.values())
    assert isinstance(registry.load_scene("sphere"), Scene)


# ----------------------------------------------------------------------------- pibr scenes

def run_cli(argv):
    from pibr.scenes import cli

    parser = argparse.ArgumentParser(prog="pibr")
    cli.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    return args.func(args)


def test_cli_lists_and_shows(fake_builtins, assets, capsys):
    assert run_cli(["scenes", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert listed["default"] == "room" and listed["scenes"]["sphere"] == "one sphere"
    assert run_cli(["scenes"]) == 0
    assert "room" in capsys.readouterr().out

    path = assets / "courtyard.toml"
    path.write_text(VALID_TOML)
    assert run_cli(["scenes", "--show", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["objects"] == 5 and info["name"] == "courtyard"
    assert [d["name"] for d in info["dynamic_objects"]] == ["ball", "box"]
    assert info["viewer_origin"]["position"] == [0, 1.6, 5]
    assert run_cli(["scenes", "--show", str(path)]) == 0
    text = capsys.readouterr().out
    assert "ball (spin)" in text and "triangles" in text


def test_module_docstring_example_is_valid(tmp_path):
    import pibr.scenes.description as description

    doc = description.__doc__
    block = doc[doc.index("A complete example"):doc.index("The same structure works as JSON")]
    example = "\n".join(line[4:] for line in block.splitlines()[1:])
    (tmp_path / "models").mkdir()
    (tmp_path / "textures").mkdir()
    trimesh.creation.box((500.0, 500.0, 1000.0)).export(tmp_path / "models" / "statue.obj")  # mm, Z-up
    Image.fromarray(np.zeros((2, 2, 3), np.uint8)).save(tmp_path / "textures" / "tiles.png")
    path = tmp_path / "courtyard.toml"
    path.write_text(example)
    scene = load_description(path)
    assert [o.name for o in scene.objects] == ["floor", "statue", "ball"]
    lo, hi = scene.objects[1].world_bounds()
    assert hi[1] - lo[1] == pytest.approx(2.0) and lo[1] == pytest.approx(0.0)  # fit_size, base, Z-up
    assert len(scene.lights) == 3 and scene.is_dynamic


# ---------------------------------------------------------------- issue 13, defect 16: bounds on what a file controls

HOSTILE = [
    ("bad.json", '{"objects": ' + "[" * 100_000 + "]" * 100_000 + "}", "invalid JSON: nested deeper than 32 levels"),
    ("bad.toml", "objects = " + "[" * 100_000 + "]" * 100_000, "invalid TOML: nested deeper than 32 levels"),
    ("bad.toml", "near = {a = " * 3000 + "1" + "}" * 3000, "nested deeper than 32 levels"),
    ("bad.json", '{"near": ' + "1" * 5000 + "}", "near: a number of 5000 characters"),
    ("bad.toml", "near = " + "1" * 5000, "invalid TOML: "),
    ("bad.toml", "near = " + "1" * 401, "near: an integer of more than 100 digits"),
    ("bad.json", '{"near": 1' + "0" * 400 + "}", "near: a number of 401 characters"),
    ("bad.toml", "near = 1e400", "near: inf is not a finite number"),
    ("bad.toml", "far = nan", "far: nan is not a finite number"),
    ("bad.json", '{"far": Infinity}', "far: Infinity is not a finite number"),
    ("bad.toml", "near = 10000000000000000000000000", "near: must be at most 1e+12"),
    ("bad.toml", "far = 1e300", "far: must be at most 1e+15"),
    ("bad.toml", "near = 1e-300", "near: must be at least 1e-09"),
    ("bad.toml", "[viewer_origin]\nposition = [0, 1, 0]\nquaternion = [1, 0, 1e308, 0]",
     "viewer_origin.quaternion: values must lie in [-1e+09, 1e+09]"),
    ("bad.toml", "[[objects]]\nbuiltin = \"sphere\"\nsegments = 1000000",
     "objects[0].segments: expected an integer in 3..1024"),
    ("bad.toml", "[[objects]]\nbuiltin = \"cylinder\"\nsegments = 9223372036854775808",
     "objects[0].segments: expected an integer in 3..1024"),
    ("bad.toml", "[[objects]]\nbuiltin = \"box\"\nposition = [1e300, 0, 0]", "objects[0].position: values must lie in"),
    ("bad.toml", "[[objects]]\nbuiltin = \"box\"\nscale = 1e-300", "objects[0].scale: must be at least 1e-09"),
    ("bad.toml", "[[objects]]\nbuiltin = \"box\"\nsize = [1, 1e-300, 1]", "objects[0].size: must be positive"),
    ("bad.toml", "[[objects]]\nbuiltin = \"box\"\n[objects.animation]\nkind = \"spin\"\nspeed = 1e300",
     "objects[0].animation.speed: must be at most 1e+09"),
    ("bad.toml", "[[lights]]\nkind = \"point\"\nposition = [0, 0, 0]\nintensity = 1e30",
     "lights[0].intensity: must be at most 1e+09"),
    ("bad.toml", "[[objects]]\nasset = \"models/tower.obj\"\nsplit = 1", "objects[0].split: expected a whole number"),
    ("bad.toml", "[[objects]]\nasset = \"models/tower.obj\"\nsplit = 9223372036854775808", "objects[0].split"),
    ("bad.toml", '[[objects]]\nbuiltin = "box"\ntexture = "a\\u0000b"', "objects[0].texture: file"),
    ("bad.toml", f'[[objects]]\nbuiltin = "box"\ntexture = "{"x" * 5000}"', "objects[0].texture: at most 4096"),
    ("bad.toml", f'name = "{"n" * 300}"', "name: at most 256 characters, got 300"),
    ("bad.toml", f'description = "{"d" * 5000}"', "description: at most 4096 characters, got 5000"),
    ("bad.toml", f'[[objects]]\nname = "{"o" * 300}"\nbuiltin = "box"', "objects[0].name: at most 256 characters"),
]


@pytest.mark.parametrize("name, text, message", HOSTILE, ids=[m.split(":")[0][:40] for _, _, m in HOSTILE])
def test_hostile_descriptions_raise_scene_error_naming_the_problem(assets, name, text, message):
    path = assets / name
    path.write_text(text)
    with pytest.raises(SceneError) as info:
        load_description(path)
    assert str(info.value).startswith(f"{path}: ")
    assert message in str(info.value)


def test_object_count_and_triangle_budget(assets, monkeypatch):
    from pibr.scenes import description

    path = assets / "many.toml"
    path.write_text('[[objects]]\nbuiltin = "box"\n' * 3)
    monkeypatch.setattr(description, "MAX_OBJECTS", 2)
    with pytest.raises(SceneError, match="objects: at most 2 objects, got 3"):
        load_description(path)
    monkeypatch.setattr(description, "MAX_OBJECTS", 100)
    path.write_text('[[objects]]\nbuiltin = "sphere"\nsegments = 1024\n' * 2)
    monkeypatch.setattr(description, "MAX_TRIANGLES", 1_500_000)   # one sphere of 1024 segments fits, two do not
    with pytest.raises(SceneError, match=r"objects\[1\].segments: the scene would have more than 1500000 triangles"):
        load_description(path)


def test_largest_sphere_builds_quickly(assets):
    from pibr.scenes.description import MAX_SEGMENTS, sphere_mesh

    mesh = sphere_mesh(1.0, MAX_SEGMENTS)
    rings = MAX_SEGMENTS // 2
    assert len(mesh.faces) == MAX_SEGMENTS * (2 * rings - 2)


@pytest.mark.parametrize("segments", [3, 4, 7, 32])
def test_sphere_faces_keep_their_order(segments):
    """The vectorised UV sphere makes exactly the triangles, in the order, of the loop it replaced."""
    from pibr.scenes.description import _drop_unused, _orient, sphere_mesh

    rings = max(segments // 2, 2)
    theta, phi = np.linspace(0, np.pi, rings + 1), np.linspace(0, 2 * np.pi, segments + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    n = np.stack([np.sin(t) * np.sin(p), np.cos(t), np.sin(t) * np.cos(p)], axis=-1).reshape(-1, 3)
    uv = np.stack([p / (2 * np.pi), 1 - t / np.pi], axis=-1).reshape(-1, 2)
    faces, cols = [], segments + 1
    for i in range(rings):
        for j in range(segments):
            a, b, c, d = i * cols + j, i * cols + j + 1, (i + 1) * cols + j, (i + 1) * cols + j + 1
            if i > 0:
                faces.append((a, c, b))
            if i < rings - 1:
                faces.append((b, c, d))
    f = np.array(faces)
    reference = _drop_unused(Mesh(n * 0.7, _orient(n * 0.7, f, n), n, uv))
    mesh = sphere_mesh(0.7, segments)
    assert np.array_equal(mesh.faces, reference.faces) and np.array_equal(mesh.vertices, reference.vertices)


def test_limits_are_documented():
    from pibr.scenes import description

    doc = description.__doc__
    for name in ("MAX_DESCRIPTION_BYTES", "MAX_MAGNITUDE", "MIN_POSITIVE", "MAX_SEGMENTS", "MAX_OBJECTS",
                 "MAX_TRIANGLES", "MIN_PIECE_TRIANGLES", "MAX_NAME_CHARS", "MAX_LIGHTS"):
        assert name in doc, name
    assert f"3 .. MAX_SEGMENTS ({description.MAX_SEGMENTS}:" in doc
