"""Scene description files: compose a scene from assets and primitives in TOML or JSON.

All numbers in a description are in metres, degrees where the key says ``_deg``, radians
and seconds in animations, with pibr's axes (right-handed, +Y up, the viewer looks along
-Z). ``units`` and ``up`` only say how to read the *asset files* (each object may override
them). Paths are relative to the description file. Unknown keys are errors, so typos
do not pass silently; every error names the file and the key path, e.g.
``scene.toml: objects[2].position: expected 3 numbers, got [1, 2]``.

A complete example (``courtyard.toml``)::

    name = "courtyard"                 # default: the file name without extension
    description = "A statue on a tiled floor, a ball circling it"
    units = "cm"                       # asset files' unit (m, cm, mm, km, in, ft or metres per unit)
    up = "z"                           # asset files' up axis: "y", "z" or "auto"
    near = 0.05                        # clip spheres, metres (defaults 0.1 and 1000)
    far = 200.0
    sky_color = [0.62, 0.76, 0.92]     # linear RGB in [0, 1]
    extra_view = true                  # does this scene need the dual view's extra view
    view_region = [[-3, 1.0, 2], [3, 2.2, 8]]   # optional (2, 3) box where eyes go

    [viewer_origin]                    # default: in front of the scene (+Z), looking at it
    position = [0, 1.6, 5]
    yaw_deg = 0                        # about +Y, positive turns left
    pitch_deg = -10                    # positive looks up
    # quaternion = [1, 0, 0, 0]        # (w, x, y, z), instead of yaw_deg / pitch_deg

    [extra_view_offset]                # optional; default: the server's
    forward = 1.5                      # metres along the view direction
    up = 1.8                           # metres up
    tilt_deg = 15                      # pitched down

    [[lights]]                         # default when no lights are given: ambient + one sun
    kind = "ambient"
    intensity = 0.3

    [[lights]]
    kind = "directional"
    direction = [-0.4, -1, -0.3]       # the direction the light travels
    color = [1.0, 0.95, 0.9]
    intensity = 0.9

    [[lights]]
    kind = "point"
    position = [0, 3, 0]
    range = 12
    intensity = 1.5

    [[objects]]
    name = "floor"
    builtin = "plane"                  # box (size [x, y, z]), sphere (radius, segments),
    size = [20, 20]                    # cylinder (radius, height, segments), plane (size [x, z])
    texture = "textures/tiles.png"
    uv_scale = 10                      # texture repeats (primitives only)

    [[objects]]
    name = "statue"
    asset = "models/statue.obj"        # any format trimesh reads: OBJ+MTL, glTF/GLB, PLY, STL ...
    units = "mm"                       # overrides the file-wide units (also: up)
    fit_size = 2.0                     # scale the asset so its largest extent is 2 m
    center = "base"                    # "bounds" or "base" (stand on y = 0); default: keep origin
    position = [0, 0, 0]
    rotation_deg = [90, 0, 0]          # yaw, pitch, roll; or quaternion = [w, x, y, z]
    scale = 1.0                        # a number or [x, y, z], positive

    [[objects]]
    name = "ball"
    builtin = "sphere"
    radius = 0.3
    position = [2, 1, 0]
    color = [0.9, 0.2, 0.1]            # RGB or RGBA in [0, 1]; multiplies an asset's own colours
    [objects.animation]                # as pibr.scenes.animation.Animation
    kind = "orbit"                     # spin | orbit | swing | slide | travel
    axis = [0, 1, 0]
    radius = 1.5                       # orbit radius, metres (position is the circle's centre)
    speed = 0.5                        # rad/s (travel: m/s)
    # pivot = [0, 1, 0]                # spin/swing pivot; default: the object's position
    # amplitude = 0.3                  # swing (rad), slide or travel (m)
    # phase = 0.0                      # rad (travel: seconds into its cycle)
    # rest = 1.0                       # travel: seconds at rest at each end before it starts again

The same structure works as JSON (``{"name": ..., "objects": [{...}, ...]}``).

Limits: every size and number a description controls is bounded, and a description past a
limit raises SceneError naming the key (the server then never builds a scene its clients
would refuse, nor one that exhausts memory)::

    file                      at most MAX_DESCRIPTION_BYTES (4 MiB)
    nesting, number literals  as protocol/bounded_json.py: 32 levels, 100 characters, finite
                              (TOML: the same checks on what tomllib parsed)
    any number                |x| <= MAX_MAGNITUDE (1e9: metres, degrees, rad/s, factors)
    positive numbers          >= MIN_POSITIVE (1e-9)
    near, far                 a session's ranges: 1e-9 .. 1e12 and .. 1e15 m (protocol/session.py)
    segments                  3 .. MAX_SEGMENTS (1024: a sphere of a million triangles)
    objects                   at most MAX_OBJECTS (100,000, a proxy bundle's limit), counting
                              the pieces assets are split into
    triangles                 at most MAX_TRIANGLES (30 million) in all; primitives are counted
                              before they are built
    split                     0 or MIN_PIECE_TRIANGLES (64) .. 2**31 - 1 (scenes/loaders.py)
    name, object names        at most MAX_NAME_CHARS (256) characters; description MAX_TEXT (4096)
    lights                    at most MAX_LIGHTS (8)
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from pibr.protocol import bounded_json
from pibr.protocol.errors import InvalidPose, JSONError, SceneError
from pibr.protocol.messages import MAX_TEXT
from pibr.protocol.pose import Pose, quat_from_axis_angle, quat_from_euler, quat_normalize, quat_to_matrix
from pibr.protocol.proxy import MAX_OBJECTS
from pibr.protocol.session import FAR_RANGE, NEAR_RANGE

from .primitives import box
from .scene import Animation, Light, Material, Mesh, Scene, SceneObject

DESCRIPTION_SUFFIXES = (".toml", ".json")
MAX_DESCRIPTION_BYTES = 4 * 1024 * 1024
MAX_MAGNITUDE = 1e9
MIN_POSITIVE = 1e-9
MAX_SEGMENTS = 1024
MAX_TRIANGLES = 30_000_000
MAX_NAME_CHARS = 256
MAX_PATH_CHARS = 4096

_TOP_KEYS = ("name", "description", "units", "up", "near", "far", "sky_color", "viewer_origin",
             "extra_view", "extra_view_offset", "view_region", "lights", "objects")
_COMMON_OBJECT_KEYS = ("name", "position", "rotation_deg", "quaternion", "scale", "color", "texture",
                       "animation")
_ASSET_KEYS = ("asset", "units", "up", "fit_size", "center", "split")
PRIMITIVES = {  # kind -> parameters it accepts (besides the common ones)
    "box": ("size",),
    "sphere": ("radius", "segments"),
    "cylinder": ("radius", "height", "segments"),
    "plane": ("size",),
}
_PRIMITIVE_KEYS = ("builtin", "uv_scale")
_LIGHT_KEYS = {
    "ambient": ("kind", "color", "intensity"),
    "directional": ("kind", "color", "intensity", "direction"),
    "point": ("kind", "color", "intensity", "position", "range"),
}
_ANIMATION_KEYS = ("kind", "axis", "speed", "pivot", "radius", "amplitude", "phase", "rest")


def is_description_path(path) -> bool:
    return Path(path).suffix.lower() in DESCRIPTION_SUFFIXES


def load_description(path) -> Scene:
    """Read a ``.toml`` or ``.json`` scene description and build its :class:`Scene`."""
    path = Path(path).expanduser()
    suffix = path.suffix.lower()
    if suffix not in DESCRIPTION_SUFFIXES:
        raise SceneError(f"{path}: a scene description must be .toml or .json, got {suffix or 'no extension'!r}")
    try:
        size = path.stat().st_size
        if size > MAX_DESCRIPTION_BYTES:
            raise SceneError(f"{path}: a scene description of {size} bytes exceeds the limit of "
                             f"{MAX_DESCRIPTION_BYTES}")
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SceneError(f"{path}: scene description does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(f"{path}: cannot read scene description: {exc}") from exc
    return build_scene(parse_description(text, suffix, path), path)


def parse_description(text: str, suffix: str, path) -> dict:
    """The tree of a description's ``text`` (``suffix`` .toml or .json), within the limits of
    :mod:`pibr.protocol.bounded_json`; SceneError naming ``path`` otherwise."""
    import tomllib

    try:
        if suffix == ".json":
            return bounded_json.loads(text, what="invalid JSON", max_bytes=MAX_DESCRIPTION_BYTES)
        bounded_json.check_toml_depth(text, what="invalid TOML")
        try:
            data = tomllib.loads(text)
        except ValueError as exc:   # TOMLDecodeError, or int() refusing a literal of over 4300 digits
            raise SceneError(f"{path}: invalid TOML: {exc}") from None
        bounded_json.check_tree(data, what="invalid TOML")
        return data
    except JSONError as exc:
        raise SceneError(f"{path}: {exc}") from None


def build_scene(data, path) -> Scene:
    """Build a :class:`Scene` from parsed description ``data`` (a dict); ``path`` names the file
    in errors and is the base for relative asset and texture paths."""
    return _Builder(Path(path)).scene(data)


class _Builder:
    def __init__(self, path: Path):
        self.path = path
        self.base_dir = path.parent

    # --------------------------------------------------------------- validation helpers

    def fail(self, key: str, message: str):
        where = f"{key}: " if key else ""
        raise SceneError(f"{self.path}: {where}{message}")

    def table(self, value, key: str, allowed) -> dict:
        if not isinstance(value, dict):
            self.fail(key, f"expected a table, got {_show(value)}")
        unknown = [k for k in value if k not in allowed]
        if unknown:
            prefix = f"{key}." if key else ""
            self.fail(f"{prefix}{unknown[0]}", f"unknown key; allowed here: {', '.join(allowed)}")
        return value

    def number(self, value, key: str, *, positive=False, minimum=None, maximum=MAX_MAGNITUDE) -> float:
        """A finite number in [minimum (default -MAX_MAGNITUDE), maximum]; ``positive``: at least MIN_POSITIVE."""
        if not _is_number(value):
            self.fail(key, f"expected a number, got {_show(value)}")
        lo = MIN_POSITIVE if positive else (-MAX_MAGNITUDE if minimum is None else minimum)
        if positive and value <= 0:
            self.fail(key, f"must be positive, got {_show(value)}")
        if value < lo:
            self.fail(key, f"must be at least {lo:g}, got {_show(value)}")
        if value > maximum:   # compared before float(): an int of 400 digits does not fit one
            self.fail(key, f"must be at most {maximum:g}, got {_show(value)}")
        return float(value)

    def integer(self, value, key: str, minimum: int, maximum: int) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or not minimum <= value <= maximum:
            self.fail(key, f"expected an integer in {minimum}..{maximum}, got {_show(value)}")
        return value

    def vector(self, value, key: str, n, *, lo=-MAX_MAGNITUDE, hi=MAX_MAGNITUDE) -> tuple:
        counts = (n,) if isinstance(n, int) else tuple(n)
        want = " or ".join(str(c) for c in counts)
        ok = isinstance(value, (list, tuple)) and len(value) in counts and all(_is_number(x) for x in value)
        if not ok:
            self.fail(key, f"expected {want} numbers, got {_show(value)}")
        if min(value) < lo or max(value) > hi:
            self.fail(key, f"values must lie in [{lo:g}, {hi:g}], got {_show(value)}")
        return tuple(float(x) for x in value)

    def string(self, value, key: str, max_chars: int = MAX_NAME_CHARS) -> str:
        if not isinstance(value, str) or not value.strip():
            self.fail(key, f"expected a non-empty string, got {_show(value)}")
        if len(value) > max_chars:
            self.fail(key, f"at most {max_chars} characters, got {len(value)}")
        return value

    def boolean(self, value, key: str) -> bool:
        if not isinstance(value, bool):
            self.fail(key, f"expected true or false, got {_show(value)}")
        return value

    def choice(self, value, key: str, choices) -> str:
        if value not in choices:
            self.fail(key, f"expected one of {', '.join(map(str, choices))}, got {_show(value)}")
        return value

    def units(self, value, key: str):
        from .loaders import unit_scale

        try:
            unit_scale(value)
        except SceneError as exc:
            self.fail(key, str(exc))
        return value

    def file(self, value, key: str) -> Path:
        text = self.string(value, key, MAX_PATH_CHARS)
        try:
            p = Path(text).expanduser()
            p = p if p.is_absolute() else self.base_dir / p
            found = p.is_file()
        except (OSError, ValueError, RuntimeError) as exc:   # a NUL byte, a name too long, ~nobody
            self.fail(key, f"not a usable file name: {exc}")
        if not found:
            self.fail(key, f"file {str(p)!r} does not exist")
        return p

    def orientation(self, t: dict, key: str, euler_key: str, euler_names) -> np.ndarray:
        """Quaternion (4,) from ``quaternion`` or Euler degrees (yaw about Y, pitch about X, roll about Z)."""
        if "quaternion" in t:
            if euler_key in t or any(k in t for k in euler_names):
                self.fail(f"{key}quaternion", f"give either quaternion or {euler_key or '/'.join(euler_names)}, not both")
            q = self.vector(t["quaternion"], f"{key}quaternion", 4)
            try:
                return quat_normalize(q)
            except InvalidPose as exc:
                self.fail(f"{key}quaternion", str(exc))
        if euler_key:
            angles = self.vector(t.get(euler_key, (0, 0, 0)), f"{key}{euler_key}", 3)
        else:
            angles = tuple(self.number(t.get(k, 0), f"{key}{k}") for k in euler_names) + (0.0,)
        return quat_from_euler(np.radians(angles), "yxz")

    # --------------------------------------------------------------- the scene

    def scene(self, data) -> Scene:
        d = self.table(data, "", _TOP_KEYS)
        name = self.string(d["name"], "name") if "name" in d else self.path.stem
        description = d.get("description", "")
        if not isinstance(description, str):
            self.fail("description", f"expected a string, got {_show(description)}")
        if len(description) > MAX_TEXT:
            self.fail("description", f"at most {MAX_TEXT} characters, got {len(description)}")
        self.default_units = self.units(d.get("units", "m"), "units")
        self.default_up = self.choice(d.get("up", "auto"), "up", ("y", "z", "auto"))
        self.notes = []
        self.triangles = 0
        near = self.number(d.get("near", 0.1), "near", minimum=NEAR_RANGE[0], maximum=NEAR_RANGE[1])
        far = self.number(d.get("far", 1000.0), "far", minimum=FAR_RANGE[0], maximum=FAR_RANGE[1])
        if far <= near:
            self.fail("far", f"must be greater than near ({near}), got {far}")
        sky = self.vector(d.get("sky_color", (0.62, 0.76, 0.92)), "sky_color", 3, lo=0.0, hi=1.0)
        extra_view = self.boolean(d.get("extra_view", True), "extra_view")
        offset = self.extra_offset(d["extra_view_offset"]) if "extra_view_offset" in d else None
        region = self.view_region(d["view_region"]) if "view_region" in d else None

        objects = []
        raw_objects = d.get("objects", [])
        if not isinstance(raw_objects, list):
            self.fail("objects", f"expected a list of tables, got {_show(raw_objects)}")
        if len(raw_objects) > MAX_OBJECTS:
            self.fail("objects", f"at most {MAX_OBJECTS} objects, got {len(raw_objects)}")
        used_names: dict[str, int] = {}
        for i, o in enumerate(raw_objects):
            objects.extend(self.object(o, i, used_names))
            if len(objects) > MAX_OBJECTS:
                self.fail(f"objects[{i}]", f"the scene has more than {MAX_OBJECTS} objects (asset pieces included)")

        kwargs = {}
        if "lights" in d:
            kwargs["lights"] = self.lights(d["lights"])
        if "viewer_origin" in d:
            viewer = self.viewer(d["viewer_origin"])
        else:
            from .loaders import default_viewer

            bounds = _bounds(objects)
            viewer = default_viewer(bounds) if bounds is not None else Pose.make((0.0, 1.6, 0.0))
        try:
            return Scene(name=name, objects=objects, description=description, viewer_origin=viewer,
                         near=near, far=far, sky_color=sky, extra_view=extra_view,
                         extra_view_offset=offset, view_region=region, source=str(self.path), notes=self.notes,
                         **kwargs)
        except SceneError as exc:
            self.fail("", str(exc))

    def viewer(self, value) -> Pose:
        key = "viewer_origin"
        t = self.table(value, key, ("position", "yaw_deg", "pitch_deg", "quaternion"))
        if "position" not in t:
            self.fail(f"{key}.position", "required")
        position = self.vector(t["position"], f"{key}.position", 3)
        return Pose.make(position, self.orientation(t, f"{key}.", "", ("yaw_deg", "pitch_deg")))

    def extra_offset(self, value) -> Pose:
        key = "extra_view_offset"
        t = self.table(value, key, ("forward", "up", "tilt_deg"))
        for k in ("forward", "up", "tilt_deg"):
            if k not in t:
                self.fail(f"{key}.{k}", "required (the offset needs forward, up and tilt_deg)")
        forward = self.number(t["forward"], f"{key}.forward")
        up = self.number(t["up"], f"{key}.up")
        tilt = self.number(t["tilt_deg"], f"{key}.tilt_deg")
        # Same convention as the server's --extra-offset: forward along -Z, up along +Y, pitched down.
        return Pose.make((0.0, up, -forward), quat_from_axis_angle((1.0, 0.0, 0.0), -math.radians(tilt)))

    def view_region(self, value) -> np.ndarray:
        if not isinstance(value, list) or len(value) != 2:
            self.fail("view_region", f"expected [[min x, y, z], [max x, y, z]], got {_show(value)}")
        lo = np.array(self.vector(value[0], "view_region[0]", 3))
        hi = np.array(self.vector(value[1], "view_region[1]", 3))
        if np.any(hi <= lo):
            self.fail("view_region", "the max corner must exceed the min corner on every axis")
        return np.stack([lo, hi])

    def lights(self, value) -> list[Light]:
        from .scene import MAX_LIGHTS

        if not isinstance(value, list):
            self.fail("lights", f"expected a list of tables, got {_show(value)}")
        if len(value) > MAX_LIGHTS:
            self.fail("lights", f"at most {MAX_LIGHTS} lights, got {len(value)}")
        out = []
        for i, raw in enumerate(value):
            key = f"lights[{i}]"
            if not isinstance(raw, dict):
                self.fail(key, f"expected a table, got {_show(raw)}")
            if "kind" not in raw:
                self.fail(f"{key}.kind", f"required: one of {', '.join(_LIGHT_KEYS)}")
            kind = self.choice(raw["kind"], f"{key}.kind", tuple(_LIGHT_KEYS))
            t = self.table(raw, key, _LIGHT_KEYS[kind])
            kw = {"kind": kind}
            if "color" in t:
                kw["color"] = self.vector(t["color"], f"{key}.color", 3, lo=0.0)
            if "intensity" in t:
                kw["intensity"] = self.number(t["intensity"], f"{key}.intensity", minimum=0.0)
            if "direction" in t:
                kw["direction"] = self.vector(t["direction"], f"{key}.direction", 3)
                if np.linalg.norm(kw["direction"]) < 1e-12:
                    self.fail(f"{key}.direction", "must not be zero")
            if "position" in t:
                kw["position"] = self.vector(t["position"], f"{key}.position", 3)
            if "range" in t:
                kw["range"] = self.number(t["range"], f"{key}.range", positive=True)
            out.append(Light(**kw))
        return out

    # --------------------------------------------------------------- objects

    def object(self, raw, i: int, used_names: dict) -> list[SceneObject]:
        key = f"objects[{i}]"
        if not isinstance(raw, dict):
            self.fail(key, f"expected a table, got {_show(raw)}")
        if ("asset" in raw) == ("builtin" in raw):
            self.fail(key, "needs exactly one of 'asset' (a file) or 'builtin' "
                           f"({', '.join(PRIMITIVES)})")
        if "builtin" in raw:
            kind = self.choice(raw["builtin"], f"{key}.builtin", tuple(PRIMITIVES))
            t = self.table(raw, key, _COMMON_OBJECT_KEYS + _PRIMITIVE_KEYS + PRIMITIVES[kind])
            default_name = kind
        else:
            t = self.table(raw, key, _COMMON_OBJECT_KEYS + _ASSET_KEYS)
            asset = self.file(t["asset"], f"{key}.asset")
            default_name = asset.stem

        if "name" in t:
            name = self.string(t["name"], f"{key}.name")
            if name in used_names:
                self.fail(f"{key}.name", f"{name!r} is already used by objects[{used_names[name]}]")
        else:
            name, k = default_name, 2
            while name in used_names:
                name, k = f"{default_name}~{k}", k + 1
        used_names[name] = i

        position = np.array(self.vector(t.get("position", (0, 0, 0)), f"{key}.position", 3))
        rotation = quat_to_matrix(self.orientation(t, f"{key}.", "rotation_deg", ()))
        scale = t.get("scale", 1.0)
        if isinstance(scale, (list, tuple)):
            scale = np.array(self.vector(scale, f"{key}.scale", 3))
            if np.any(scale < MIN_POSITIVE):
                self.fail(f"{key}.scale", f"must be positive (at least {MIN_POSITIVE:g}), got {_show(t['scale'])}")
        else:
            scale = np.full(3, self.number(scale, f"{key}.scale", positive=True))
        color = self.vector(t["color"], f"{key}.color", (3, 4), lo=0.0, hi=1.0) if "color" in t else None
        texture = None
        if "texture" in t:
            from .loaders import load_texture

            texture = load_texture(self.file(t["texture"], f"{key}.texture"))
        animation = self.animation(t["animation"], f"{key}.animation", position) if "animation" in t else None

        placement = np.eye(4)
        placement[:3, :3] = rotation
        placement[:3, 3] = position
        if "builtin" in t:
            mesh = self.primitive(t, key, scale)
            material = Material(name=name, base_color=color if color is not None else (0.8, 0.8, 0.8, 1.0),
                                texture=texture)
            return [SceneObject(name, mesh, material, placement, animation)]

        parts = self.asset(t, key, asset, name, scale)
        self.count_triangles(f"{key}.asset", sum(p.mesh.triangle_count for p in parts))
        if texture is not None and all(p.mesh.uvs is None for p in parts):
            self.fail(f"{key}.texture", f"asset {asset.name!r} has no texture coordinates to map a texture with")
        objects = []
        for p in parts:
            material = p.material
            if color is not None or (texture is not None and p.mesh.uvs is not None):
                material = Material(name=material.name,
                                    base_color=color if color is not None else material.base_color,
                                    texture=texture if texture is not None and p.mesh.uvs is not None
                                    else material.texture)
            objects.append(SceneObject(p.name, p.mesh, material, placement @ p.transform, animation, layer=p.layer))
        return objects

    def asset(self, t: dict, key: str, path: Path, name: str, scale: np.ndarray) -> list[SceneObject]:
        from .loaders import load_asset

        units = self.units(t["units"], f"{key}.units") if "units" in t else self.default_units
        up = self.choice(t["up"], f"{key}.up", ("y", "z", "auto")) if "up" in t else self.default_up
        fit = self.number(t["fit_size"], f"{key}.fit_size", positive=True) if "fit_size" in t else None
        center = self.choice(t["center"], f"{key}.center", ("bounds", "base")) if "center" in t else None
        split = None
        if "split" in t:
            from .loaders import MAX_PIECE_TRIANGLES, MIN_PIECE_TRIANGLES

            split = t["split"]
            if isinstance(split, bool) or not isinstance(split, int) or not (
                    split == 0 or MIN_PIECE_TRIANGLES <= split <= MAX_PIECE_TRIANGLES):
                self.fail(f"{key}.split", f"expected a whole number of triangles, 0 (none) or "
                                          f"{MIN_PIECE_TRIANGLES}..{MAX_PIECE_TRIANGLES}, got {_show(split)}")
        try:
            return load_asset(path, up=up, units=units, fit_size=fit, center=center, scale=scale, name=name,
                              notes=self.notes, split=split)
        except SceneError as exc:
            self.fail(f"{key}.asset", str(exc))

    def primitive(self, t: dict, key: str, scale: np.ndarray) -> Mesh:
        kind = t["builtin"]
        uv_scale = self.number(t.get("uv_scale", 1.0), f"{key}.uv_scale", positive=True)
        if kind in ("box", "plane"):
            n = 3 if kind == "box" else 2
            size = np.array(self.vector(t.get("size", (1.0,) * n), f"{key}.size", n))
            if np.any(size < MIN_POSITIVE):
                self.fail(f"{key}.size", f"must be positive (at least {MIN_POSITIVE:g}), got {_show(t['size'])}")
            mesh = box(size * scale) if kind == "box" else plane_mesh(size * scale[[0, 2]])
        else:
            radius = self.number(t.get("radius", 0.5), f"{key}.radius", positive=True)
            segments = self.integer(t.get("segments", 32), f"{key}.segments", 3, MAX_SEGMENTS)
            rings = max(segments // 2, 2)
            self.count_triangles(f"{key}.segments", segments * (2 * rings - 2) if kind == "sphere" else 4 * segments)
            if kind == "sphere":
                mesh = sphere_mesh(radius, segments)
            else:
                height = self.number(t.get("height", 1.0), f"{key}.height", positive=True)
                mesh = cylinder_mesh(radius, height, segments)
            mesh = scale_mesh(mesh, scale)
        if uv_scale != 1.0:
            mesh = Mesh(mesh.vertices, mesh.faces, mesh.normals, mesh.uvs * uv_scale, mesh.colors)
        return mesh

    def count_triangles(self, key: str, n: int) -> None:
        self.triangles += n
        if self.triangles > MAX_TRIANGLES:
            self.fail(key, f"the scene would have more than {MAX_TRIANGLES} triangles")

    def animation(self, value, key: str, position: np.ndarray) -> Animation:
        t = self.table(value, key, _ANIMATION_KEYS)
        if "kind" not in t:
            self.fail(f"{key}.kind", f"required: one of {', '.join(Animation.KINDS)}")
        kw = {"kind": self.choice(t["kind"], f"{key}.kind", Animation.KINDS)}
        for k in ("axis", "pivot"):
            if k in t:
                kw[k] = self.vector(t[k], f"{key}.{k}", 3)
        for k in ("speed", "radius", "amplitude", "phase", "rest"):
            if k in t:
                kw[k] = self.number(t[k], f"{key}.{k}")
        if "pivot" not in kw:
            kw["pivot"] = tuple(position)  # spinning in place is what users mean by default
        try:
            return Animation(**kw)
        except SceneError as exc:
            self.fail(key, str(exc))


def _is_number(value) -> bool:
    """An int or a finite float (an int of any size: it is compared, never converted, first)."""
    return (isinstance(value, int) and not isinstance(value, bool)) or (isinstance(value, float)
                                                                        and math.isfinite(value))


def _show(value) -> str:
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 200:
        return f"an integer of {value.bit_length()} bits"   # str() refuses past 4300 digits
    try:
        text = json.dumps(value) if isinstance(value, (list, dict, str, int, float, bool)) else repr(value)
    except (ValueError, TypeError, RecursionError):   # not JSON (a TOML date, a huge int inside a list, ...)
        text = f"a {type(value).__name__}"
    return text if len(text) <= 60 else text[:57] + "..."


def _bounds(objects) -> np.ndarray | None:
    bs = [o.world_bounds() for o in objects if len(o.mesh.vertices)]
    if not bs:
        return None
    bs = np.array(bs)
    return np.stack([bs[:, 0].min(0), bs[:, 1].max(0)])


# ----------------------------------------------------------------------------- primitives
# Meshes centred on the origin, +Y up, with UVs in [0, 1] (v = 0 at the image's bottom).

def _orient(vertices, faces, normals) -> np.ndarray:
    """Flip faces whose winding disagrees with their vertex normals (so all are counter-clockwise outside)."""
    v = vertices.astype(np.float64)
    cross = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    along = np.einsum("ij,ij->i", cross, normals[faces].sum(axis=1))
    faces = faces.copy()
    faces[along < 0] = faces[along < 0][:, [0, 2, 1]]
    return faces


def plane_mesh(size) -> Mesh:
    """Horizontal square at y = 0 facing +Y, ``size`` (2,) = (x extent, z extent) metres."""
    hx, hz = np.asarray(size, dtype=np.float64) / 2
    v = np.array([[-hx, 0, hz], [hx, 0, hz], [hx, 0, -hz], [-hx, 0, -hz]])
    n = np.tile([0.0, 1.0, 0.0], (4, 1))
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float64)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    return Mesh(v, _orient(v, f, n), n, uv)


def sphere_mesh(radius: float, segments: int = 32) -> Mesh:
    """UV sphere: ``segments`` around, ``segments // 2`` rings (at least 2), smooth normals."""
    rings = max(segments // 2, 2)
    theta = np.linspace(0, np.pi, rings + 1)             # from the north pole
    phi = np.linspace(0, 2 * np.pi, segments + 1)         # the seam column is duplicated for UVs
    t, p = np.meshgrid(theta, phi, indexing="ij")
    n = np.stack([np.sin(t) * np.sin(p), np.cos(t), np.sin(t) * np.cos(p)], axis=-1).reshape(-1, 3)
    uv = np.stack([p / (2 * np.pi), 1 - t / np.pi], axis=-1).reshape(-1, 2)
    cols = segments + 1
    i, j = np.meshgrid(np.arange(rings), np.arange(segments), indexing="ij")
    a, c = i * cols + j, (i + 1) * cols + j
    b, d = a + 1, c + 1
    # Per quad (ring i, column j) the upper triangle (not at the north pole), then the lower
    # (not at the south pole), in ring-major order.
    quads = np.stack([np.stack([a, c, b], -1), np.stack([b, c, d], -1)], axis=2)   # (rings, segments, 2, 3)
    keep = np.stack([i > 0, i < rings - 1], axis=2)
    f = quads[keep]
    v = n * radius
    mesh = Mesh(v, _orient(v, f, n), n, uv)
    return _drop_unused(mesh)


def cylinder_mesh(radius: float, height: float, segments: int = 32) -> Mesh:
    """Cylinder along +Y centred on the origin, with caps; smooth side normals, flat cap normals."""
    phi = np.linspace(0, 2 * np.pi, segments + 1)
    ring = np.stack([np.sin(phi), np.zeros_like(phi), np.cos(phi)], axis=-1)
    h = height / 2
    verts, norms, uvs, faces = [], [], [], []
    # side: two rings with radial normals
    for y, v in ((-h, 0.0), (h, 1.0)):
        verts.append(ring * radius + [0, y, 0])
        norms.append(ring)
        uvs.append(np.stack([phi / (2 * np.pi), np.full_like(phi, v)], axis=-1))
    cols = segments + 1
    for j in range(segments):
        faces += [(j, j + 1, cols + j + 1), (j, cols + j + 1, cols + j)]
    # caps: a centre vertex plus a ring with flat normals
    for y, sign in ((-h, -1.0), (h, 1.0)):
        base = sum(len(x) for x in verts)
        verts.append(np.vstack([[0, y, 0], ring * radius + [0, y, 0]]))
        norms.append(np.tile([0.0, sign, 0.0], (cols + 1, 1)))
        uvs.append(np.vstack([[0.5, 0.5], 0.5 + 0.5 * ring[:, [0, 2]]]))
        faces += [(base, base + 1 + j, base + 2 + j) for j in range(segments)]
    v, n, uv, f = np.vstack(verts), np.vstack(norms), np.vstack(uvs), np.array(faces)
    return Mesh(v, _orient(v, f, n), n, uv)


def _drop_unused(mesh: Mesh) -> Mesh:
    used = np.unique(mesh.faces)
    remap = np.zeros(len(mesh.vertices), dtype=np.int64)
    remap[used] = np.arange(len(used))
    return Mesh(mesh.vertices[used], remap[mesh.faces], mesh.normals[used],
                None if mesh.uvs is None else mesh.uvs[used],
                None if mesh.colors is None else mesh.colors[used])


def scale_mesh(mesh: Mesh, scale) -> Mesh:
    """``mesh`` scaled by ``scale`` (3,) > 0 per axis; normals follow (inverse transpose)."""
    s = np.broadcast_to(np.asarray(scale, dtype=np.float64), (3,))
    if np.all(s == 1.0):
        return mesh
    n = mesh.normals / s
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    return Mesh(mesh.vertices * s, mesh.faces, n, mesh.uvs, mesh.colors)
