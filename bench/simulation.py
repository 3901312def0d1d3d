"""Server and client of one session in one process, on one GL context: what every benchmark
that scores client methods runs.

:class:`Simulation` makes each frame with the server's own pipeline (server/pipeline.py, built
from a :class:`~pibr.server.config.ServerConfig` as a server session builds it), decodes it with
the client's decoders and textures, re-renders any displayed pose with the client's methods and
renders ground truth there. No sockets: the schedule of which frame a tick shows comes from the
caller (pibr.common.replay, pibr.common.link), so nothing but the methods differs between them.
"""
from __future__ import annotations

import math
import time

import numpy as np

from pibr.protocol.messages import Hello, OutputConfig, PayloadKind

from pibr.server.coverage import displayed_points, uncovered_by_views

from .metrics import dssim, nearly_uniform, psnr, ssim

#: The primary view size benchmarks use unless told otherwise (a server sizes its view for the
#: client's output: 1088x1088 at 960x540; benchmarks keep one size so their numbers compare).
BENCH_VIEW_SIZE = (1024, 1024)


def bench_server_config(view_size=BENCH_VIEW_SIZE, **settings):
    """The server settings of a benchmark: ``ServerConfig`` with the benchmarks' view size and,
    unless told otherwise, depth in the atlas (benchmarks name the codec they measure rather than
    leave it to the plan's choice for a bandwidth)."""
    from pibr.server.config import ServerConfig

    settings.setdefault("depth_codec", "h264")
    return ServerConfig(view_size=tuple(view_size), **settings)


_FLOOR_FS = """
#version 410
%(frame)s
uniform vec4 u_color_rect;
uniform vec2 u_out_size;
out vec4 f_color;
void main() {
    vec2 uv = gl_FragCoord.xy / u_out_size;
    float d = primary_distance(uv) + extra_distance(uv.yx);
    f_color = vec4(atlas_rgb(u_color_rect, uv) + 1e-9 * d, 1.0);
}
"""


class FloorPass:
    """The speed floor: a full-screen pass with the proxy pass's texture lookups per pixel."""

    name = "floor"

    def __init__(self, ctx, output, config):
        from pibr.client.frame_textures import bind_frame_uniforms, frame_glsl, rect_uniform
        from pibr.client.methods.base import FULLSCREEN_VS, fullscreen_quad

        self.ctx = ctx
        self.prog = ctx.program(vertex_shader=FULLSCREEN_VS, fragment_shader=_FLOOR_FS % {"frame": frame_glsl(config)})
        bind_frame_uniforms(self.prog, config)
        self.prog["u_color_rect"].value = rect_uniform(config, "primary.color")
        self.prog["u_out_size"].value = (float(output.width), float(output.height))
        self.vbo, self.vao = fullscreen_quad(ctx, self.prog)

    def render(self, out_pose, frame, textures, scene_t=0.0):
        textures.use()
        self.ctx.disable(self.ctx.DEPTH_TEST)
        self.vao.render(self.ctx.TRIANGLE_STRIP)

    def release(self):
        for r in (self.vao, self.vbo, self.prog):
            r.release()


def blas_on_one_thread():
    """A context in which numpy's BLAS runs on the calling thread alone, for benches that time the
    client's CPU. Between its calls OpenBLAS's worker threads keep spinning for a while, on every
    core: the process CPU time of whatever runs next is charged with that spinning, and llvmpipe
    loses the cores meanwhile. Measured in ``pibr bench stereo`` (dynamic scene, proxy): the first
    display after each tick's ground-truth maths cost 85 CPU-ms against 42 for the same view drawn
    after it; with BLAS on one thread both cost 42 (and mono against a pair read 1.06x instead of
    2.0x)."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")


class Simulation:
    """Server and client pipelines of one session in one process, on one GL context.

    Frames carry what the server's do, the moving objects' transforms included; ``poses`` is
    the client's history of them (every server frame's, shown or not), handed to the methods
    with ``oracle_pose`` (the scene's animation, for proxy's ``motion="oracle"``)."""

    def __init__(self, scene, server=None, out_size=(960, 540), fov_deg=90.0, proxies=None, ctx=None,
                 keep_distances=False, flow_frames=False, moving_truth=False, depth_streams=None):
        """server: the server's settings (:class:`~pibr.server.config.ServerConfig`; default
        :func:`bench_server_config`); depth_streams: a callable (session, fps) -> an object with
        ``encode(produced)`` -> [(kind, bytes)], ``decode(frame)`` -> {view: distance} and
        ``close()`` that carries depth instead of the edge codec (the server's depth codec must be
        ``edge``: no depth in the atlas), e.g. a ``depth_codecs.ViewDepthStreams`` of a competing
        codec; keep_distances: keep the views' true distances (:attr:`distances`, for geometric
        holes); flow_frames: decode each frame's motion flow and hand the textures a FlowFrame, for
        methods with ``motion="flow"``; moving_truth: the ground truth also says which moving object
        each pixel shows (:meth:`ground_truth_moving`)."""
        from pibr.client.depth_decoders import make_depth_decoder
        from pibr.client.frame_textures import FrameTextures
        from pibr.client.output_target import OutputTarget
        from pibr.client.video import H264Decoder
        from pibr.common.gl import create_context
        from pibr.protocol.depth_codecs import DEPTH_CODECS
        from pibr.server.pipeline import SessionPipeline
        from pibr.server.render_target import RenderTarget

        server = server if server is not None else bench_server_config()
        if depth_streams is not None and DEPTH_CODECS[server.depth_codec].in_atlas:
            raise ValueError("depth_streams replace the edge codec's streams: use depth_codec='edge'")
        self.ctx = ctx or create_context()
        self.scene, self.server, self.fps = scene, server, server.fps
        info = {"objects": len(proxies)} if proxies else None
        self.pipeline = SessionPipeline(server, scene, Hello(want_proxies=bool(proxies)), info, deterministic=True,
                                        keep_distance=keep_distances, depth_encoder=depth_streams).open(self.ctx)
        self.session, self.spec = self.pipeline.session, self.pipeline.spec
        self.renderer = self.pipeline.renderer
        self._depth_streams = depth_streams is not None
        self._depth_of_its_own = not DEPTH_CODECS[self.session.depth_codec].in_atlas   # payloads, not the atlas
        self.depth_decoder = self.pipeline.depth if self._depth_streams else make_depth_decoder(self.session)
        self.decoder = H264Decoder(self.spec.layout.width, self.spec.layout.height)
        self.textures = FrameTextures(self.ctx, self.session)
        self.output = OutputConfig(out_size[0], out_size[1], fov_deg, 60.0)
        self.target = OutputTarget(self.ctx, *out_size)
        self._pair_target = None   # both eyes side by side (display_pair_timed), made when first used
        self.gt = RenderTarget(self.ctx, *out_size, motion=moving_truth)
        self.proxies = proxies
        self._last_render = None
        self.distances = {}    # the newest frame's true distance maps (keep_distances)
        self._quadtrees = {}   # threshold -> the newest frame's quadtree payload
        self._oracle = None    # (encoder, decoder, textures) of the zero-latency stream
        self.bytes = []        # H.264 bytes per frame
        self.depth_bytes = []  # depth bytes per frame (edge codec or depth_streams)
        self.pose_bytes = []   # OBJECT_POSES bytes per frame (scenes that move)
        self.flow_bytes = []   # MOTION_FLOW bytes per frame (scenes that move)
        self.server_cpu_ms = []  # per frame: process CPU ms of render, pack and every encoder
        self.flow = None       # the newest frame's decoded (flow (h, w, 2), moving (h, w)), with flow_frames
        self.true_flow = None  # ... and the renderer's own (flow, moving) before coding
        self.motion_decoder = None
        self.flow_decode_ms = []    # per frame with flow_frames: MOTION_FLOW decode (and diffusion)
        self.flow_prepare_ms = []   # ... and the FlowFrame's background fill
        if flow_frames and scene.is_dynamic:
            from pibr.client.motion_flow import MotionFlowDecoder

            self.motion_decoder = MotionFlowDecoder(*self.spec.primary_size)
        # Moving objects' transforms as a client receives them: from every server frame, including
        # those the display's stride never shows (a client receives them all).
        self.poses = None
        if scene.is_dynamic:
            from pibr.client.object_motion import PoseHistory

            rest = [o.transform for o in scene.objects]
            bounds = [o.mesh.bounds().astype(np.float64) for o in scene.objects]
            self.poses = PoseHistory(np.stack(rest), np.stack(bounds))

    def frame_at(self, t_render: float, pose):
        """Make (and decode, upload) the server frame rendered at ``t_render`` from ``pose``."""
        cache_key = (t_render, pose.as_array().tobytes())
        if self._last_render is not None and cache_key == self._last_render[0]:
            return self._last_render[1]
        frame, distances = self.serve(t_render, pose)
        self.receive(frame, distances)
        self._last_render = (cache_key, frame)
        return frame

    def serve(self, t_render: float, pose):
        """The server's half: render, pack and encode the frame rendered at ``t_render`` from
        ``pose`` -> (Frame, its views' true distances {view: (h, w)} when kept). Frames must be
        received (:meth:`receive`) in the order they were served."""
        c0 = time.process_time()
        p = self.pipeline.produce(pose, t_render, frame_id=len(self.bytes))
        encoded = self.pipeline.encode(p)
        self.server_cpu_ms.append((time.process_time() - c0) * 1e3)
        self.bytes.append(len(encoded.video))
        if self._depth_of_its_own:
            self.depth_bytes.append(sum(len(d) for _, d in encoded.depth))
        if encoded.object_poses is not None:
            self.pose_bytes.append(len(encoded.object_poses))
        if encoded.motion is not None:
            self.flow_bytes.append(len(encoded.motion))
            self.true_flow = (p.motion, p.moving)
        us = int(round(t_render * 1e6))
        frame = self.pipeline.frame(len(self.bytes) - 1, us, us, 0, p, encoded)
        return frame, p.distances

    def frame_bits(self, index: int = -1) -> int:
        """Bits of colour, depth and motion (poses, flow) of served frame ``index``."""
        total = self.bytes[index]
        for series in (self.depth_bytes, self.pose_bytes, self.flow_bytes):
            if series:
                total += series[index]
        return 8 * total

    def receive(self, frame, distances=None, textures=None) -> None:
        """The client's half: decode ``frame`` and upload it as the newest. ``distances``: the
        frame's true distances (from :meth:`serve`), kept as ``self.distances`` for geometric holes;
        ``textures``: the FrameTextures to upload to (default :attr:`textures`; a stereo client keeps
        one set per eye)."""
        t_render = frame.render_t_us / 1e6
        if distances is not None:
            self.distances = distances
            self._quadtrees = {}
        poses = frame.payload(PayloadKind.OBJECT_POSES)
        if poses is not None:
            self._receive_poses(t_render, poses)
        data = frame.payload(PayloadKind.H264_ATLAS)
        distances = self.depth_decoder.decode(frame)
        image = self.decoder.decode(data)
        flow_frame = None
        if self.motion_decoder is not None:
            from pibr.client.frame_textures import primary_flow_frame

            t0 = time.perf_counter()
            self.flow = self.motion_decoder.decode(frame.payload(PayloadKind.MOTION_FLOW))
            t1 = time.perf_counter()
            flow_frame = primary_flow_frame(self.session, image, distances, *self.flow, t_render)
            self.flow_decode_ms.append((t1 - t0) * 1e3)
            self.flow_prepare_ms.append((time.perf_counter() - t1) * 1e3)
        (textures or self.textures).upload(image, frame, distances, flow_frame)

    def restart_stream(self) -> None:
        """A new session's stream: fresh encoders and decoders (the next frame is a keyframe);
        renderer, textures and methods are kept."""
        from pibr.client.depth_decoders import make_depth_decoder
        from pibr.client.video import H264Decoder

        self.pipeline.restart_stream()
        self.decoder = H264Decoder(self.spec.layout.width, self.spec.layout.height)
        if not self._depth_streams:
            self.depth_decoder.close()
            self.depth_decoder = make_depth_decoder(self.session)
        else:
            self.depth_decoder = self.pipeline.depth
        self._last_render = None
        self.distances = {}

    def _receive_poses(self, t_render: float, payload: bytes) -> None:
        """Feed the pose history with the frames of the server's ticks up to ``t_render``: those the
        display skipped (from the scene, as the server makes them) and this one (its payload)."""
        from pibr.client.object_motion import HISTORY
        from pibr.protocol.object_poses import decode_object_poses
        from pibr.server.object_poses import object_poses_at

        interval = 1.0 / self.fps
        newest = self.poses.newest_time
        if newest is not None and abs(newest - t_render) < 1e-9:   # a second frame of the tick (stereo per-eye)
            return
        if newest is None or newest >= t_render:   # a new timeline: the frames before it, as a pre-roll
            newest = t_render - HISTORY * interval
        k0 = int(math.floor(newest / interval + 1e-6)) + 1
        for k in range(k0, int(round(t_render / interval))):
            self.poses.add(k * interval, object_poses_at(self.scene, k * interval))
        self.poses.add(t_render, decode_object_poses(payload, len(self.scene.objects)))

    def oracle_pose(self, index: int, t: float) -> np.ndarray:
        """The scene's animation: object ``index``'s (4, 4) motion at scene time ``t`` (the
        ``oracle`` extrapolation; a benchmark's knowledge, never a client's)."""
        return self.scene.objects[index].animation.matrix(t)

    def with_quadtree(self, frame, threshold: float):
        """``frame`` with the views' quadtrees at ``threshold`` attached, as a server sends them to a
        client that asked (built from the newest frame's true distances: keep_distances)."""
        import dataclasses

        from pibr.server.quadtree import quadtree_payload

        if not self.distances:
            raise ValueError("quadtrees need the views' distances: make the Simulation with keep_distances=True")
        if threshold not in self._quadtrees:
            self._quadtrees[threshold] = quadtree_payload(self.distances, threshold)
        payloads = tuple(p for p in frame.payloads if p[0] != PayloadKind.QUADTREE)
        return dataclasses.replace(frame, payloads=payloads + ((PayloadKind.QUADTREE, self._quadtrees[threshold]),))

    def oracle_frame(self, t: float, pose, rate_hz: float):
        """The zero-latency oracle: the server's frame rendered at the display pose itself, through
        the same colour codec (its own H.264 stream of frames ``rate_hz`` apart, at the bits per
        frame of the session's stream). -> (Frame, its textures); show it with ``none``."""
        from pibr.client.frame_textures import FrameTextures
        from pibr.client.video import H264Decoder
        from pibr.protocol.messages import Frame

        if self._oracle is None:
            w, h = self.spec.layout.width, self.spec.layout.height
            kbps = self.server.bitrate_kbps * rate_hz / self.fps
            self._oracle = (self.pipeline.new_video_encoder(rate_hz, kbps), H264Decoder(w, h),
                            FrameTextures(self.ctx, self.session))
        encoder, decoder, textures = self._oracle
        p = self.pipeline.produce(pose, t)
        data, key = encoder.encode(p.yuv)
        us = int(round(t * 1e6))
        frame = Frame(decoder.frames, us, us, 0, us, p.primary_pose, p.extra_pose, self.scene.near, self.scene.far,
                      payloads=((PayloadKind.H264_ATLAS, data),), keyframe=key)
        textures.upload(decoder.decode(data), frame)
        return frame, textures

    def make_method(self, name, **options):
        from pibr.client.methods import make_method

        if name == "floor":
            return FloorPass(self.ctx, self.output, self.session)
        options = {"poses": self.poses, "oracle_pose": self.oracle_pose, **options}
        return make_method(name, self.ctx, self.output, self.session, proxies=self.proxies, **options)

    def display(self, method, pose, frame, scene_t, textures=None):
        """-> (rgb (h, w, 3), hole fraction, ms of the display pass). A method that needs quadtrees
        gets the frame with them attached if it has none (the server's work, not timed)."""
        if getattr(method, "needs_quadtree", False) and frame.payload(PayloadKind.QUADTREE) is None:
            frame = self.with_quadtree(frame, method.threshold)
        self.target.begin()
        t0 = time.perf_counter()
        method.render(pose, frame, textures or self.textures, scene_t)
        self.ctx.finish()
        ms = (time.perf_counter() - t0) * 1e3
        rgba = self.target.read()
        return rgba[:, :, :3].copy(), float(np.mean(rgba[:, :, 3] == 0)), ms

    def display_timed(self, method, pose, frame, t, textures=None):
        """:meth:`display` and the process CPU ms it took -> (rgb, hole fraction, ms, CPU ms)."""
        c0 = time.process_time()
        rgb, own, ms = self.display(method, pose, frame, t, textures)
        return rgb, own, ms, (time.process_time() - c0) * 1e3

    def display_pair_timed(self, method, left, right, frame, t, textures=None):
        """Both eyes at once (a method whose ``shares_pair(left, right)``: its ``render_pair``) ->
        per eye (left, right) (rgb (h, w, 3), hole fraction), and the process CPU ms of the pair."""
        if self._pair_target is None:
            from pibr.client.output_target import OutputTarget

            self._pair_target = OutputTarget(self.ctx, 2 * self.output.width, self.output.height)
        c0 = time.process_time()
        self._pair_target.begin()
        method.render_pair(left, right, frame, textures or self.textures, t)
        self.ctx.finish()
        rgba = self._pair_target.read()
        w = self.output.width
        eyes = [(rgba[:, half, :3].copy(), float(np.mean(rgba[:, half, 3] == 0)))
                for half in (slice(0, w), slice(w, 2 * w))]
        return eyes, (time.process_time() - c0) * 1e3

    def ground_truth(self, pose, t, frustum=None):
        """(h, w, 3) uint8 ground truth at ``pose`` and scene time ``t`` (through ``frustum``, an
        eye's (left, right, down, up) tangents, when given)."""
        self.renderer.render_perspective(self.gt, pose, t, self.output.fov_deg, frustum)
        return self.gt.read_color().copy()

    def ground_truth_moving(self) -> np.ndarray:
        """(h, w) int32 scene index of the moving object each pixel of the last ground truth shows,
        -1 elsewhere (a Simulation made with moving_truth=True)."""
        if self.gt.motion is None:
            raise ValueError("make the Simulation with moving_truth=True")
        return self.gt.read_moving_index()

    def ground_truth_distance(self) -> np.ndarray:
        """(h, w) float32 radial distance of the last ground truth rendered (0 = sky)."""
        return self.gt.read_distance().copy()

    def close(self):
        self.depth_decoder.close()
        if self._oracle is not None:
            self._oracle[0].close()
            self._oracle[2].release()
        self.pipeline.release()
        self.textures.release()
        self.target.release()
        if self._pair_target is not None:
            self._pair_target.release()
        self.gt.release()


def load_proxies(scene, progress=False, settings=None):
    """The scene's proxies as a client receives them: (list of ProxyObject, the server's bundle);
    ``settings``: the server's ProxySettings (None: its defaults)."""
    from pibr.protocol.proxy import decode_bundle, decompress_bundle
    from pibr.server.proxies import ProxySettings, build_bundle

    bundle = build_bundle(scene, settings or ProxySettings(), progress=progress)
    return decode_bundle(decompress_bundle(bundle.compressed, bundle.raw_bytes)), bundle


def evaluate_methods(sim: Simulation, samples, variants: dict, with_quality=True, bar=None) -> dict:
    """variants: label -> (method name, options). -> label -> per-tick lists of metrics.

    Every method first draws the first sample once, untimed: a first use pays for shader
    compilation and buffer set-up, which would otherwise count against whichever method
    happens to run first."""
    methods = {label: sim.make_method(name, **opts) for label, (name, opts) in variants.items()}
    out = {label: {"psnr": [], "ssim": [], "dssim": [], "holes": [], "ms": [], "triangles": [], "uniform": []}
           for label in variants}
    try:
        if samples:
            t_disp, display, t_render, rendered = samples[0]
            frame = sim.frame_at(t_render, rendered)
            for m in methods.values():
                sim.display(m, display, frame, t_disp)
        for t_disp, display, t_render, rendered in samples:
            frame = sim.frame_at(t_render, rendered)
            gt = sim.ground_truth(display, t_disp) if with_quality else None
            uniform = gt is not None and nearly_uniform(gt)
            for label, m in methods.items():
                rgb, holes, ms = sim.display(m, display, frame, t_disp)
                r = out[label]
                r["ms"].append(ms)
                r["holes"].append(holes)
                r["triangles"].append(getattr(m, "last_primitives", 0))
                r["uniform"].append(uniform)
                if gt is not None:
                    s = ssim(gt, rgb)
                    r["psnr"].append(psnr(gt, rgb))
                    r["ssim"].append(s)
                    r["dssim"].append(dssim(s))
            if bar is not None:
                bar.update(1)
    finally:
        for m in methods.values():
            m.release()
    return out


def summarize(series: dict) -> dict:
    def mean(k):
        return float(np.mean(series[k])) if series[k] else None

    return {"psnr_mean": mean("psnr"), "ssim_mean": mean("ssim"), "dssim_mean": mean("dssim"),
            "hole_fraction_mean": mean("holes"), "client_ms_median": float(np.median(series["ms"])),
            "triangles_mean": mean("triangles"), "frames": len(series["ms"]),
            "nearly_uniform_frames": int(sum(series.get("uniform", [])))}


def geometric_holes(rays, pose, gt_distance, frame, distances, peeled_marked: bool) -> dict:
    """Geometric hole fraction of the displayed view for the primary view alone and for both."""
    points, sky, dirs = displayed_points(rays, pose, gt_distance)
    views = [(frame.primary_pose, distances["primary"], False)]
    if "extra" in distances and frame.extra_pose is not None:
        views.append((frame.extra_pose, distances["extra"], True))
    masks = uncovered_by_views(points, sky, dirs, views, peeled_marked=peeled_marked)   # the primary tested once
    return {"primary": float(masks[0].mean()), "both": float(masks[-1].mean())}
