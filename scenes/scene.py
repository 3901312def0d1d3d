"""Scene description: meshes, materials, objects (static or moving), lights, viewer origin.

Everything is in metres, right-handed, +Y up (DESIGN.md). Loaders convert units and up axis
once, at import; nothing downstream ever sees another convention.
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field

import numpy as np

from pibr.protocol.errors import SceneError
from pibr.protocol.pose import Pose

from .animation import Animation


@dataclass
class Mesh:
    """Triangle mesh in object space.

    vertices : (n, 3) float32
    faces    : (m, 3) uint32, counter-clockwise seen from outside
    normals  : (n, 3) float32, unit (computed from faces when the asset has none)
    uvs      : (n, 2) float32 or None (no texture coordinates)
    colors   : (n, 4) uint8 or None (per-vertex colour multiplies the material)
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray | None = None
    uvs: np.ndarray | None = None
    colors: np.ndarray | None = None

    def __post_init__(self):
        v = np.asarray(self.vertices, dtype=np.float32)
        f = np.asarray(self.faces)
        if v.ndim != 2 or v.shape[1] != 3:
            raise SceneError(f"mesh vertices must have shape (n, 3), got {v.shape}")
        if f.size == 0:
            f = np.zeros((0, 3), dtype=np.uint32)
        if f.ndim != 2 or f.shape[1] != 3:
            raise SceneError(f"mesh faces must have shape (m, 3), got {f.shape}")
        if not np.all(np.isfinite(v)):
            raise SceneError("mesh vertices contain NaN or infinite coordinates")
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise SceneError(f"mesh faces index vertex {int(f.max())} but the mesh has {len(v)} vertices")
        self.vertices = np.ascontiguousarray(v)
        self.faces = np.ascontiguousarray(f, dtype=np.uint32)
        if self.normals is None:
            self.normals = vertex_normals(self.vertices, self.faces)
        self.normals = _check_attr(self.normals, (len(v), 3), np.float32, "normals")
        if self.uvs is not None:
            self.uvs = _check_attr(self.uvs, (len(v), 2), np.float32, "uvs")
        if self.colors is not None:
            self.colors = _check_attr(self.colors, (len(v), 4), np.uint8, "colors")

    @property
    def triangle_count(self) -> int:
        return len(self.faces)

    def bounds(self) -> np.ndarray:
        """(2, 3) min and max corner; zeros for an empty mesh."""
        if len(self.vertices) == 0:
            return np.zeros((2, 3), dtype=np.float32)
        return np.stack([self.vertices.min(0), self.vertices.max(0)])

    def digest(self) -> str:
        """Stable content hash (geometry and attributes), for caches."""
        h = hashlib.sha256()
        for a in (self.vertices, self.faces, self.normals, self.uvs, self.colors):
            h.update(b"-" if a is None else np.ascontiguousarray(a).tobytes())
        return h.hexdigest()


def _check_attr(a, shape, dtype, name):
    a = np.asarray(a)
    if a.shape != shape:
        raise SceneError(f"mesh {name} must have shape {shape}, got {a.shape}")
    if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
        raise SceneError(f"mesh {name} contain NaN or infinite values")
    return np.ascontiguousarray(a, dtype=dtype)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (n, 3) float32; +Y for vertices no face touches or degenerate fans."""
    n = np.zeros((len(vertices), 3), dtype=np.float64)
    if len(faces):
        v = vertices.astype(np.float64)
        fn = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
        for k in range(3):
            np.add.at(n, faces[:, k], fn)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    out = np.where(length > 1e-20, n / np.maximum(length, 1e-30), np.array([0.0, 1.0, 0.0]))
    return out.astype(np.float32)


@dataclass
class Material:
    """Diffuse material.

    base_color : (4,) linear RGBA in [0, 1], multiplies the texture
    texture    : (h, w, 3) uint8 sRGB or None; row 0 is the top of the image, and UVs put
                 v = 0 at its *bottom* row (the OpenGL / OBJ / trimesh convention)
    """

    name: str = "default"
    base_color: tuple = (0.8, 0.8, 0.8, 1.0)
    texture: np.ndarray | None = None

    def __post_init__(self):
        c = tuple(float(x) for x in self.base_color)
        if len(c) == 3:
            c = c + (1.0,)
        if len(c) != 4 or not all(math.isfinite(x) for x in c):
            raise SceneError(f"material {self.name!r}: base_color must be 3 or 4 finite numbers")
        self.base_color = tuple(min(max(x, 0.0), 1.0) for x in c)
        if self.texture is not None:
            t = np.asarray(self.texture)
            if t.ndim == 2:
                t = np.repeat(t[:, :, None], 3, axis=2)
            if t.ndim != 3 or t.shape[2] not in (3, 4) or t.shape[0] < 1 or t.shape[1] < 1:
                raise SceneError(f"material {self.name!r}: texture must have shape (h, w, 3|4), got {t.shape}")
            if t.dtype != np.uint8:
                if t.dtype.kind == "f":
                    t = np.clip(t * 255.0 + 0.5, 0, 255)
                t = t.astype(np.uint8)
            self.texture = np.ascontiguousarray(t[:, :, :3])


@dataclass
class SceneObject:
    """A mesh with one material placed in the world; moving when ``animation`` is set.

    transform : (4, 4) float64 object-to-world at rest.
    """

    name: str
    mesh: Mesh
    material: Material = field(default_factory=Material)
    transform: np.ndarray = field(default_factory=lambda: np.eye(4))
    animation: Animation | None = None
    #: Decal layer: drawn over coplanar surfaces of lower layers (a road marking on its road),
    #: where equal depths would otherwise z-fight. See scenes.loaders.decal_layers.
    layer: int = 0

    def __post_init__(self):
        t = np.asarray(self.transform, dtype=np.float64)
        if t.shape != (4, 4) or not np.all(np.isfinite(t)):
            raise SceneError(f"object {self.name!r}: transform must be a finite (4, 4) matrix")
        self.transform = t

    @property
    def is_dynamic(self) -> bool:
        return self.animation is not None

    def world_matrix(self, t: float = 0.0) -> np.ndarray:
        """(4, 4) object-to-world at time t."""
        if self.animation is None:
            return self.transform
        return self.animation.matrix(t) @ self.transform

    def world_bounds(self, t: float = 0.0) -> np.ndarray:
        """(2, 3) world-space axis-aligned bounds of the mesh at time t."""
        b = self.mesh.bounds().astype(np.float64)
        corners = np.array([[b[i][0], b[j][1], b[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        w = corners @ self.world_matrix(t)[:3, :3].T + self.world_matrix(t)[:3, 3]
        return np.stack([w.min(0), w.max(0)])


@dataclass
class Light:
    """``"ambient"`` (colour only), ``"directional"`` (direction the light travels) or ``"point"`` (position, range)."""

    kind: str
    color: tuple = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    direction: tuple = (0.0, -1.0, 0.0)
    position: tuple = (0.0, 0.0, 0.0)
    range: float = 10.0

    KINDS = ("ambient", "directional", "point")

    def __post_init__(self):
        if self.kind not in self.KINDS:
            raise SceneError(f"unknown light kind {self.kind!r}; choose from {', '.join(self.KINDS)}")
        d = np.asarray(self.direction, dtype=np.float64)
        if self.kind == "directional":
            if d.shape != (3,) or np.linalg.norm(d) < 1e-12:
                raise SceneError("directional light needs a non-zero direction")
            self.direction = tuple(float(x) for x in d / np.linalg.norm(d))


MAX_LIGHTS = 8


@dataclass
class Scene:
    """A complete scene in metres, +Y up.

    viewer_origin : where a head trace's origin is placed (traces are replayed as
                    ``viewer_origin ∘ trace_pose``), e.g. standing eye height in a room.
    near, far     : clip *spheres* (radial distance) for every view of this scene.
    extra_view    : whether views of this scene need the dual view's extra view at all
                    (a single convex object seen from outside has nothing to disocclude).
    extra_view_offset : the dual view's offset for this scene (``None``: the default).
    view_region   : (2, 3) world box where viewers' eyes go (``None``: 3 m around the viewer
                    origin horizontally, 0.6 m vertically); geometry is tessellated for it.
    notes         : what loading decided or fixed (an asset's up axis and why, ...).
    """

    name: str
    objects: list
    lights: list = field(default_factory=lambda: [Light("ambient", intensity=0.35),
                                                  Light("directional", direction=(-0.4, -1.0, -0.3), intensity=0.8)])
    description: str = ""
    viewer_origin: Pose = field(default_factory=Pose.identity)
    near: float = 0.1
    far: float = 1000.0
    sky_color: tuple = (0.62, 0.76, 0.92)
    extra_view: bool = True
    extra_view_offset: Pose | None = None
    view_region: np.ndarray | None = None
    source: str = "builtin"
    notes: list = field(default_factory=list)   # what loading decided (up axis, fixes), for 'pibr scenes --show'

    def __post_init__(self):
        if not (0 < self.near < self.far) or not math.isfinite(self.far):
            raise SceneError(f"scene {self.name!r}: need 0 < near < far < inf, got near={self.near}, far={self.far}")
        if len(self.lights) > MAX_LIGHTS:
            raise SceneError(f"scene {self.name!r}: at most {MAX_LIGHTS} lights, got {len(self.lights)}")
        names = [o.name for o in self.objects]
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise SceneError(f"scene {self.name!r}: object names must be unique, repeated: {', '.join(dup)}")

    @property
    def is_dynamic(self) -> bool:
        return any(o.is_dynamic for o in self.objects)

    def viewing_region(self) -> np.ndarray:
        """(2, 3) world box where viewers' eyes are expected."""
        if self.view_region is not None:
            return np.asarray(self.view_region, dtype=np.float64)
        c = self.viewer_origin.p
        half = np.array([3.0, 0.6, 3.0])
        return np.stack([c - half, c + half])

    @property
    def triangle_count(self) -> int:
        return sum(o.mesh.triangle_count for o in self.objects)

    def bounds(self, t: float = 0.0) -> np.ndarray:
        """(2, 3) world bounds of all objects at time t (zeros for an empty scene)."""
        bs = [o.world_bounds(t) for o in self.objects if len(o.mesh.vertices)]
        if not bs:
            return np.zeros((2, 3))
        bs = np.array(bs)
        return np.stack([bs[:, 0].min(0), bs[:, 1].max(0)])

    def info(self) -> dict:
        """What a client needs to know about the scene (sent in ``Welcome``); never the geometry."""
        return {
            "name": self.name,
            "description": self.description,
            "units": "m",
            "up": "+y",
            "near": self.near,
            "far": self.far,
            "viewer_origin": list(self.viewer_origin.as_array()),
            "bounds": self.bounds().tolist(),
            "dynamic": self.is_dynamic,
            "extra_view": self.extra_view,
            "objects": len(self.objects),
            "triangles": self.triangle_count,
        }
