"""``gridwarp``: adaptive-grid warping with depth-aware low-pass hole filling (Schollmeyer et
al. 2017, Sections 4.1, 5.1 and 5.2), from what the client receives.

Per **new server frame** (not per display tick) each view's decoded distance map becomes an
adaptive grid on the CPU (:mod:`pibr.client.surface_grid`: a surface-estimation quadtree per
``tile`` x ``tile`` pixels with the partial cross-kernel reduction, cells from 1 pixel to the
tile, corner depths that join connected surfaces and detach discontinuities), uploaded once as
vertex data. The tolerances are the depth transport's: a depth code is ``near x code range /
distance``, and ``DEPTH_SLACK_CODES`` codes of error are forgiven, as in the shaders.

Per display tick the grids of the primary view, and of the extra view when the session sends
its depth, are drawn depth-tested at the current pose (``warp_point`` of
:mod:`.view_warp`: the extra view's points are tested as if a little farther, so the primary
wins within the transport's error). The primary view's sky is a surface at ``SKY_FRACTION`` of
the far distance; the extra view's empty pixels are not drawn, and neither are its pixels at a
depth discontinuity (``void_at_discontinuities``): at 8 bits its silhouettes' depth is off by
codes, the extra camera's baseline turns that into pixels of misplacement, and those slivers
then cover correct primary surfaces. Measured in the room (512-pixel views, 320 x 180; trace
pred6dof-1 from 20 s, and six poses moved 0.2-0.5 m from the frame's): trace PSNR 26.72 ->
28.28 dB, DSSIM 0.0343 -> 0.0294; moved 23.40 -> 23.49 dB, 0.0972 -> 0.0954. The primary view
alone scores 28.50 dB, 0.0285 and 23.16 dB, 0.0930: with 8-bit depth the extra view buys PSNR
in large disocclusions at a small cost in DSSIM.

Colour (5.1): each fragment projects its interpolated camera-space position back into the
view (exact in the wide-angle projection, however large the cell) and samples it bilinearly,
except within ``NEAREST_BAND`` (half a texel) of a cell side or corner whose connectedness bit
is unset -- where the bilinear footprint would reach across the discontinuity -- there the
nearest texel inside the cell is taken, so colour does not bleed across discontinuities. (The
paper decides per pixel "in the vicinity of a depth discontinuity"; a cell's bits tell which of
its sides that is. Same measurement, moved poses: DSSIM 0.0961 with a 1-texel band, 0.0954 with
half a texel, 0.0966 always bilinear -- which scores best on the trace, 0.0287 against 0.0294.)

Hole filling (5.2, ``fill``): the warp goes to an offscreen RGBA float target (colour and
distance to the output camera) and :class:`~pibr.client.hole_fill.HoleFill` fills its holes
from a depth-aware low-pass pyramid into the output: alpha 1 where the grid covered the pixel,
alpha 0 where the filling supplied it. With ``fill=False`` the grid is drawn straight into the
output and holes stay transparent black.

Moving objects (``motion="flow"``): the primary view is extrapolated along its motion flow
(client/flow_warp.py) as for every other method that re-projects it, and its grid is rebuilt
from the extrapolated distances whenever the extrapolation changes (per tick while something
moves in view; the extra view's grid stays the frame's).
"""
from __future__ import annotations

import math
import time

import numpy as np

from pibr.protocol.errors import ConfigError
from pibr.protocol.pose import Pose

from ..frame_textures import DEPTH_SLACK_CODES, bind_frame_uniforms, frame_glsl
from ..hole_fill import HoleFill
from ..surface_grid import MAX_TILE, build_surface_grid
from .base import Method
from .view_warp import SKY_FRACTION, VIEW_POINT_GLSL, VOID_MARGIN, output_projection, source_views

DEFAULT_TILE = 32
#: Relative collinearity tolerance and estimation-error threshold of the surface quadtree.
DEFAULT_EPSILON = 0.02

#: Texels next to a cell's disconnected side (or corner) where colour is the nearest texel's.
NEAREST_BAND = 0.5

#: Floats per vertex: camera-space position (3), the cell's pixel rectangle (4), its connectedness bits (1).
_VERTEX_FLOATS = 8
_FORMAT = "3f 4f 1f"
_ATTRIBUTES = ("in_pos", "in_rect", "in_bits")
# Two triangles per cell, corners top-left, top-right, bottom-left, bottom-right.
_CELL_INDICES = np.array([0, 1, 2, 1, 3, 2], np.uint32)

_VS = """
#version 410
%(frame)s
%(view)s
in vec3 in_pos;     // a cell corner in the view's camera space
in vec4 in_rect;    // the cell's pixels: x0, y0, x1, y1 (exclusive)
in float in_bits;   // its connectedness to the 8 neighbours
out vec3 v_p;
flat out vec4 v_rect;
flat out int v_bits;
void main() {
    v_p = in_pos;
    v_rect = in_rect;
    v_bits = int(in_bits + 0.5);
    float d = length(in_pos);
    gl_Position = warp_point(in_pos / d, d);
}
"""

_FS = """
#version 410
%(frame)s
uniform vec4 u_color_rect;
uniform vec2 u_view_size;
uniform bool u_write_distance;   // alpha: distance to the output camera (for hole filling) or 1
uniform float u_band;            // texels from a disconnected side that take the nearest texel
in vec3 v_p;
flat in vec4 v_rect;
flat in int v_bits;
out vec4 f_color;
// Bits: 0 E, 1 SE, 2 S, 3 SW, 4 W, 5 NW, 6 N, 7 NE (set: connected on that side).
bool cut(int bit) { return (v_bits & (1 << bit)) == 0; }
void main() {
    vec2 uv = wa_uv(wa_project(v_p).xy);
    if (v_bits != 255) {
        vec2 px = uv * u_view_size;
        bool l = px.x - v_rect.x < u_band, r = v_rect.z - px.x < u_band;
        bool t = px.y - v_rect.y < u_band, b = v_rect.w - px.y < u_band;
        if ((r && cut(0)) || (b && cut(2)) || (l && cut(4)) || (t && cut(6)) || (r && b && cut(1))
                || (l && b && cut(3)) || (l && t && cut(5)) || (r && t && cut(7))) {
            uv = (clamp(floor(px), v_rect.xy, v_rect.zw - 1.0) + 0.5) / u_view_size;
        }
    }
    f_color = vec4(atlas_rgb(u_color_rect, uv), u_write_distance ? 1.0 / gl_FragCoord.w : 1.0);
}
"""


def _check_knobs(tile, epsilon, fill) -> tuple[int, float, bool]:
    if not (isinstance(tile, (int, np.integer)) and not isinstance(tile, bool) and 2 <= tile <= MAX_TILE
            and tile & (tile - 1) == 0):
        raise ConfigError(f"gridwarp tile must be a power of two in 2..{MAX_TILE} pixels, got {tile!r}")
    if isinstance(epsilon, bool) or not isinstance(epsilon, (int, float)) or not (
            math.isfinite(epsilon) and 0 < epsilon <= 1):
        raise ConfigError(f"gridwarp epsilon must be a relative tolerance in (0, 1], got {epsilon!r}")
    if not isinstance(fill, (bool, np.bool_)):
        raise ConfigError(f"gridwarp fill must be true or false, got {fill!r}")
    return int(tile), float(epsilon), bool(fill)


class _ViewGrid:
    """One view's grid on the GPU: vertex and index buffers that grow as needed."""

    def __init__(self, ctx, prog, view, capacity: int = 1024):
        self.ctx, self.prog, self.view = ctx, prog, view
        self.capacity = 0
        self.cells = 0
        self.vbo = ctx.buffer(reserve=capacity * 4 * _VERTEX_FLOATS * 4)
        self.ibo = ctx.buffer(reserve=capacity * 6 * 4)
        self._grow(capacity)
        self.vao = ctx.vertex_array(prog, [(self.vbo, _FORMAT, *_ATTRIBUTES)], index_buffer=self.ibo,
                                    index_element_size=4)

    def _grow(self, capacity: int) -> None:
        self.vbo.orphan(capacity * 4 * _VERTEX_FLOATS * 4)
        self.ibo.orphan(capacity * 6 * 4)
        idx = (np.arange(capacity, dtype=np.uint32)[:, None] * 4 + _CELL_INDICES[None, :]).reshape(-1)
        self.ibo.write(idx.tobytes())
        self.capacity = capacity

    def upload(self, grid) -> None:
        n = grid.count
        if n > self.capacity:
            self._grow(max(n, self.capacity + self.capacity // 2))
        if n:
            data = np.empty((n, 4, _VERTEX_FLOATS), np.float32)
            data[:, :, 0:3] = grid.vertices
            data[:, :, 3:7] = grid.cells[:, None, :]
            data[:, :, 7] = grid.bits[:, None]
            self.vbo.write(data.tobytes())
        self.cells = n

    def release(self) -> None:
        for r in (self.vao, self.vbo, self.ibo):
            r.release()


class GridWarp(Method):
    """Adaptive-grid warp of both views with depth-aware low-pass hole filling."""

    name = "gridwarp"

    def __init__(self, ctx, output, config, tile: int = DEFAULT_TILE, epsilon: float = DEFAULT_EPSILON,
                 fill: bool = True, motion: str = "static"):
        self.tile, self.epsilon, self.fill = _check_knobs(tile, epsilon, fill)
        super().__init__(ctx, output, config)
        self.set_motion(motion)
        glsl = {"frame": frame_glsl(config), "view": VIEW_POINT_GLSL}
        self.prog = ctx.program(vertex_shader=_VS % glsl, fragment_shader=_FS % glsl)
        bind_frame_uniforms(self.prog, config)
        self.prog["u_write_distance"].value = self.fill
        self.prog["u_band"].value = NEAREST_BAND
        self.views = source_views(config)
        self.uses_extra_view = len(self.views) > 1
        self.grids = []
        try:
            for view in self.views:
                self.grids.append(_ViewGrid(ctx, self.prog, view))
            self._frustum_changed()
            self.sky_distance = SKY_FRACTION * config.far
            # The depth transport: code = code_scale / distance, DEPTH_SLACK_CODES codes of error.
            self.code_scale = config.near * float((1 << config.depth_bits) - 1 - config.depth_min_code)
            self.slack_codes = DEPTH_SLACK_CODES[config.depth_codec]
            self.target = self.target_depth = self.target_fbo = self.hole_fill = None
            if self.fill:
                size = (output.width, output.height)
                self.target = ctx.texture(size, 4, dtype="f4")
                self.target.filter = (ctx.NEAREST, ctx.NEAREST)
                self.target_depth = ctx.depth_renderbuffer(size)
                self.target_fbo = ctx.framebuffer(color_attachments=[self.target], depth_attachment=self.target_depth)
                self.hole_fill = HoleFill(ctx, output.width, output.height)
        except Exception:
            self.release()
            raise
        self._frame_id = None
        self._extrapolated = None   # the flow extrapolation the primary grid was built from
        self.last_primitives = 0
        self.last_build_ms = 0.0   # CPU grid construction + upload for the newest frame
        self.builds = 0

    def _frustum_changed(self) -> None:
        self.projection = output_projection(self.output, self.config.near, self.config.far)

    # -- per server frame ------------------------------------------------------------------

    def build(self, textures, primary_only: bool = False) -> None:
        """(Re)build and upload every view's grid from the newest frame's distance maps (the
        primary's as extrapolated along the motion flow when ``textures`` holds it so)."""
        t0 = time.perf_counter()
        for grid in self.grids:
            primary = grid.view.index == 0
            if primary_only and not primary:
                continue
            dist = textures.view_distances("primary" if primary else "extra")
            if dist is None:
                grid.cells = 0
                continue
            ext = textures.extrapolated if primary else None
            if ext is not None:
                x0, y0, w, h = ext.rect
                dist = dist.copy()
                dist[y0:y0 + h, x0:x0 + w] = ext.distance
            g = build_surface_grid(dist, self.tile, self.epsilon, self.code_scale, self.slack_codes,
                                   sky_distance=self.sky_distance if primary else None, void_margin=VOID_MARGIN,
                                   void_at_discontinuities=not primary)
            grid.upload(g)
        self._frame_id = textures.frame_id
        self._extrapolated = textures.extrapolated
        self.builds += 1
        self.last_build_ms = (time.perf_counter() - t0) * 1e3

    # -- per display tick ------------------------------------------------------------------

    def render(self, out_pose: Pose, frame, textures, scene_t: float = 0.0) -> None:
        ctx = self.ctx
        textures.use(self.flow_time(scene_t))     # under ``flow``: the primary view extrapolated
        if textures.frame_id != self._frame_id:
            self.build(textures)
        elif textures.extrapolated is not self._extrapolated:
            self.build(textures, primary_only=True)
        output_fbo = ctx.fbo
        viewport = ctx.viewport
        if self.fill:
            self.target_fbo.use()
            self.target_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.enable(ctx.DEPTH_TEST)
        n = 0
        for grid in self.grids:
            if grid.cells == 0:
                continue
            grid.view.bind(self.prog, frame, self.projection, out_pose, self.sky_distance)
            grid.vao.render(ctx.TRIANGLES, vertices=6 * grid.cells)
            n += 2 * grid.cells
        ctx.disable(ctx.DEPTH_TEST)
        self.last_primitives = n
        if self.fill:
            output_fbo.use()
            ctx.viewport = viewport
            self.hole_fill.fill(self.target)

    def release(self) -> None:
        for grid in getattr(self, "grids", []):
            grid.release()
        self.grids = []
        for name in ("hole_fill", "target_fbo", "target_depth", "target", "prog"):
            obj = getattr(self, name, None)
            if obj is not None:
                obj.release()
                setattr(self, name, None)
