"""A decoded server frame on the GPU, and the GLSL that samples it.

The atlas's Y, U and V planes are three textures; a view's colour is sampled bilinearly
and converted to RGB in the shader. Depth comes from the transport the session uses:

* ``h264``: the 8-bit disparity code in the atlas's luma, dequantized in the shader;
* ``edge``: dense distance maps the client reconstructed from the edge codec (R32F).

Shaders call ``primary_distance(uv)`` / ``extra_distance(uv)`` (radial distance, 0 = sky or
nothing known) and ``atlas_rgb(rect, uv)``, whichever the transport; :func:`frame_glsl`
writes the matching implementation. At a colour scale (``SessionConfig.colour_scale`` 0.5) the
video carries a quarter of each view's colour pixels; every upload rebuilds the views' whole
colour (client/colour_rebuild.py) and ``atlas_rgb`` reads that.

A frame uploaded with a :class:`~pibr.client.flow_warp.FlowFrame` can show its primary view
extrapolated along its motion flow to a display time: ``use(flow_time)`` writes the rectangle
that changes (colour and depth, either transport), ``use()`` puts the decoded frame back. The
CPU copies (:meth:`FrameTextures.view_distances`) stay the frame as decoded.
"""
from __future__ import annotations

import numpy as np

from pibr.protocol.depth import GLSL as DEPTH_GLSL
from pibr.protocol.depth_codecs import DEPTH_CODECS
from pibr.protocol.projection import GLSL as PROJECTION_GLSL
from pibr.protocol.session import SessionConfig

from .colour_rebuild import UNIT_REBUILT, ColourRebuild, RebuildSettings, rebuilt_layout
from .video import YUVImage

#: Codes of depth-transport error a comparison of distances forgives (quantization and coding
#: noise): H.264 moves the 8-bit codes by a few levels, the edge codec's diffused 12-bit codes
#: by one or two. Measured for ``proxy`` (room, trace 1, 128 ms, the tuning window): edge
#: slack 1 -> DSSIM 0.0417, holes 0.85 %; 2 -> 0.0402, 0.68 %; 4 -> 0.0401, 0.66 %; h264 2.5
#: -> 0.0443; 4 -> 0.0439.
DEPTH_SLACK_CODES = {"h264": 2.5, "edge": 2.0}

#: Texture units of the frame; methods use units from 6 upwards.
UNIT_Y, UNIT_U, UNIT_V, UNIT_DIST_PRIMARY, UNIT_DIST_EXTRA = 0, 1, 2, 3, 4

_COMMON = """
uniform sampler2D u_atlas_y;
uniform sampler2D u_atlas_u;
uniform sampler2D u_atlas_v;
uniform vec2 u_atlas_size;     // atlas width, height in pixels
uniform vec4 u_rect_primary_depth;
uniform vec4 u_rect_extra_depth;
uniform float u_depth_near;      // the depth transport's quantization
uniform float u_depth_far;
uniform float u_depth_min_code;
uniform float u_depth_max_code;
uniform float u_slack_codes;     // codes of depth-transport error to forgive (DEPTH_SLACK_CODES)

// The distance step of one depth code at distance r (disparity coding: it grows as r^2).
float depth_code_step(float r) { return r * r / (u_depth_near * (u_depth_max_code - u_depth_min_code)); }
// Full-range BT.601 (as the server's packer): Y, U, V texels in [0, 1] -> RGB.
vec3 yuv_rgb(vec3 yuv) {
    float y = yuv.x, u = yuv.y - 128.0 / 255.0, v = yuv.z - 128.0 / 255.0;
    return clamp(vec3(y + 1.402 * v, y - 0.344136 * u - 0.714136 * v, y + 1.772 * u), 0.0, 1.0);
}
// Colour the frame's video holds for a view at uv in [0,1]^2 (row 0 on top); rect = (x, y, w, h)
// of the view's colour in the atlas.
vec3 wire_rgb(vec4 rect, vec2 uv) {
    vec2 p = rect.xy + clamp(uv * rect.zw, vec2(0.5), rect.zw - 0.5);
    vec2 pc = clamp(0.5 * p, 0.5 * rect.xy + 0.5, 0.5 * (rect.xy + rect.zw) - 0.5);
    vec2 uvc = pc / (0.5 * u_atlas_size);
    return yuv_rgb(vec3(texture(u_atlas_y, p / u_atlas_size).r, texture(u_atlas_u, uvc).r, texture(u_atlas_v, uvc).r));
}
"""

_H264_DEPTH = """
// Radial distance stored for a view at uv (nearest texel), 0 for sky.
float atlas_distance(vec4 rect, vec2 uv) {
    if (rect.z <= 0.0) return 0.0;
    ivec2 p = ivec2(rect.xy + clamp(floor(uv * rect.zw), vec2(0.0), rect.zw - 1.0));
    float code = floor(texelFetch(u_atlas_y, p, 0).r * 255.0 + 0.5);
    return depth_dequantize(code, u_depth_near, u_depth_far, u_depth_min_code, u_depth_max_code);
}
float primary_distance(vec2 uv) { return atlas_distance(u_rect_primary_depth, uv); }
float extra_distance(vec2 uv) { return atlas_distance(u_rect_extra_depth, uv); }
// ... at pixel p of the view (row 0 on top), inside it
float atlas_distance_at(vec4 rect, ivec2 p) {
    float code = floor(texelFetch(u_atlas_y, ivec2(rect.xy) + p, 0).r * 255.0 + 0.5);
    return depth_dequantize(code, u_depth_near, u_depth_far, u_depth_min_code, u_depth_max_code);
}
float primary_distance_at(ivec2 p) { return atlas_distance_at(u_rect_primary_depth, p); }
float extra_distance_at(ivec2 p) { return atlas_distance_at(u_rect_extra_depth, p); }
"""

_EDGE_DEPTH = """
uniform sampler2D u_dist_primary;   // reconstructed radial distance (R32F), row 0 on top
uniform sampler2D u_dist_extra;
float map_distance(sampler2D map, vec2 uv) {
    ivec2 size = textureSize(map, 0);
    return texelFetch(map, clamp(ivec2(floor(uv * vec2(size))), ivec2(0), size - 1), 0).r;
}
float primary_distance(vec2 uv) { return map_distance(u_dist_primary, uv); }
float extra_distance(vec2 uv) { return map_distance(u_dist_extra, uv); }
// ... at pixel p of the view (row 0 on top), inside it
float primary_distance_at(ivec2 p) { return texelFetch(u_dist_primary, p, 0).r; }
float extra_distance_at(ivec2 p) { return texelFetch(u_dist_extra, p, 0).r; }
"""


_WIRE_COLOUR = """
// Colour of a view at uv in [0,1]^2 (row 0 on top); rect = rect_uniform(config, "<view>.color").
vec3 atlas_rgb(vec4 rect, vec2 uv) { return wire_rgb(rect, uv); }
"""

_REBUILT_COLOUR = """
uniform sampler2D u_rebuilt;     // the views' whole colour (Y, U, V) rebuilt from a colour-scaled frame
uniform vec2 u_rebuilt_size;
// Colour of a view at uv in [0,1]^2 (row 0 on top); rect = rect_uniform(config, "<view>.color").
vec3 atlas_rgb(vec4 rect, vec2 uv) {
    vec2 p = rect.xy + clamp(uv * rect.zw, vec2(0.5), rect.zw - 0.5);
    return yuv_rgb(texture(u_rebuilt, p / u_rebuilt_size).xyz);
}
"""


def wire_glsl(config: SessionConfig) -> str:
    """GLSL of the frame as it arrives: projection maths, ``wire_rgb`` and the views' distances."""
    depth = _H264_DEPTH if DEPTH_CODECS[config.depth_codec].in_atlas else _EDGE_DEPTH
    return PROJECTION_GLSL + DEPTH_GLSL + _COMMON + depth


def frame_glsl(config: SessionConfig) -> str:
    """GLSL for sampling a frame of this session (projection maths included): ``atlas_rgb`` reads
    the video, or the colour rebuilt from it at a colour scale (client/colour_rebuild.py)."""
    return wire_glsl(config) + (_WIRE_COLOUR if config.colour_scale == 1.0 else _REBUILT_COLOUR)


def bind_frame_uniforms(prog, config: SessionConfig) -> None:
    """Set the uniforms :func:`frame_glsl` reads that stay fixed for the session."""
    values = {
        "u_atlas_y": UNIT_Y, "u_atlas_u": UNIT_U, "u_atlas_v": UNIT_V,
        "u_dist_primary": UNIT_DIST_PRIMARY, "u_dist_extra": UNIT_DIST_EXTRA,
        "u_atlas_size": (float(config.atlas.width), float(config.atlas.height)),
        "u_rect_primary_depth": rect_uniform(config, "primary.depth"),
        "u_rect_extra_depth": rect_uniform(config, "extra.depth"),
        "u_depth_near": config.near, "u_depth_far": config.far,
        "u_depth_min_code": float(config.depth_min_code),
        "u_depth_max_code": float((1 << config.depth_bits) - 1),
        "u_slack_codes": DEPTH_SLACK_CODES[config.depth_codec],
        "u_rebuilt": UNIT_REBUILT,
    }
    if config.colour_scale != 1.0:
        values["u_rebuilt_size"] = tuple(float(v) for v in rebuilt_layout(config)["size"])
    for name, value in values.items():
        if name in prog:
            prog[name].value = value


def rect_uniform(config: SessionConfig, name: str) -> tuple:
    """The rectangle (x, y, w, h) a shader passes for ``name`` (protocol/atlas.py RECT_NAMES): where
    the atlas holds it, a view's colour where :func:`frame_glsl`'s ``atlas_rgb`` reads it (the
    rebuilt texture at a colour scale); zeros when the session has no such rectangle."""
    if name.endswith(".color") and config.colour_scale != 1.0 and config.atlas.rect(name) is not None:
        return tuple(float(x) for x in rebuilt_layout(config)[name.split(".")[0]])
    r = config.atlas.rect(name)
    return (0.0, 0.0, 0.0, 0.0) if r is None else tuple(float(x) for x in r)


def has_extra_depth(config: SessionConfig) -> bool:
    return config.extra is not None and (not DEPTH_CODECS[config.depth_codec].in_atlas
                                         or config.atlas.rect("extra.depth") is not None)


def transport_quantizer(config: SessionConfig):
    """The depth transport's :class:`~pibr.protocol.depth.DepthQuantizer`."""
    from pibr.protocol.depth import DepthQuantizer

    return DepthQuantizer(config.near, config.far, config.depth_bits, config.depth_min_code)


def primary_flow_frame(config: SessionConfig, image: YUVImage, distances: dict | None, flow, moving,
                       scene_t: float, horizon_frames: float | None = None):
    """A :class:`~pibr.client.flow_warp.FlowFrame` of a decoded frame's primary view, for
    :meth:`FrameTextures.upload` (CPU only: make it where the frame is decoded). flow (h, w, 2)
    and moving (h, w) from the frame's MOTION_FLOW; distances: the edge codec's, else the
    atlas's 8-bit disparity is read."""
    from .flow_warp import DEFAULT_HORIZON_FRAMES, FlowFrame

    x, y, w, h = config.atlas.rect("primary.color")
    if distances and "primary" in distances:
        distance = distances["primary"]
    else:
        dx, dy, dw, dh = config.atlas.rect("primary.depth")
        distance = transport_quantizer(config).dequantize(image.y[dy:dy + dh, dx:dx + dw])
    # the transport's error forgiven in depth tests, in disparity (1 / m)
    slack = DEPTH_SLACK_CODES[config.depth_codec] / (config.near * ((1 << config.depth_bits) - 1 - config.depth_min_code))
    return FlowFrame(image.y[y:y + h, x:x + w], image.u[y // 2:(y + h) // 2, x // 2:(x + w) // 2],
                     image.v[y // 2:(y + h) // 2, x // 2:(x + w) // 2], distance, flow, moving, scene_t,
                     config.frame_interval_us / 1e6, DEFAULT_HORIZON_FRAMES if horizon_frames is None else horizon_frames,
                     slack)


def _inside(inner, outer) -> bool:
    """Whether rectangle ``inner`` (x, y, w, h) lies within ``outer``."""
    return (outer[0] <= inner[0] and outer[1] <= inner[1] and inner[0] + inner[2] <= outer[0] + outer[2]
            and inner[1] + inner[3] <= outer[1] + outer[3])


class FrameTextures:
    """The newest frame's textures; :meth:`upload` replaces their contents. GL thread only."""

    def __init__(self, ctx, config: SessionConfig, rebuild_settings: RebuildSettings | None = None):
        self.ctx = ctx
        w, h = config.atlas.width, config.atlas.height
        self.y = ctx.texture((w, h), 1)
        self.u = ctx.texture((w // 2, h // 2), 1)
        self.v = ctx.texture((w // 2, h // 2), 1)
        for t in (self.y, self.u, self.v):
            t.filter = (ctx.LINEAR, ctx.LINEAR)
            t.repeat_x = t.repeat_y = False
        self.distances = {}
        if not DEPTH_CODECS[config.depth_codec].in_atlas:   # depth arrives decoded: a float texture per view
            views = {"primary": config.primary, "extra": config.extra}
            for name, view in views.items():
                size = (view.width, view.height) if view is not None else (1, 1)
                t = ctx.texture(size, 1, dtype="f4")
                t.filter = (ctx.NEAREST, ctx.NEAREST)
                t.write(np.zeros(size[::-1], np.float32).tobytes())
                self.distances[name] = t
        self.frame_id = None
        self.config = config
        #: a colour-scaled session's views rebuilt whole each frame (client/colour_rebuild.py)
        self.rebuild = None
        if config.colour_scale != 1.0:
            self.rebuild = ColourRebuild(ctx, config, wire_glsl(config), bind_frame_uniforms,
                                         DEPTH_SLACK_CODES[config.depth_codec], rebuild_settings or RebuildSettings())
        self.flow = None
        self.extrapolated = None
        self._image: YUVImage | None = None
        self._cpu_distances: dict = {}

    def upload(self, image: YUVImage, frame, distances: dict | None = None, flow=None) -> None:
        """image: the atlas planes of ``frame`` (its Frame message); distances: view name -> (h, w)
        float32 (edge codec); flow: the frame's :class:`~pibr.client.flow_warp.FlowFrame` (see
        :meth:`use`), or None. At a colour scale the views' colour is rebuilt here."""
        if flow is not None and self.rebuild is not None:
            raise ValueError("extrapolating a frame along its motion flow needs its whole colour: the session "
                             "sends colour at scale %g" % self.config.colour_scale)
        self._image = image
        self._cpu_distances = dict(distances or {})
        self.y.write(np.ascontiguousarray(image.y), alignment=1)
        self.u.write(np.ascontiguousarray(image.u), alignment=1)
        self.v.write(np.ascontiguousarray(image.v), alignment=1)
        for name, d in (distances or {}).items():
            self.distances[name].write(np.ascontiguousarray(d, np.float32).tobytes())
        self.frame_id = frame.frame_id
        self.flow = flow
        self.extrapolated = None   # what of the primary view the textures hold extrapolated (see use())
        if self.rebuild is not None:
            self.use()
            self.rebuild.run(frame)
            self.rebuild.use()

    def view_distances(self, name: str) -> np.ndarray | None:
        """The newest frame's radial distance of view ``name`` ("primary" or "extra") on the CPU,
        (h, w) float32, row 0 on top, 0 = sky or nothing; None if the session has no depth for it.

        What the shaders' ``primary_distance`` / ``extra_distance`` read: the edge codec's
        reconstruction, or the atlas's 8-bit disparity dequantized (computed once per frame)."""
        if name in self._cpu_distances:
            return self._cpu_distances[name]
        rect = self.config.atlas.rect(f"{name}.depth")
        if not DEPTH_CODECS[self.config.depth_codec].in_atlas or rect is None or self._image is None:
            return None
        x, y, w, h = rect
        d = transport_quantizer(self.config).dequantize(self._image.y[y:y + h, x:x + w]).astype(np.float32)
        self._cpu_distances[name] = d
        return d

    def show_at(self, flow_time: float | None) -> None:
        """Make the primary view's textures show the frame extrapolated along its motion flow to
        scene time ``flow_time`` (client/flow_warp.py), or as decoded (None, or no flow). Only the
        rectangle extrapolation changes is written; :meth:`use` calls this."""
        ext = None
        if flow_time is not None and self.flow is not None:
            ext = self.flow.extrapolate(self.flow.steps(flow_time))
        old = self.extrapolated
        if ext is old:
            return
        if old is not None and not (ext is not None and _inside(old.rect, ext.rect)):
            self._write_primary(old.rect)
        if ext is not None:
            self._write_primary(ext.rect, ext)
        self.extrapolated = ext

    def _write_primary(self, rect, ext=None) -> None:
        """Write ``rect`` (x, y, w, h) of the primary view: from ``ext`` (Extrapolated over exactly
        that rectangle) or from the frame as decoded."""
        x0, y0, w, h = rect
        cx, cy = self.config.atlas.rect("primary.color")[:2]
        img = self._image
        if ext is None:
            planes = (img.y[cy + y0:cy + y0 + h, cx + x0:cx + x0 + w],
                      img.u[(cy + y0) // 2:(cy + y0 + h) // 2, (cx + x0) // 2:(cx + x0 + w) // 2],
                      img.v[(cy + y0) // 2:(cy + y0 + h) // 2, (cx + x0) // 2:(cx + x0 + w) // 2])
        else:
            planes = (ext.y, ext.u, ext.v)
        self.y.write(np.ascontiguousarray(planes[0]), viewport=(cx + x0, cy + y0, w, h), alignment=1)
        for tex, plane in ((self.u, planes[1]), (self.v, planes[2])):
            tex.write(np.ascontiguousarray(plane), viewport=((cx + x0) // 2, (cy + y0) // 2, w // 2, h // 2),
                      alignment=1)
        if "primary" in self.distances:
            d = self._cpu_distances["primary"][y0:y0 + h, x0:x0 + w] if ext is None else ext.distance
            self.distances["primary"].write(np.ascontiguousarray(d, np.float32).tobytes(), viewport=(x0, y0, w, h))
            return
        depth = self.config.atlas.rect("primary.depth")
        if depth is None:
            return
        dx, dy = depth[:2]
        codes = img.y[dy + y0:dy + y0 + h, dx + x0:dx + x0 + w]
        if ext is not None:
            codes = codes.copy()
            codes[ext.changed] = transport_quantizer(self.config).quantize(ext.distance[ext.changed])
        self.y.write(np.ascontiguousarray(codes), viewport=(dx + x0, dy + y0, w, h), alignment=1)

    def use(self, flow_time: float | None = None) -> None:
        """Bind the frame's textures; ``flow_time``: see :meth:`show_at` (None: the frame as decoded)."""
        if self._image is not None:
            self.show_at(flow_time)
        self.y.use(UNIT_Y)
        self.u.use(UNIT_U)
        self.v.use(UNIT_V)
        for name, unit in (("primary", UNIT_DIST_PRIMARY), ("extra", UNIT_DIST_EXTRA)):
            if name in self.distances:
                self.distances[name].use(unit)
        if self.rebuild is not None:
            self.rebuild.use()

    def release(self) -> None:
        for t in (self.y, self.u, self.v, *self.distances.values()):
            t.release()
        if self.rebuild is not None:
            self.rebuild.release()
