"""``iterative``: iterative image warping (Yang et al. 2011, Bowles et al. 2012), initialised
by the quadtree warp, as compared in Reinert et al. 2016, Section 6.2.

Backward warping: per output pixel, a fixed-point search for the source pixel whose
reconstructed point lands on it. Two passes:

1. *Initialisation.* The ``quadtree`` warp of both views (:mod:`.quadtree_warp`) is drawn,
   depth-tested, into an offscreen RGBA32F target whose fragments store where they come
   from: (u, v, view). Pixels it leaves uncovered start in the primary view from the
   rotation-only guess (the output ray turned into the view), as ``rotation`` would sample.
2. *Iteration*, one full-screen pass, in the view the pixel started in. With ``s`` the current
   source direction, ``P = s * d(s)`` its reconstructed point, ``c`` the output camera's
   centre and ``a`` the target pixel's ray (both in the view's camera space), the point is
   seen from the output camera along ``b = (P - c) / |P - c|``; the update
   ``s <- s + damping * (a - b)`` moves the source direction by the miss, mapped into the
   view through the rotation-only relation between output rays and source directions
   (their difference is what a pure rotation would have corrected). It is done on directions
   rather than on the view's (u, v): the wide-angle projection stretches rows towards its
   poles, and the source and output projections differ, which is what makes an undamped
   iteration in image coordinates diverge (hence the paper's damping; ``damping`` and
   ``iterations`` keep its 0.9 and 10). ``s`` is kept in the view's front hemisphere.

After the iterations, the pixel shows the view's colour where ``s`` ended; if that point
projects more than ``MAX_RESIDUAL_PX`` from the pixel's centre (the search did not converge,
or ended behind the output camera or on the extra view's peeled-away pixels), the pixel is
the method's hole (alpha 0; the colour is still written).

Distances are read as ``meshwarp`` interpolates them: bilinearly between the four nearest
texels unless they span a depth discontinuity (the same split test and transport slack),
else from the nearest texel. With nearest texels only, 8-bit disparity's steps leave gaps in
the warped surface that no search can land in.
"""
from __future__ import annotations

import numpy as np

from pibr.protocol.errors import ConfigError
from pibr.protocol.pose import Pose

from ..frame_textures import bind_frame_uniforms, frame_glsl
from .base import FULLSCREEN_VS, Method, fullscreen_quad, output_tan_centre, output_tan_half
from .mesh_warp import DEFAULT_SPLIT, MeshWarpProgram, check_split
from .quadtree_warp import DEFAULT_THRESHOLD, QuadtreeMesh, check_threshold
from .view_warp import SKY_FRACTION, VOID_MARGIN, output_projection

DEFAULT_ITERATIONS = 10
DEFAULT_DAMPING = 0.9
#: A pixel whose final source point lands farther than this from its centre is a hole.
MAX_RESIDUAL_PX = 1.0
#: Texture units of the initialisation's references and of the views' distances.
_UNIT_REFS, _UNIT_DIST = 6, (7, 8)


def void_marked(extra: np.ndarray, margin: int = VOID_MARGIN) -> np.ndarray:
    """The extra view's distances (h, w) with its empty pixels, and those within ``margin``
    pixels of one, set to -1 (``source_is_void``'s rule)."""
    empty = np.asarray(extra) <= 0
    grown = empty.copy()
    h, w = empty.shape
    for dy in range(-margin, margin + 1):
        for dx in range(-margin, margin + 1):
            grown[max(dy, 0):h + min(dy, 0), max(dx, 0):w + min(dx, 0)] |= \
                empty[max(-dy, 0):h + min(-dy, 0), max(-dx, 0):w + min(-dx, 0)]
    return np.where(grown, np.float32(-1.0), np.asarray(extra, np.float32))

_ITERATE_FS = """
#version 410
%(frame)s
uniform sampler2D u_refs;       // (u, v, view, covered) from the quadtree pass
uniform sampler2D u_dist0;      // the primary view's distances (R32F, 0 = sky)
uniform sampler2D u_dist1;      // the extra view's (negative where void)
uniform vec2 u_out_size;
uniform vec2 u_tan_half;
uniform vec2 u_tan_centre;  // the image centre on the plane at distance 1 (0: symmetric frustum)
uniform mat3 u_out_to_src[2];   // rotation: output camera space -> view camera space
uniform vec3 u_out_centre[2];   // the output camera's centre in view camera space
uniform vec4 u_color_rect[2];
uniform vec2 u_view_size[2];
uniform float u_sky_distance;
uniform float u_split;
uniform int u_iterations;
uniform float u_damping;
uniform float u_max_residual;
uniform bool u_state;           // write (u, v, view, residual) instead of the colour
out vec4 f_out;

// The view's distance at uv: bilinear between the four nearest texels where they are one
// surface (meshwarp's split test), else the nearest texel's; sky (and void) at
// u_sky_distance. 'nearest' is the nearest texel's own value (negative: void).
float view_distance(int v, vec2 uv, out float nearest) {
    vec4 g = v == 0 ? textureGather(u_dist0, uv) : textureGather(u_dist1, uv);
    vec2 t = fract(uv * u_view_size[v] - 0.5);
    // gather order: (i0, j1), (i1, j1), (i1, j0), (i0, j0); rows j grow downwards
    nearest = t.y < 0.5 ? (t.x < 0.5 ? g.w : g.z) : (t.x < 0.5 ? g.x : g.y);
    float lo = min(min(g.x, g.y), min(g.z, g.w));
    float hi = max(max(g.x, g.y), max(g.z, g.w));
    if (lo > 0.0 && hi - lo <= u_split * lo + u_slack_codes * depth_code_step(lo))
        return mix(mix(g.w, g.z, t.x), mix(g.x, g.y, t.x), t.y);
    return nearest > 0.0 ? nearest : u_sky_distance;
}
vec3 safe_normalize(vec3 p, vec3 fallback) {
    float l = length(p);
    return l > 1e-20 ? p / l : fallback;
}
// Directions stay in the view's front hemisphere, the projection's domain.
vec3 to_front(vec3 s, vec3 fallback) { return safe_normalize(vec3(s.xy, min(s.z, 0.0)), fallback); }
vec2 dir_uv(vec3 s) { return clamp(wa_uv(wa_project(s).xy), 0.0, 1.0); }

void main() {
    vec2 px = gl_FragCoord.xy;   // row 0 on top, as every output image
    vec2 ndc = vec2(2.0 * px.x / u_out_size.x - 1.0, 1.0 - 2.0 * px.y / u_out_size.y);
    vec3 ray = normalize(vec3(u_tan_centre + ndc * u_tan_half, -1.0));
    vec4 ref = texelFetch(u_refs, ivec2(px), 0);
    int v = 0;
    vec3 s;
    if (ref.w > 0.0) {                       // the quadtree warp's fragment
        v = ref.z > 0.5 ? 1 : 0;
        s = wa_unproject(wa_from_uv(ref.xy));
    } else {                                 // rotation only, in the primary view
        s = to_front(u_out_to_src[0] * ray, vec3(0.0, 0.0, -1.0));
    }
    vec3 a = u_out_to_src[v] * ray;          // the target ray in the view's camera space
    vec3 c = u_out_centre[v];
    float nearest;
    for (int i = 0; i < u_iterations; ++i) {
        vec3 p = s * view_distance(v, dir_uv(s), nearest);
        vec3 b = safe_normalize(p - c, a);
        s = to_front(s + u_damping * (a - b), s);
    }
    vec2 uv = dir_uv(s);
    vec3 q = transpose(u_out_to_src[v]) * (s * view_distance(v, uv, nearest) - c);   // output camera space
    float residual = 1e30;
    if (q.z < -1e-9) {
        vec2 n = (q.xy + q.z * u_tan_centre) / (-q.z * u_tan_half);
        if (all(lessThan(abs(n), vec2(1e6)))) {
            vec2 qpx = vec2(0.5 * (n.x + 1.0) * u_out_size.x, 0.5 * (1.0 - n.y) * u_out_size.y);
            residual = length(qpx - px);
        }
    }
    bool ok = residual <= u_max_residual && nearest >= 0.0;
    if (u_state) {
        f_out = vec4(uv, float(v), residual);
    } else {
        f_out = vec4(atlas_rgb(u_color_rect[v], uv), ok ? 1.0 : 0.0);
    }
}
"""


class IterativeWarp(Method):
    """Per pixel, a damped fixed-point search for the source point that lands on it,
    started from the quadtree warp."""

    name = "iterative"
    needs_quadtree = True

    def __init__(self, ctx, output, config, iterations: int = DEFAULT_ITERATIONS, damping: float = DEFAULT_DAMPING,
                 threshold: float = DEFAULT_THRESHOLD, split: float = DEFAULT_SPLIT):
        super().__init__(ctx, output, config)
        if not (isinstance(iterations, (int, np.integer)) and not isinstance(iterations, bool)
                and 0 <= iterations <= 1000):
            raise ConfigError(f"iterative warp iterations must be a whole number in 0..1000, got {iterations!r}")
        if not (isinstance(damping, (int, float)) and 0 < damping <= 2):
            raise ConfigError(f"iterative warp damping must be in (0, 2], got {damping!r}")
        self.iterations, self.damping = int(iterations), float(damping)
        self.threshold = check_threshold(threshold)
        self.split = check_split(split)
        self.init = MeshWarpProgram(ctx, config, self.split, grid=False, refs=True)
        self.mesh = QuadtreeMesh(ctx, config, self.init.prog, self.name)
        self.views = self.mesh.views
        self.uses_extra_view = len(self.views) > 1
        self.prog = ctx.program(vertex_shader=FULLSCREEN_VS,
                                fragment_shader=_ITERATE_FS % {"frame": frame_glsl(config)})
        bind_frame_uniforms(self.prog, config)
        rects = [v.color_rect for v in self.views]
        sizes = [(float(v.width), float(v.height)) for v in self.views]
        rects += rects[:1] * (2 - len(rects))
        sizes += sizes[:1] * (2 - len(sizes))
        values = {"u_refs": _UNIT_REFS, "u_dist0": _UNIT_DIST[0], "u_dist1": _UNIT_DIST[1],
                  "u_out_size": (float(output.width), float(output.height)),
                  "u_sky_distance": SKY_FRACTION * config.far, "u_split": self.split,
                  "u_iterations": self.iterations, "u_damping": self.damping, "u_max_residual": MAX_RESIDUAL_PX}
        for k, v in values.items():
            if k in self.prog:
                self.prog[k].value = v
        self.prog["u_color_rect"].write(np.array(rects, np.float32).tobytes())
        if "u_view_size" in self.prog:
            self.prog["u_view_size"].write(np.array(sizes, np.float32).tobytes())
        self.vbo, self.vao = fullscreen_quad(ctx, self.prog)
        size = (output.width, output.height)
        self.refs = ctx.texture(size, 4, dtype="f4")
        self.refs.filter = (ctx.NEAREST, ctx.NEAREST)
        self.refs_depth = ctx.depth_renderbuffer(size)
        self.refs_fbo = ctx.framebuffer(color_attachments=[self.refs], depth_attachment=self.refs_depth)
        self._state = None   # (texture, framebuffer) of solve()
        # The views' distances as the search reads them, replaced when the frame changes.
        self.distances = []
        for view in self.views:
            t = ctx.texture((view.width, view.height), 1, dtype="f4")
            t.filter = (ctx.NEAREST, ctx.NEAREST)
            t.repeat_x = t.repeat_y = False
            self.distances.append(t)
        self._distances_key = None
        self._frustum_changed()
        self.sky_distance = SKY_FRACTION * config.far
        self.last_primitives = 0

    def _frustum_changed(self) -> None:
        self.prog["u_tan_half"].value = output_tan_half(self.output)
        self.prog["u_tan_centre"].value = output_tan_centre(self.output)
        self.projection = output_projection(self.output, self.config.near, self.config.far)

    def _iterate_uniforms(self, out_pose: Pose, frame) -> None:
        rots, centres = [], []
        for view in self.views:
            pose = view.pose(frame)
            rots.append(pose.rotation().T @ out_pose.rotation())            # output -> view camera
            centres.append(pose.rotation().T @ (np.asarray(out_pose.p, float) - np.asarray(pose.p, float)))
        rots += rots[:1] * (2 - len(rots))
        centres += centres[:1] * (2 - len(centres))
        # mat3 uniforms are column-major: the transpose's rows.
        self.prog["u_out_to_src"].write(np.array([r.T for r in rots], np.float32).tobytes())
        self.prog["u_out_centre"].write(np.array(centres, np.float32).tobytes())

    def _initialise(self, out_pose: Pose, frame, textures) -> None:
        """The quadtree warp's references into ``self.refs``."""
        ctx = self.ctx
        self.mesh.update(frame, textures)
        key = (textures.frame_id, frame.frame_id)
        if key != self._distances_key:
            for view, tex in zip(self.views, self.distances):
                d = textures.view_distances("primary" if view.index == 0 else "extra")
                if d is None:
                    raise ConfigError(f"the {self.name} method needs the distances of view {view.index}; "
                                      "the session has none")
                d = np.ascontiguousarray(d if view.index == 0 else void_marked(d), np.float32)
                tex.write(d.tobytes())
            self._distances_key = key
        textures.use()
        self.refs_fbo.use()
        self.refs_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.enable(ctx.DEPTH_TEST)
        self.last_primitives = self.mesh.draw(frame, self.projection, out_pose, self.sky_distance)
        ctx.disable(ctx.DEPTH_TEST)

    def render(self, out_pose: Pose, frame, textures, scene_t: float = 0.0) -> None:
        output_fbo = self.ctx.fbo
        self._initialise(out_pose, frame, textures)
        output_fbo.use()
        self._iterate(out_pose, frame, state=False)

    def _iterate(self, out_pose: Pose, frame, state: bool) -> None:
        self.refs.use(_UNIT_REFS)
        for unit, tex in zip(_UNIT_DIST, self.distances):
            tex.use(unit)
        self._iterate_uniforms(out_pose, frame)
        self.prog["u_state"].value = state
        self.ctx.disable(self.ctx.DEPTH_TEST)
        self.vao.render(self.ctx.TRIANGLE_STRIP)

    def solve(self, out_pose: Pose, frame, textures) -> np.ndarray:
        """Where each output pixel's search ended: (h, w, 4) float32 (u, v, view, residual in
        output pixels; 1e30 where the point is behind the output camera), row 0 on top.
        For tests and diagnosis; leaves the output framebuffer bound as it found it."""
        ctx = self.ctx
        if self._state is None:
            tex = ctx.texture((self.output.width, self.output.height), 4, dtype="f4")
            self._state = (tex, ctx.framebuffer(color_attachments=[tex]))
        tex, fbo = self._state
        previous = ctx.fbo
        self._initialise(out_pose, frame, textures)
        fbo.use()
        self._iterate(out_pose, frame, state=True)
        data = fbo.read(components=4, dtype="f4", alignment=1)
        previous.use()
        return np.frombuffer(data, np.float32).reshape(self.output.height, self.output.width, 4).copy()

    def release(self) -> None:
        if self._state is not None:
            for r in reversed(self._state):
                r.release()
        for r in (self.vao, self.vbo, self.prog, self.refs_fbo, self.refs, self.refs_depth, *self.distances):
            r.release()
        self.mesh.release()
        self.init.release()
