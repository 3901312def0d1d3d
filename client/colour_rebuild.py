"""Whole-resolution colour from a session's jittered quarter-resolution colour.

At ``SessionConfig.colour_scale`` 0.5 each frame carries, of each view, the luma of one pixel
of every 2x2 block and the chroma of one 2x2 block of every 4x4, a different one every frame
(protocol/atlas.py ``COLOUR_JITTER``), and the view's depth whole. The client rebuilds every
view's whole colour once per frame, as Pajak et al. 2011 (Sec. 3.3, Fig. 2) do after Herzog et
al. 2010, luma per pixel and chroma per 2x2 block (4:2:0, as whole colour is sent), each a
bilateral weighting of

* the new samples around it, each at the very pixel (block) it was taken at, weighted by screen
  distance and kept only on the pixel's own surface (their distances agree): a sample never
  bleeds across a depth edge;
* the view's previous rebuilt colour, reprojected with this frame's depth and both frames'
  poses (the point seen at this pixel, looked up where the previous frame saw it), used only
  from the texels where the previous frame saw that same point (its distance there agrees): at
  disocclusions, or where the point left the previous view, only the new samples count.

The new samples' weight falls with the distance to the nearest one (a pixel sampled this frame
takes its sample; the others lean on the history), the history's with its age: each pixel keeps
a confidence for its luma and for its chroma, the weights gathered, decayed every frame and
capped. A still view has had every pixel's luma and every block's chroma sent after four frames
and converges on the whole colour (exactly when the weights between samples are near zero;
``RebuildSettings``); a moving one keeps what reprojects and fills the rest from the new samples.
Pixels of moving objects are checked by depth alone (the client reprojects with the views'
poses, not the objects' motion), so an object that moves within its own depth can leave a trace
for a few frames. The reprojection is only as good as the depth: 8-bit disparity in the atlas
(``h264``) misplaces it by pixels where the head moves (``pibr bench upsampling``); Pajak et
al. pair the lever with their edge codec's depth.

Each frame: two short passes per view gather the new samples once (luma, and chroma with the
distances at their pixels), then one pass per view writes the rebuilt Y, U, V and the luma's
confidence (RGBA16F) and the distance and the chroma's confidence (RG32F) into textures where
the views sit side by side (:func:`rebuilt_layout`); the methods' ``atlas_rgb`` samples the
newest (client/frame_textures.py), the other holds the previous frame's.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pibr.protocol.atlas import colour_jitter
from pibr.protocol.errors import ConfigError
from pibr.protocol.session import SessionConfig

#: Texture units: the rebuilt colour the methods sample (above the frame's 0-4, proxy's 5, the
#: hole filler's 6-8 and below the scaled render's 15), and, during a rebuild, the new luma and
#: chroma samples and the previous rebuild.
UNIT_REBUILT, UNIT_LUMA, UNIT_CHROMA, UNIT_PREVIOUS, UNIT_PREVIOUS_AUX = 12, 10, 11, 13, 14


@dataclass(frozen=True)
class RebuildSettings:
    """The weights (module docstring); distances in whole-resolution pixels (blocks for chroma).
    The defaults were fitted on the tuning windows (bench/windows.py; room, edge depth, 384^2):
    interpolations weigh more and the history decays faster than exactness on a still view would
    want, which buys about 0.7 dB on a moving head for 0.2 dB after four still frames.

    spatial_sigma    : screen-distance falloff among the new samples that make a pixel's spatial estimate
    sample_sigma     : falloff of that estimate's weight with the distance to the nearest new sample
    decay            : the history's confidence is multiplied by this every frame
    max_confidence   : and capped here (the most frames' worth of weight the history may hold)
    depth_tolerance  : relative distance within which two points are one surface (plus the depth
                       transport's slack, client/frame_textures.py DEPTH_SLACK_CODES)
    """

    spatial_sigma: float = 0.5
    sample_sigma: float = 0.45
    decay: float = 0.7
    max_confidence: float = 4.0
    depth_tolerance: float = 0.02

    def __post_init__(self):
        for name in ("spatial_sigma", "sample_sigma", "max_confidence"):
            if not 0.0 < getattr(self, name) < 1e3:
                raise ConfigError(f"colour rebuild: {name} must be positive, got {getattr(self, name)!r}")
        if not 0.0 < self.decay <= 1.0:
            raise ConfigError(f"colour rebuild: decay must be in (0, 1], got {self.decay!r}")
        if not 0.0 < self.depth_tolerance < 1.0:
            raise ConfigError(f"colour rebuild: depth_tolerance must be in (0, 1), got {self.depth_tolerance!r}")


DEFAULT_SETTINGS = RebuildSettings()


def rebuilt_layout(config: SessionConfig) -> dict:
    """name -> (x, y, w, h) of each view in the rebuilt texture: the primary view at the origin,
    the extra view to its right; and "size" -> (w, h) of the texture."""
    p, e = config.primary, config.extra
    rects = {"primary": (0, 0, p.width, p.height)}
    width, height = p.width, p.height
    if e is not None:
        rects["extra"] = (p.width, 0, e.width, e.height)
        width, height = width + e.width, max(height, e.height)
    rects["size"] = (width, height)
    return rects


_SAMPLES_FS = """
#version 410
%(frame_glsl)s
uniform vec4 u_low_rect;            // this view's colour in the frame's atlas
uniform ivec2 u_jitter;
layout(location = 0) out vec4 o_sample;
// Each new sample once. Luma (u_chroma false): sample s, taken at pixel 2 s + jitter -> (Y, its
// distance). Chroma: sample s, of block 2 s + jitter -> (U, V, the distance at the block's pixel
// whose luma was sent).
uniform bool u_chroma;
void main() {
    ivec2 s = ivec2(gl_FragCoord.xy);
    ivec2 origin = ivec2(u_low_rect.xy);
    if (u_chroma) {
        ivec2 c = origin / 2 + s;
        o_sample = vec4(texelFetch(u_atlas_u, c, 0).r, texelFetch(u_atlas_v, c, 0).r,
                        %(distance)s_at(2 * (2 * s + u_jitter) + u_jitter), 0.0);
    } else {
        o_sample = vec4(texelFetch(u_atlas_y, origin + s, 0).r, %(distance)s_at(2 * s + u_jitter), 0.0, 0.0);
    }
}
"""

_REBUILD_FS = """
#version 410
%(frame_glsl)s
uniform sampler2D u_luma;           // this frame's luma samples of the view: (Y, distance)
uniform sampler2D u_chroma;         // ... and chroma samples: (U, V, distance)
uniform sampler2D u_prev_colour;    // the previous rebuild: (Y, U, V, luma confidence)
uniform sampler2D u_prev_aux;       // ... and (distance, chroma confidence)
uniform vec4 u_view_rect;           // this view in the rebuilt texture (x, y, w, h), pixels
uniform ivec2 u_jitter;
uniform mat4 u_to_prev;             // this frame's camera space -> the previous frame's (this view)
uniform bool u_history;             // the previous rebuild holds this view
uniform float u_spatial_sigma2;     // 2 sigma^2 of RebuildSettings.spatial_sigma
uniform float u_sample_sigma2;      // 2 sigma^2 of RebuildSettings.sample_sigma
uniform float u_decay;
uniform float u_max_confidence;
uniform float u_depth_tolerance;
layout(location = 0) out vec4 o_colour;
layout(location = 1) out vec4 o_aux;

uniform float u_slack_per_metre;     // the transport's slack over distance^2 (u_slack_codes * depth_code_step(r) / r^2)
// One surface: both sky, both peeled, or distances within the tolerance and the transport's slack.
bool same_surface(float a, float b) {
    if (a <= 0.0 || b <= 0.0) return sign(a) == sign(b);
    return abs(a - b) <= a * (u_depth_tolerance + u_slack_per_metre * a);
}

// The new samples around grid position g (pixels for luma, 2x2 blocks for chroma): the four
// samples s around it, taken at 2 s + jitter, on the surface at distance d -> their weighted
// mean in .xy (luma: .x) and, in .w, the estimate's weight (falling with the distance to the nearest).
vec4 spatial(sampler2D samples, ivec2 g, float d, int channels) {
    ivec2 size = textureSize(samples, 0);
    ivec2 first = (g - u_jitter) >> 1;
    vec2 sum = vec2(0.0), any_value = vec2(0.0);
    float weight = 0.0, nearest2 = 1e9, any2 = 1e9;
    for (int k = 0; k < 4; ++k) {
        ivec2 s = clamp(first + ivec2(k & 1, k >> 1), ivec2(0), size - 1);
        vec4 v = texelFetch(samples, s, 0);
        float sd = channels == 1 ? v.y : v.z;
        vec2 delta = vec2(2 * s + u_jitter - g);
        float r2 = dot(delta, delta);
        if (r2 < any2) { any2 = r2; any_value = v.xy; }
        if (!same_surface(d, sd)) continue;
        float w = exp(-r2 / u_spatial_sigma2);
        sum += w * v.xy;
        weight += w;
        nearest2 = min(nearest2, r2);
    }
    // no sample on this surface nearby (a thin object): the nearest of any, barely trusted; a floor
    // on the weight so that a pixel without history never divides 0 by 0
    return weight > 0.0 ? vec4(sum / weight, 0.0, max(exp(-nearest2 / u_sample_sigma2), 1e-4))
                        : vec4(any_value, 0.0, 1e-4);
}

void main() {
    ivec2 q = ivec2(gl_FragCoord.xy) - ivec2(u_view_rect.xy);   // this pixel of the view, row 0 on top
    vec2 size = u_view_rect.zw;
    float d = %(distance)s_at(q);
    vec4 luma = spatial(u_luma, q, d, 1);
    vec4 chroma = spatial(u_chroma, q >> 1, d, 2);

    // the history: where the previous frame saw the point this pixel sees, if it saw it
    vec3 history = vec3(0.0);
    float luma_history = 0.0, chroma_history = 0.0;
    if (u_history) {
        vec3 dir = wa_unproject(wa_from_uv((vec2(q) + 0.5) / size));
        vec3 p = d > 0.0 ? (u_to_prev * vec4(dir * d, 1.0)).xyz : mat3(u_to_prev) * dir;
        vec3 t = wa_project(p);
        float expected = d > 0.0 ? t.z : d;
        vec2 pp = wa_uv(t.xy) * size - 0.5;           // in the previous view's pixels, texel centres on integers
        if (p.z < 0.0 && all(greaterThanEqual(pp, vec2(-0.5))) && all(lessThan(pp, size - 0.5))) {
            ivec2 p0 = ivec2(floor(pp));
            vec2 f = pp - vec2(p0);
            ivec2 origin = ivec2(u_view_rect.xy);
            ivec2 last = ivec2(size) - 1;
            ivec2 t00 = clamp(p0, ivec2(0), last) + origin, t10 = clamp(p0 + ivec2(1, 0), ivec2(0), last) + origin;
            ivec2 t01 = clamp(p0 + ivec2(0, 1), ivec2(0), last) + origin, t11 = clamp(p0 + ivec2(1, 1), ivec2(0), last) + origin;
            vec2 a00 = texelFetch(u_prev_aux, t00, 0).xy, a10 = texelFetch(u_prev_aux, t10, 0).xy;
            vec2 a01 = texelFetch(u_prev_aux, t01, 0).xy, a11 = texelFetch(u_prev_aux, t11, 0).xy;
            // which of the four texels around saw the same point, by their bilinear weights
            vec4 w = vec4((1.0 - f.x) * (1.0 - f.y), f.x * (1.0 - f.y), (1.0 - f.x) * f.y, f.x * f.y)
                     * vec4(same_surface(expected, a00.x), same_surface(expected, a10.x),
                            same_surface(expected, a01.x), same_surface(expected, a11.x));
            float total = w.x + w.y + w.z + w.w;
            if (total > 1e-3) {
                vec4 c;
                if (total > 0.999) {                   // one surface all around: the filtered lookup
                    vec2 at = clamp(pp + 0.5, vec2(0.5), size - 0.5) + vec2(origin);
                    c = texture(u_prev_colour, at / vec2(textureSize(u_prev_colour, 0)));
                } else {                               // an edge: only the texels of this surface
                    c = (w.x * texelFetch(u_prev_colour, t00, 0) + w.y * texelFetch(u_prev_colour, t10, 0)
                         + w.z * texelFetch(u_prev_colour, t01, 0) + w.w * texelFetch(u_prev_colour, t11, 0)) / total;
                }
                float chroma_confidence = dot(w, vec4(a00.y, a10.y, a01.y, a11.y)) / total;
                history = c.xyz;
                luma_history = u_decay * min(c.w, u_max_confidence) * total;
                chroma_history = u_decay * min(chroma_confidence, u_max_confidence) * total;
            }
        }
    }
    float lw = luma.w + luma_history, cw = chroma.w + chroma_history;
    o_colour = vec4((luma.w * luma.x + luma_history * history.x) / lw,
                    (chroma.w * chroma.xy + chroma_history * history.yz) / cw, min(lw, u_max_confidence));
    o_aux = vec4(d, min(cw, u_max_confidence), 0.0, 0.0);
}
"""


class ColourRebuild:
    """Rebuilds each view's whole colour from a colour-scaled session's frames (module docstring).
    GL thread only: :meth:`run` after the frame's textures are written and bound."""

    def __init__(self, ctx, config: SessionConfig, wire_glsl: str, bind_frame_uniforms, slack_codes: float,
                 settings: RebuildSettings = DEFAULT_SETTINGS):
        """wire_glsl, bind_frame_uniforms, slack_codes: client/frame_textures.py's GLSL of the frame
        as it arrives, the function that sets its uniforms on a program, and the depth slack (codes)
        of the session's transport."""
        from .methods.base import FULLSCREEN_VS, fullscreen_quad

        if config.colour_scale != 0.5:
            raise ValueError(f"colour rebuilding is for sessions at colour scale 0.5, got {config.colour_scale:g}")
        self.ctx, self.config, self.settings = ctx, config, settings
        layout = rebuilt_layout(config)
        self.size = layout.pop("size")
        self.rects = layout
        self.colour = [ctx.texture(self.size, 4, dtype="f2") for _ in range(2)]   # Y, U, V, luma confidence
        self.aux = [ctx.texture(self.size, 2, dtype="f4") for _ in range(2)]      # distance, chroma confidence
        for t in self.colour:
            t.filter = (ctx.LINEAR, ctx.LINEAR)
            t.repeat_x = t.repeat_y = False
        for t in self.aux:
            t.filter = (ctx.NEAREST, ctx.NEAREST)
        self.fbos = [ctx.framebuffer(color_attachments=[c, a]) for c, a in zip(self.colour, self.aux)]
        self.passes = {}   # view -> (samples program, its quad, [(luma|chroma samples, fbo)], rebuild program, its quad)
        s = settings
        # the depth transport's slack (DEPTH_SLACK_CODES codes) at distance r, over r^2: one code
        # of disparity coding is r^2 / (near * code span) metres
        slack_per_metre = slack_codes / (config.near * ((1 << config.depth_bits) - 1 - config.depth_min_code))
        for view in self.rects:
            glsl = {"frame_glsl": wire_glsl, "distance": f"{view}_distance"}
            sample_prog = ctx.program(vertex_shader=FULLSCREEN_VS, fragment_shader=_SAMPLES_FS % glsl)
            prog = ctx.program(vertex_shader=FULLSCREEN_VS, fragment_shader=_REBUILD_FS % glsl)
            low = config.atlas.rect(f"{view}.color")
            samples = []
            for size, components in ((low[2:], 2), ((low[2] // 2, low[3] // 2), 4)):
                tex = ctx.texture(size, components, dtype="f4")
                tex.filter = (ctx.NEAREST, ctx.NEAREST)
                samples.append((tex, ctx.framebuffer(color_attachments=[tex])))
            for p, values in ((sample_prog, {"u_low_rect": tuple(float(v) for v in low)}),
                              (prog, {"u_luma": UNIT_LUMA, "u_chroma": UNIT_CHROMA, "u_prev_colour": UNIT_PREVIOUS,
                                      "u_prev_aux": UNIT_PREVIOUS_AUX,
                                      "u_spatial_sigma2": 2.0 * s.spatial_sigma ** 2,
                                      "u_sample_sigma2": 2.0 * s.sample_sigma ** 2,
                                      "u_decay": s.decay, "u_max_confidence": s.max_confidence,
                                      "u_depth_tolerance": s.depth_tolerance,
                                      "u_slack_per_metre": slack_per_metre,
                                      "u_view_rect": tuple(float(v) for v in self.rects[view])})):
                bind_frame_uniforms(p, config)
                for name, value in values.items():
                    if name in p:
                        p[name].value = value
            self.passes[view] = (sample_prog, fullscreen_quad(ctx, sample_prog), samples, prog, fullscreen_quad(ctx, prog))
        self.current = 0               # which texture holds the newest rebuild
        self.poses = {}                # view -> the pose of its newest rebuild
        self.frames = 0                # frames rebuilt

    def run(self, frame) -> None:
        """Rebuild the views of ``frame`` (its Frame message: id and poses) into the other texture,
        which becomes the current one. The frame's textures must be bound (FrameTextures.use)."""
        ctx = self.ctx
        bound = ctx.fbo            # given back at the end: an upload leaves the caller's framebuffer bound
        previous, target = self.current, 1 - self.current
        ctx.disable(ctx.DEPTH_TEST | ctx.BLEND)
        jitter = colour_jitter(frame.frame_id)
        poses = {"primary": frame.primary_pose, "extra": frame.extra_pose}
        for view, (sample_prog, (_, sample_vao), samples, prog, (_, vao)) in self.passes.items():
            sample_prog["u_jitter"].value = jitter
            for (tex, fbo), chroma in zip(samples, (False, True)):
                fbo.use()
                sample_prog["u_chroma"].value = chroma
                sample_vao.render(ctx.TRIANGLE_STRIP)
            pose = poses[view]
            before = self.poses.get(view)
            values = {"u_jitter": jitter, "u_history": before is not None}
            if before is not None:
                values["u_to_prev"] = tuple(np.asarray(before.view_matrix() @ pose.matrix(), np.float64).T.ravel())
            for name, value in values.items():
                if name in prog:
                    prog[name].value = value
            samples[0][0].use(UNIT_LUMA)
            samples[1][0].use(UNIT_CHROMA)
            self.colour[previous].use(UNIT_PREVIOUS)
            self.aux[previous].use(UNIT_PREVIOUS_AUX)
            self.fbos[target].use()
            ctx.viewport = self.rects[view]
            vao.render(ctx.TRIANGLE_STRIP)
            self.poses[view] = pose
        self.current = target
        self.frames += 1
        if bound is not None and type(bound.mglo).__name__ != "InvalidObject":   # not released since
            bound.use()

    def reset(self) -> None:
        """Forget the history: the next frame is rebuilt from its own samples alone."""
        self.poses = {}

    def use(self) -> None:
        """Bind the newest rebuild where the methods' ``atlas_rgb`` reads it."""
        self.colour[self.current].use(UNIT_REBUILT)

    def read(self, view: str) -> np.ndarray:
        """The newest rebuild of ``view``: (h, w, 4) float32 Y, U, V in [0, 1] and the luma's
        confidence, row 0 on top."""
        x, y, w, h = self.rects[view]
        full = np.frombuffer(self.colour[self.current].read(), np.float16).reshape(self.size[1], self.size[0], 4)
        return full[y:y + h, x:x + w].astype(np.float32)

    def release(self) -> None:
        ours = {id(f) for f in self.fbos} | {id(fbo) for *_, samples, _p, _q in self.passes.values()
                                             for _t, fbo in samples}
        if id(self.ctx.fbo) in ours:   # leave no released framebuffer bound (the next one made would rebind it)
            self.ctx.detect_framebuffer(0).use()
        for sample_prog, (svbo, svao), samples, prog, (vbo, vao) in self.passes.values():
            for r in (svao, svbo, sample_prog, *(x for pair in samples for x in reversed(pair)), vao, vbo, prog):
                r.release()
        for r in (*self.fbos, *self.colour, *self.aux):
            r.release()
