"""Pack rendered views into the atlas as planar YUV 4:2:0 (``yuv420p``, what libx264 takes).

The atlas is laid out exactly as libx264 wants its input (Y, then U, then V, row-major).
Colour is converted with full-range BT.601 (JPEG) coefficients; depth rectangles get the
disparity code straight into luma and neutral chroma, so nothing but the video codec itself
touches depth. Two packers make the same bytes:

:class:`CpuAtlasPacker` (the server's) converts the views' colour and distance after one
readback, in numba: about a quarter of the GL passes' CPU time on llvmpipe (1024² + 512²
views: 9 against 33 ms), which pay for rasterising and still need their planes read back.

:class:`AtlasPacker` does it in short GL passes and is the reference. The CPU kernels
repeat its float32 arithmetic operation for operation as Mesa 22.3's llvmpipe compiles it
(texels x * (1 / 255), constant factors folded into one constant, the rounding offset added
to the first term, correctly rounded division). Checked once on every 8-bit colour and every
float32 distance from 0.04 to 10486; tests/server/test_packer.py checks the colours, blocks
and distances where float32 rounding decides, and rendered frames. Another GL driver may
compile the passes differently; the CPU packer's bytes do not depend on the driver.
"""
from __future__ import annotations

import sys

import numpy as np
from numba import njit

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


# float32 constants of the shaders above, as llvmpipe folds them: a texel is x * (1 / 255)
# rounded to float32; ``texel * 255.0 * k`` becomes ``texel * (255 k)``, and the chroma
# pass's ``(sum of 4 texels) * (255 / 4) * k`` becomes ``sum * (63.75 k)``.
_F = np.float32
_INV255 = _F(1.0 / 255.0)
_L0, _L1, _L2 = (_F(_F(k) * _F(255.0)) for k in (0.299, 0.587, 0.114))
_U0, _U1, _U2 = (_F(_F(k) * _F(255.0 / 4.0)) for k in (-0.168736, -0.331264, 0.5))
_V0, _V1, _V2 = (_F(_F(k) * _F(255.0 / 4.0)) for k in (0.5, -0.418688, -0.081312))

# error_model="numpy": no zero-division branch, so LLVM vectorises the loops (2-3x here);
# without fastmath nothing is reassociated or contracted, so every lane rounds as above.


@njit(cache=True, nogil=True, error_model="numpy")
def _pack_color(rgba, y_plane, u_plane, v_plane, x0, y0, step, jx, jy):
    """rgba (H, W) uint32, RGBA bytes little-endian, H and W multiples of 2 ``step`` -> a
    (H / step, W / step) image: Y at (y0, x0) of the pixels (step j + jy, step i + jx), U and V at
    (y0 / 2, x0 / 2) of the 2x2 blocks of rows 2 (step j + jy) and columns 2 (step i + jx): the
    luma and chroma passes' float32 arithmetic. ``step`` 1 (jx = jy = 0): the whole view; 2: the
    colour scale 0.5's pixels and blocks of jitter (jx, jy) (protocol/atlas.py colour_jitter), so
    that four frames send every pixel's luma and every block's chroma of a still view once."""
    height, width = rgba.shape
    h, w = height // step, width // step
    for j in range(h):
        src = rgba[step * j + jy]
        dst = y_plane[y0 + j]
        for i in range(w):
            p = src[step * i + jx]
            r = _F(p & 255) * _INV255
            g = _F((p >> 8) & 255) * _INV255
            b = _F((p >> 16) & 255) * _INV255
            dst[x0 + i] = np.uint8(np.floor(((r * _L0 + _F(0.5)) + g * _L1) + b * _L2))
    for j in range(h // 2):
        top = rgba[2 * (step * j + jy)]
        bottom = rgba[2 * (step * j + jy) + 1]
        u_row = u_plane[y0 // 2 + j]
        v_row = v_plane[y0 // 2 + j]
        for i in range(w // 2):
            x = 2 * (step * i + jx)
            # the order the chroma pass adds its texels: (0, 0), (1, 0), (0, 1), (1, 1)
            a, b, c, d = top[x], top[x + 1], bottom[x], bottom[x + 1]
            sr = ((_F(a & 255) * _INV255 + _F(b & 255) * _INV255) + _F(c & 255) * _INV255) + _F(d & 255) * _INV255
            sg = (((_F((a >> 8) & 255) * _INV255 + _F((b >> 8) & 255) * _INV255) + _F((c >> 8) & 255) * _INV255)
                  + _F((d >> 8) & 255) * _INV255)
            sb = (((_F((a >> 16) & 255) * _INV255 + _F((b >> 16) & 255) * _INV255) + _F((c >> 16) & 255) * _INV255)
                  + _F((d >> 16) & 255) * _INV255)
            u = np.floor(((sr * _U0 + _F(128.5)) + sg * _U1) + sb * _U2)
            v = np.floor(((sr * _V0 + _F(128.5)) + sg * _V1) + sb * _V2)
            u_row[x0 // 2 + i] = np.uint8(min(max(u, _F(0.0)), _F(255.0)))
            v_row[x0 // 2 + i] = np.uint8(min(max(v, _F(0.0)), _F(255.0)))


@njit(cache=True, nogil=True, error_model="numpy")
def _pack_depth(distance, y_plane, x0, y0, near, far, min_code, max_code):
    """distance (h, w) float32 -> disparity codes into Y at (y0, x0): protocol/depth.py's
    ``depth_quantize`` in float32, as the depth pass computes it (all arguments float32).
    NaN (never rendered) codes as sky, as DepthQuantizer.quantize has it."""
    h, w = distance.shape
    span = max_code - min_code
    peeled = np.floor(_F(0.5) * min_code)
    for j in range(h):
        src = distance[j]
        dst = y_plane[y0 + j]
        for i in range(w):
            r = src[i]
            r = r if abs(r) >= _F(1.1754944e-38) else _F(0.0)   # subnormals: sky, as llvmpipe mostly flushes them
            code = min_code + np.floor((near / max(r, near)) * span + _F(0.5))
            code = _F(0.0) if (r > far or r <= _F(0.0) or r != r) else code
            code = peeled if r < _F(0.0) else code
            dst[x0 + i] = np.uint8(code)


class CpuAtlasPacker:
    """Views read back from GL -> yuv420p bytes of the atlas, identical to :class:`AtlasPacker`'s.

    Keeps one buffer; parts of the atlas no rectangle covers stay Y 0, U and V 128 as the GL
    passes clear them, and a rectangle a call is not given keeps what was last packed
    there. Thread-safe only per instance; the kernels release the GIL.
    """

    def __init__(self, layout: AtlasLayout, quantizer: DepthQuantizer | None):
        if sys.byteorder != "little":
            raise RuntimeError("the CPU atlas packer reads RGBA pixels as little-endian 32-bit words")
        if quantizer is not None and quantizer.bits > 8:
            raise ValueError(f"the atlas carries 8-bit depth codes, got a {quantizer.bits}-bit quantizer")
        for name in RECT_NAMES:
            r = layout.rect(name)
            if r is not None and not name.endswith(".depth") and any(v % 2 for v in r):
                raise ValueError(f"atlas rectangle {name} {r} must have even corners and sizes for 4:2:0 chroma")
        self.layout, self.quantizer = layout, quantizer
        w, h = layout.width, layout.height
        self._buf = np.empty((h * 3 // 2, w), np.uint8)
        self._buf[:h] = 0
        self._buf[h:] = 128
        q = (w // 2) * (h // 2)
        chroma = self._buf[h:].reshape(-1)
        self._y = self._buf[:h]
        self._u = chroma[:q].reshape(h // 2, w // 2)
        self._v = chroma[q:].reshape(h // 2, w // 2)

    def pack(self, colors: dict, distances: dict, jitter: tuple | None = None) -> np.ndarray:
        """colors: rect name -> (h, w, 4) uint8 RGBA; distances: rect name -> (h, w) float32 radial
        distance (0 sky, negative peeled). -> (1.5 H, W) uint8 yuv420p buffer (reused between calls).
        ``jitter`` (x, y): the colours are whole views twice the size of their rectangles, which
        take the pixels and chroma blocks of that jitter (colour scale 0.5, :func:`_pack_color`)."""
        step, (jx, jy) = (1, (0, 0)) if jitter is None else (2, jitter)
        for name in RECT_NAMES:
            r = self.layout.rect(name)
            if r is None:
                continue
            x, y, w, h = r
            if name.endswith(".depth"):
                if name not in distances:
                    continue
                if self.quantizer is None:
                    raise ValueError(f"atlas rectangle {name} needs a depth quantizer")
                src = distances[name]
                _check_source(name, src, (h, w), np.float32)
                q = self.quantizer
                _pack_depth(src, self._y, x, y, _F(q.near), _F(q.far), _F(q.min_code), _F(q.max_code))
            elif name in colors:
                src = colors[name]
                _check_source(name, src, (step * h, step * w, 4), np.uint8)
                _pack_color(src.view(np.uint32).reshape(step * h, step * w), self._y, self._u, self._v, x, y,
                            step, jx, jy)
        return self._buf


def _check_source(name: str, src: np.ndarray, shape: tuple, dtype) -> None:
    if src.shape != shape or src.dtype != dtype or not src.flags.c_contiguous:
        raise ValueError(f"atlas rectangle {name} needs a C-contiguous {shape} {np.dtype(dtype).name} image, "
                         f"got {src.shape} {src.dtype}")
