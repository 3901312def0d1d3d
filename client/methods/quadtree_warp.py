"""``quadtree``: quadtree warping (Didyk et al. 2010, as compared in Reinert et al. 2016, 6.2).

The server sends, with every frame, a quadtree over each view's distance map whose leaves
group pixels of one depth (``Hello.quadtree_threshold``, ``PayloadKind.QUADTREE``; built by
``pibr.server.quadtree``, bitstream in ``pibr.protocol.quadtree``). The client makes each leaf
(x, y, size) one quad with corners at the pixel centres (x, y), (x + size, y), (x, y + size),
(x + size, y + size), clamped to the image, and warps its four corners like ``meshwarp``'s
vertices (:class:`~.mesh_warp.MeshWarpProgram` with given vertices): two triangles per quad,
split into a minimum- and a maximum-distance copy where they span a depth discontinuity, both
views, depth-tested. Neighbouring leaves of one size share corners; where a large leaf meets
smaller ones their corners do not line up, which leaves the small cracks at level boundaries
the paper mentions (no hole filling, as for every competitor).

The payload is decoded and the quads uploaded once per server frame (when the frame
changes); each output tick only draws. ``last_primitives`` counts the quads drawn.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from pibr.protocol.errors import ConfigError, UnexpectedMessage
from pibr.protocol.messages import MAX_QUADTREE_THRESHOLD, PayloadKind
from pibr.protocol.pose import Pose
from pibr.protocol.quadtree import decode_quadtrees

from .base import Method
from .mesh_warp import DEFAULT_SPLIT, MeshWarpProgram, check_split
from .view_warp import SKY_FRACTION, output_projection, source_views

#: Leaves may span this relative distance range ((max - min) / min) unless the method is told otherwise.
DEFAULT_THRESHOLD = 0.02


def check_threshold(threshold: float) -> float:
    if not (isinstance(threshold, (int, float)) and math.isfinite(threshold)
            and 0 < threshold <= MAX_QUADTREE_THRESHOLD):
        raise ConfigError(f"quadtree threshold must be in (0, {MAX_QUADTREE_THRESHOLD:g}] (relative distance "
                          f"range of a leaf), got {threshold!r}")
    return float(threshold)


@njit(cache=True, nogil=True)
def _quad_mesh(leaves, width, height, ids, vertices, tris):
    """Fill vertices / tris for the leaves' quads; ids (height * width) int32 of -1 on entry.
    -> (vertices, quads) written."""
    nv = 0
    nq = 0
    corner = np.empty(4, np.int64)
    for i in range(leaves.shape[0]):
        x0, y0, s = leaves[i, 0], leaves[i, 1], leaves[i, 2]
        x1 = min(x0 + s, width - 1)
        y1 = min(y0 + s, height - 1)
        if x1 <= x0 or y1 <= y0:
            continue
        corner[0], corner[1] = y0 * width + x0, y0 * width + x1
        corner[2], corner[3] = y1 * width + x0, y1 * width + x1
        for k in range(4):
            c = corner[k]
            if ids[c] < 0:
                ids[c] = nv
                vertices[nv, 0] = c % width
                vertices[nv, 1] = c // width
                nv += 1
            corner[k] = ids[c]
        o = 6 * nq
        tris[o], tris[o + 1], tris[o + 2] = corner[0], corner[1], corner[2]
        tris[o + 3], tris[o + 4], tris[o + 5] = corner[1], corner[3], corner[2]
        nq += 1
    return nv, nq


def leaf_quads(leaves, width: int, height: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Leaves (n, 3) (x, y, size) of a ``width`` x ``height`` view -> (vertices (m, 2) float32
    pixel coordinates, triangle indices (q * 6,) uint32, quads q).

    Corners sit at pixel centres, clamped to the last row and column; quads that the clamp
    flattens (leaves in the last row or column) are dropped; each distinct corner is one vertex.
    """
    a = np.ascontiguousarray(np.asarray(leaves).reshape(-1, 3), dtype=np.int64)
    ids = np.full(width * height, -1, np.int32)
    vertices = np.empty((min(4 * len(a), width * height), 2), np.float32)
    tris = np.empty(6 * len(a), np.uint32)
    nv, nq = _quad_mesh(a, width, height, ids, vertices, tris)
    return vertices[:nv], tris[:6 * nq], nq


class QuadtreeMesh:
    """The quads of the current frame's quadtrees on the GPU, one vertex array per view, for
    one :class:`MeshWarpProgram`. GL thread only."""

    def __init__(self, ctx, config, prog, method_name: str):
        self.ctx, self.config, self.prog, self.method_name = ctx, config, prog, method_name
        self.views = source_views(config)
        # The payload holds a tree for every view the session has, used or not.
        self.sizes = [(config.primary.width, config.primary.height)]
        if config.extra is not None:
            self.sizes.append((config.extra.width, config.extra.height))
        self.meshes = {}   # view index -> (vao, vbo, ibo, indices, quads)
        self._key = None
        self._payload = None

    def update(self, frame, textures) -> None:
        """Decode the frame's quadtrees and upload their quads, if the frame is new."""
        data = frame.payload(PayloadKind.QUADTREE)
        if data is None:
            raise UnexpectedMessage(f"frame {frame.frame_id} carries no quadtree payload, which the {self.method_name} "
                                    "method needs in every frame: the client's Hello must ask for one with "
                                    "quadtree_threshold > 0")
        key = (textures.frame_id, frame.frame_id)
        if key == self._key and data is self._payload:
            return
        trees = decode_quadtrees(data, self.sizes)
        self._release_meshes()
        for view in self.views:
            vertices, tris, quads = leaf_quads(trees[view.index], view.width, view.height)
            if quads == 0:
                continue
            vbo = self.ctx.buffer(vertices.tobytes())
            ibo = self.ctx.buffer(tris.tobytes())
            vao = self.ctx.vertex_array(self.prog, [(vbo, "2f", "in_px")], index_buffer=ibo, index_element_size=4)
            self.meshes[view.index] = (vao, vbo, ibo, len(tris), quads)
        self._key, self._payload = key, data

    def draw(self, frame, projection, out_pose: Pose, sky_distance: float) -> int:
        """Draw every view's quads (depth test as set by the caller); -> quads drawn."""
        n = 0
        for view in self.views:
            if view.index not in self.meshes:
                continue
            vao, _, _, count, quads = self.meshes[view.index]
            view.bind(self.prog, frame, projection, out_pose, sky_distance)
            vao.render(self.ctx.TRIANGLES, vertices=count)
            n += quads
        return n

    def _release_meshes(self) -> None:
        for vao, vbo, ibo, _, _ in self.meshes.values():
            vao.release()
            vbo.release()
            ibo.release()
        self.meshes = {}

    def release(self) -> None:
        self._release_meshes()
        self._key = self._payload = None


class QuadtreeWarp(Method):
    """Quadtree leaves of both views as quads, warped and split like ``meshwarp``."""

    name = "quadtree"
    needs_quadtree = True

    def __init__(self, ctx, output, config, threshold: float = DEFAULT_THRESHOLD, split: float = DEFAULT_SPLIT):
        super().__init__(ctx, output, config)
        self.threshold = check_threshold(threshold)   # what the client asks the server for
        self.split = check_split(split)
        self.program = MeshWarpProgram(ctx, config, self.split, grid=False)
        self.mesh = QuadtreeMesh(ctx, config, self.program.prog, self.name)
        self.uses_extra_view = len(self.mesh.views) > 1
        self._frustum_changed()
        self.sky_distance = SKY_FRACTION * config.far
        self.last_primitives = 0

    def _frustum_changed(self) -> None:
        self.projection = output_projection(self.output, self.config.near, self.config.far)

    def render(self, out_pose: Pose, frame, textures, scene_t: float = 0.0) -> None:
        ctx = self.ctx
        self.mesh.update(frame, textures)
        textures.use()
        ctx.enable(ctx.DEPTH_TEST)
        self.last_primitives = self.mesh.draw(frame, self.projection, out_pose, self.sky_distance)
        ctx.disable(ctx.DEPTH_TEST)

    def release(self) -> None:
        self.mesh.release()
        self.program.release()
