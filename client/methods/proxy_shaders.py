"""The GLSL of ``proxy`` (proxy.py): the proxy passes that gather and test colour from the
transmitted views, the background pass, the resolves of their per-pixel records, and the
variants' passes (nearest fragment only, points), with the constants both sides share."""
from __future__ import annotations

import numpy as np


#: The background pass counts and boxes the pixels left to pass 2 with storage-buffer atomics.
GL_FOR_RESTRICTED_CARVING = 430
GL_CLIP_DISTANCE0 = 0x3000

_PROXY_VS = """
#version 410
uniform mat4 u_mvp%(eyes)s;          // object -> clip space of the output camera%(eyes_note)s%(eye_uniform)s
uniform mat4 u_to_primary;   // object -> primary camera space
uniform mat4 u_to_extra;     // object -> extra camera space
uniform float u_depth_half;  // -1: window depth into [0, 0.5) (accepted), +1: into [0.5, 1] (fallback)
in vec3 in_position;
out vec3 v_p;
out vec3 v_e;
void main() {
    vec4 p = vec4(in_position, 1.0);
    v_p = (u_to_primary * p).xyz;
    v_e = (u_to_extra * p).xyz;
    gl_Position = u_mvp%(eye)s * p;
    gl_Position.y = -gl_Position.y;   // top-row-first images
    // Halve the depth range in clip space (linear, so interpolation is unchanged): accepted
    // fragments always lie in front of fallback ones without writing gl_FragDepth. That moves
    // the far clip plane of the front half and the near one of the back half; a clip distance
    // puts the moved one back.
    float z = gl_Position.z, w = gl_Position.w;
    gl_ClipDistance[0] = u_depth_half < 0.0 ? w - z : z + w;
    gl_Position.z = 0.5 * (z + u_depth_half * w);%(pair)s
}
"""
PROXY_VS = _PROXY_VS % {"eyes": "", "eyes_note": "", "eye_uniform": "", "eye": "", "pair": ""}
#: Both eyes of a stereo pair in one draw (two instances: the left eye, then the right; one
#: instance from eye u_first_eye on), side by side in a target twice as wide: each eye's clip
#: space is squeezed into its half, and two clip distances keep its triangles out of the other
#: half (no viewport arrays needed).
PAIR_PROXY_VS = _PROXY_VS % {
    "eyes": "[2]", "eyes_note": " of each eye (left, right)",
    "eye_uniform": "\nuniform int u_first_eye;   // the eye of instance 0", "eye": "[u_first_eye + gl_InstanceID]",
    "pair": """
    float x = gl_Position.x;
    gl_ClipDistance[1] = w + x;
    gl_ClipDistance[2] = w - x;
    gl_Position.x = 0.5 * x + (u_first_eye + gl_InstanceID == 0 ? -0.5 : 0.5) * w;"""}
#: How many clip distances PAIR_PROXY_VS writes.
PAIR_CLIP_DISTANCES = 3

# The views' colour rectangles and the background of a pixel (for BACKGROUND_FS and the resolves
# of carve_all and carve=False).
BACKGROUND_GLSL = """
uniform vec4 u_primary_color;
uniform vec4 u_extra_color;
uniform mat3 u_out_to_src;   // output camera -> primary camera rotation
uniform mat3 u_out_to_extra; // output camera -> extra camera rotation
uniform bool u_extra_sky;    // the extra view's sky may fill in (it marks peeled pixels apart)
uniform vec2 u_tan_half;
uniform vec2 u_tan_centre;  // the image centre on the plane at distance 1 (0: symmetric frustum)
uniform vec2 u_out_size;
// Where no proxy fragment landed: the sky along this pixel's ray. Sky is at infinity, so any
// view shows it in the same direction: the primary view's if it shows sky there, else the
// extra view's if that one does (it saw past what blocks the primary: a lamp post in front of
// the sky); else a rotation-only fallback from the primary (alpha 0: no view vouches for it).
// -> false where nothing can be shown (behind the primary camera); else rect, uv and alpha.
// A stereo pair drawn side by side (PAIR_PROXY_VS) shares the eyes' rotation: the right half's
// pixels wrap onto the left's (x exactly as it is in one view, where it is below the width).
bool background(out vec4 rect, out vec2 uv, out float alpha) {
    float x = mod(gl_FragCoord.x, u_out_size.x);
    vec2 ndc = vec2(2.0 * x / u_out_size.x - 1.0, 1.0 - 2.0 * gl_FragCoord.y / u_out_size.y);
    vec3 ray = normalize(vec3(u_tan_centre + ndc * u_tan_half, -1.0));
    vec3 d = u_out_to_src * ray;
    uv = wa_uv(wa_project(d).xy);
    rect = u_primary_color;
    alpha = 1.0;
    if (d.z <= 0.0 && primary_distance(uv) == 0.0) return true;
    if (u_extra_sky) {
        vec3 e = u_out_to_extra * ray;
        vec2 uv_e = wa_uv(wa_project(e).xy);
        if (e.z <= 0.0 && extra_distance(uv_e) == 0.0) {
            rect = u_extra_color;
            uv = uv_e;
            return true;
        }
    }
    alpha = 0.0;
    return d.z <= 0.0;
}
"""

RECORD_GLSL = """
// A pixel's record, two floats: where to fetch its colour (uv in [0, 1]^2) and from which view
// (0 primary, 1 extra, 2 none: black; 3, the clear value: no proxy fragment here), in the
// integer parts: u + 2 view, v + 2 accepted. 8 bytes, not 16, to clear and write; the uv keep
// 2^-22 of precision, a quarter of a thousandth of a pixel.
vec2 record(vec2 uv, float view, bool accepted) { return vec2(uv.x + 2.0 * view, uv.y + (accepted ? 2.0 : 0.0)); }
// -> a record's view; its uv and alpha (1: accepted) into uv, alpha.
float read_record(vec2 ref, out vec2 uv, out float alpha) {
    float view = floor(0.5 * ref.x);
    uv = vec2(ref.x - 2.0 * view, ref.y >= 2.0 ? ref.y - 2.0 : ref.y);
    alpha = ref.y >= 2.0 ? 1.0 : 0.0;
    return view;
}
"""

# The background of a pixel (see background()) as a record: its view, the uv there, accepted
# where a view vouches for it, black (view 2) where nothing can be shown.
BACKGROUND_RECORD_GLSL = """
vec2 background_record() {
    vec4 rect;
    vec2 uv;
    float alpha;
    if (!background(rect, uv, alpha)) return record(vec2(0.0), 2.0, false);
    return record(uv, rect == u_extra_color ? 1.0 : 0.0, alpha != 0.0);
}
"""

# Colour is fetched once per pixel, after the depth test picked the fragment, from the one view
# and place the pixel's record (or, where no proxy was drawn, its background) chose.
RESOLVE_FS = """
#version 410
%(frame)s
uniform sampler2D u_refs;
%(background)s
""" + RECORD_GLSL + BACKGROUND_RECORD_GLSL + """
out vec4 f_color;
void main() {
    vec2 uv;
    float alpha;
    precise vec2 ref = texelFetch(u_refs, ivec2(gl_FragCoord.xy), 0).xy;
    if (ref.x >= 6.0) ref = background_record();   // no proxy fragment: the background, as a record
    float view = read_record(ref, uv, alpha);
    vec4 rect = view == 0.0 ? u_primary_color : u_extra_color;
    f_color = view >= 2.0 ? vec4(0.0) : vec4(atlas_rgb(rect, uv), alpha);
}
"""

#: The record of a pixel no proxy fragment reached (view 3).
NO_PROXY = (6.0, 0.0)
VIEW_ERROR_GLSL = """
uniform bool u_has_extra;
uniform float u_tau;
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
"""

ACCEPT_GLSL = """
// Whether a view vouches for the proxy point at p (primary camera space) = e (extra camera
// space); if so, its record.
bool accepted(vec3 p, vec3 e, out vec2 ref) {
    vec2 uv_p, uv_e;
    bool sky_p, sky_e, past_p, past_e;
    ref = vec2(0.0);
    if (view_error(p, false, uv_p, sky_p, past_p) < u_tau) {   // the primary saw this very point
        ref = record(uv_p, 0.0, true);
        return true;
    }
    // Where the primary view saw past the fragment (a farther surface, or sky), its point is
    // empty space: carve it, whatever the extra view seems to confirm there. The extra view
    // fills only what the primary could not see: points hidden behind its nearer surfaces.
    if (u_has_extra && !(past_p || sky_p) && view_error(e, true, uv_e, sky_e, past_e) < u_tau) {
        ref = record(uv_e, 1.0, true);
        return true;
    }
    return false;
}
"""

# Two passes over the proxies, so that no fragment writes gl_FragDepth: on a software rasteriser
# that rules out early depth tests, and every overlapping fragment would run the shader. One
# program per pass (%(main)s): this rasteriser runs both sides of every branch, even of a
# uniform one, so a program that could do either pass would pay for both in each.
PROXY_FS = "#version 410\n%(frame)s\n" + VIEW_ERROR_GLSL + RECORD_GLSL + ACCEPT_GLSL + """
in vec3 v_p;
in vec3 v_e;
out vec2 f_ref;   // the pixel's record, see record()
// Pass 1, accepted fragments only, depth in [0, 0.5): fragments behind an accepted one already
// drawn fail the depth test before the shader runs (objects are drawn nearest first).
void accept() {
    vec2 ref;
    if (!accepted(v_p, v_e, ref)) discard;
    f_ref = ref;
}

// Pass 2, depth in [0.5, 1]: only pixels where no fragment was accepted still pass the depth
// test. The proxy is not where the true surface is there (an encaging proxy bulges past the
// silhouette, or the surface was hidden in both views): the nearest fragment is coloured from
// the view with the lower error, alpha 0 (no view covered it), unless the primary sees sky.
void fallback() {
    vec2 uv_p, uv_e;
    bool sky_p, sky_e, past_p, past_e;
    float e_p = view_error(v_p, false, uv_p, sky_p, past_p);
    if (sky_p) discard;   // the primary sees nothing there: carve, let the sky show
    float e_e = NO_MATCH;
    if (u_has_extra && !past_p) e_e = view_error(v_e, true, uv_e, sky_e, past_e);
    f_ref = (e_e < e_p) ? record(uv_e, 1.0, false) : record(uv_p, v_p.z <= 0.0 ? 0.0 : 2.0, false);
}
%(main)s

"""
ACCEPT_MAIN, FALLBACK_MAIN = "void main() { accept(); }", "void main() { fallback(); }"
#: carve_all: the two passes in one program, chosen by u_fallback
EITHER_MAIN = "uniform bool u_fallback;\nvoid main() { if (u_fallback) fallback(); else accept(); }"


# After pass 1, the pixels where it accepted no fragment, at depth 1 still (the quad lies at
# 0.75): their record is the background's (a record like the proxy passes', so every record is 8
# bytes), unless pass 2 finds a proxy fragment there; and they are counted, with
# their bounding box (one per eye of a pair drawn side by side), so that pass 2 is scissored to
# them, or skipped. Only these pixels run the
# background's lookups, not all (the resolve after it does one lookup per pixel), and pass 2
# costs its rasterisation even where every fragment fails the depth test.
BACKGROUND_VS = """
#version 410
in vec2 in_pos;
void main() { gl_Position = vec4(in_pos, 0.5, 1.0); }
"""

BACKGROUND_FS = "#version 430\n%(frame)s\n%(background)s\n" + RECORD_GLSL + BACKGROUND_RECORD_GLSL + """
// the depth test before the shader, although it writes the counters (it would run the shader first)
layout(early_fragment_tests) in;
// box k: min x, min y, max x, max y of eye k (the right half of a pair: x from u_out_size.x on)
layout(std430, binding = 0) buffer Left { uint n_left; uint box[8]; };
out vec2 f_ref;
void main() {
    f_ref = background_record();
    uvec2 px = uvec2(gl_FragCoord.xy);
    uint k = px.x >= uint(u_out_size.x) ? 4u : 0u;
    atomicAdd(n_left, 1u);
    atomicMin(box[k], px.x);
    atomicMin(box[k + 1u], px.y);
    atomicMax(box[k + 2u], px.x);
    atomicMax(box[k + 3u], px.y);
}
"""
#: The Left block of BACKGROUND_FS before it runs: no pixel, empty boxes.
LEFT_EMPTY = np.array([0] + [0xFFFFFFFF, 0xFFFFFFFF, 0, 0] * 2, np.uint32).tobytes()

# The resolve after BACKGROUND_FS: one lookup per pixel, from the view and place its record says.
RECORD_RESOLVE_FS = """
#version 410
%(frame)s
uniform sampler2D u_refs;
uniform vec4 u_primary_color;
uniform vec4 u_extra_color;
""" + RECORD_GLSL + """
out vec4 f_color;
void main() {
    vec2 uv;
    float alpha;
    float view = read_record(texelFetch(u_refs, ivec2(gl_FragCoord.xy), 0).xy, uv, alpha);
    vec4 rect = view == 0.0 ? u_primary_color : u_extra_color;
    f_color = view >= 2.0 ? vec4(0.0) : vec4(atlas_rgb(rect, uv), alpha);
}
"""


# carve=False: one geometry pass, no test in it: each pixel keeps the nearest proxy fragment's
# position where the views saw it (world space, at the frame's time), and the resolve tests
# that fragment alone. Cheap where the depth test runs before the shader; but a proxy fragment
# no view confirms is not carved away any more: the surface behind it cannot show through.
NEAREST_VS = """
#version 410
uniform mat4 u_mvp;          // object -> clip space of the output camera
uniform mat4 u_seen;         // object -> world, where the views saw it
in vec3 in_position;
out vec3 v_w;
void main() {
    vec4 p = vec4(in_position, 1.0);
    v_w = (u_seen * p).xyz;
    gl_Position = u_mvp * p;
    gl_Position.y = -gl_Position.y;   // top-row-first images
}
"""

NEAREST_FS = """
#version 410
in vec3 v_w;
out vec4 f_pos;
void main() { f_pos = vec4(v_w, 1.0); }
"""

NEAREST_RESOLVE_FS = "#version 410\n%(frame)s\n" + VIEW_ERROR_GLSL + """
uniform sampler2D u_pos;
uniform mat4 u_world_to_primary;
uniform mat4 u_world_to_extra;
%(background)s
out vec4 f_color;
void main() {
    vec4 w = texelFetch(u_pos, ivec2(gl_FragCoord.xy), 0);
    vec4 rect = u_primary_color;
    vec2 uv;
    float alpha = 1.0;
    bool show_background = w.w == 0.0;
    if (!show_background) {
        vec3 vp = (u_world_to_primary * vec4(w.xyz, 1.0)).xyz;
        vec2 uv_p, uv_e;
        bool sky_p, sky_e, past_p, past_e;
        float e_p = view_error(vp, false, uv_p, sky_p, past_p);
        uv = uv_p;
        if (e_p >= u_tau) {   // as the accept and fallback passes decide, for this fragment only
            float e_e = NO_MATCH;
            if (u_has_extra && !(past_p || sky_p))
                e_e = view_error((u_world_to_extra * vec4(w.xyz, 1.0)).xyz, true, uv_e, sky_e, past_e);
            if (e_e < u_tau) {
                rect = u_extra_color;
                uv = uv_e;
            } else if (sky_p) {
                show_background = true;
            } else {
                alpha = 0.0;
                if (e_e < e_p) {
                    rect = u_extra_color;
                    uv = uv_e;
                } else if (vp.z > 0.0) {
                    f_color = vec4(0.0);
                    return;
                }
            }
        }
    }
    if (show_background && !background(rect, uv, alpha)) { f_color = vec4(0.0); return; }
    f_color = vec4(atlas_rgb(rect, uv), alpha);
}
"""


# motion="flow": the pixels the extrapolated primary view's moving pixels landed on, as points at
# their distance (accepted from the primary view, in the front half of the depth range). Each
# fragment of a point looks up the primary view where its own output ray meets the sphere of the
# point's distance about the primary camera, so a point magnified on screen is resampled, not a
# flat square, and a fragment past the object's outline finds what the view shows there.
POINTS_VS = """
#version 410
%(frame)s
uniform mat4 u_primary_to_clip;   // primary camera space -> output clip space
uniform vec2 u_view_size;
uniform float u_depth_half;
in vec2 in_px;                     // the primary view's pixel
in float in_distance;
flat out float v_d;
void main() {
    v_d = in_distance;
    vec3 p = wa_unproject(wa_from_uv((in_px + 0.5) / u_view_size)) * in_distance;
    gl_Position = u_primary_to_clip * vec4(p, 1.0);
    gl_Position.y = -gl_Position.y;   // top-row-first images
    float z = gl_Position.z, w = gl_Position.w;
    gl_ClipDistance[0] = w - z;
    gl_Position.z = 0.5 * (z + u_depth_half * w);
}
"""

POINTS_FS = """
#version 410
%(frame)s
flat in float v_d;
out vec4 f_out;
uniform bool u_position;          // carve=False: the records are world positions
uniform mat3 u_out_to_primary;    // output camera rotation -> primary camera space
uniform vec3 u_eye;               // output camera position in primary camera space
uniform mat4 u_primary_to_world;
uniform vec2 u_tan_half;
uniform vec2 u_tan_centre;  // the image centre on the plane at distance 1 (0: symmetric frustum)
uniform vec2 u_out_size;
void main() {
    vec2 ndc = vec2(2.0 * gl_FragCoord.x / u_out_size.x - 1.0, 1.0 - 2.0 * gl_FragCoord.y / u_out_size.y);
    vec3 r = u_out_to_primary * normalize(vec3(u_tan_centre + ndc * u_tan_half, -1.0));
    float b = dot(u_eye, r), c = dot(u_eye, u_eye) - v_d * v_d;
    float disc = b * b - c;
    if (disc < 0.0) discard;
    float t = c < 0.0 ? -b + sqrt(disc) : -b - sqrt(disc);   // the eye inside the sphere, or the near hit
    vec3 p = u_eye + t * r;
    if (t <= 0.0 || p.z > 0.0) discard;
    vec2 uv = wa_uv(wa_project(p).xy);
    f_out = u_position ? vec4((u_primary_to_world * vec4(p, 1.0)).xyz, 1.0) : vec4(uv.x, uv.y + 2.0, 0.0, 0.0);
}
"""
