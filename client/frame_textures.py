"""A decoded server frame on the GPU: the atlas's Y, U and V planes as textures, and the
GLSL that samples a view's colour (bilinear, converted to RGB) or distance (nearest, dequantized)
from them."""
from __future__ import annotations

import numpy as np

from pibr.protocol.depth import GLSL as DEPTH_GLSL
from pibr.protocol.projection import GLSL as PROJECTION_GLSL
from pibr.protocol.session import SessionConfig

from .video import YUVImage

#: Texture units the atlas planes are bound to; methods use units from 4 upwards.
UNIT_Y, UNIT_U, UNIT_V, UNIT_DEPTH = 0, 1, 2, 3

ATLAS_GLSL = PROJECTION_GLSL + DEPTH_GLSL + """
uniform sampler2D u_atlas_y;
uniform sampler2D u_atlas_u;
uniform sampler2D u_atlas_v;
uniform vec2 u_atlas_size;     // atlas width, height in pixels
uniform float u_depth_near;
uniform float u_depth_far;
uniform float u_depth_min_code;
uniform float u_depth_max_code;

// Colour of a view at uv in [0,1]^2 (row 0 on top); rect = (x, y, w, h) of the view in the atlas.
vec3 atlas_rgb(vec4 rect, vec2 uv) {
    vec2 p = rect.xy + clamp(uv * rect.zw, vec2(0.5), rect.zw - 0.5);
    float y = texture(u_atlas_y, p / u_atlas_size).r;
    vec2 pc = clamp(0.5 * p, 0.5 * rect.xy + 0.5, 0.5 * (rect.xy + rect.zw) - 0.5);
    vec2 uvc = pc / (0.5 * u_atlas_size);
    float u = texture(u_atlas_u, uvc).r - 128.0 / 255.0;
    float v = texture(u_atlas_v, uvc).r - 128.0 / 255.0;
    return clamp(vec3(y + 1.402 * v, y - 0.344136 * u - 0.714136 * v, y + 1.772 * u), 0.0, 1.0);
}

// Radial distance stored for a view at uv (nearest texel), 0 for sky.
float atlas_distance(vec4 rect, vec2 uv) {
    ivec2 p = ivec2(rect.xy + clamp(floor(uv * rect.zw), vec2(0.0), rect.zw - 1.0));
    float code = floor(texelFetch(u_atlas_y, p, 0).r * 255.0 + 0.5);
    return depth_dequantize(code, u_depth_near, u_depth_far, u_depth_min_code, u_depth_max_code);
}
"""


def bind_atlas_uniforms(prog, config: SessionConfig) -> None:
    """Set the uniforms ATLAS_GLSL reads that stay fixed for the session."""
    values = {
        "u_atlas_y": UNIT_Y, "u_atlas_u": UNIT_U, "u_atlas_v": UNIT_V,
        "u_atlas_size": (float(config.atlas.width), float(config.atlas.height)),
        "u_depth_near": config.near, "u_depth_far": config.far,
        "u_depth_min_code": float(config.depth_min_code),
        "u_depth_max_code": float((1 << config.depth_bits) - 1),
    }
    for name, value in values.items():
        if name in prog:
            prog[name].value = value


def rect_uniform(config: SessionConfig, name: str) -> tuple:
    r = config.atlas.rect(name)
    return (0.0, 0.0, 0.0, 0.0) if r is None else tuple(float(x) for x in r)


class FrameTextures:
    """Y, U, V textures of the atlas; :meth:`upload` replaces their contents. GL thread only."""

    def __init__(self, ctx, config: SessionConfig):
        self.ctx = ctx
        w, h = config.atlas.width, config.atlas.height
        self.y = ctx.texture((w, h), 1)
        self.u = ctx.texture((w // 2, h // 2), 1)
        self.v = ctx.texture((w // 2, h // 2), 1)
        for t in (self.y, self.u, self.v):
            t.filter = (ctx.LINEAR, ctx.LINEAR)
            t.repeat_x = t.repeat_y = False
        self.frame_id = None

    def upload(self, image: YUVImage, frame_id: int) -> None:
        self.y.write(np.ascontiguousarray(image.y), alignment=1)
        self.u.write(np.ascontiguousarray(image.u), alignment=1)
        self.v.write(np.ascontiguousarray(image.v), alignment=1)
        self.frame_id = frame_id

    def use(self) -> None:
        self.y.use(UNIT_Y)
        self.u.use(UNIT_U)
        self.v.use(UNIT_V)

    def release(self) -> None:
        for t in (self.y, self.u, self.v):
            t.release()
