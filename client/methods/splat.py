"""``splat``: point splatting (Chen and Williams 1993, as compared in Reinert et al. 2016, 6.2).

Every pixel of both transmitted views becomes one point at its reconstructed position,
projected into the output camera and drawn ``point_size`` output pixels wide (2 by default,
to close the small gaps between neighbouring points), depth-tested so the nearest wins.
No hole filling: pixels no point reaches stay holes (alpha 0). Sky pixels are points on the
far sphere (see :mod:`.view_warp`).
"""
from __future__ import annotations

from pibr.protocol.pose import Pose

from ..frame_textures import bind_frame_uniforms, frame_glsl
from .base import Method
from .view_warp import COLOR_FS, SKY_FRACTION, VIEW_POINT_GLSL, output_projection, source_views

DEFAULT_POINT_SIZE = 2.0

_VS = """
#version 410
%(frame)s
%(view)s
out vec2 v_uv;
void main() {
    int w = int(u_view_size.x);
    ivec2 px = ivec2(gl_VertexID %% w, gl_VertexID / w);
    v_uv = (vec2(px) + 0.5) / u_view_size;
    gl_Position = source_is_void(v_uv) ? CLIPPED : warp_point(source_direction(v_uv), source_distance(v_uv));
}
"""

class PointSplat(Method):
    name = "splat"

    def __init__(self, ctx, output, config, point_size: float = DEFAULT_POINT_SIZE, motion: str = "static"):
        super().__init__(ctx, output, config)
        self.set_motion(motion)
        if not (0.5 <= point_size <= 64):
            from pibr.protocol.errors import ConfigError

            raise ConfigError(f"splat point size must be in 0.5..64 pixels, got {point_size}")
        glsl = {"frame": frame_glsl(config), "view": VIEW_POINT_GLSL}
        self.prog = ctx.program(vertex_shader=_VS % glsl, fragment_shader=COLOR_FS % glsl)
        bind_frame_uniforms(self.prog, config)
        self.vao = ctx.vertex_array(self.prog, [])
        self.views = source_views(config)
        self.uses_extra_view = len(self.views) > 1
        self.point_size = float(point_size)
        self._frustum_changed()
        self.sky_distance = SKY_FRACTION * config.far
        self.last_primitives = 0

    def _frustum_changed(self) -> None:
        self.projection = output_projection(self.output, self.config.near, self.config.far)

    def render(self, out_pose: Pose, frame, textures, scene_t: float = 0.0) -> None:
        ctx = self.ctx
        textures.use(self.flow_time(scene_t))
        ctx.enable(ctx.DEPTH_TEST)
        ctx.point_size = self.point_size
        n = 0
        for view in self.views:
            view.bind(self.prog, frame, self.projection, out_pose, self.sky_distance)
            count = view.width * view.height
            self.vao.render(ctx.POINTS, vertices=count)
            n += count
        ctx.disable(ctx.DEPTH_TEST)
        self.last_primitives = n

    def release(self) -> None:
        self.vao.release()
        self.prog.release()
