"""What the forward-warping methods share: where a pixel of a transmitted view lands in the
output camera (Reinert et al. 2016, Section 6.2: every competitor reconstructs each input
pixel's world position from its depth and the view's pose, then re-projects it).

A pixel at ``uv`` of a wide-angle view lies along ``wa_unproject`` of its t' coordinates at
the view's transmitted radial distance. Sky (distance 0) has no position; the warps place it
at ``SKY_FRACTION`` of the scene's far distance, so it moves as a far background would and
stays inside the output's clip volume.

GLSL (after :func:`~pibr.client.frame_textures.frame_glsl`):

* ``source_distance(uv)``: the bound view's distance at ``uv`` (sky moved to the far sphere);
* ``source_is_sky(uv)``; ``source_is_void(uv)``: nothing to draw there (the peeled extra
  view's empty pixels); ``CLIPPED``: a clip position that drops its primitive;
* ``source_direction(uv)``: unit direction of ``uv`` in the view's camera space;
* ``warp_to_clip(p)``: a view-camera-space point -> output clip space (row 0 on top);
  ``warp_point(dir, d)``: the same for the point at distance ``d`` along ``dir``, with the
  extra view's points depth-tested behind the primary's within the transport's error.

Python: :func:`output_projection`, :func:`view_to_clip` and :class:`SourceView`, the views a
frame offers with their poses, sizes and atlas rectangles.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pibr.protocol.frustum import projection as frustum_projection
from pibr.protocol.pose import Pose
from pibr.protocol.session import SessionConfig

from ..frame_textures import has_extra_depth, rect_uniform

#: Sky pixels are warped as a surface at this fraction of the scene's far distance.
SKY_FRACTION = 0.9
#: Pixels of the extra view within this many pixels of an empty one are not drawn.
VOID_MARGIN = 1

VIEW_POINT_GLSL = """
uniform int u_view;            // 0: primary view, 1: extra view
uniform vec2 u_view_size;      // the bound view's size in pixels
uniform float u_sky_distance;  // where sky is placed
uniform mat4 u_view_to_clip;   // the bound view's camera space -> output clip space
bool source_is_sky(vec2 uv) {
    return (u_view == 0 ? primary_distance(uv) : extra_distance(uv)) <= 0.0;
}
uniform int u_void_margin;     // extra view: pixels this close to an empty one are void too
// Nothing to draw: the depth-peeled extra view's empty pixels are peeled-away surfaces or
// sky (the primary view vouches for sky), and so are the pixels next to them, whose depth
// and colour the video codec blurred across the boundary.
bool source_is_void(vec2 uv) {
    if (u_view != 1) return false;
    vec2 texel = 1.0 / u_view_size;
    for (int dy = -u_void_margin; dy <= u_void_margin; ++dy)
        for (int dx = -u_void_margin; dx <= u_void_margin; ++dx)
            if (extra_distance(uv + vec2(dx, dy) * texel) <= 0.0) return true;
    return false;
}
// A clip-space position outside every clip plane: the primitive is dropped.
const vec4 CLIPPED = vec4(0.0, 0.0, 2.0, 1.0);
float source_distance(vec2 uv) {
    float d = u_view == 0 ? primary_distance(uv) : extra_distance(uv);
    return d > 0.0 ? d : u_sky_distance;
}
vec3 source_direction(vec2 uv) { return wa_unproject(wa_from_uv(uv)); }
vec4 warp_to_clip(vec3 p) { return u_view_to_clip * vec4(p, 1.0); }
// The point at distance d along dir, in clip space. The extra view's points are depth-tested
// as if they lay u_slack_codes of depth codes farther (where they are drawn does not change):
// within the transport's error the primary view wins, as in proxy IBR, and the extra view
// fills in where it shows something clearly nearer, or where the primary shows nothing.
vec4 warp_point(vec3 dir, float d) {
    vec4 c = warp_to_clip(dir * d);
    if (u_view == 0) return c;
    vec4 b = warp_to_clip(dir * (d + u_slack_codes * depth_code_step(d)));
    return vec4(c.xy, b.z / b.w * c.w, c.w);
}
"""


# The fragment shader of the forward warps: the bound view's colour at the interpolated uv.
COLOR_FS = """
#version 410
%(frame)s
uniform vec4 u_color_rect;
in vec2 v_uv;
out vec4 f_color;
void main() { f_color = vec4(atlas_rgb(u_color_rect, v_uv), 1.0); }
"""


def output_projection(output, near: float, far: float) -> np.ndarray:
    """(4, 4) OpenGL perspective matrix of the output camera."""
    return frustum_projection(output.tangents(), near, far)


_FLIP_Y = np.diag([1.0, -1.0, 1.0, 1.0])   # images are stored top row first


def view_to_clip(projection: np.ndarray, out_pose: Pose, view_pose: Pose) -> np.ndarray:
    """(4, 4) matrix from a view's camera space to the output camera's clip space."""
    return _FLIP_Y @ projection @ out_pose.view_matrix() @ view_pose.matrix()


def mat4_bytes(m: np.ndarray) -> bytes:
    """A numpy (4, 4) matrix as a GLSL mat4 uniform (column-major float32)."""
    return np.ascontiguousarray(m.T, dtype=np.float32).tobytes()


@dataclass(frozen=True)
class SourceView:
    """One transmitted view of a session: index (0 primary, 1 extra), size, colour rectangle."""

    index: int
    width: int
    height: int
    color_rect: tuple

    def pose(self, frame) -> Pose:
        return frame.primary_pose if self.index == 0 else frame.extra_pose

    def bind(self, prog, frame, projection: np.ndarray, out_pose: Pose, sky_distance: float) -> None:
        """Set the uniforms of VIEW_POINT_GLSL (and ``u_color_rect``, if used) for this view."""
        values = {"u_view": self.index, "u_view_size": (float(self.width), float(self.height)),
                  "u_void_margin": VOID_MARGIN,
                  "u_sky_distance": float(sky_distance), "u_color_rect": self.color_rect}
        for name, value in values.items():
            if name in prog:
                prog[name].value = value
        prog["u_view_to_clip"].write(mat4_bytes(view_to_clip(projection, out_pose, self.pose(frame))))


def source_views(config: SessionConfig, primary_only: bool = False) -> list[SourceView]:
    """The views a session's frames carry with depth: the primary, and the extra view when it
    has depth and ``primary_only`` is False."""
    views = [SourceView(0, config.primary.width, config.primary.height, rect_uniform(config, "primary.color"))]
    if not primary_only and has_extra_depth(config):
        views.append(SourceView(1, config.extra.width, config.extra.height, rect_uniform(config, "extra.color")))
    return views
