"""``none`` and ``rotation``: re-sample the primary wide-angle view along output rays.

``none`` shows the newest frame as it was rendered: output rays are taken at the frame's own
pose. ``rotation`` turns them to the current orientation first (asynchronous timewarp):
head rotation since the render is corrected, translation is ignored. Neither needs depth.
Output rays that leave the primary view's front hemisphere have no source (alpha 0).
With ``motion="flow"`` both show the primary view extrapolated along its motion flow.
"""
from __future__ import annotations

from pibr.protocol.pose import Pose

from ..frame_textures import bind_frame_uniforms, frame_glsl, rect_uniform
from .base import FULLSCREEN_VS, Method, fullscreen_quad, output_tan_centre, output_tan_half

_FS = """
#version 410
%(frame)s
uniform mat3 u_out_to_src;    // output camera -> source camera rotation
uniform vec2 u_tan_half;
uniform vec2 u_tan_centre;  // the image centre on the plane at distance 1 (0: symmetric frustum)
uniform vec2 u_out_size;
uniform vec4 u_color_rect;
out vec4 f_color;
void main() {
    vec2 ndc = vec2(2.0 * gl_FragCoord.x / u_out_size.x - 1.0, 1.0 - 2.0 * gl_FragCoord.y / u_out_size.y);
    vec3 d = u_out_to_src * normalize(vec3(u_tan_centre + ndc * u_tan_half, -1.0));
    if (d.z > 0.0) { f_color = vec4(0.0); return; }
    f_color = vec4(atlas_rgb(u_color_rect, wa_uv(wa_project(d).xy)), 1.0);
}
"""


class DirectionWarp(Method):
    """A full-screen pass sampling the primary view along each output ray (turned by
    ``u_out_to_src``); subclasses may bring their own fragment shader."""

    follow_rotation = True
    fragment_shader = _FS

    def __init__(self, ctx, output, config, motion: str = "static"):
        super().__init__(ctx, output, config)
        self.set_motion(motion)
        self.prog = ctx.program(vertex_shader=FULLSCREEN_VS,
                                fragment_shader=self.fragment_shader % {"frame": frame_glsl(config)})
        bind_frame_uniforms(self.prog, config)
        self._frustum_changed()
        self.prog["u_out_size"].value = (float(output.width), float(output.height))
        self.prog["u_color_rect"].value = rect_uniform(config, "primary.color")
        self.vbo, self.vao = fullscreen_quad(ctx, self.prog)

    def _frustum_changed(self) -> None:
        self.prog["u_tan_half"].value = output_tan_half(self.output)
        self.prog["u_tan_centre"].value = output_tan_centre(self.output)

    def render(self, out_pose: Pose, frame, textures, scene_t: float = 0.0) -> None:
        src = frame.primary_pose
        view_rotation = out_pose.rotation() if self.follow_rotation else src.rotation()
        out_to_src = src.rotation().T @ view_rotation
        self.prog["u_out_to_src"].write(out_to_src.T.astype("f4").tobytes())
        textures.use(self.flow_time(scene_t))
        self.ctx.disable(self.ctx.DEPTH_TEST)
        self.vao.render(self.ctx.TRIANGLE_STRIP)

    def release(self) -> None:
        self.vao.release()
        self.vbo.release()
        self.prog.release()


class NoCompensation(DirectionWarp):
    """The newest frame as rendered, at its own pose."""

    name = "none"
    follow_rotation = False


class RotationWarp(DirectionWarp):
    """Re-projected to the current orientation; translation ignored."""

    name = "rotation"
    follow_rotation = True
