"""``homography``: every pixel assumed on one plane (the Oculus SDK's warp, as compared in
Reinert et al. 2016, Section 6.2).

The primary view's pixels are taken to lie on the plane ``plane_distance`` metres in front of
its camera, perpendicular to its view axis. Each output ray is intersected with that plane and
the hit point is looked up in the primary view: a closed-form backward warp, one full-screen
pass, no depth used. It corrects rotation exactly and translation only for surfaces near the
plane; ``rotation`` is the limit of an infinitely distant plane. Rays that miss the plane (the eye has
passed it) fall back to the direction alone, shown but counted as own holes (alpha 0, as
``proxy`` counts its fallback along the ray), and rays that leave the primary view's hemisphere
are black holes.
"""
from __future__ import annotations

import math

from pibr.protocol.errors import ConfigError
from pibr.protocol.pose import Pose

from .direction_warp import DirectionWarp

#: Metres. Fitted on the tuning windows (``pibr bench pareto --method rotation,homography
#: --windows tuning``, room, 128 ms): DSSIM 1 m 0.150, 2 m 0.112, 4 m 0.075, 8 m 0.102,
#: rotation (infinitely far) 0.123.
DEFAULT_PLANE_DISTANCE = 4.0

_FS = """
#version 410
%(frame)s
uniform mat3 u_out_to_src;    // output camera -> primary camera rotation
uniform vec3 u_eye;           // output camera position in the primary camera's space
uniform float u_plane;        // plane z = -u_plane in the primary camera's space
uniform vec2 u_tan_half;
uniform vec2 u_tan_centre;  // the image centre on the plane at distance 1 (0: symmetric frustum)
uniform vec2 u_out_size;
uniform vec4 u_color_rect;
out vec4 f_color;
void main() {
    vec2 ndc = vec2(2.0 * gl_FragCoord.x / u_out_size.x - 1.0, 1.0 - 2.0 * gl_FragCoord.y / u_out_size.y);
    vec3 d = u_out_to_src * normalize(vec3(u_tan_centre + ndc * u_tan_half, -1.0));
    float t = d.z < 0.0 ? (-u_plane - u_eye.z) / d.z : -1.0;
    vec3 p = t > 0.0 ? u_eye + t * d : d;       // on the plane, or along the ray's direction
    if (p.z > 0.0) { f_color = vec4(0.0); return; }
    f_color = vec4(atlas_rgb(u_color_rect, wa_uv(wa_project(p).xy)), t > 0.0 ? 1.0 : 0.0);
}
"""


class HomographyWarp(DirectionWarp):
    name = "homography"
    fragment_shader = _FS

    def __init__(self, ctx, output, config, plane_distance: float = DEFAULT_PLANE_DISTANCE, motion: str = "static"):
        if not (math.isfinite(plane_distance) and plane_distance > 0):
            raise ConfigError(f"homography plane distance must be a positive number of metres, got {plane_distance}")
        super().__init__(ctx, output, config, motion)
        self.plane_distance = float(plane_distance)
        self.prog["u_plane"].value = self.plane_distance

    def render(self, out_pose: Pose, frame, textures, scene_t: float = 0.0) -> None:
        src = frame.primary_pose
        r_src = src.rotation()
        self.prog["u_out_to_src"].write((r_src.T @ out_pose.rotation()).T.astype("f4").tobytes())
        self.prog["u_eye"].value = tuple(float(x) for x in r_src.T @ (out_pose.p - src.p))
        textures.use(self.flow_time(scene_t))
        self.ctx.disable(self.ctx.DEPTH_TEST)
        self.vao.render(self.ctx.TRIANGLE_STRIP)
