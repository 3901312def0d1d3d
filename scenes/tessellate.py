"""Pre-tessellation for rasterising in a non-linear projection.

The wide-angle projection bends straight edges; a rasteriser draws them straight between
projected vertices. Splitting triangles until each spans a small angle keeps that error
below a pixel. Triangles near the viewing region get short edges, far ones long edges:
the target edge length grows with distance, so a 300 m terrain costs no more than a room.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from .scene import Mesh


@lru_cache(maxsize=None)
def _template(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric grid of one triangle split into n x n: weights (V, 3) float64, faces (n*n, 3)."""
    idx = {}
    bary = []
    for i in range(n + 1):
        for j in range(n + 1 - i):
            idx[i, j] = len(bary)
            bary.append(((n - i - j) / n, i / n, j / n))
    faces = []
    for i in range(n):
        for j in range(n - i):
            faces.append((idx[i, j], idx[i + 1, j], idx[i, j + 1]))
            if i + j < n - 1:
                faces.append((idx[i + 1, j], idx[i + 1, j + 1], idx[i, j + 1]))
    return np.array(bary), np.array(faces, dtype=np.int64)


def subdivide(mesh: Mesh, levels) -> Mesh:
    """Split face k into ``levels[k]`` x ``levels[k]`` triangles (levels (m,) int >= 1).

    Faces with level 1 keep their original (shared) vertices; split faces get their own grid.
    Attributes (normals, UVs, colours) are interpolated barycentrically.
    """
    levels = np.asarray(levels, dtype=np.int64)
    if levels.shape != (len(mesh.faces),):
        raise ValueError(f"levels must have shape ({len(mesh.faces)},), got {levels.shape}")
    if len(levels) and levels.min() < 1:
        raise ValueError("subdivision levels must be >= 1")
    keep = levels == 1
    verts = [mesh.vertices.astype(np.float64)]
    norms = [mesh.normals.astype(np.float64)]
    uvs = [mesh.uvs.astype(np.float64)] if mesh.uvs is not None else None
    cols = [mesh.colors.astype(np.float64)] if mesh.colors is not None else None
    faces = [mesh.faces[keep].astype(np.int64)]
    base = len(mesh.vertices)
    for n in np.unique(levels[~keep]):
        sel = mesh.faces[levels == n]
        bary, tf = _template(int(n))
        nv = len(bary)

        def interp(attr):
            corners = attr[sel]  # (k, 3, c)
            return np.einsum("vj,kjc->kvc", bary, corners.astype(np.float64)).reshape(-1, corners.shape[-1])

        verts.append(interp(mesh.vertices))
        nrm = interp(mesh.normals)
        nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-20)
        norms.append(nrm)
        if uvs is not None:
            uvs.append(interp(mesh.uvs))
        if cols is not None:
            cols.append(interp(mesh.colors))
        offsets = base + np.arange(len(sel))[:, None, None] * nv
        faces.append((tf[None, :, :] + offsets).reshape(-1, 3))
        base += len(sel) * nv
    return Mesh(
        vertices=np.concatenate(verts).astype(np.float32),
        faces=np.concatenate(faces).astype(np.uint32),
        normals=np.concatenate(norms).astype(np.float32),
        uvs=None if uvs is None else np.concatenate(uvs).astype(np.float32),
        colors=None if cols is None else np.clip(np.concatenate(cols) + 0.5, 0, 255).astype(np.uint8),
    )


def levels_for_view_region(mesh: Mesh, world_matrix: np.ndarray, region: np.ndarray,
                           max_angle_deg: float = 3.0, min_edge: float = 0.02, max_level: int = 32,
                           min_distance: float = 0.0) -> np.ndarray:
    """Per-face subdivision level so every edge spans at most ``max_angle_deg`` seen from
    anywhere in ``region`` ((2, 3) world box where viewers go) that is at least ``min_distance``
    from the mesh's box (a coarser copy for viewers known to stand that far off).

    An edge of length L at distance d from the region subtends about L / d radians, so the
    target length is ``d * tan(angle)``, never below ``min_edge``.
    """
    if len(mesh.faces) == 0:
        return np.zeros(0, dtype=np.int64)
    v = mesh.vertices.astype(np.float64) @ world_matrix[:3, :3].T + world_matrix[:3, 3]
    tri = v[mesh.faces]
    edge = np.stack([np.linalg.norm(tri[:, 1] - tri[:, 0], axis=1),
                     np.linalg.norm(tri[:, 2] - tri[:, 1], axis=1),
                     np.linalg.norm(tri[:, 0] - tri[:, 2], axis=1)], axis=1).max(axis=1)
    # Distance from the region to the nearest point of the face's bounding box.
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    gap = np.maximum(0.0, np.maximum(region[0] - hi, lo - region[1]))
    dist = np.maximum(np.linalg.norm(gap, axis=1), min_distance)
    target = np.maximum(dist * np.tan(np.radians(max_angle_deg)), min_edge)
    return np.clip(np.ceil(edge / target), 1, max_level).astype(np.int64)
