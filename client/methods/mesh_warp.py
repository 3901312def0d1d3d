"""Triangle-mesh warps of the transmitted views (Reinert et al. 2016, Section 6.2).

The pixels of a view are the vertices of a triangle mesh (two triangles per quad of
neighbouring vertices); each vertex moves to its reconstructed position in the output
camera, and the fragments interpolate the view's texture coordinates.

* ``meshwarp``: a vertex at every pixel of both views. A triangle that spans a depth
  discontinuity (its largest vertex distance more than ``1 + split`` times its smallest,
  decided from depth alone as the paper does, no normals) is replaced by two: one with every
  vertex at the minimum distance and one with every vertex at the maximum, so foreground and
  background each move with their own depth instead of being joined by a rubber sheet. The
  range must also exceed the depth transport's error (``DEPTH_SLACK_CODES`` codes, as
  ``proxy`` forgives): 8-bit disparity steps by 20 % at 5 m, which would split every
  triangle of a distant wall.
* ``coarse-meshwarp``: the primary view only, a vertex at every ``step``-th pixel (2, 4, 8,
  16), no splitting: fast, and rubber sheets included, as in the paper.

Both draw depth-tested into the output and leave uncovered pixels as holes (alpha 0).
:class:`MeshWarpProgram` is also the warp of the ``quadtree`` and ``iterative`` methods.
"""
from __future__ import annotations

import math

import numpy as np

from pibr.protocol.errors import ConfigError
from pibr.protocol.pose import Pose

from ..frame_textures import bind_frame_uniforms, frame_glsl
from .base import Method
from .view_warp import COLOR_FS, SKY_FRACTION, VIEW_POINT_GLSL, output_projection, source_views

#: A triangle is split where max - min distance > DEFAULT_SPLIT * min distance + slack.
DEFAULT_SPLIT = 0.05

# Vertex i of a regular grid (every ``u_step``-th pixel, the last row and column included),
# attributeless: drawn with an index buffer, so each vertex is shaded once.
_GRID_VERTEX = """
uniform int u_step;           // pixels between grid vertices
uniform int u_grid_width;     // vertices per grid row
vec2 vertex_pixel() {
    ivec2 v = ivec2(gl_VertexID %% u_grid_width, gl_VertexID / u_grid_width) * u_step;
    return vec2(min(v, ivec2(u_view_size) - 1));
}
"""

# Vertices given as pixel coordinates (the corners of quadtree leaves).
_LIST_VERTEX = """
in vec2 in_px;
vec2 vertex_pixel() { return in_px; }
"""

_VS = """
#version 410
%(frame)s
%(view)s
%(vertex)s
out vec2 g_uv;
out float g_dist;
out vec3 g_dir;
out float g_void;
out vec2 v_uv;
void main() {
    vec2 uv = (vertex_pixel() + 0.5) / u_view_size;
    g_uv = uv;
    v_uv = uv;
    g_dist = source_distance(uv);
    g_dir = source_direction(uv);
    g_void = source_is_void(uv) ? 1.0 : 0.0;
    // Used as is when there is no split pass:
    gl_Position = g_void > 0.0 ? CLIPPED : warp_point(g_dir, g_dist);
}
"""

_SPLIT_GS = """
#version 410
%(frame)s
%(view)s
layout(triangles) in;
layout(triangle_strip, max_vertices = 6) out;
uniform float u_split;        // relative distance range that makes a depth discontinuity
in vec2 g_uv[];
in float g_dist[];
in vec3 g_dir[];
in float g_void[];
out vec2 v_uv;
void emit(float d0, float d1, float d2) {
    float d[3] = float[3](d0, d1, d2);
    for (int i = 0; i < 3; ++i) {
        v_uv = g_uv[i];
        gl_Position = warp_point(g_dir[i], d[i]);
        EmitVertex();
    }
    EndPrimitive();
}
void main() {
    if (g_void[0] + g_void[1] + g_void[2] > 0.0) return;
    float lo = min(g_dist[0], min(g_dist[1], g_dist[2]));
    float hi = max(g_dist[0], max(g_dist[1], g_dist[2]));
    if (hi - lo > u_split * lo + u_slack_codes * depth_code_step(lo)) {
        emit(lo, lo, lo);
        emit(hi, hi, hi);
    } else {
        emit(g_dist[0], g_dist[1], g_dist[2]);
    }
}
"""

# Instead of the colour, where it comes from: (u, v, view, 1) into an RGBA32F target, for a
# pass that resolves each pixel later (iterative warping starts from it).
_REFS_FS = """
#version 410
uniform int u_view;
in vec2 v_uv;
out vec4 f_ref;
void main() { f_ref = vec4(v_uv, float(u_view), 1.0); }
"""


class MeshWarpProgram:
    """The shaders of a mesh warp: grid vertices (attributeless, indexed) or given ones
    (``in_px``), with the discontinuity split (a geometry shader) or without (``split`` None).
    ``refs``: the fragments write (u, v, view, 1) instead of the view's colour."""

    def __init__(self, ctx, config, split: float | None, grid: bool = True, refs: bool = False):
        glsl = {"frame": frame_glsl(config), "view": VIEW_POINT_GLSL,
                "vertex": (_GRID_VERTEX if grid else _LIST_VERTEX) % {}}
        gs = None if split is None else _SPLIT_GS % glsl
        fs = _REFS_FS if refs else COLOR_FS % glsl
        self.prog = ctx.program(vertex_shader=_VS % glsl, geometry_shader=gs, fragment_shader=fs)
        bind_frame_uniforms(self.prog, config)
        if split is not None:
            self.prog["u_split"].value = float(split)

    def release(self) -> None:
        self.prog.release()


def grid_indices(width: int, height: int, step: int) -> tuple[np.ndarray, int, int]:
    """Triangles of a grid with a vertex every ``step`` pixels (last row/column included).

    -> (indices (n_quads * 6,) uint32, vertices per row, quads)."""
    gw = -(-(width - 1) // step) + 1
    gh = -(-(height - 1) // step) + 1
    i = np.arange(gw * gh, dtype=np.uint32).reshape(gh, gw)
    a, b, c, d = i[:-1, :-1], i[:-1, 1:], i[1:, :-1], i[1:, 1:]
    tris = np.stack([a, b, c, b, d, c], axis=-1).reshape(-1)
    return np.ascontiguousarray(tris), gw, (gw - 1) * (gh - 1)


def check_split(split: float) -> float:
    if not (math.isfinite(split) and 0 < split <= 100):
        raise ConfigError(f"split threshold must be in (0, 100] (relative distance range), got {split}")
    return float(split)


class _GridWarp(Method):
    """Shared by meshwarp and coarse-meshwarp: a regular grid per view."""

    step = 1
    split: float | None = None
    primary_only = False

    def __init__(self, ctx, output, config, motion: str = "static"):
        super().__init__(ctx, output, config)
        self.set_motion(motion)
        self.program = MeshWarpProgram(ctx, config, self.split, grid=True)
        self.views = source_views(config, primary_only=self.primary_only)
        self.uses_extra_view = len(self.views) > 1
        self.grids = []     # per view: (vao, index buffer, vertices per row, quads)
        for view in self.views:
            indices, grid_width, quads = grid_indices(view.width, view.height, self.step)
            ibo = ctx.buffer(indices.tobytes())
            vao = ctx.vertex_array(self.program.prog, [], index_buffer=ibo, index_element_size=4)
            self.grids.append((vao, ibo, grid_width, quads))
        self._frustum_changed()
        self.sky_distance = SKY_FRACTION * config.far
        self.last_primitives = 0

    def _frustum_changed(self) -> None:
        self.projection = output_projection(self.output, self.config.near, self.config.far)

    def render(self, out_pose: Pose, frame, textures, scene_t: float = 0.0) -> None:
        ctx, prog = self.ctx, self.program.prog
        textures.use(self.flow_time(scene_t))
        ctx.enable(ctx.DEPTH_TEST)
        n = 0
        for view, (vao, _, grid_width, quads) in zip(self.views, self.grids):
            view.bind(prog, frame, self.projection, out_pose, self.sky_distance)
            prog["u_step"].value = self.step
            prog["u_grid_width"].value = grid_width
            vao.render(ctx.TRIANGLES)
            n += 2 * quads
        ctx.disable(ctx.DEPTH_TEST)
        self.last_primitives = n

    def release(self) -> None:
        for vao, ibo, _, _ in self.grids:
            vao.release()
            ibo.release()
        self.program.release()


class MeshWarp(_GridWarp):
    """Every pixel of both views a vertex; triangles across depth discontinuities split."""

    name = "meshwarp"

    def __init__(self, ctx, output, config, split: float = DEFAULT_SPLIT, motion: str = "static"):
        self.split = check_split(split)
        super().__init__(ctx, output, config, motion)


class CoarseMeshWarp(_GridWarp):
    """Every ``step``-th pixel of the primary view a vertex; no splitting (rubber sheets)."""

    name = "coarse-meshwarp"
    primary_only = True

    def __init__(self, ctx, output, config, step: int = 4, motion: str = "static"):
        if not (isinstance(step, int) and 1 <= step <= 4096):
            raise ConfigError(f"coarse mesh warp step must be a whole number of pixels in 1..4096, got {step!r}")
        self.step = step
        super().__init__(ctx, output, config, motion)
