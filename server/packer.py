"""Pack rendered views into the atlas as planar YUV 4:2:0 on the GPU.

Short passes write the Y plane and the half-size U and V planes; read back, they are laid
out exactly as libx264 wants its ``yuv420p`` input (Y, then U, then V, row-major), so the
encoder gets them with no colour conversion on the CPU. Colour is converted with full-range BT.601 (JPEG)
coefficients; depth rectangles get the disparity code straight into luma and neutral
chroma, so nothing but the video codec itself touches depth.
"""
from __future__ import annotations

import numpy as np

from pibr.protocol.atlas import RECT_NAMES, AtlasLayout
from pibr.protocol.depth import GLSL as DEPTH_GLSL
from pibr.protocol.depth import DepthQuantizer

_VS = """
#version 410
in vec2 in_pos;
void main() { gl_Position = vec4(in_pos, 0.0, 1.0); }
"""

# Each pass draws one rectangle of one plane (the viewport is the rectangle), so the
# shaders have no loops or branches over rectangles: on a software rasteriser that is
# several times faster than one pass that finds each pixel's rectangle.
_LUMA_COLOR_FS = """
#version 410
uniform sampler2D u_src;
uniform ivec2 u_origin;          // the rectangle's corner in the plane
out float f_y;
void main() {
    vec3 c = texelFetch(u_src, ivec2(gl_FragCoord.xy) - u_origin, 0).rgb * 255.0;
    f_y = floor(0.299 * c.r + 0.587 * c.g + 0.114 * c.b + 0.5) / 255.0;
}
"""

_LUMA_DEPTH_FS = """
#version 410
uniform sampler2D u_src;
uniform ivec2 u_origin;
uniform float u_near;
uniform float u_far;
uniform float u_min_code;
uniform float u_max_code;
out float f_y;
%(depth)s
void main() {
    float r = texelFetch(u_src, ivec2(gl_FragCoord.xy) - u_origin, 0).r;
    f_y = depth_quantize(r, u_near, u_far, u_min_code, u_max_code) / 255.0;
}
""" % {"depth": DEPTH_GLSL}

_CHROMA_FS = """
#version 410
uniform sampler2D u_src;
uniform ivec2 u_origin;          // the rectangle's corner in the half-size chroma planes
layout(location = 0) out float f_u;
layout(location = 1) out float f_v;
void main() {
    ivec2 p = 2 * (ivec2(gl_FragCoord.xy) - u_origin);
    vec3 s = (texelFetch(u_src, p, 0).rgb + texelFetch(u_src, p + ivec2(1, 0), 0).rgb
              + texelFetch(u_src, p + ivec2(0, 1), 0).rgb + texelFetch(u_src, p + ivec2(1, 1), 0).rgb) * (255.0 / 4.0);
    f_u = clamp(floor(-0.168736 * s.r - 0.331264 * s.g + 0.5 * s.b + 128.5), 0.0, 255.0) / 255.0;
    f_v = clamp(floor(0.5 * s.r - 0.418688 * s.g - 0.081312 * s.b + 128.5), 0.0, 255.0) / 255.0;
}
"""


class AtlasPacker:
    """GL passes: view textures -> yuv420p bytes of the atlas. Use on the GL thread."""

    def __init__(self, ctx, layout: AtlasLayout, quantizer: DepthQuantizer | None):
        self.ctx, self.layout, self.quantizer = ctx, layout, quantizer
        self.progs = {
            "color": ctx.program(vertex_shader=_VS, fragment_shader=_LUMA_COLOR_FS),
            "depth": ctx.program(vertex_shader=_VS, fragment_shader=_LUMA_DEPTH_FS),
            "chroma": ctx.program(vertex_shader=_VS, fragment_shader=_CHROMA_FS),
        }
        quad = np.array([-1, -1, 1, -1, -1, 1, 1, 1], dtype="f4")
        self.vbo = ctx.buffer(quad.tobytes())
        self.vaos = {k: ctx.vertex_array(p, [(self.vbo, "2f", "in_pos")]) for k, p in self.progs.items()}
        w, h = layout.width, layout.height
        self.y = ctx.texture((w, h), 1)
        self.u = ctx.texture((w // 2, h // 2), 1)
        self.v = ctx.texture((w // 2, h // 2), 1)
        self.y_fbo = ctx.framebuffer(color_attachments=[self.y])
        self.uv_fbo = ctx.framebuffer(color_attachments=[self.u, self.v])
        if quantizer is not None:
            d = self.progs["depth"]
            d["u_near"].value = quantizer.near
            d["u_far"].value = quantizer.far
            d["u_min_code"].value = float(quantizer.min_code)
            d["u_max_code"].value = float(quantizer.max_code)
        self._buf = np.empty((h * 3 // 2, w), np.uint8)

    def _draw(self, kind: str, texture, x: int, y: int, w: int, h: int) -> None:
        texture.use(0)
        self.progs[kind]["u_origin"].value = (x, y)
        self.ctx.viewport = (x, y, w, h)
        self.vaos[kind].render(self.ctx.TRIANGLE_STRIP)

    def pack(self, sources: dict) -> None:
        """Draw the atlas planes. ``sources`` maps rect names to textures (colour RGBA8 or distance R32F)."""
        ctx = self.ctx
        ctx.disable(ctx.DEPTH_TEST)
        self.y_fbo.use()
        self.y_fbo.clear(0.0, 0.0, 0.0, 0.0)
        for name in RECT_NAMES:
            r = self.layout.rect(name)
            if r is None or name not in sources:
                continue
            self._draw("depth" if name.endswith(".depth") else "color", sources[name], *r)
        self.uv_fbo.use()
        self.uv_fbo.clear(128 / 255, 128 / 255, 128 / 255, 128 / 255)
        for name in RECT_NAMES:
            r = self.layout.rect(name)
            if r is None or name not in sources or name.endswith(".depth"):
                continue
            x, y, w, h = r
            self._draw("chroma", sources[name], x // 2, y // 2, w // 2, h // 2)

    def read(self) -> np.ndarray:
        """(1.5 H, W) uint8 yuv420p buffer of the last :meth:`pack` (reused between calls)."""
        w, h = self.layout.width, self.layout.height
        q = (w // 2) * (h // 2)
        self._buf[:h] = np.frombuffer(self.y_fbo.read(components=1, alignment=1), np.uint8).reshape(h, w)
        flat = self._buf[h:].reshape(-1)
        flat[:q] = np.frombuffer(self.uv_fbo.read(components=1, attachment=0, alignment=1), np.uint8)
        flat[q:] = np.frombuffer(self.uv_fbo.read(components=1, attachment=1, alignment=1), np.uint8)
        return self._buf

    def release(self) -> None:
        for v in self.vaos.values():
            v.release()
        for p in self.progs.values():
            p.release()
        for r in (self.vbo, self.y_fbo, self.uv_fbo, self.y, self.u, self.v):
            r.release()


def yuv420_to_rgb(yuv: np.ndarray, width: int, height: int) -> np.ndarray:
    """Reference CPU conversion of a (1.5 H, W) full-range BT.601 yuv420p buffer to (H, W, 3) uint8."""
    y = yuv[:height].astype(np.float32)
    q = (width // 2) * (height // 2)
    flat = yuv[height:].reshape(-1)
    u = flat[:q].reshape(height // 2, width // 2).astype(np.float32) - 128.0
    v = flat[q:2 * q].reshape(height // 2, width // 2).astype(np.float32) - 128.0
    u = np.repeat(np.repeat(u, 2, 0), 2, 1)
    v = np.repeat(np.repeat(v, 2, 0), 2, 1)
    rgb = np.stack([y + 1.402 * v, y - 0.344136 * u - 0.714136 * v, y + 1.772 * u], axis=-1)
    return np.clip(rgb + 0.5, 0, 255).astype(np.uint8)
