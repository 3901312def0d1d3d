"""Wide-angle views drawn as five perspective cube faces, then resampled (projection ``"cube"``).

The front hemisphere of a wide-angle view (protocol/projection.py) is covered by the front
face of a cube around the camera and the front halves of the four side faces. Each face is
an ordinary perspective view of the *original* meshes (no pre-tessellation: perspective
keeps straight edges straight), culled per face; one full-screen pass then looks every
wide-angle pixel's direction up in the faces: colour bilinear, distance bilinear within a
surface and nearest across silhouettes, motion from the nearest texel.

The faces lie in one ``(2n, 2n)`` texture as a cross, each next to the faces it shares an
edge with, so bilinear filtering across a seam reads the right neighbour (GL coordinates,
y up; ``h = n / 2``)::

              up (h, 3h, n, h)
    left (0, h, h, n)  front (h, h, n, n)  right (3h, h, h, n)
              down (h, 0, n, h)

Trade (measured by ``pibr bench server --projection vertex,cube --accuracy``): the wide
image has ``width / 2`` pixels per radian at its centre; a face ``n`` pixels wide has
``n / 2`` there and up to twice that at its rim, so faces as sharp as the wide image at its
centre cost three times its pixels, and smaller faces blur it.
"""
from __future__ import annotations

import numpy as np

#: name -> (rotation camera -> face (3, 3) whose rows are the face's right, up and backward
#: axes; tangent bounds (left, right, bottom, top) of the part inside the front hemisphere)
FACES = {
    "front": (np.eye(3), (-1.0, 1.0, -1.0, 1.0)),
    "right": (np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]]), (-1.0, 0.0, -1.0, 1.0)),
    "left": (np.array([[0.0, 0, -1], [0, 1, 0], [1, 0, 0]]), (0.0, 1.0, -1.0, 1.0)),
    "up": (np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]), (-1.0, 1.0, -1.0, 0.0)),
    "down": (np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]), (-1.0, 1.0, 0.0, 1.0)),
}


def face_rects(n: int) -> dict:
    """name -> (x, y, w, h) of each face in the (2n, 2n) cross, GL coordinates (y up); n even."""
    h = n // 2
    return {"front": (h, h, n, n), "right": (3 * h, h, h, n), "left": (0, h, h, n),
            "up": (h, 3 * h, n, h), "down": (h, 0, n, h)}


def face_matrix(name: str, near: float, far: float) -> np.ndarray:
    """(4, 4) camera space -> clip space of one face: its rotation, then an off-centre frustum."""
    rotation, (l, r, b, t) = FACES[name]
    m = np.zeros((4, 4))
    m[0, 0], m[0, 2] = 2.0 / (r - l), (r + l) / (r - l)
    m[1, 1], m[1, 2] = 2.0 / (t - b), (t + b) / (t - b)
    m[2, 2], m[2, 3] = (far + near) / (near - far), 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    rot = np.eye(4)
    rot[:3, :3] = rotation
    return m @ rot


def face_planes(name: str, near: float) -> np.ndarray:
    """(5, 4) camera-space planes (normal, offset) of a face's frustum: inside where n . p + d >= 0."""
    rotation, (l, r, b, t) = FACES[name]
    in_face = np.array([[1.0, 0, l, 0], [-1, 0, -r, 0], [0, 1, b, 0], [0, -1, -t, 0], [0, 0, -1, -near]])
    out = in_face.copy()
    out[:, :3] = in_face[:, :3] @ rotation   # n_cam = R^T n_face, as rows
    return out


CUBE_VS = """
#version 410
%(uniforms)s
uniform mat4 u_face;              // camera space -> this face's clip space
out vec3 v_cam;
out vec3 v_prev_cam;
out vec3 v_world;
out vec3 v_normal;
out vec2 v_uv;
out vec4 v_color;
void main() {
    vec3 cam = (u_model_view * vec4(in_position, 1.0)).xyz;
    v_cam = cam;                  // the wide camera's space: distance and motion as in a wide pass
    v_prev_cam = (u_prev_model_view * vec4(in_position, 1.0)).xyz;
    v_world = (u_model * vec4(in_position, 1.0)).xyz;
    v_normal = u_normal_matrix * in_normal;
    v_uv = in_uv;
    v_color = in_color;
    gl_Position = u_face * vec4(cam, 1.0);
}
"""

RESAMPLE_VS = """
#version 410
in vec2 in_pos;
void main() { gl_Position = vec4(in_pos, 0.0, 1.0); }
"""

RESAMPLE_FS = """
#version 410
uniform sampler2D u_cube_color;    // bilinear
uniform sampler2D u_cube_dist;     // nearest
uniform sampler2D u_cube_motion;   // nearest
uniform float u_n;                 // face size in pixels
uniform vec2 u_size;               // wide view size in pixels
layout(location = 0) out vec4 f_color;
layout(location = 1) out float f_dist;
layout(location = 2) out vec4 f_motion;
%(projection)s
void main() {
    // framebuffer row 0 is the image's top row (t'_y = +1), as in the wide passes
    vec2 t = vec2(2.0 * gl_FragCoord.x / u_size.x - 1.0, 1.0 - 2.0 * gl_FragCoord.y / u_size.y);
    vec3 d = wa_unproject(t);
    float h = 0.5 * u_n;
    vec2 px;
    if (-d.z >= abs(d.x) && -d.z >= abs(d.y)) {
        px = vec2(h) + (d.xy / -d.z + 1.0) * h;
    } else if (abs(d.x) >= abs(d.y)) {
        if (d.x > 0.0) px = vec2(3.0 * h + (d.z / d.x + 1.0) * h, h + (d.y / d.x + 1.0) * h);
        else           px = vec2((d.z / d.x) * h, h + (d.y / -d.x + 1.0) * h);
    } else {
        if (d.y > 0.0) px = vec2(h + (d.x / d.y + 1.0) * h, 3.0 * h + (d.z / d.y + 1.0) * h);
        else           px = vec2(h + (d.x / -d.y + 1.0) * h, (d.z / d.y) * h);
    }
    vec2 uv = px / (2.0 * u_n);
    f_color = vec4(texture(u_cube_color, uv).rgb, 1.0);
    ivec2 texel = clamp(ivec2(floor(px)), ivec2(0), ivec2(2.0 * u_n) - 1);
    f_motion = texelFetch(u_cube_motion, texel, 0);
    // Distance: bilinear where the 2x2 texels around lie on one surface (within 3 percent), else the
    // nearest texel's, so silhouettes stay sharp.
    vec4 g = textureGather(u_cube_dist, uv, 0);          // (0, 1), (1, 1), (1, 0), (0, 0)
    float lo = min(min(g.x, g.y), min(g.z, g.w));
    float hi = max(max(g.x, g.y), max(g.z, g.w));
    if (lo > 0.0 && hi < 1.03 * lo) {
        vec2 f = fract(px - 0.5);
        f_dist = mix(mix(g.w, g.z, f.x), mix(g.x, g.y, f.x), f.y);
    } else {
        f_dist = texelFetch(u_cube_dist, texel, 0).r;
    }
}
"""
