"""One session's frame production on the GL thread: render the views, read back, pack.

A :class:`FrameProducer` lives on the GL thread (pibr.common.gl); the session pipeline
(pipeline.py) calls ``producer.produce(pose, t)`` there and hands the returned yuv420p buffer to
its encoders. Renderers are shared by every session showing the same scene; render targets
belong to the producer. The atlas is packed on the CPU after one readback of each view's colour
and distance (server/packer.py: the same bytes as the GL passes, ``gpu_pack``, at a quarter of
their cost on llvmpipe).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from pibr.common.gl import wait_idle
from pibr.protocol.atlas import AtlasLayout, colour_jitter
from pibr.protocol.depth import DepthQuantizer
from pibr.protocol.pose import Pose

from .object_poses import object_poses_payload
from .packer import AtlasPacker, CpuAtlasPacker
from .render_target import RenderTarget
from .renderer import PEEL_TOLERANCE, Renderer, edge_angle_for_width
from .view_upsample import ViewUpsampler


@dataclass
class ProducerSpec:
    """What a session's frames contain."""

    primary_size: tuple
    layout: AtlasLayout
    quantizer: DepthQuantizer | None
    projection: str = "vertex"
    extra_size: tuple | None = None
    extra_offset: Pose | None = None
    keep_distance: bool = False   # hand the float distance maps to the caller (edge codec)
    peel: bool = True             # depth-peel the extra view against the primary
    mark_peeled: bool = True      # ... marking peeled pixels apart from sky (protocol/depth.py)
    peel_tolerance: float = PEEL_TOLERANCE
    motion_dt: float | None = None  # render the primary's object motion over this many seconds
    object_poses: bool = False     # hand the moving objects' transforms (the scene moves)
    low_colour: int = 0            # hand a colour image downsampled by this factor (0: none)
    #: rasterise the smaller extra view with edges as much longer as keeps their bend in pixels
    #: (renderer.edge_angle_for_width): fewer triangles for the same accuracy in its own pixels
    extra_edges_by_size: bool = True
    #: pack the atlas in GL passes and read back the planes (same bytes as the CPU packer, slower
    #: on llvmpipe; kept as the reference the CPU packer is tested against)
    gpu_pack: bool = False
    #: the views' colour at this scale of their size: 0.5 packs the luma of one pixel of each 2x2
    #: block and the chroma of one 2x2 block of each 4x4, those protocol/atlas.py's ``colour_jitter``
    #: names for the frame's id (server/packer.py; depth and motion stay whole)
    colour_scale: float = 1.0


@dataclass
class ProducedFrame:
    """yuv : (1.5 H, W) uint8 atlas; distances : name -> (h, w) float32 when requested."""

    yuv: np.ndarray
    primary_pose: Pose
    extra_pose: Pose | None
    scene_t: float
    render_ms: float
    readback_ms: float
    pack_ms: float
    distances: dict = field(default_factory=dict)
    motion: np.ndarray | None = None       # (h, w, 2) pixels of moving objects, primary view
    moving: np.ndarray | None = None       # (h, w) bool: pixels of moving objects
    low_colour: np.ndarray | None = None   # (h / k, w / k, 3) uint8 primary colour
    object_poses: bytes | None = None      # the OBJECT_POSES payload at scene_t (moving objects)
    frame_id: int = 0                      # the id of the Frame it is made for (its colour's jitter)
    colours: dict = field(default_factory=dict)  # view name -> (h, w, 3) uint8 whole colour (keep_colour)


#: Upsamples a primary view rendered at a lower resolution into the full-size target: colour
#: bilinearly, distance and motion from the nearest low pixel (a distance between two surfaces, or a
#: moving flag between an object and what is behind it, would be neither), motion in full pixels.
#: Used by the GL packer and on frames that peel the extra view against the primary; otherwise the
#: small view is read back and brought to size on the CPU (view_upsample.py), several times cheaper
#: on llvmpipe.
_UPSAMPLE_FS = """
#version 410
uniform sampler2D u_color;
uniform sampler2D u_distance;
uniform sampler2D u_motion;
uniform vec2 u_size;
uniform float u_scale;
uniform bool u_with_motion;
layout(location = 0) out vec4 o_color;
layout(location = 1) out float o_distance;
layout(location = 2) out vec4 o_motion;
void main() {
    vec2 uv = gl_FragCoord.xy / u_size;
    ivec2 low = textureSize(u_distance, 0);
    ivec2 p = clamp(ivec2(uv * vec2(low)), ivec2(0), low - 1);
    o_color = texture(u_color, uv);
    o_distance = texelFetch(u_distance, p, 0).r;
    o_motion = vec4(0.0);
    if (u_with_motion) {
        vec4 m = texelFetch(u_motion, p, 0);
        o_motion = vec4(m.xy / u_scale, m.zw);
    }
}
"""
_UPSAMPLE_VS = """
#version 410
in vec2 in_pos;
void main() { gl_Position = vec4(in_pos, 0.0, 1.0); }
"""


@dataclass(frozen=True)
class FrameLevel:
    """How much of a frame to make (server/rate_control.py chooses it per frame).

    extra : render the extra view this frame (False: the atlas keeps the last one, with its pose);
    edge_deg : the primary view's longest straight edge as a view angle (None: the renderer's);
    scale : render the primary view at this fraction of its size, upsampled into the atlas.
    """

    extra: bool = True
    edge_deg: float | None = None
    scale: float = 1.0


FULL = FrameLevel()


class FrameProducer:
    """Render targets and atlas packer of one session. Create, use and release on the GL thread."""

    def __init__(self, ctx, renderer: Renderer, spec: ProducerSpec):
        self.ctx, self.renderer, self.spec = ctx, renderer, spec
        self.primary = RenderTarget(ctx, *spec.primary_size, motion=spec.motion_dt is not None)
        self.extra = RenderTarget(ctx, *spec.extra_size) if spec.extra_size else None
        if spec.gpu_pack:
            self.packer = AtlasPacker(ctx, spec.layout, spec.quantizer)
        else:
            self.packer = CpuAtlasPacker(spec.layout, spec.quantizer)
        views = [("primary", self.primary)] + ([("extra", self.extra)] if self.extra is not None else [])
        #: readback buffers, reused every frame: name -> (target, (h, w, 4) uint8, (h, w) float32)
        self._reads = {name: (t, np.empty((t.height, t.width, 4), np.uint8), np.empty((t.height, t.width), np.float32))
                       for name, t in views}
        self.extra_edge_deg = None
        if spec.extra_size and spec.extra_edges_by_size:
            self.extra_edge_deg = edge_angle_for_width(renderer.max_edge_angle_deg, spec.primary_size[0],
                                                       spec.extra_size[0])
            renderer.prepare_edge_angle(self.extra_edge_deg)
        self._low = {}              # scale -> the primary view's smaller render target
        self._low_reads = {}        # (w, h) of a smaller target -> its readback buffers (RGBA, distance)
        self._small_primary = None  # this frame's smaller primary target, brought to size on the CPU
        self._upsampler = ViewUpsampler()
        self._extra_packed = False  # the CPU packer's buffer holds the extra view's planes
        self._upsample = None       # (program, vbo, vao) of the upsampling pass, made when first needed
        self._extra_pose = None     # the extra view's pose in the atlas (frames that keep it)
        self._produced = 0          # frames made so far: the next frame's id unless the caller names it
        if spec.colour_scale != 1.0 and spec.gpu_pack:
            raise ValueError("a colour scale needs the CPU packer (gpu_pack is the reference only)")

    def produce(self, pose: Pose, t: float, level: FrameLevel = FULL, frame_id: int | None = None,
                keep_colour: bool = False) -> ProducedFrame:
        """The frame of ``pose`` at scene time ``t``, made at ``level`` (default: all of it), for the
        Frame ``frame_id`` (default: counted from 0 by this producer; a colour scale's jitter follows it).
        ``keep_colour``: also hand each view's whole colour (benchmarks measure against it)."""
        ctx = self.ctx
        frame_id = self._produced if frame_id is None else frame_id
        self._produced = frame_id + 1
        t0 = time.perf_counter()
        primary_edge = level.edge_deg
        self._small_primary = None
        fresh_extra = self.extra is not None and (level.extra or self._extra_pose is None)
        if level.scale == 1.0:
            self.renderer.render_wide(self.primary, pose, t, self.spec.projection, motion_dt=self.spec.motion_dt,
                                      max_edge_deg=primary_edge)
        else:
            low = self._low_target(level.scale)
            self.renderer.render_wide(low, pose, t, self.spec.projection, motion_dt=self.spec.motion_dt,
                                      max_edge_deg=primary_edge)
            if self.spec.gpu_pack or (fresh_extra and self.spec.peel):
                # the extra view is peeled against the whole-size distance, as at full scale
                self._upsample_into_primary(low, level.scale)
            else:
                self._small_primary = low     # brought to size after its readback (view_upsample.py; its
                                              # time counts as the frame's readback)
        if fresh_extra:
            self._extra_pose = pose.compose(self.spec.extra_offset)
            peel = (self.primary, pose, self.spec.peel_tolerance) if self.spec.peel else None
            extra_edge = self.extra_edge_deg
            if level.edge_deg is not None and self.spec.extra_edges_by_size:
                extra_edge = edge_angle_for_width(level.edge_deg, self.spec.primary_size[0], self.spec.extra_size[0])
            elif level.edge_deg is not None:
                extra_edge = level.edge_deg
            self.renderer.render_wide(self.extra, self._extra_pose, t, self.spec.projection, peel=peel,
                                      mark_peeled=self.spec.mark_peeled, max_edge_deg=extra_edge)
        extra_pose = self._extra_pose if self.extra is not None else None
        wait_idle(ctx)   # the GIL released while the rasteriser draws (common/gl.py)
        t1 = time.perf_counter()
        if self.spec.gpu_pack:
            if level != FULL:
                raise ValueError("frame levels need the CPU packer (gpu_pack is the reference only)")
            yuv, distances, low, pack_ms, readback_ms = self._pack_on_gpu(t1)
            colours = {}
            if keep_colour:
                colours = {name: t.read_rgba_into(rgba)[:, :, :3].copy() for name, (t, rgba, _) in self._reads.items()}
        else:
            yuv, distances, low, pack_ms, readback_ms, colours = self._pack_on_cpu(t1, fresh_extra, frame_id,
                                                                                   keep_colour)
        motion, moving = None, None
        if self.spec.motion_dt is not None:
            t2 = time.perf_counter()
            small = self._small_primary
            if small is None:
                motion, moving = self.primary.read_moving_motion()
            else:
                motion, moving = small.read_moving_motion()
                motion = self._upsampler.nearest(motion, self.spec.primary_size)
                motion /= np.float32(level.scale)       # in whole-size pixels
                moving = self._upsampler.nearest(moving, self.spec.primary_size)
            readback_ms += (time.perf_counter() - t2) * 1e3
        poses = object_poses_payload(self.renderer.scene, t) if self.spec.object_poses else None
        return ProducedFrame(yuv, pose, extra_pose, t, (t1 - t0) * 1e3, readback_ms, pack_ms, distances,
                             motion, moving, low, poses, frame_id, colours)

    def _low_target(self, scale: float) -> RenderTarget:
        if scale not in self._low:
            w, h = (max(16, int(round(side * scale))) for side in self.spec.primary_size)
            target = RenderTarget(self.ctx, w, h, motion=self.spec.motion_dt is not None)
            target.color.filter = (self.ctx.LINEAR, self.ctx.LINEAR)
            self._low[scale] = target
        return self._low[scale]

    def _small_reads(self, target: RenderTarget) -> tuple:
        key = (target.width, target.height)
        if key not in self._low_reads:
            self._low_reads[key] = (np.empty((target.height, target.width, 4), np.uint8),
                                    np.empty((target.height, target.width), np.float32))
        return self._low_reads[key]

    def _upsample_into_primary(self, low: RenderTarget, scale: float) -> None:
        ctx = self.ctx
        if self._upsample is None:
            prog = ctx.program(vertex_shader=_UPSAMPLE_VS, fragment_shader=_UPSAMPLE_FS)
            vbo = ctx.buffer(np.array([-1, -1, 1, -1, -1, 1, 1, 1], dtype="f4").tobytes())
            self._upsample = (prog, vbo, ctx.vertex_array(prog, [(vbo, "2f", "in_pos")]))
        prog, _, vao = self._upsample
        with_motion = low.motion is not None
        fbo = self.primary.all_fbo if with_motion else self.primary.fbo
        fbo.use()
        ctx.disable(ctx.DEPTH_TEST)
        low.color.use(location=0)
        low.distance.use(location=1)
        if with_motion:
            low.motion.use(location=2)
        for name, value in (("u_color", 0), ("u_distance", 1), ("u_motion", 2), ("u_scale", float(scale)),
                            ("u_with_motion", with_motion),
                            ("u_size", (float(self.primary.width), float(self.primary.height)))):
            if name in prog:
                prog[name].value = value
        vao.render(ctx.TRIANGLE_STRIP)

    def _pack_on_cpu(self, t1: float, read_extra: bool, frame_id: int, keep_colour: bool) -> tuple:
        """One readback of each view's colour and distance, then the CPU packer; the distances
        and low-resolution colour the caller wants come from the same reads. ``read_extra``
        False: the extra view was not rendered again; its planes stay in the packer's buffer as
        they were packed (at a colour scale its last reads are packed again with this frame's
        jitter: the client rebuilds it like any view)."""
        layout, colors, dists = self.spec.layout, {}, {}
        keep = self.spec.keep_distance
        small = self._small_primary
        for name, (target, rgba, dist) in self._reads.items():
            fresh = name != "extra" or read_extra
            with_distance = keep or layout.rect(name + ".depth") is not None
            if name == "primary" and small is not None:
                low_rgba, low_dist = self._small_reads(small)
                colors[name + ".color"] = self._upsampler.colour(small.read_rgba_into(low_rgba), rgba)
                if with_distance:
                    dists[name + ".depth"] = self._upsampler.distance(small.read_distance_into(low_dist), dist)
                continue
            colors[name + ".color"] = target.read_rgba_into(rgba) if fresh else rgba
            if with_distance:
                dists[name + ".depth"] = target.read_distance_into(dist) if fresh else dist
        t2 = time.perf_counter()
        jitter = colour_jitter(frame_id) if self.spec.colour_scale != 1.0 else None
        if not read_extra and jitter is None and self._extra_packed:
            # the packer's buffer still holds the kept extra view's planes
            yuv = self.packer.pack({k: v for k, v in colors.items() if not k.startswith("extra.")},
                                   {k: v for k, v in dists.items() if not k.startswith("extra.")}).copy()
        else:
            yuv = self.packer.pack(colors, dists, jitter).copy()
            self._extra_packed = "extra" in self._reads
        t3 = time.perf_counter()
        distances = {name: dists[name + ".depth"].copy() for name in self._reads} if keep else {}
        low = None
        if self.spec.low_colour:
            k = self.spec.low_colour
            low = colors["primary.color"][k // 2::k, k // 2::k, :3].copy()
        colours = {name: colors[name + ".color"][:, :, :3].copy() for name in self._reads} if keep_colour else {}
        return yuv, distances, low, (t3 - t2) * 1e3, (t2 - t1 + time.perf_counter() - t3) * 1e3, colours

    def _pack_on_gpu(self, t1: float) -> tuple:
        """The GL packing passes, then reading back their planes (and what the caller wants)."""
        sources = {"primary.color": self.primary.color, "primary.depth": self.primary.distance}
        if self.extra is not None:
            sources.update({"extra.color": self.extra.color, "extra.depth": self.extra.distance})
        self.packer.pack(sources)
        wait_idle(self.ctx)
        t2 = time.perf_counter()
        yuv = self.packer.read().copy()
        distances, low = {}, None
        if self.spec.keep_distance:
            distances["primary"] = self.primary.read_distance().copy()
            if self.extra is not None:
                distances["extra"] = self.extra.read_distance().copy()
        if self.spec.low_colour:
            k = self.spec.low_colour
            low = self.primary.read_color()[k // 2::k, k // 2::k].copy()
        return yuv, distances, low, (t2 - t1) * 1e3, (time.perf_counter() - t2) * 1e3

    def release(self) -> None:
        self.primary.release()
        if self.extra is not None:
            self.extra.release()
        for target in self._low.values():
            target.release()
        if self._upsample is not None:
            for r in reversed(self._upsample):
                r.release()
        if self.spec.gpu_pack:
            self.packer.release()
