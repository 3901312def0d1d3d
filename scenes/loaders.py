"""Load real assets (OBJ+MTL, glTF/GLB, PLY, STL, OFF, ... anything ``trimesh`` reads) as scene objects.

Every asset is converted once, here, to pibr's conventions (metres, right-handed, +Y up):

* node transforms of scene graphs (glTF) are applied, and so are ``units`` and ``up``;
* each geometry (trimesh already splits OBJ per material and glTF per primitive) becomes
  one :class:`SceneObject` with a unique name;
* vertices are re-centred on their bounding-box centre, the offset going into the float64
  ``transform``, so float32 vertices stay small even for assets placed at 1e6 m;
* degenerate triangles, triangles touching NaN/inf vertices and unreferenced vertices are
  removed; point clouds and line sets are skipped with a warning;
* materials: glTF ``baseColorFactor`` x ``baseColorTexture``, OBJ ``Kd`` or ``map_Kd``,
  vertex or face colours (PLY) as :attr:`Mesh.colors`; textures become ``(h, w, 3) uint8``
  of at most :data:`MAX_TEXTURE_SIZE` pixels a side, and only for meshes that have UVs.

Any failure raises :class:`SceneError` naming the file and the reason.
"""
from __future__ import annotations

import io
import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pibr.protocol.errors import SceneError
from pibr.protocol.pose import Pose

from .scene import Material, Mesh, SceneObject

log = logging.getLogger(__name__)

#: Longest texture side after loading; larger images are downscaled (aspect kept).
MAX_TEXTURE_SIZE = 2048
#: Range of ``split`` (triangles per piece; 0 keeps meshes whole): smaller pieces would turn one
#: mesh into more objects than a scene (or a proxy bundle) may hold.
MIN_PIECE_TRIANGLES, MAX_PIECE_TRIANGLES = 64, 2**31 - 1

#: Metres per unit, for ``units=``.
UNIT_SCALES = {
    "m": 1.0, "meter": 1.0, "meters": 1.0, "metre": 1.0, "metres": 1.0,
    "cm": 0.01, "centimeters": 0.01, "centimetres": 0.01,
    "mm": 0.001, "millimeters": 0.001, "millimetres": 0.001,
    "km": 1000.0,
    "in": 0.0254, "inch": 0.0254, "inches": 0.0254,
    "ft": 0.3048, "foot": 0.3048, "feet": 0.3048,
}

UP_AXES = ("y", "z", "auto")
CENTER_MODES = (None, "bounds", "base")

# glTF is +Y up and in metres by specification: 'auto' never guesses for it.
_Y_UP_FORMATS = (".gltf", ".glb")
#: Formats +Y up by convention, not by specification: ``auto`` overrules them only on strong evidence.
_Y_UP_BY_CONVENTION = {".obj": "OBJ"}
#: The share of the surface area facing +Z without a counterpart that overrules a +Y convention
#: (a room open on one side leaves one wall's share, 10-20 %; a pitch or terrain most of it).
STRONG_Z_EVIDENCE = 1 / 3

# Z-up to Y-up: a rotation of -90 degrees about +X, (x, y, z) -> (x, z, -y).
_Z_TO_Y = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, -1.0, 0, 0], [0, 0, 0, 1.0]])


def unit_scale(units) -> float:
    """Metres per unit: a name from :data:`UNIT_SCALES`, a positive number, or None (metres)."""
    if units is None:
        return 1.0
    if isinstance(units, str):
        key = units.strip().lower()
        if key not in UNIT_SCALES:
            raise SceneError(f"unknown units {units!r}; use a number (metres per unit) or one of "
                             f"m, cm, mm, km, in, ft")
        return UNIT_SCALES[key]
    if isinstance(units, bool) or not isinstance(units, (int, float)):
        raise SceneError(f"units must be a name or a number, got {units!r}")
    if not math.isfinite(units) or units <= 0:
        raise SceneError(f"units scale must be a positive finite number, got {units!r}")
    return float(units)


def asset_formats() -> list[str]:
    """File extensions (without dot) that the installed trimesh can read."""
    import trimesh

    return sorted(trimesh.available_formats())


def is_asset_path(path) -> bool:
    """Whether ``path``'s extension is one trimesh reads (the file need not exist)."""
    name = Path(path).name.lower()
    return any(name.endswith("." + ext) for ext in asset_formats())


# ----------------------------------------------------------------------------- textures

def texture_array(image, max_size: int = MAX_TEXTURE_SIZE) -> np.ndarray:
    """PIL image -> (h, w, 3) uint8, downscaled so neither side exceeds ``max_size``."""
    from PIL import Image

    if image.mode in ("I", "I;16", "I;16B", "I;16L", "F"):
        # 16-bit / float greyscale: PIL's convert("RGB") clips instead of scaling.
        a = np.asarray(image, dtype=np.float64)
        peak = a.max() if a.size and a.max() > 0 else 1.0
        image = Image.fromarray(np.clip(a / peak * 255.0 + 0.5, 0, 255).astype(np.uint8))
    if image.mode != "RGB":
        image = image.convert("RGB")
    w, h = image.size
    if max(w, h) > max_size:
        s = max_size / max(w, h)
        image = image.resize((max(1, round(w * s)), max(1, round(h * s))), Image.Resampling.LANCZOS)
    return np.ascontiguousarray(np.asarray(image, dtype=np.uint8))


def load_texture(path, max_size: int = MAX_TEXTURE_SIZE) -> np.ndarray:
    """Read an image file as a texture: (h, w, 3) uint8, at most ``max_size`` px a side."""
    from PIL import Image, UnidentifiedImageError

    path = Path(path)
    if not path.is_file():
        raise SceneError(f"{path}: texture image does not exist")
    try:
        with Image.open(path) as im:
            im.load()
            return texture_array(im, max_size)
    except (OSError, UnidentifiedImageError, ValueError) as exc:
        raise SceneError(f"{path}: cannot read texture image: {exc}") from exc


# ----------------------------------------------------------------------------- loading

@dataclass
class _Part:
    """One geometry instance in world space (float64), before re-centring."""

    name: str
    vertices: np.ndarray          # (n, 3) float64
    faces: np.ndarray             # (m, 3) int64
    normals: np.ndarray | None    # (n, 3) float64 unit, or None: let Mesh compute them
    uvs: np.ndarray | None        # (n, 2)
    colors: np.ndarray | None     # (n, 4) uint8
    material: Material


def load_asset(path, *, up: str = "auto", units=None, fit_size: float | None = None,
               center: str | None = None, scale=1.0, name: str | None = None,
               notes: list | None = None, split: int | None = None) -> list[SceneObject]:
    """Load an asset file as a list of static scene objects, in metres and +Y up.

    up       : 'y', 'z' (converted to +Y up) or 'auto' (the default; glTF: 'y' by spec; other
               formats: decided from the geometry, see :func:`guess_up`, and logged).
    units    : the file's unit, a name (m, cm, mm, km, in, ft) or metres per unit; None: metres.
    fit_size : if given, scale the asset so its largest bounding-box extent is this many metres.
    center   : None (keep the file's origin), 'bounds' (box centre to the origin) or 'base'
               (bottom centre of the box to the origin: the asset stands on y = 0).
    scale    : extra scale factor, a number or (3,) per axis, positive, applied last.
    name     : object name prefix (default: the file stem); parts are named ``name/part``.
    notes    : a list to which what was decided or fixed is appended (the up axis and why).
    split    : cut meshes of more triangles than this into spatially coherent pieces
               (scenes/split.py; default :data:`~pibr.scenes.split.DEFAULT_PIECE_TRIANGLES`,
               0 keeps every mesh whole).

    Each object's ``transform`` is the translation to its bounding-box centre; rotations,
    scales and node transforms are baked into the (float32, small) vertices.
    """
    path = Path(path).expanduser()
    if up not in UP_AXES:
        raise SceneError(f"{path}: up must be one of {', '.join(UP_AXES)}, got {up!r}")
    if center not in CENTER_MODES:
        raise SceneError(f"{path}: center must be None, 'bounds' or 'base', got {center!r}")
    try:
        to_metres = unit_scale(units)
    except SceneError as exc:
        raise SceneError(f"{path}: {exc}") from None
    if fit_size is not None and (not math.isfinite(fit_size) or fit_size <= 0):
        raise SceneError(f"{path}: fit_size must be a positive number of metres, got {fit_size!r}")
    user_scale = _check_scale(scale, path)

    tscene = _read(path)
    parts, skipped = _extract_parts(tscene, path)
    if not parts:
        what = f" (skipped: {', '.join(skipped)})" if skipped else ""
        raise SceneError(f"{path}: the asset contains no triangles{what}")

    up_reason = "as given"
    if up == "auto":
        if path.suffix.lower() in _Y_UP_FORMATS:
            up, up_reason = "y", "auto: glTF is +Y up by specification"
        else:
            up, why = guess_up(parts, convention=_Y_UP_BY_CONVENTION.get(path.suffix.lower()))
            up_reason = f"auto: {why}"
        log.info("%s: up axis %s (%s)", path, up, up_reason)
    if notes is not None:
        notes.append(f"{path.name}: +{up} up ({up_reason})")
    convert = np.diag([to_metres, to_metres, to_metres, 1.0])
    if up == "z":
        convert = convert @ _Z_TO_Y
    for p in parts:
        _transform_part(p, convert)

    lo, hi = _union_bounds(parts)
    anchor = np.zeros(3)
    if center == "bounds":
        anchor = (lo + hi) / 2
    elif center == "base":
        anchor = np.array([(lo[0] + hi[0]) / 2, lo[1], (lo[2] + hi[2]) / 2])
    factor = np.ones(3)
    if fit_size is not None:
        largest = float(np.max(hi - lo))
        if largest <= 0:
            raise SceneError(f"{path}: cannot fit_size an asset with zero extent")
        factor *= fit_size / largest
    factor = factor * user_scale
    if center is not None or fit_size is not None or np.any(user_scale != 1.0):
        m = np.diag(np.append(factor, 1.0))
        m[:3, 3] = -anchor * factor
        for p in parts:
            _transform_part(p, m)

    base = name if name is not None else path.stem
    names = _unique_names(base, [p.name for p in parts])
    from .split import DEFAULT_PIECE_TRIANGLES, split_arrays

    split = DEFAULT_PIECE_TRIANGLES if split is None else split
    if isinstance(split, bool) or not isinstance(split, int) or not (
            split == 0 or MIN_PIECE_TRIANGLES <= split <= MAX_PIECE_TRIANGLES):
        raise SceneError(f"{path}: split must be a whole number of triangles, 0 (none) or "
                         f"{MIN_PIECE_TRIANGLES}..{MAX_PIECE_TRIANGLES}, got {split!r:.40}")
    objects = []
    layers = decal_layers(parts)
    if split:
        pieces_parts, pieces_names, pieces_layers, cut = [], [], [], []
        for p, obj_name, layer in zip(parts, names, layers):
            pieces = split_arrays(p.vertices, p.faces, {"normals": p.normals, "uvs": p.uvs, "colors": p.colors},
                                  split)
            if len(pieces) > 1:
                cut.append(f"{obj_name} ({len(p.faces)} triangles) into {len(pieces)}")
            for k, (v, f, a) in enumerate(pieces):
                pieces_parts.append(_Part(p.name, v, f, a["normals"], a["uvs"], a["colors"], p.material))
                pieces_names.append(obj_name if len(pieces) == 1 else f"{obj_name}.{k}")
                pieces_layers.append(layer)
        if cut and notes is not None:
            notes.append(f"{path.name}: cut into pieces of at most {split} triangles: " + "; ".join(cut))
        parts, names, layers = pieces_parts, pieces_names, pieces_layers
    if any(layers) and notes is not None:
        notes.append(f"{path.name}: {sum(1 for x in layers if x)} part(s) lie flat on larger ones and are drawn as "
                     "decals over them (no z-fighting)")
    for p, obj_name, layer in zip(parts, names, layers):
        try:
            objects.append(_to_object(p, obj_name, layer))
        except SceneError as exc:
            raise SceneError(f"{path}: part {p.name!r}: {exc}") from None
    return objects


def _check_scale(scale, path) -> np.ndarray:
    try:
        s = np.broadcast_to(np.asarray(scale, dtype=np.float64), (3,)).copy()
    except (ValueError, TypeError):
        raise SceneError(f"{path}: scale must be a number or 3 numbers, got {scale!r}") from None
    if not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise SceneError(f"{path}: scale must be positive and finite, got {scale!r}")
    return s


def _read(path: Path):
    """trimesh.Scene of the file; every failure as a SceneError naming the file."""
    import trimesh

    if not path.exists():
        raise SceneError(f"{path}: asset file does not exist")
    if not path.is_file():
        raise SceneError(f"{path}: not a file")
    formats = asset_formats()
    if not is_asset_path(path):
        raise SceneError(f"{path}: unsupported asset format {path.suffix or '(no extension)'!r}; "
                         f"readable: {', '.join(formats)}")
    try:
        if path.suffix.lower() == ".obj":
            text, stats = normalise_obj(path)
            tscene = trimesh.load_scene(file_obj=io.BytesIO(text.encode("utf-8")), file_type="obj",
                                        resolver=trimesh.resolvers.FilePathResolver(str(path.parent)),
                                        split_objects=True, split_groups=True)
            _check_obj_counts(path, tscene, stats)
            return tscene
        return trimesh.load_scene(str(path))
    except SceneError:
        raise
    except Exception as exc:  # trimesh raises anything from KeyError to struct.error on bad files
        reason = str(exc) or type(exc).__name__
        raise SceneError(f"{path}: cannot read asset: {type(exc).__name__}: {reason}") from exc


@dataclass
class ObjStats:
    """What an OBJ file itself holds: vertices, triangles its faces make (an n-gon makes n - 2)."""

    vertices: int = 0
    triangles: int = 0
    relative_indices: int = 0
    objects: int = 0


def normalise_obj(path: Path) -> tuple[str, ObjStats]:
    """The OBJ text with what trimesh misreads rewritten, and what the file holds.

    trimesh takes relative (negative) face indices against the current object's vertices
    rather than the file's (a later object's faces then point into the wrong vertices, and a
    whole object can vanish), and is unreliable with tab-separated fields. Every index is
    made absolute and every run of whitespace one space; all else is kept."""
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError as exc:
        raise SceneError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    counts = {"v": 0, "vt": 0, "vn": 0}
    stats = ObjStats()
    out = []
    for number, line in enumerate(lines, start=1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            out.append(line)
            continue
        key = fields[0]
        if key in counts:
            counts[key] += 1
        elif key in ("o", "g"):
            stats.objects += key == "o"
        elif key == "f":
            corners = []
            for corner in fields[1:]:
                refs = corner.split("/")
                for k, (ref, kind) in enumerate(zip(refs, ("v", "vt", "vn"))):
                    if not ref:
                        continue
                    try:
                        i = int(ref)
                    except ValueError:
                        raise SceneError(f"{path}:{number}: face index {ref!r} is not an integer") from None
                    if i < 0:
                        stats.relative_indices += 1
                        i = counts[kind] + 1 + i
                    if not 1 <= i <= counts[kind]:
                        raise SceneError(f"{path}:{number}: face refers to {kind} {ref} but only "
                                         f"{counts[kind]} are defined before it")
                    refs[k] = str(i)
                corners.append("/".join(refs))
            if len(corners) >= 3:
                stats.triangles += len(corners) - 2
            out.append("f " + " ".join(corners))
            continue
        out.append(" ".join(fields))
    stats.vertices = counts["v"]
    return "\n".join(out) + "\n", stats


def _check_obj_counts(path: Path, tscene, stats: ObjStats) -> None:
    """Refuse a read that lost triangles, rather than serve a scene with parts missing."""
    loaded = sum(len(g.faces) for g in tscene.geometry.values() if hasattr(g, "faces"))
    if loaded < stats.triangles:
        raise SceneError(f"{path}: the file has {stats.triangles} triangles but only {loaded} were read "
                         "(a malformed face or an OBJ feature the reader does not handle)")
    log.info("%s: OBJ with %d vertices, %d triangles in %d geometries%s", path, stats.vertices, loaded,
             len(tscene.geometry), f"; {stats.relative_indices} relative indices made absolute"
             if stats.relative_indices else "")


def _extract_parts(tscene, path: Path) -> tuple[list[_Part], list[str]]:
    """World-space (file units, file axes) triangle parts of every node, and what was skipped."""
    import trimesh

    parts, skipped = [], []
    textures: dict[int, np.ndarray] = {}  # id(PIL image) -> array, so shared images convert once
    for node in sorted(tscene.graph.nodes_geometry):
        matrix, geom_name = tscene.graph[node]
        geom = tscene.geometry[geom_name]
        label = node if node == geom_name else f"{node} ({geom_name})"
        if not isinstance(geom, trimesh.Trimesh):
            n = len(getattr(geom, "vertices", ()))
            kind = "point cloud" if isinstance(geom, trimesh.PointCloud) else type(geom).__name__
            log.warning("%s: skipping %s %r with %d points and no triangles", path, kind, label, n)
            skipped.append(f"{kind} {label!r} with {n} points")
            continue
        if len(geom.faces) == 0:
            log.warning("%s: skipping mesh %r: it has no faces", path, label)
            skipped.append(f"mesh {label!r} without faces")
            continue
        try:
            part = _part_from_trimesh(geom, np.asarray(matrix, dtype=np.float64), node, textures)
        except SceneError as exc:
            raise SceneError(f"{path}: part {label!r}: {exc}") from None
        except (ValueError, TypeError, IndexError, AttributeError, OSError) as exc:
            # Malformed visuals (UV count mismatch, broken embedded image) surface here.
            raise SceneError(f"{path}: part {label!r}: cannot convert: {type(exc).__name__}: {exc}") from exc
        if part is None:
            log.warning("%s: skipping mesh %r: all its triangles are degenerate", path, label)
            skipped.append(f"mesh {label!r} with only degenerate triangles")
            continue
        parts.append(part)
    return parts, skipped


def _part_from_trimesh(geom, matrix: np.ndarray, node: str, textures: dict) -> _Part | None:
    """Convert one trimesh geometry placed by ``matrix`` (4, 4); None if nothing is left after cleaning."""
    vertices = np.asarray(geom.vertices, dtype=np.float64)
    faces = np.asarray(geom.faces, dtype=np.int64)
    normals = None
    # Normals read from the file sit in trimesh's cache; otherwise trimesh would compute them.
    if "vertex_normals" in getattr(geom, "_cache", ()):
        n = np.asarray(geom.vertex_normals, dtype=np.float64)
        if n.shape == vertices.shape:
            normals = n
    material, uvs, colors, face_colors = _visual_attributes(geom.visual, len(vertices), len(faces), textures)
    if face_colors is not None:
        # Face colours that differ: give every face its own three vertices so colours stay exact.
        vertices = vertices[faces].reshape(-1, 3)
        normals = normals[faces].reshape(-1, 3) if normals is not None else None
        uvs = uvs[faces].reshape(-1, 2) if uvs is not None else None
        colors = np.repeat(face_colors, 3, axis=0)
        faces = np.arange(len(vertices), dtype=np.int64).reshape(-1, 3)
    part = _Part(node, vertices, faces, normals, uvs, colors, material)
    _transform_part(part, matrix)
    return part if _clean(part) else None


def _visual_attributes(visual, n_vertices: int, n_faces: int, textures: dict):
    """(Material, uvs (n, 2) or None, vertex colours (n, 4) uint8 or None, face colours (m, 4) or None).

    Face colours are returned only when they differ between faces; uniform ones become vertex colours.
    """
    kind = getattr(visual, "kind", None)
    mat = getattr(visual, "material", None)
    if mat is None:  # ColorVisuals
        # White base: the colours alone give the surface colour, as the file means.
        white = Material(base_color=(1.0, 1.0, 1.0, 1.0))
        if kind == "vertex":
            vc = np.asarray(visual.vertex_colors, dtype=np.uint8)
            if vc.shape == (n_vertices, 4):
                return white, None, vc, None
        elif kind == "face":
            fc = np.asarray(visual.face_colors, dtype=np.uint8)
            if fc.shape == (n_faces, 4):
                if np.all(fc == fc[0]):
                    return white, None, np.repeat(fc[:1], n_vertices, axis=0), None
                return white, None, None, fc
        return Material(), None, None, None

    name = str(getattr(mat, "name", None) or "default")
    pbr = hasattr(mat, "baseColorFactor") or hasattr(mat, "baseColorTexture")
    if pbr:  # PBRMaterial (glTF): factor x texture, as the spec says
        factor = getattr(mat, "baseColorFactor", None)
        base = (1.0, 1.0, 1.0, 1.0) if factor is None else _rgba01(factor)
        image = getattr(mat, "baseColorTexture", None)
    else:  # SimpleMaterial (OBJ/MTL)
        diffuse = getattr(mat, "diffuse", None)
        base = (0.8, 0.8, 0.8, 1.0) if diffuse is None else _rgba01(diffuse)
        image = getattr(mat, "image", None)
    uv = getattr(visual, "uv", None)
    uvs = None
    if uv is not None:
        uv = np.asarray(uv, dtype=np.float64)
        if uv.shape == (n_vertices, 2) and np.all(np.isfinite(uv)):
            uvs = uv
    texture = None
    if image is not None and uvs is not None:
        key = id(image)
        if key not in textures:
            textures[key] = texture_array(image)
        texture = textures[key]
        if not pbr:
            # map_Kd replaces Kd, as Blender's importer does: exporters write a placeholder
            # "Kd 0.8" next to the texture that would otherwise darken it.
            base = (1.0, 1.0, 1.0, base[3] if len(base) == 4 else 1.0)
    colors = None
    vc = getattr(visual, "vertex_attributes", {}).get("color") if hasattr(visual, "vertex_attributes") else None
    if vc is not None:  # glTF COLOR_0 next to a material
        vc = np.asarray(vc)
        if vc.shape[0] == n_vertices and vc.ndim == 2 and vc.shape[1] in (3, 4):
            if vc.dtype.kind == "f":
                vc = np.clip(vc * 255.0 + 0.5, 0, 255)
            vc = vc.astype(np.uint8)
            if vc.shape[1] == 3:
                vc = np.concatenate([vc, np.full((n_vertices, 1), 255, np.uint8)], axis=1)
            colors = vc
    return Material(name=name, base_color=base, texture=texture), (uvs if texture is not None else None), colors, None


def _rgba01(color) -> tuple:
    """trimesh colour (uint8 0..255, or float 0..1) -> RGBA floats in [0, 1]."""
    c = np.asarray(color).reshape(-1)
    c = c / 255.0 if c.dtype.kind in "ui" else c.astype(np.float64)
    if len(c) == 3:
        c = np.append(c, 1.0)
    return tuple(float(x) for x in c[:4])


def _transform_part(part: _Part, matrix: np.ndarray) -> None:
    """Apply an affine (4, 4) to a part in place: positions, normals (inverse transpose), winding."""
    if np.array_equal(matrix, np.eye(4)):
        return
    linear = matrix[:3, :3]
    part.vertices = part.vertices @ linear.T + matrix[:3, 3]
    det = np.linalg.det(linear)
    if abs(det) < 1e-300:
        raise SceneError("a node transform is singular (it flattens the mesh)")
    if part.normals is not None:
        n = part.normals @ np.linalg.inv(linear)  # row vectors: (inv(L).T @ n.T).T
        length = np.linalg.norm(n, axis=1, keepdims=True)
        part.normals = n / np.maximum(length, 1e-300)
    if det < 0:  # a mirror turns the triangles inside out: restore counter-clockwise winding
        part.faces = part.faces[:, [0, 2, 1]]


def _clean(part: _Part) -> bool:
    """Drop degenerate triangles, triangles on non-finite vertices, and unreferenced vertices.

    Returns False if no triangle is left.
    """
    v, f = part.vertices, part.faces
    if len(f) and (f.min() < 0 or f.max() >= len(v)):
        raise SceneError(f"faces index vertex {int(f.max())} but there are {len(v)} vertices")
    finite = np.all(np.isfinite(v), axis=1)
    ok = np.all(finite[f], axis=1)
    ok &= (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
    vs = np.where(finite[:, None], v, 0.0)
    a, b, c = vs[f[:, 0]], vs[f[:, 1]], vs[f[:, 2]]
    cross = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    longest = np.max([np.sum((b - a) ** 2, 1), np.sum((c - b) ** 2, 1), np.sum((a - c) ** 2, 1)], axis=0)
    # Relative test: a zero-area (collinear or collapsed) triangle at any scale, 1e-4 m or 1e6 m.
    ok &= cross > 1e-12 * longest
    f = f[ok]
    if len(f) == 0:
        return False
    used = np.unique(f)
    remap = np.full(len(v), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    part.faces = remap[f]
    part.vertices = v[used]
    if part.normals is not None:
        n = part.normals[used]
        good = np.all(np.isfinite(n), axis=1) & (np.linalg.norm(np.nan_to_num(n), axis=1) > 0.5)
        part.normals = n if np.all(good) else None  # broken file normals: recompute all
    if part.uvs is not None:
        part.uvs = part.uvs[used]
    if part.colors is not None:
        part.colors = part.colors[used]
    return True


def decal_layers(parts, tolerance: float = 1e-4) -> list[int]:
    """Per part, its decal layer: 0, or one more than the highest layer of the larger parts it
    lies flat on (a flat part whose plane holds triangles of a larger part overlapping it,
    within ``tolerance`` of the asset's size). Coplanar surfaces of different materials --
    the lines painted on a pitch -- would otherwise z-fight; the renderer draws each layer a
    little in front of the ones below (a polygon offset, not a move in space)."""
    lo, hi = _union_bounds(parts)
    tol = tolerance * max(float(np.linalg.norm(hi - lo)), 1e-9)
    planes = []                # per part: (normal, offset) if it is flat, else None
    areas = []
    for p in parts:
        tri = p.vertices[p.faces]
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        areas.append(0.5 * float(np.linalg.norm(cross, axis=1).sum()))
        n = cross.sum(axis=0)
        plane = None
        if np.linalg.norm(n) > 0:
            n = n / np.linalg.norm(n)
            d = p.vertices @ n
            if d.max() - d.min() <= tol:
                plane = (n, float(d.mean()))
        planes.append(plane)
    layers = [0] * len(parts)
    order = sorted(range(len(parts)), key=lambda i: -areas[i])    # bases before what lies on them
    for rank, i in enumerate(order):
        if planes[i] is None:
            continue
        n, d = planes[i]
        a_lo, a_hi = parts[i].vertices.min(0) - tol, parts[i].vertices.max(0) + tol
        for j in order[:rank]:
            other = parts[j]
            if np.any(other.vertices.max(0) < a_lo) or np.any(other.vertices.min(0) > a_hi):
                continue
            tri = other.vertices[other.faces]
            on_plane = np.all(np.abs(tri @ n - d) <= tol, axis=1)
            if not on_plane.any():
                continue
            t = tri[on_plane]
            overlap = np.all(t.max(axis=1) >= a_lo, axis=1) & np.all(t.min(axis=1) <= a_hi, axis=1)
            if overlap.any():
                layers[i] = max(layers[i], layers[j] + 1)
    return layers


def _to_object(part: _Part, name: str, layer: int = 0) -> SceneObject:
    lo, hi = part.vertices.min(0), part.vertices.max(0)
    centre = (lo + hi) / 2
    transform = np.eye(4)
    transform[:3, 3] = centre
    mesh = Mesh((part.vertices - centre).astype(np.float32), part.faces.astype(np.uint32),
                normals=None if part.normals is None else part.normals.astype(np.float32),
                uvs=part.uvs, colors=part.colors)
    return SceneObject(name, mesh, part.material, transform, layer=layer)


def _union_bounds(parts) -> tuple[np.ndarray, np.ndarray]:
    lo = np.min([p.vertices.min(0) for p in parts], axis=0)
    hi = np.max([p.vertices.max(0) for p in parts], axis=0)
    return lo, hi


def guess_up(parts, convention: str | None = None) -> tuple[str, str]:
    """('y' or 'z', why) for an asset, from its geometry in file axes.

    ``convention``: the name of a format that is +Y up by convention (OBJ), or None. Such a
    file is read +Z up only when at least :data:`STRONG_Z_EVIDENCE` of its surface area faces +Z
    without a counterpart, or when it rests on z = 0 and not on y = 0: a room open on one side
    (a classic test box) leaves its back wall facing the opening, which looks like a floor.

    A closed surface's area-weighted normals sum to zero; what does not cancel comes from open
    surfaces -- terrain, ground planes, floors, the tops of stands -- and those face up. So the
    axis among y and z with the larger net area facing one way is up, when that net area is a
    sizeable share (5 %) of the total. Otherwise the asset is a set of closed objects: one that
    rests on z = 0 but not on y = 0 is Z-up, the reverse Y-up, and failing that the flatter of
    the two axes is up (scenes are wider than tall). Pass ``up`` explicitly when you know."""
    total = 0.0
    net = np.zeros(3)
    for p in parts:
        tri = p.vertices[p.faces]
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])   # 2 x area x unit normal
        net += 0.5 * cross.sum(axis=0)
        total += 0.5 * float(np.linalg.norm(cross, axis=1).sum())
    if total > 0:
        share = np.abs(net[1:]) / total
        axis = int(np.argmax(share))
        if share[axis] >= 0.05:
            name = "yz"[axis]
            sign = "+" if net[1 + axis] > 0 else "-"
            why = f"{100 * share[axis]:.0f} % of the surface area faces {sign}{name} without a counterpart"
            if sign == "-":
                why += " (it faces down: the file may be upside down)"
            if convention is None or name == "y":
                return name, why
            if sign == "+" and share[axis] >= STRONG_Z_EVIDENCE:
                return "z", why + f", enough to overrule {convention}'s +Y convention"
            return "y", why + (f", not the {100 * STRONG_Z_EVIDENCE:.0f} % facing +z that would overrule "
                               f"{convention}'s +Y convention")
    lo, hi = _union_bounds(parts)
    ext = hi - lo
    tol = 0.02 * max(float(np.linalg.norm(ext)), 1e-12)
    on_y, on_z = abs(lo[1]) <= tol, abs(lo[2]) <= tol
    if on_z and not on_y:
        return "z", "it rests on z = 0" + (f", which overrules {convention}'s +Y convention" if convention else "")
    if convention is not None:
        return "y", f"{convention} is +Y up by convention and nothing in the geometry overrules it"
    if on_y and not on_z:
        return "y", "it rests on y = 0"
    flatter = "z" if ext[2] < ext[1] else "y"
    return flatter, f"it is flatter along {flatter} (closed objects, no ground to tell)"


def _unique_names(base: str, part_names: list[str]) -> list[str]:
    """``base`` for a single part, else ``base/part``, with ``~2``, ``~3`` ... on repeats."""
    if len(part_names) == 1:
        return [base]
    out, seen = [], set()
    for pn in part_names:
        candidate = f"{base}/{pn or 'part'}"
        unique, k = candidate, 2
        while unique in seen:
            unique, k = f"{candidate}~{k}", k + 1
        seen.add(unique)
        out.append(unique)
    return out


# ----------------------------------------------------------------------------- asset as a scene

def default_viewer(bounds) -> Pose:
    """Viewer origin ~2.5 radii in front (+Z) of the (2, 3) bounds' centre, looking along -Z at it."""
    lo, hi = np.asarray(bounds, dtype=np.float64)
    centre = (lo + hi) / 2
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-3)
    return Pose.make(centre + np.array([0.0, 0.0, 2.5 * radius]))


def clip_range(bounds) -> tuple[float, float]:
    """(near, far) clip spheres for a viewer placed by :func:`default_viewer` near these bounds.

    near is 5 % of the radius (at most 0.1 m, at least 1 mm); far covers the whole asset seen
    from 2.5 radii plus room for the head to move back.
    """
    lo, hi = np.asarray(bounds, dtype=np.float64)
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-3)
    near = min(max(0.05 * radius, 1e-3), 0.1)
    far = 12.0 * radius + 2.0
    return near, far


def load_asset_scene(path, name: str | None = None, **options):
    """An asset file as a :class:`Scene`: default lights, viewer in front of it, near/far from its size.

    ``options`` are :func:`load_asset`'s (up, units, fit_size, center, scale).
    """
    from .scene import Scene

    path = Path(path).expanduser()
    notes: list = []
    objects = load_asset(path, notes=notes, **options)
    scene_name = name if name is not None else path.stem
    lo = np.min([o.world_bounds()[0] for o in objects], axis=0)
    hi = np.max([o.world_bounds()[1] for o in objects], axis=0)
    near, far = clip_range((lo, hi))
    triangles = sum(o.mesh.triangle_count for o in objects)
    return Scene(
        name=scene_name,
        objects=objects,
        description=f"asset {path.name}: {len(objects)} object(s), {triangles} triangles",
        viewer_origin=default_viewer((lo, hi)),
        near=near,
        far=far,
        source=str(path),
        notes=notes,
    )
