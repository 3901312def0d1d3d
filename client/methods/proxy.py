"""``proxy``: proxy-guided image-based rendering (Reinert et al. 2016).

One pass over the scene's level-of-detail proxy at the *current* pose. Per fragment, with
f_p and f_e its distances to the primary and extra cameras and d_p, d_e the distances
those views stored where it back-projects, e = |(d - f) / f|:

* e_p < tau: the primary view saw this very surface point: take its colour;
* else, unless the primary saw past the fragment (its point is empty space, carved), if
  e_e < tau the extra view saw it: take the extra view's colour;
* else the proxy is not where the true surface is (an encaging proxy bulges past the
  silhouette, or the surface was hidden in both views). The fragment is not discarded but
  *deprioritised*: written behind every accepted fragment (depth mapped to [0.5, 1) instead
  of [0, 0.5)) and coloured from the view with the lower error. Silhouettes stay carved —
  any accepted fragment behind wins — and holes are inpainted at no extra cost. Its alpha
  is 0, so the client counts the pixel as one no view covered.

Where the primary view shows sky the fragment is dropped so the sky behind shows. Pixels no
proxy fragment reached take the primary view along their ray: the sky, or a rotation-only
fallback (alpha 0).

Shading is deferred: the proxy pass stores, per pixel, which view and where to sample; one
full-screen pass then fetches each pixel's colour once (or the background where no proxy
was drawn). Measured here (960x540, room): 48 ms per frame deferred against 80-88 ms with the
colour fetched in the proxy pass, since every overlapping proxy fragment runs the shader when
it writes its own depth.
"""
from __future__ import annotations

import numpy as np

from pibr.protocol.pose import Pose

from ..frame_textures import bind_frame_uniforms, frame_glsl, has_extra_depth, rect_uniform
from ..lod_select import DEFAULT_TARGET_PX, LodSelector
from .base import FULLSCREEN_VS, Method, fullscreen_quad, output_tan_half
from .view_warp import output_projection

DEFAULT_TAU = 0.1

_PROXY_VS = """
#version 410
uniform mat4 u_mvp;          // object -> clip space of the output camera
uniform mat4 u_to_primary;   // object -> primary camera space
uniform mat4 u_to_extra;     // object -> extra camera space
in vec3 in_position;
out vec3 v_p;
out vec3 v_e;
void main() {
    vec4 p = vec4(in_position, 1.0);
    v_p = (u_to_primary * p).xyz;
    v_e = (u_to_extra * p).xyz;
    gl_Position = u_mvp * p;
    gl_Position.y = -gl_Position.y;   // top-row-first images
}
"""

# Colour is fetched once per pixel, after the depth test picked the fragment: on a software
# rasteriser, writing gl_FragDepth rules out early depth tests, so every overlapping proxy
# fragment runs the shader, and the three colour-plane lookups are the costly part. Pixels no
# proxy reached get the background here too, which saves a full-screen pass.
_RESOLVE_FS = """
#version 410
%(frame)s
uniform sampler2D u_refs;
uniform vec4 u_primary_color;
uniform vec4 u_extra_color;
uniform mat3 u_out_to_src;   // output camera -> primary camera rotation
uniform mat3 u_out_to_extra; // output camera -> extra camera rotation
uniform bool u_extra_sky;    // the extra view's sky may fill in (it marks peeled pixels apart)
uniform vec2 u_tan_half;
uniform vec2 u_out_size;
out vec4 f_color;
// Where no proxy fragment landed: the sky along this pixel's ray. Sky is at infinity, so any
// view shows it in the same direction: the primary view's if it shows sky there, else the
// extra view's if that one does (it saw past what blocks the primary: a lamp post in front of
// the sky); else a rotation-only fallback from the primary (alpha 0: no view vouches for it).
vec4 background() {
    vec2 ndc = vec2(2.0 * gl_FragCoord.x / u_out_size.x - 1.0, 1.0 - 2.0 * gl_FragCoord.y / u_out_size.y);
    vec3 ray = normalize(vec3(ndc * u_tan_half, -1.0));
    vec3 d = u_out_to_src * ray;
    vec2 uv = wa_uv(wa_project(d).xy);
    if (d.z <= 0.0 && primary_distance(uv) == 0.0) return vec4(atlas_rgb(u_primary_color, uv), 1.0);
    if (u_extra_sky) {
        vec3 e = u_out_to_extra * ray;
        vec2 uv_e = wa_uv(wa_project(e).xy);
        if (e.z <= 0.0 && extra_distance(uv_e) == 0.0) return vec4(atlas_rgb(u_extra_color, uv_e), 1.0);
    }
    if (d.z > 0.0) return vec4(0.0);
    return vec4(atlas_rgb(u_primary_color, uv), 0.0);
}
void main() {
    vec4 ref = texelFetch(u_refs, ivec2(gl_FragCoord.xy), 0);
    if (ref.z < 0.0) {                        // no proxy here
        f_color = background();
        return;
    }
    vec3 c = ref.z < 0.5 ? atlas_rgb(u_primary_color, ref.xy)
           : ref.z < 1.5 ? atlas_rgb(u_extra_color, ref.xy) : vec3(0.0);
    f_color = vec4(c, ref.w);
}
"""

_PROXY_FS = """
#version 410
%(frame)s
uniform vec4 u_primary_color;
uniform vec4 u_extra_color;
uniform bool u_has_extra;
uniform float u_tau;
in vec3 v_p;
in vec3 v_e;
out vec4 f_ref;   // (u, v, view: 0 primary / 1 extra / 2 none, accepted)
const float NO_MATCH = 1e30;
// Relative error between a view's stored distance d and the fragment's f; NO_MATCH behind
// the camera, at its centre, or where the view stores sky (then 'sky' is set). 'past': the
// view saw beyond the fragment (d > f).
float view_error(vec3 c, bool extra, out vec2 uv, out bool sky, out bool past) {
    sky = false;
    past = false;
    uv = vec2(0.0);
    float f = length(c);
    if (c.z > 0.0 || f < 1e-6) return NO_MATCH;
    uv = wa_uv(wa_project(c).xy);
    float d = extra ? extra_distance(uv) : primary_distance(uv);
    if (d <= 0.0) { sky = true; return NO_MATCH; }
    past = d > f;
    // The transport knows a distance only to within its code step, which grows as f^2
    // (disparity coding): forgive that much before comparing with tau.
    return max(abs(d - f) - u_slack_codes * depth_code_step(f), 0.0) / f;
}
void main() {
    vec2 uv_p, uv_e;
    bool sky_p, sky_e, past_p, past_e;
    float e_p = view_error(v_p, false, uv_p, sky_p, past_p);
    float z = gl_FragCoord.z;
    if (e_p < u_tau) {   // the common case: no need to look at the extra view
        f_ref = vec4(uv_p, 0.0, 1.0);
        gl_FragDepth = 0.5 * z;
        return;
    }
    // Where the primary view saw past the fragment (a farther surface, or sky), its point is
    // empty space: carve it, whatever the extra view seems to confirm there. The extra view
    // fills only what the primary could not see: points hidden behind its nearer surfaces.
    float e_e = NO_MATCH;
    if (u_has_extra && !(past_p || sky_p)) e_e = view_error(v_e, true, uv_e, sky_e, past_e);
    if (e_e < u_tau) {
        f_ref = vec4(uv_e, 1.0, 1.0);
        gl_FragDepth = 0.5 * z;
    } else {
        if (sky_p) discard;   // the primary sees nothing there: carve, let the sky show
        f_ref = (e_e < e_p) ? vec4(uv_e, 1.0, 0.0) : vec4(uv_p, v_p.z <= 0.0 ? 0.0 : 2.0, 0.0);
        gl_FragDepth = 0.5 + 0.5 * z;
    }
}
"""


class ProxyIBR(Method):
    name = "proxy"
    needs_proxies = True

    def __init__(self, ctx, output, config, proxies=None, tau: float = DEFAULT_TAU,
                 lod_target_px: float = DEFAULT_TARGET_PX, lod_level: str | None = None, extra_view: bool = True):
        super().__init__(ctx, output, config)
        if not proxies:
            from pibr.protocol.errors import ConfigError

            raise ConfigError("the proxy method needs the scene's proxies; the server sent none")
        self.tau = tau
        self.objects = proxies
        self.selector = LodSelector(proxies, output, lod_target_px, force_level=lod_level)
        frame = {"frame": frame_glsl(config)}
        self.prog = ctx.program(vertex_shader=_PROXY_VS, fragment_shader=_PROXY_FS % frame)
        self.resolve = ctx.program(vertex_shader=FULLSCREEN_VS, fragment_shader=_RESOLVE_FS % frame)
        for p in (self.prog, self.resolve):
            bind_frame_uniforms(p, config)
        self.refs = ctx.texture((output.width, output.height), 4, dtype="f4")
        self.refs.filter = (ctx.NEAREST, ctx.NEAREST)
        self.refs_depth = ctx.depth_renderbuffer((output.width, output.height))
        self.refs_fbo = ctx.framebuffer(color_attachments=[self.refs], depth_attachment=self.refs_depth)
        self.resolve["u_refs"].value = 5
        self.resolve["u_tan_half"].value = output_tan_half(output)
        self.resolve["u_out_size"].value = (float(output.width), float(output.height))
        for k, rect in (("u_primary_color", "primary.color"), ("u_extra_color", "extra.color")):
            if k in self.resolve:
                self.resolve[k].value = rect_uniform(config, rect)
        # extra_view=False ignores a transmitted extra view: what proxy IBR does without one.
        self.uses_extra_view = bool(extra_view) and has_extra_depth(config)
        self.prog["u_has_extra"].value = self.uses_extra_view
        # Sessions whose extra view marks peeled pixels apart from sky, in depth codes that keep
        # the mark (min_code >= 2; see protocol/depth.py), let the extra view vouch for sky.
        self.resolve["u_extra_sky"].value = (self.uses_extra_view and bool(config.options.get("peel_marker"))
                                             and config.depth_min_code >= 2)
        self.prog["u_tau"].value = float(tau)
        self.resolve_vbo, self.resolve_vao = fullscreen_quad(ctx, self.resolve)
        self.near, self.far = config.near, config.far
        self.projection = output_projection(output, self.near, self.far)
        self._buffers = []
        self.vaos = []   # per object: level -> (vao, triangles)
        for o in proxies:
            levels = {}
            for level in ("original", "proxy", "box"):
                v, f = o.level(level)
                if len(f) == 0:
                    continue
                vbo = ctx.buffer(np.ascontiguousarray(v, np.float32).tobytes())
                ibo = ctx.buffer(np.ascontiguousarray(f, np.uint32).tobytes())
                vao = ctx.vertex_array(self.prog, [(vbo, "3f", "in_position")], index_buffer=ibo,
                                       index_element_size=4)
                self._buffers += [vbo, ibo]
                levels[level] = (vao, len(f))
            self.vaos.append(levels)
        self.last_primitives = 0

    def render(self, out_pose: Pose, frame, textures, scene_t: float = 0.0) -> None:
        ctx = self.ctx
        output_fbo = ctx.fbo
        textures.use()
        # Proxies, depth-tested, with deprioritised fragments pushed behind accepted ones; each
        # pixel keeps where to fetch its colour.
        self.refs_fbo.use()
        self.refs_fbo.clear(0.0, 0.0, -1.0, 0.0, depth=1.0)
        ctx.enable(ctx.DEPTH_TEST)
        view = out_pose.view_matrix()
        to_p = frame.primary_pose.view_matrix()
        to_e = frame.extra_pose.view_matrix() if frame.extra_pose is not None else to_p
        vp = self.projection @ view
        frame_t = frame.scene_t_us / 1e6
        tris = 0
        for sel in self.selector.select(out_pose, scene_t, self.near):
            levels = self.vaos[sel.index]
            level = sel.level if sel.level in levels else next(iter(levels), None)
            if level is None:
                continue
            obj = self.objects[sel.index]
            model = obj.world_matrix(scene_t)
            # A moving object is drawn where it is now, but looked up where the views saw it.
            seen = obj.world_matrix(frame_t) if obj.motion is not None else model
            self.prog["u_mvp"].write((vp @ model).T.astype("f4").tobytes())
            self.prog["u_to_primary"].write((to_p @ seen).T.astype("f4").tobytes())
            self.prog["u_to_extra"].write((to_e @ seen).T.astype("f4").tobytes())
            vao, n = levels[level]
            vao.render(ctx.TRIANGLES)
            tris += n
        self.last_primitives = tris
        ctx.disable(ctx.DEPTH_TEST)
        output_fbo.use()
        self.refs.use(5)
        rot = frame.primary_pose.rotation().T @ out_pose.rotation()
        self.resolve["u_out_to_src"].write(rot.T.astype("f4").tobytes())
        if self.uses_extra_view and frame.extra_pose is not None:
            rot = frame.extra_pose.rotation().T @ out_pose.rotation()
            self.resolve["u_out_to_extra"].write(rot.T.astype("f4").tobytes())
        self.resolve_vao.render(ctx.TRIANGLE_STRIP)

    def release(self) -> None:
        for levels in self.vaos:
            for vao, _ in levels.values():
                vao.release()
        for b in self._buffers:
            b.release()
        for r in (self.prog, self.resolve_vao, self.resolve_vbo, self.resolve,
                  self.refs_fbo, self.refs, self.refs_depth):
            r.release()
