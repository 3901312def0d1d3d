"""The GLSL of the server's renderer (renderer.py): one shading model for the wide-angle views
and for ground truth, the vertex stages of the three wide-angle projections (pre-tessellated
vertices, tessellation shaders, perspective cube faces) and the motion pass of moving objects."""
from __future__ import annotations

import numpy as np

from pibr.protocol.projection import GLSL as PROJECTION_GLSL
from pibr.scenes.scene import MAX_LIGHTS


def _vec3(v) -> str:
    return "vec3(%s)" % ", ".join(repr(float(x)) for x in v)


def shading_glsl(lights) -> str:
    """GLSL ``vec3 shade(world_pos, normal, uv, vcolor)`` with the scene's lights written in as
    constants: a loop over uniform arrays costs llvmpipe more than the rest of the pass."""
    terms = []
    for light in lights[:MAX_LIGHTS]:
        color = _vec3(np.asarray(light.color[:3], dtype=np.float64) * light.intensity)
        if light.kind == "ambient":
            terms.append(f"    light += {color};")
        elif light.kind == "directional":
            terms.append(f"    light += {color} * max(dot(n, {_vec3(-np.asarray(light.direction))}), 0.0);")
        else:
            terms.append(
                f"    {{ vec3 d = {_vec3(light.position)} - world_pos; float dist = length(d);\n"
                f"      float fall = clamp(1.0 - dist / {float(light.range)!r}, 0.0, 1.0);\n"
                f"      light += {color} * max(dot(n, d / max(dist, 1e-6)), 0.0) * fall * fall; }}")
    return """
uniform vec4 u_base_color;
uniform bool u_has_texture;
uniform sampler2D u_texture;
uniform vec3 u_eye;

vec3 shade(vec3 world_pos, vec3 normal, vec2 uv, vec4 vcolor) {
    vec3 n = normalize(normal);
    if (dot(n, u_eye - world_pos) < 0.0) n = -n;   // two-sided: light the side we see
    vec4 albedo = u_base_color * vcolor;
    if (TEXTURED) {
        vec3 t = texture(u_texture, uv).rgb;
        albedo.rgb *= t * t;                          // sRGB -> linear (gamma 2)
    }
    vec3 light = vec3(0.0);
%s
    return sqrt(clamp(albedo.rgb * light, 0.0, 1.0));  // linear -> sRGB (gamma 2)
}
""" % "\n".join(terms)


#: The fragment shader's per-object switch (TEXTURED) is compiled in as a constant, one program
#: per kind an object needs: llvmpipe runs the body of a branch on a uniform for every fragment
#: (masked), so untextured objects paid for a texture lookup. ``Renderer(specialise=False)`` keeps
#: one program with a uniform switch.
SPECIALISED = "#define TEXTURED %s\n"
UNIFORM_SWITCHES = "#define TEXTURED u_has_texture\n"

FRAGMENT = """
#version 410
%(defines)s
in vec3 v_cam;
in vec3 v_prev_cam;
in vec3 v_world;
in vec3 v_normal;
in vec2 v_uv;
in vec4 v_color;
layout(location = 0) out vec4 f_color;
layout(location = 1) out float f_dist;
%(shading)s
%(projection)s
#ifdef PEEL
// Depth peeling against the primary view (Reinert et al.): a fragment of the extra view is
// dropped when the primary view already shows the same surface point, i.e. when one of the
// four primary texels around its back-projection stores a distance within a relative
// tolerance of the fragment's own distance to the primary camera.
uniform sampler2D u_peel_dist;    // primary view's radial distance (top row first), 0 = sky
uniform mat4 u_peel_from_cam;     // this camera's space -> primary camera space
uniform vec2 u_peel_size;         // primary view size in pixels
uniform float u_peel_tolerance;   // relative
const float PEELED_DEPTH = 0.99999;   // behind every kept fragment, in front of the cleared 1
uniform vec3 u_sky_color;
bool seen_by_primary(vec3 cam) {
    vec3 p = (u_peel_from_cam * vec4(cam, 1.0)).xyz;
    if (p.z > 0.0) return false;                  // behind the primary camera
    vec3 t = wa_project(p);
    // the 2x2 texels bilinear filtering would read, clamped at the edges (one fetch)
    vec4 d = textureGather(u_peel_dist, wa_uv(t.xy), 0);
    vec4 hit = vec4(greaterThan(d, vec4(0.0))) * vec4(lessThan(abs(d - t.z), vec4(u_peel_tolerance * t.z)));
    return dot(hit, hit) > 0.0;
}
#endif
void main() {
#ifdef PEEL_MARK
    // A peeled fragment is not dropped: it marks its pixel (distance PEELED) from behind every
    // kept fragment, so the view tells "nothing new here" from sky (nothing at all). Writing
    // gl_FragDepth costs the early depth test: the extra view took a third longer here.
    if (seen_by_primary(v_cam)) {
        f_color = vec4(u_sky_color, 1.0);          // as an empty pixel: codes smoothly
        f_dist = -1.0;
        gl_FragDepth = PEELED_DEPTH;
        return;
    }
    gl_FragDepth = gl_FragCoord.z;
#elif defined(PEEL)
    if (seen_by_primary(v_cam)) discard;
#endif
#ifdef DISTANCE_ONLY
    f_color = vec4(0.0, 0.0, 0.0, 1.0);   // coverage probes read distances only
#else
    f_color = vec4(shade(v_world, v_normal, v_uv, v_color), 1.0);
#endif
    f_dist = length(v_cam);
}
"""

# Moving objects' motion, drawn after every object's colour and distance into the motion attachment
# (a framebuffer of its own on the same depth buffer), where the depth test finds their visible
# fragments (see Renderer._draw_motion): the motion the camera does not explain, where this surface
# point was one server frame ago, seen from the current camera (rows grow downwards, t'_y upwards).
MOTION_FRAGMENT = """
#version 410
in vec3 v_cam;
in vec3 v_prev_cam;
layout(location = 0) out vec4 f_motion;   // (dx, dy) pixels, object index, moving flag (1)
uniform float u_object_index;             // the object's index in the scene
uniform vec2 u_half_px;                   // pixels per unit of t' (wide views)
%(projection)s
void main() {
    f_motion = vec4((wa_project(v_cam).xy - wa_project(v_prev_cam).xy) * vec2(1.0, -1.0) * u_half_px,
                    u_object_index, 1.0);
}
"""

COMMON_VS_UNIFORMS = """
uniform mat4 u_model;
uniform mat4 u_model_view;
uniform mat4 u_prev_model_view;   // where the object was one server frame ago (moving objects)
uniform mat3 u_normal_matrix;
uniform float u_near;
uniform float u_far;
in vec3 in_position;
in vec3 in_normal;
in vec2 in_uv;
in vec4 in_color;
"""

WIDE_VERTEX_VS = """
#version 410
%(uniforms)s
%(projection)s
out vec3 v_cam;
out vec3 v_prev_cam;
out vec3 v_world;
out vec3 v_normal;
out vec2 v_uv;
out vec4 v_color;
out float gl_ClipDistance[1];
void main() {
    vec3 cam = (u_model_view * vec4(in_position, 1.0)).xyz;
    v_cam = cam;
    v_prev_cam = (u_prev_model_view * vec4(in_position, 1.0)).xyz;
    v_world = (u_model * vec4(in_position, 1.0)).xyz;
    v_normal = u_normal_matrix * in_normal;
    v_uv = in_uv;
    v_color = in_color;
    vec3 t = wa_project_extended(cam);
    gl_Position = vec4(t.x, -t.y, 2.0 * (t.z - u_near) / (u_far - u_near) - 1.0, 1.0);
    gl_ClipDistance[0] = 1.5 - abs(t.x);   // cut where x' jumps from +2 to -2 behind the camera
}
""" % {"uniforms": COMMON_VS_UNIFORMS, "projection": PROJECTION_GLSL}

TESS_VS = """
#version 410
%(uniforms)s
out vec3 c_cam;
out vec3 c_prev_cam;
out vec3 c_world;
out vec3 c_normal;
out vec2 c_uv;
out vec4 c_color;
void main() {
    c_cam = (u_model_view * vec4(in_position, 1.0)).xyz;
    c_prev_cam = (u_prev_model_view * vec4(in_position, 1.0)).xyz;
    c_world = (u_model * vec4(in_position, 1.0)).xyz;
    c_normal = u_normal_matrix * in_normal;
    c_uv = in_uv;
    c_color = in_color;
}
""" % {"uniforms": COMMON_VS_UNIFORMS}

TESS_TCS = """
#version 410
layout(vertices = 3) out;
uniform float u_max_angle;
uniform float u_max_level;
uniform float u_max_screen_edge;   // pixels
uniform vec2 u_half_size;          // pixels per unit of t'
%(projection)s
in vec3 c_cam[];
in vec3 c_prev_cam[];
in vec3 c_world[];
in vec3 c_normal[];
in vec2 c_uv[];
in vec4 c_color[];
out vec3 e_cam[];
out vec3 e_prev_cam[];
out vec3 e_world[];
out vec3 e_normal[];
out vec2 e_uv[];
out vec4 e_color[];
// A function of the edge alone, symmetric in its ends: both triangles sharing an edge
// split it identically, so the tessellated mesh has no cracks. Two limits: the angle the
// edge spans (bends in the projection), and its length on screen, which near the poles and
// the hemisphere's rim grows much faster than the angle.
float edge_level(vec3 a, vec3 b) {
    float la = length(a);
    float lb = length(b);
    if (la < 1e-6 || lb < 1e-6) return u_max_level;
    float ang = acos(clamp(dot(a, b) / (la * lb), -1.0, 1.0));
    vec2 pa = wa_project_extended(a).xy;
    vec2 pb = wa_project_extended(b).xy;
    float screen = length((pa - pb) * u_half_size);
    return clamp(ceil(max(ang / u_max_angle, screen / u_max_screen_edge)), 1.0, u_max_level);
}
void main() {
    e_cam[gl_InvocationID] = c_cam[gl_InvocationID];
    e_prev_cam[gl_InvocationID] = c_prev_cam[gl_InvocationID];
    e_world[gl_InvocationID] = c_world[gl_InvocationID];
    e_normal[gl_InvocationID] = c_normal[gl_InvocationID];
    e_uv[gl_InvocationID] = c_uv[gl_InvocationID];
    e_color[gl_InvocationID] = c_color[gl_InvocationID];
    if (gl_InvocationID == 0) {
        if (c_cam[0].z > 0.0 && c_cam[1].z > 0.0 && c_cam[2].z > 0.0) {
            gl_TessLevelOuter[0] = 0.0;   // entirely behind the camera: drop the patch
            gl_TessLevelOuter[1] = 0.0;
            gl_TessLevelOuter[2] = 0.0;
            gl_TessLevelInner[0] = 0.0;
        } else {
            float l0 = edge_level(c_cam[1], c_cam[2]);
            float l1 = edge_level(c_cam[2], c_cam[0]);
            float l2 = edge_level(c_cam[0], c_cam[1]);
            gl_TessLevelOuter[0] = l0;
            gl_TessLevelOuter[1] = l1;
            gl_TessLevelOuter[2] = l2;
            gl_TessLevelInner[0] = max(l0, max(l1, l2));
        }
    }
}
""" % {"projection": PROJECTION_GLSL}

TESS_TES = """
#version 410
layout(triangles, equal_spacing, ccw) in;
uniform float u_near;
uniform float u_far;
in vec3 e_cam[];
in vec3 e_prev_cam[];
in vec3 e_world[];
in vec3 e_normal[];
in vec2 e_uv[];
in vec4 e_color[];
out vec3 v_cam;
out vec3 v_prev_cam;
out vec3 v_world;
out vec3 v_normal;
out vec2 v_uv;
out vec4 v_color;
out float gl_ClipDistance[1];
%(projection)s
void main() {
    vec3 b = gl_TessCoord;
    vec3 cam = b.x * e_cam[0] + b.y * e_cam[1] + b.z * e_cam[2];
    v_cam = cam;
    v_prev_cam = b.x * e_prev_cam[0] + b.y * e_prev_cam[1] + b.z * e_prev_cam[2];
    v_world = b.x * e_world[0] + b.y * e_world[1] + b.z * e_world[2];
    v_normal = b.x * e_normal[0] + b.y * e_normal[1] + b.z * e_normal[2];
    v_uv = b.x * e_uv[0] + b.y * e_uv[1] + b.z * e_uv[2];
    v_color = b.x * e_color[0] + b.y * e_color[1] + b.z * e_color[2];
    vec3 t = wa_project_extended(cam);
    gl_Position = vec4(t.x, -t.y, 2.0 * (t.z - u_near) / (u_far - u_near) - 1.0, 1.0);
    gl_ClipDistance[0] = 1.5 - abs(t.x);   // cut where x' jumps from +2 to -2 behind the camera
}
""" % {"projection": PROJECTION_GLSL}

PERSPECTIVE_VS = """
#version 410
%(uniforms)s
uniform mat4 u_projection;
out vec3 v_cam;
out vec3 v_prev_cam;
out vec3 v_world;
out vec3 v_normal;
out vec2 v_uv;
out vec4 v_color;
void main() {
    vec4 cam = u_model_view * vec4(in_position, 1.0);
    v_cam = cam.xyz;
    v_prev_cam = cam.xyz;
    v_world = (u_model * vec4(in_position, 1.0)).xyz;
    v_normal = u_normal_matrix * in_normal;
    v_uv = in_uv;
    v_color = in_color;
    gl_Position = u_projection * cam;
    gl_Position.y = -gl_Position.y;   // top-row-first images
}
""" % {"uniforms": COMMON_VS_UNIFORMS}
