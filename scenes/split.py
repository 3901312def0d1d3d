"""Level-sized meshes cut into spatially coherent pieces.

An asset that arrives as one mesh (a whole game level, an atrium) would be one object: one
encaging proxy for everything, a level of detail chosen for all of it at once, nothing to
cull. Cutting it into pieces of at most ``max_triangles`` triangles -- recursively halving the
triangles at the median of their centroids along the longest axis of their bounds, a k-d
split -- gives the LoD selection and the culling something to work with, and the LoD build
pieces it can run in parallel. Every vertex attribute follows its triangles.
"""
from __future__ import annotations

import numpy as np

#: Triangles per piece when an asset does not say otherwise (``split=N`` in its spec or
#: description; 0 keeps meshes whole). Chosen on a generated one-mesh atrium (tests/scenes).
DEFAULT_PIECE_TRIANGLES = 16384


def split_faces(centroids: np.ndarray, max_triangles: int) -> list[np.ndarray]:
    """Indices (k,) into ``centroids`` (m, 3) of each piece, every piece at most ``max_triangles``
    long, neighbouring triangles together (a median k-d split along the longest axis)."""
    if max_triangles < 1:
        raise ValueError("max_triangles must be at least 1")
    out = []
    stack = [np.arange(len(centroids))]
    while stack:
        idx = stack.pop()
        if len(idx) <= max_triangles:
            out.append(idx)
            continue
        c = centroids[idx]
        axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        order = np.argsort(c[:, axis], kind="stable")
        half = len(idx) // 2
        stack += [idx[order[half:]], idx[order[:half]]]
    return out


def split_arrays(vertices: np.ndarray, faces: np.ndarray, attributes: dict, max_triangles: int):
    """Cut a mesh: -> [(vertices (n_i, 3), faces (m_i, 3) re-indexed, attributes of the piece's
    vertices)], one per piece. ``attributes``: name -> (n, ...) per-vertex array or None."""
    if len(faces) <= max_triangles:
        return [(vertices, faces, attributes)]
    centroids = vertices[faces].mean(axis=1)
    pieces = []
    for idx in split_faces(centroids, max_triangles):
        f = faces[idx]
        used, inverse = np.unique(f, return_inverse=True)
        pieces.append((vertices[used], inverse.reshape(-1, 3),
                       {k: (None if a is None else a[used]) for k, a in attributes.items()}))
    return pieces
