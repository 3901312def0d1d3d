"""Procedural mesh generators and transform helpers (metres, +Y up, CCW seen from outside).

Every generator returns a :class:`~pibr.scenes.scene.Mesh` with unit normals and UVs
(``v = 0`` at a texture's bottom row). ``uv_scale`` is *metres per texture repeat*: with it,
UVs are world lengths divided by ``uv_scale``, so one texture tiles at the same size on
every object; without it, each face or surface spans UV [0, 1].

Parametric surfaces are built on an (ns + 1, nt + 1) vertex grid whose parameters s, t are
ordered so that dP/ds x dP/dt points outward; :func:`_grid_faces` then winds every quad
counter-clockwise seen from outside.
"""
from __future__ import annotations

import math
from functools import lru_cache
from typing import Iterable

import numpy as np

from pibr.protocol.errors import SceneError
from pibr.protocol.proxy import signed_volume as mesh_signed_volume

from .scene import Mesh, vertex_normals

_Y = np.array([0.0, 1.0, 0.0])


# ----------------------------------------------------------------------------- transforms

def translation(x, y=None, z=None) -> np.ndarray:
    """(4, 4) translation by (x, y, z) (or one (3,) vector)."""
    t = np.asarray([x, y, z] if y is not None else x, dtype=np.float64)
    m = np.eye(4)
    m[:3, 3] = t
    return m


def rotation(axis, angle_rad: float) -> np.ndarray:
    """(4, 4) rotation by ``angle_rad`` (right-hand rule) about ``axis`` (3,) through the origin."""
    a = np.asarray(axis, dtype=np.float64)
    n = float(np.sqrt(a @ a))
    if not math.isfinite(n) or n < 1e-12 or not math.isfinite(angle_rad):
        raise SceneError("rotation needs a finite non-zero axis and a finite angle")
    x, y, z = a / n
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    t = 1.0 - c
    m = np.eye(4)
    m[:3, :3] = [[t * x * x + c, t * x * y - s * z, t * x * z + s * y],
                 [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
                 [t * x * z - s * y, t * y * z + s * x, t * z * z + c]]   # Rodrigues
    return m


def scaling(s) -> np.ndarray:
    """(4, 4) scale by ``s`` (scalar or (3,))."""
    m = np.eye(4)
    m[:3, :3] = np.diag(np.broadcast_to(np.asarray(s, dtype=np.float64), (3,)))
    return m


def compose(*matrices) -> np.ndarray:
    """(4, 4) product ``m0 @ m1 @ ...``: the last one is applied first."""
    out = np.eye(4)
    for m in matrices:
        out = out @ np.asarray(m, dtype=np.float64)
    return out


def transform_mesh(mesh: Mesh, matrix) -> Mesh:
    """``mesh`` with vertices mapped by ``matrix`` (4, 4); normals by its inverse transpose.

    A mirroring matrix (negative determinant) reverses the winding so faces stay CCW outside.
    """
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (4, 4):
        raise SceneError(f"transform must have shape (4, 4), got {m.shape}")
    lin = m[:3, :3]
    det = np.linalg.det(lin)
    if abs(det) < 1e-15:
        raise SceneError("transform is singular (it flattens the mesh)")
    v = mesh.vertices.astype(np.float64) @ lin.T + m[:3, 3]
    n = mesh.normals.astype(np.float64) @ np.linalg.inv(lin)  # == (inv(lin).T @ n.T).T
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    faces = mesh.faces if det > 0 else mesh.faces[:, [0, 2, 1]]
    return Mesh(v, faces, n, mesh.uvs, mesh.colors)


def rotation_between(a, b) -> np.ndarray:
    """(4, 4) shortest rotation taking direction ``a`` (3,) to direction ``b`` (3,)."""
    a, b = _unit(np.asarray(a, dtype=np.float64)), _unit(np.asarray(b, dtype=np.float64))
    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(np.dot(a, b))
    if s < 1e-12:
        if c > 0:
            return np.eye(4)
        ortho = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 0.0, 1.0])
        return rotation(ortho, np.pi)
    return rotation(axis, math.atan2(s, c))


def instances(mesh: Mesh, matrices) -> Mesh:
    """One mesh holding a copy of ``mesh`` per transform in ``matrices`` (n, 4, 4) (vectorised :func:`merge`)."""
    m = np.asarray(matrices, dtype=np.float64).reshape(-1, 4, 4)
    lin = m[:, :3, :3]
    det = np.linalg.det(lin)
    if np.any(np.abs(det) < 1e-15):
        raise SceneError("instances: a transform is singular")
    nv = len(mesh.vertices)
    v = np.einsum("nij,kj->nki", lin, mesh.vertices.astype(np.float64)) + m[:, None, :3, 3]
    n = np.einsum("nji,kj->nki", np.linalg.inv(lin), mesh.normals.astype(np.float64))
    n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-30)
    faces = np.where((det > 0)[:, None, None], mesh.faces[None].astype(np.int64),
                     mesh.faces[None][:, :, [0, 2, 1]].astype(np.int64))
    faces = (faces + nv * np.arange(len(m))[:, None, None]).reshape(-1, 3)
    tile = (lambda a: None if a is None else np.tile(a, (len(m), 1)))
    return Mesh(v.reshape(-1, 3), faces, n.reshape(-1, 3), tile(mesh.uvs), tile(mesh.colors))


def colored(mesh: Mesh, rgba) -> Mesh:
    """``mesh`` with every vertex coloured ``rgba`` (3 or 4 values, 0..255 ints or 0..1 floats)."""
    c = np.asarray(rgba, dtype=np.float64).ravel()
    if c.shape not in ((3,), (4,)):
        raise SceneError(f"colour must have 3 or 4 components, got {c.shape}")
    if c.max() <= 1.0 and np.asarray(rgba).dtype.kind == "f":
        c = c * 255.0
    if len(c) == 3:
        c = np.append(c, 255.0)
    colors = np.tile(np.clip(np.round(c), 0, 255).astype(np.uint8), (len(mesh.vertices), 1))
    return Mesh(mesh.vertices, mesh.faces, mesh.normals, mesh.uvs, colors)


def merge(meshes_with_transforms: Iterable) -> Mesh:
    """One mesh from many: items are ``Mesh`` or ``(Mesh, (4, 4) matrix or None)``.

    UVs (colours) are kept when any part has them; parts without get (0, 0) (opaque white).
    """
    parts = []
    for item in meshes_with_transforms:
        mesh, matrix = (item, None) if isinstance(item, Mesh) else item
        parts.append(mesh if matrix is None else transform_mesh(mesh, matrix))
    if not parts:
        return Mesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.uint32))
    offsets = np.cumsum([0] + [len(p.vertices) for p in parts[:-1]])
    faces = np.vstack([p.faces.astype(np.int64) + o for p, o in zip(parts, offsets)])
    verts = np.vstack([p.vertices for p in parts])
    normals = np.vstack([p.normals for p in parts])
    uvs = colors = None
    if any(p.uvs is not None for p in parts):
        uvs = np.vstack([p.uvs if p.uvs is not None else np.zeros((len(p.vertices), 2), np.float32)
                         for p in parts])
    if any(p.colors is not None for p in parts):
        colors = np.vstack([p.colors if p.colors is not None else np.full((len(p.vertices), 4), 255, np.uint8)
                            for p in parts])
    return Mesh(verts, faces, normals, uvs, colors)


# ----------------------------------------------------------------------------- helpers

def _grid_faces(ns: int, nt: int) -> np.ndarray:
    """(2 * ns * nt, 3) faces of an (ns + 1, nt + 1) row-major vertex grid, CCW when dP/ds x dP/dt is outward."""
    s, t = np.meshgrid(np.arange(ns), np.arange(nt), indexing="ij")
    a = (s * (nt + 1) + t).ravel()
    b = a + (nt + 1)          # (s + 1, t)
    c = b + 1                 # (s + 1, t + 1)
    d = a + 1                 # (s, t + 1)
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def _drop_degenerate(vertices: np.ndarray, faces: np.ndarray, eps: float = 1e-14) -> np.ndarray:
    """Faces (m', 3) whose area is above ``eps`` (pole and apex slivers removed)."""
    v = np.asarray(vertices, dtype=np.float64)
    cross = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    return faces[np.einsum("ij,ij->i", cross, cross) > eps * eps]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-30)


def _ring(segments: int) -> tuple[np.ndarray, np.ndarray]:
    """Angles (segments + 1,) from 0 to 2 pi (seam duplicated) and directions (segments + 1, 3)
    (sin phi, 0, cos phi): increasing phi turns from +Z towards +X, counter-clockwise about +Y."""
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    return phi, np.stack([np.sin(phi), np.zeros_like(phi), np.cos(phi)], axis=-1)


def _check_positive(**values) -> None:
    for name, value in values.items():
        if not (math.isfinite(value) and value > 0):
            raise SceneError(f"{name} must be a positive finite number, got {value}")


def _check_segments(name: str, value: int, minimum: int) -> None:
    if int(value) != value or value < minimum:
        raise SceneError(f"{name} must be an integer >= {minimum}, got {value}")


# ----------------------------------------------------------------------------- primitives

@lru_cache(maxsize=64)
def _box_template(divisions: tuple[int, int, int]):
    """Unit box sides split into grids: corners (V, 3) in [-1, 1], normals (V, 3), texture right
    and up directions (V, 3), corner UVs (V, 2), faces (F, 3); ``divisions`` cells along x, y, z."""
    eye = np.eye(3)
    corners, norms, rights, ups, uvs, faces = [], [], [], [], [], []
    count = 0
    for axis in range(3):
        for sign in (1.0, -1.0):
            n = eye[axis] * sign
            # texture "up" on this side, then right = up x n so that right x up = n (CCW outside)
            up = eye[1] if axis != 1 else eye[2] * -sign
            right = np.cross(up, n)
            nu = divisions[int(np.argmax(np.abs(right)))]
            nv = divisions[int(np.argmax(np.abs(up)))]
            uu, vv = np.meshgrid(np.linspace(-1, 1, nu + 1), np.linspace(-1, 1, nv + 1), indexing="ij")
            uu, vv = uu.ravel(), vv.ravel()
            corners.append(n + right * uu[:, None] + up * vv[:, None])
            for arr, vec in ((norms, n), (rights, right), (ups, up)):
                arr.append(np.tile(vec, (len(uu), 1)))
            uvs.append(np.stack([(uu + 1) / 2, (vv + 1) / 2], 1))
            faces.append(_grid_faces(nu, nv) + count)       # s = right, t = up: right x up = n
            count += len(uu)
    return tuple(np.vstack(a) for a in (corners, norms, rights, ups, uvs, faces))


def boxes(sizes, centers, uv_scale: float | None = None, divisions=(1, 1, 1)) -> Mesh:
    """Many axis-aligned boxes in one mesh (see :func:`box`): sizes (n, 3), centers (n, 3) metres;
    every side split into ``divisions`` (3,) cells along x, y, z."""
    half = np.asarray(sizes, dtype=np.float64).reshape(-1, 3) / 2
    centers = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
    if len(half) != len(centers):
        raise SceneError(f"boxes: {len(half)} sizes but {len(centers)} centers")
    if np.any(half <= 0) or not np.all(np.isfinite(half)):
        raise SceneError("box sizes must be positive and finite")
    div = tuple(int(d) for d in divisions)
    if len(div) != 3 or min(div) < 1:
        raise SceneError(f"box divisions must be 3 integers >= 1, got {divisions}")
    if uv_scale is not None:
        _check_positive(uv_scale=uv_scale)
    corners, norms, rights, ups, uv01, faces = _box_template(div)
    nv = len(corners)
    v = centers[:, None, :] + corners[None] * half[:, None, :]            # (n, V, 3)
    if uv_scale is None:
        uv = np.broadcast_to(uv01, (len(half), nv, 2))
    else:
        uv = np.stack([np.einsum("nkj,kj->nk", v, rights), np.einsum("nkj,kj->nk", v, ups)], -1) / uv_scale
    f = (faces[None] + nv * np.arange(len(half))[:, None, None]).reshape(-1, 3)
    return Mesh(v.reshape(-1, 3), f, np.tile(norms, (len(half), 1)), uv.reshape(-1, 2))


def box(size=(1.0, 1.0, 1.0), center=(0.0, 0.0, 0.0), uv_scale: float | None = None,
        max_cell: float | None = None) -> Mesh:
    """Axis-aligned box, flat-shaded: own vertices per side, 12 triangles (more with ``max_cell``).

    size : (3,) metres; center : (3,). Side faces have the texture upright (v along +Y);
    the top has v along -Z, the bottom v along +Z. With ``uv_scale`` UVs are object-space
    metres / uv_scale, so adjacent boxes continue one pattern. ``max_cell`` splits every side
    into a grid of cells at most that many metres across (large walls and floors, so that
    tessellation and lighting have vertices where they need them).
    """
    size = np.asarray(size, dtype=np.float64)
    if size.shape != (3,):
        raise SceneError(f"box size must be 3 positive numbers, got {size.tolist()}")
    div = (1, 1, 1)
    if max_cell is not None:
        _check_positive(max_cell=max_cell)
        div = tuple(max(1, int(math.ceil(s / max_cell - 1e-9))) for s in size)
    return boxes(size[None], np.asarray(center, dtype=np.float64)[None], uv_scale, div)


def box_between(lo, hi, uv_scale: float | None = None, max_cell: float | None = None) -> Mesh:
    """:func:`box` spanning corners ``lo`` (3,) and ``hi`` (3,)."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    return box(hi - lo, (lo + hi) / 2, uv_scale, max_cell)


def cylinder(radius: float, height: float, segments: int = 32, caps: bool = True,
             top_radius: float | None = None, uv_scale: float | None = None, height_segments: int = 1) -> Mesh:
    """Cylinder (or frustum with ``top_radius``) along +Y from y = 0 to y = ``height``.

    Smooth side normals, flat caps. ``top_radius=0`` makes a cone (the top ring becomes one
    apex vertex per segment, no top cap). ``height_segments`` rings split the side along its
    height (tall thin pillars tessellate better that way). Side UVs: u around (0..1, or arc
    length / uv_scale), v up (0..1, or height / uv_scale).
    """
    top = radius if top_radius is None else float(top_radius)
    _check_positive(radius=radius, height=height)
    _check_segments("segments", segments, 3)
    _check_segments("height_segments", height_segments, 1)
    if top < 0 or not math.isfinite(top):
        raise SceneError(f"top_radius must be >= 0, got {top_radius}")
    phi, d = _ring(segments)
    side_n = _unit(d * height + _Y * (radius - top))
    u = phi / (2 * np.pi) if uv_scale is None else phi * radius / uv_scale
    v_top = 1.0 if uv_scale is None else height / uv_scale
    k = np.arange(height_segments + 1) / height_segments
    ring_r = radius + (top - radius) * k                       # (rings,)
    # s = phi (around), t = ring (up): dP/dphi x dP/dy is outward
    pts = d[:, None, :] * ring_r[None, :, None] + _Y * (k * height)[None, :, None]
    norms_grid = np.repeat(side_n[:, None, :], len(k), axis=1)
    uu, vv = np.meshgrid(u, k * v_top, indexing="ij")
    verts = [pts.reshape(-1, 3)]
    norms = [norms_grid.reshape(-1, 3)]
    uvs = [np.stack([uu, vv], -1).reshape(-1, 2)]
    faces = [_grid_faces(segments, height_segments)]
    if top == 0:
        # the last ring collapsed to the apex: drop its slivers, give each segment an apex
        # vertex with the normal of the segment's middle so the cone shades smoothly
        faces = [_drop_degenerate(verts[0], faces[0])]
        # (the remaining top triangle of segment j uses the apex vertex of column j + 1)
        apex = np.arange(1, segments + 1) * (height_segments + 1) + height_segments
        mid = (phi[:-1] + phi[1:]) / 2
        mid_d = np.stack([np.sin(mid), np.zeros_like(mid), np.cos(mid)], 1)
        norms[0] = norms[0].copy()
        norms[0][apex] = _unit(mid_d * height + _Y * radius)
        uvs[0] = uvs[0].copy()
        uvs[0][apex, 0] = (u[:-1] + u[1:]) / 2
    if caps:
        cap_list = [(0.0, radius, -1.0)] + ([(height, top, 1.0)] if top > 0 else [])
        for y, r, sign in cap_list:
            base = sum(len(x) for x in verts)
            ring = d[:-1] * r + _Y * y
            verts.append(np.vstack([_Y * y, ring]))
            norms.append(np.tile(_Y * sign, (segments + 1, 1)))
            xz = np.vstack([[0.0, 0.0], ring[:, [0, 2]]])
            uvs.append(0.5 + 0.5 * xz * [1, -1] / r if uv_scale is None else xz * [1, -1] / uv_scale)
            j = np.arange(segments)
            nxt = (j + 1) % segments
            order = (base + 1 + j, base + 1 + nxt) if sign > 0 else (base + 1 + nxt, base + 1 + j)
            faces.append(np.stack([np.full(segments, base), *order], 1))
    return Mesh(np.vstack(verts), np.vstack(faces), np.vstack(norms), np.vstack(uvs))


def cone(radius: float, height: float, segments: int = 32, cap: bool = True,
         uv_scale: float | None = None) -> Mesh:
    """Cone along +Y: base disc of ``radius`` at y = 0, apex at y = ``height``."""
    return cylinder(radius, height, segments, caps=cap, top_radius=0.0, uv_scale=uv_scale)


def sphere(radius: float, segments: int = 32, rings: int = 16) -> Mesh:
    """UV sphere centred on the origin: ``segments`` around Y, ``rings`` from pole to pole.

    UV: u = longitude / 2 pi (from +Z towards +X), v = 1 at the north pole (+Y), 0 at the south.
    """
    _check_positive(radius=radius)
    _check_segments("segments", segments, 3)
    _check_segments("rings", rings, 2)
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")           # s = theta (down), t = phi (around)
    n = np.stack([np.sin(t) * np.sin(p), np.cos(t), np.sin(t) * np.cos(p)], -1).reshape(-1, 3)
    uv = np.stack([p / (2 * np.pi), 1.0 - t / np.pi], -1).reshape(-1, 2)
    v = n * radius
    return Mesh(v, _drop_degenerate(v, _grid_faces(rings, segments)), n, uv)


def torus(major_radius: float, minor_radius: float, segments: int = 48, tube_segments: int = 16) -> Mesh:
    """Torus around the Y axis (ring in the XZ plane), centred on the origin.

    UV: u around the ring, v around the tube.
    """
    _check_positive(major_radius=major_radius, minor_radius=minor_radius)
    _check_segments("segments", segments, 3)
    _check_segments("tube_segments", tube_segments, 3)
    phi, d = _ring(segments)
    psi = np.linspace(0.0, 2.0 * np.pi, tube_segments + 1)
    # s = phi (around the ring), t = psi (around the tube): dP/dphi x dP/dpsi is outward
    n = np.cos(psi)[None, :, None] * d[:, None, :] + np.sin(psi)[None, :, None] * _Y
    v = major_radius * d[:, None, :] + minor_radius * n
    ss, tt = np.meshgrid(phi / (2 * np.pi), psi / (2 * np.pi), indexing="ij")
    return Mesh(v.reshape(-1, 3), _grid_faces(segments, tube_segments), n.reshape(-1, 3),
                np.stack([ss, tt], -1).reshape(-1, 2))


def torus_knot_curve(u: np.ndarray, p: int, q: int, radius: float) -> np.ndarray:
    """Points (n, 3) on a (p, q) torus knot at parameters u (n,) in [0, 2 pi), in the XY plane.

    The knot winds p times around the Z axis and q times through the torus hole; its
    largest extent from the centre is ``radius``.
    """
    r = (2.0 + np.cos(q * u)) / 3.0 * radius
    return np.stack([r * np.cos(p * u), r * np.sin(p * u), -np.sin(q * u) * radius / 3.0], -1)


def torus_knot(radius: float = 0.3, tube_radius: float = 0.04, p: int = 2, q: int = 3,
               segments: int = 256, tube_segments: int = 16, uv_repeat: float = 8.0) -> Mesh:
    """Tube of ``tube_radius`` along a (p, q) torus knot of ``radius`` (see :func:`torus_knot_curve`).

    The tube frame follows three.js's construction (normal from the sum of neighbouring
    positions), which is periodic, so the tube closes without a twist at the seam.
    UV: u along the knot (``uv_repeat`` texture repeats per loop), v around the tube.
    """
    _check_positive(radius=radius, tube_radius=tube_radius)
    _check_segments("segments", segments, 8)
    _check_segments("tube_segments", tube_segments, 3)
    if math.gcd(int(p), int(q)) != 1:
        raise SceneError(f"torus knot p={p}, q={q} must be coprime (else it is a link)")
    u = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    c = torus_knot_curve(u, p, q, radius)
    c_next = torus_knot_curve(u + 1e-3, p, q, radius)
    tangent = _unit(c_next - c)
    binormal = _unit(np.cross(tangent, c_next + c))
    normal = np.cross(binormal, tangent)
    v = np.linspace(0.0, 2.0 * np.pi, tube_segments + 1)
    # s = v (around the tube), t = u (along the knot): dP/dv x dP/du is outward
    n = np.cos(v)[:, None, None] * normal[None] + np.sin(v)[:, None, None] * binormal[None]
    pts = c[None] + tube_radius * n
    vv, uu = np.meshgrid(v / (2 * np.pi), u / (2 * np.pi) * uv_repeat, indexing="ij")
    return Mesh(pts.reshape(-1, 3), _grid_faces(tube_segments, segments), n.reshape(-1, 3),
                np.stack([uu, vv], -1).reshape(-1, 2))


def grid_plane(size_x: float, size_z: float, cell_size: float = 1.0, uv_scale: float | None = None) -> Mesh:
    """Horizontal rectangle at y = 0 facing +Y, centred on the origin, split into square-ish cells.

    Cells are at most ``cell_size`` metres on a side. UVs: u along +X, v along -Z (the
    texture reads upright from the +Z side), object-space metres / ``uv_scale`` or [0, 1].
    Rotate it to make walls: ``rotation((1, 0, 0), pi / 2)`` faces +Z with v along +Y.
    """
    _check_positive(size_x=size_x, size_z=size_z, cell_size=cell_size)
    nx = max(1, int(math.ceil(size_x / cell_size - 1e-9)))
    nz = max(1, int(math.ceil(size_z / cell_size - 1e-9)))
    return rect_grid(np.linspace(-size_x / 2, size_x / 2, nx + 1), np.linspace(-size_z / 2, size_z / 2, nz + 1),
                     uv_scale)


def rect_grid(x_lines, z_lines, uv_scale: float | None = None) -> Mesh:
    """Horizontal grid at y = 0 facing +Y with cell boundaries at the increasing coordinates
    ``x_lines`` (nx + 1,) and ``z_lines`` (nz + 1,): e.g. fine cells near a building and coarse
    ones far away. UVs as in :func:`grid_plane`."""
    x = np.asarray(x_lines, dtype=np.float64)
    z = np.asarray(z_lines, dtype=np.float64)
    if x.ndim != 1 or z.ndim != 1 or len(x) < 2 or len(z) < 2 or np.any(np.diff(x) <= 0) or np.any(np.diff(z) <= 0):
        raise SceneError("rect_grid lines must be increasing 1-D arrays of at least 2 coordinates")
    zz, xx = np.meshgrid(z, x, indexing="ij")                # s = z, t = x: dP/dz x dP/dx = +Y
    v = np.stack([xx, np.zeros_like(xx), zz], -1).reshape(-1, 3)
    if uv_scale is None:
        uv = np.stack([(xx - x[0]) / (x[-1] - x[0]), (z[-1] - zz) / (z[-1] - z[0])], -1)
    else:
        _check_positive(uv_scale=uv_scale)
        uv = np.stack([xx / uv_scale, -zz / uv_scale], -1)
    return Mesh(v, _grid_faces(len(z) - 1, len(x) - 1), np.tile(_Y, (len(v), 1)), uv.reshape(-1, 2))


def _triangulate(poly: np.ndarray) -> np.ndarray:
    """Ear clipping of a simple polygon (n, 2) in (x, z), counter-clockwise about +Y: faces (n - 2, 3)."""
    def ccw(a, b, c):  # > 0 when a, b, c turn counter-clockwise about +Y
        return (b[1] - a[1]) * (c[0] - a[0]) - (b[0] - a[0]) * (c[1] - a[1])

    idx = list(range(len(poly)))
    faces = []
    guard = 0
    while len(idx) > 3:
        guard += 1
        if guard > 10 * len(poly) ** 2:
            raise SceneError("extrude: polygon is not simple (self-intersecting or degenerate)")
        for k in range(len(idx)):
            i0, i1, i2 = idx[k - 1], idx[k], idx[(k + 1) % len(idx)]
            a, b, c = poly[i0], poly[i1], poly[i2]
            if ccw(a, b, c) <= 1e-15:
                continue
            inside = False
            for j in idx:
                if j in (i0, i1, i2):
                    continue
                p = poly[j]
                if ccw(a, b, p) >= 0 and ccw(b, c, p) >= 0 and ccw(c, a, p) >= 0:
                    inside = True
                    break
            if not inside:
                faces.append((i0, i1, i2))
                del idx[k]
                break
        else:
            raise SceneError("extrude: polygon is not simple (no ear found)")
    faces.append(tuple(idx))
    return np.array(faces, dtype=np.int64)


def extrude(polygon, height: float, caps: bool = True, uv_scale: float | None = None) -> Mesh:
    """Prism: a simple polygon (n, 2) of (x, z) points extruded along +Y from 0 to ``height``.

    Either orientation of the polygon is accepted. Side walls are flat-shaded (own vertices
    per edge), caps triangulated by ear clipping. Side UVs: u along the perimeter, v up.
    """
    poly = np.asarray(polygon, dtype=np.float64)
    if poly.ndim != 2 or poly.shape[1] != 2 or len(poly) < 3:
        raise SceneError(f"extrude polygon must have shape (n >= 3, 2), got {poly.shape}")
    _check_positive(height=height)
    area = 0.5 * np.sum(poly[:, 1] * np.roll(poly[:, 0], -1) - poly[:, 0] * np.roll(poly[:, 1], -1))
    if abs(area) < 1e-12:
        raise SceneError("extrude polygon has zero area")
    if area < 0:
        poly = poly[::-1]
    n_pts = len(poly)
    a3 = np.stack([poly[:, 0], np.zeros(n_pts), poly[:, 1]], 1)
    b3 = np.roll(a3, -1, axis=0)
    edge = b3 - a3
    length = np.linalg.norm(edge, axis=1)
    normal = _unit(np.cross(edge, _Y))
    along = np.concatenate([[0.0], np.cumsum(length)[:-1]])
    scale_u = uv_scale if uv_scale is not None else max(length.sum(), 1e-9)
    scale_v = uv_scale if uv_scale is not None else height
    h = _Y * height
    # per edge: a0, b0, b1, a1
    verts = np.stack([a3, b3, b3 + h, a3 + h], 1).reshape(-1, 3)
    norms = np.repeat(normal, 4, axis=0)
    u0, u1 = along / scale_u, (along + length) / scale_u
    uvs = np.stack([np.stack([u0, np.zeros(n_pts)], 1), np.stack([u1, np.zeros(n_pts)], 1),
                    np.stack([u1, np.full(n_pts, height / scale_v)], 1),
                    np.stack([u0, np.full(n_pts, height / scale_v)], 1)], 1).reshape(-1, 2)
    base = np.arange(n_pts)[:, None] * 4
    faces = [base + [0, 1, 2], base + [0, 2, 3]]
    verts, norms, uvs = [verts], [norms], [uvs]
    if caps:
        tri = _triangulate(poly)
        lo, hi = poly.min(0), poly.max(0)
        if uv_scale is None:
            cap_uv = (poly - lo) / np.maximum(hi - lo, 1e-9) * [1, -1] + [0, 1]
        else:
            cap_uv = poly * [1, -1] / uv_scale
        for y, sign in ((0.0, -1.0), (height, 1.0)):
            start = sum(len(x) for x in verts)
            verts.append(a3 + _Y * y)
            norms.append(np.tile(_Y * sign, (n_pts, 1)))
            uvs.append(cap_uv)
            faces.append(start + (tri if sign > 0 else tri[:, ::-1]))
    return Mesh(np.vstack(verts), np.vstack(faces), np.vstack(norms), np.vstack(uvs))


def lathe(profile, segments: int = 32, uv_scale: float | None = None) -> Mesh:
    """Surface of revolution about +Y of a profile (n, 2) of (radius, y) points, bottom to top.

    Smooth normals from the profile's slope; repeat a point to get a crease there. A
    profile that starts and ends at radius 0 gives a closed solid (vase, bulb, pot).
    UV: u around, v along the profile (0..1, or length / uv_scale).
    """
    prof = np.asarray(profile, dtype=np.float64)
    if prof.ndim != 2 or prof.shape[1] != 2 or len(prof) < 2:
        raise SceneError(f"lathe profile must have shape (n >= 2, 2), got {prof.shape}")
    if np.any(prof[:, 0] < 0):
        raise SceneError("lathe profile radii must be >= 0")
    _check_segments("segments", segments, 3)
    seg = np.diff(prof, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    seg_dir = np.where(seg_len[:, None] > 1e-12, seg / np.maximum(seg_len[:, None], 1e-12), 0.0)
    # tangent at each profile point: mean of the adjacent non-zero segment directions,
    # except across a repeated point (zero-length segment), which makes a crease
    tangent = np.zeros_like(prof)
    tangent[:-1] += seg_dir
    tangent[1:] += seg_dir
    for k in np.flatnonzero(seg_len <= 1e-12):
        if k > 0:
            tangent[k] = seg_dir[k - 1]
        if k + 2 <= len(prof) - 1:
            tangent[k + 1] = seg_dir[k + 1]
    tangent = _unit(tangent)
    phi, d = _ring(segments)
    # s = phi (around), t = profile index (up): dP/dphi x dP/dt is outward for an upward profile
    pts = prof[None, :, 0, None] * d[:, None, :] + prof[None, :, 1, None] * _Y
    n2 = np.stack([tangent[:, 1], -tangent[:, 0]], 1)        # (dy, -dr): outward 2D normal
    n = n2[None, :, 0, None] * d[:, None, :] + n2[None, :, 1, None] * _Y
    n = _unit(n)
    along = np.concatenate([[0.0], np.cumsum(seg_len)])
    v_coord = along / (uv_scale if uv_scale is not None else max(along[-1], 1e-9))
    u_coord = phi / (2 * np.pi) if uv_scale is None else phi * prof[:, 0].max() / uv_scale
    uu, vv = np.meshgrid(u_coord, v_coord, indexing="ij")
    v = pts.reshape(-1, 3)
    faces = _drop_degenerate(v, _grid_faces(segments, len(prof) - 1))
    return Mesh(v, faces, n.reshape(-1, 3), np.stack([uu, vv], -1).reshape(-1, 2))


def leaf(length: float = 0.12, width: float = 0.05, segments: int = 4, curl: float = 0.3,
         fold: float = 0.15) -> Mesh:
    """Small curved leaf blade along +Z from its stalk at the origin, facing +Y; two-sided.

    The blade is a fan of triangles around its midrib (``segments`` pieces along it), with
    the tip bent down by ``curl`` * length and the halves folded up by ``fold`` * width at
    the edges. Both windings are emitted (back copy with reversed faces and flipped
    normals), so it shades correctly from either side: 8 * (segments - 1) triangles.
    UV: u across (0..1, midrib at 0.5), v along (0 at the stalk, 1 at the tip).
    """
    _check_positive(length=length, width=width)
    _check_segments("segments", segments, 2)
    t = np.linspace(0.0, 1.0, segments + 1)
    half_w = 0.5 * width * np.sin(np.pi * t) ** 0.8 * (1.0 - 0.25 * t)
    z = length * t
    y_mid = -curl * length * t ** 2
    mid = np.stack([np.zeros_like(t), y_mid, z], 1)
    left = np.stack([-half_w, y_mid + fold * half_w, z], 1)[1:-1]    # no width at stalk and tip
    right = np.stack([half_w, y_mid + fold * half_w, z], 1)[1:-1]
    verts = np.vstack([mid, left, right])
    n_mid = len(mid)
    li = n_mid + np.arange(segments - 1)                    # left edge point at mid index k + 1
    ri = li + (segments - 1)
    faces = []
    for k in range(segments):
        # quad between midrib k..k+1 and the edge points at k..k+1 (edges collapse at the ends)
        l0 = li[k - 1] if k >= 1 else None
        l1 = li[k] if k < segments - 1 else None
        r0 = ri[k - 1] if k >= 1 else None
        r1 = ri[k] if k < segments - 1 else None
        m0, m1 = k, k + 1
        # the left half mirrors the right, so its triangles take the reverse order
        for e0, e1, side in ((r0, r1, 1), (l0, l1, -1)):
            tris = []
            if e0 is not None and e1 is not None:
                tris = [(m0, e0, e1), (m0, e1, m1)]
            elif e1 is not None:
                tris = [(m0, e1, m1)]
            elif e0 is not None:
                tris = [(m0, e0, m1)]
            for tri in tris:
                faces.append(tri if side > 0 else tri[::-1])
    faces = np.array(faces, dtype=np.int64)
    # make the front face up (+Y): flip the whole set if the first face points down
    fn = np.cross(verts[faces[:, 1]] - verts[faces[:, 0]], verts[faces[:, 2]] - verts[faces[:, 0]])
    if fn[:, 1].sum() < 0:
        faces = faces[:, ::-1]
    normals = vertex_normals(verts, faces)
    uv = np.vstack([np.stack([np.full(n_mid, 0.5), t], 1),
                    np.stack([0.5 - half_w[1:-1] / width, t[1:-1]], 1),
                    np.stack([0.5 + half_w[1:-1] / width, t[1:-1]], 1)])
    nv = len(verts)
    return Mesh(np.vstack([verts, verts]), np.vstack([faces, faces[:, ::-1] + nv]),
                np.vstack([normals, -normals]), np.vstack([uv, uv]))


def signed_volume(mesh: Mesh) -> float:
    """Volume enclosed by a closed mesh: positive when its faces wind CCW seen from outside."""
    return mesh_signed_volume(mesh.vertices, mesh.faces)
