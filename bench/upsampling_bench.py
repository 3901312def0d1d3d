"""``pibr bench upsampling``: colour sent at a quarter of the pixels and rebuilt on the client.

Pajak et al. 2011 (Sec. 3.3, Fig. 2) lower the server's load by sending colour at half the
width and height, jittered from frame to frame, with depth whole; the client rebuilds the whole
colour from the new samples and its previous result reprojected with depth
(client/colour_rebuild.py). This measures that lever alone, the same frames through three
streams that take turns frame by frame:

* ``whole``: colour at scale 1 (the reference stream), at the server's bitrate;
* ``quarter``: colour at scale 0.5 at the same bitrate (equal bits: a like-for-like codec test);
* ``quarter-bits``: colour at scale 0.5 at a quarter of the bitrate (equal bits per pixel: the
  bandwidth the lever saves).

Per stream: the server's ms per frame by stage (render, readback, pack, H.264; process CPU time
for the codec stages), bits per second, and the client's rebuild ms; per frame, the primary and
extra views' colour as the methods read it, PSNR and DSSIM against the views' whole colour as
rendered before any coding; and, for the scaled streams, the plain bilinear upscaling of the same
low-resolution frame beside the rebuild. Sequences: every window's first pose held still for
``still_frames`` frames (the rebuild converges: every pixel is sent once in four frames), then
``moving_s`` seconds of each window at the server's frame rate.

Every stream is drawn by the same renderer in the same run, so the ratios compare; the times are
this machine's.
"""
from __future__ import annotations

import sys
import time

import numpy as np

from .metrics import dssim, psnr, ssim
from .results import write_result
from .simulation import BENCH_VIEW_SIZE, bench_server_config
from .windows import EVALUATION_WINDOWS, windows_json

#: (name, colour scale, bitrate factor) of the streams compared.
STREAMS = (("whole", 1.0, 1.0), ("quarter", 0.5, 1.0), ("quarter-bits", 0.5, 0.25))

#: Goals of issue 25 (benchmarks, not timed tests).
GOALS = {
    "colour_cost_ratio_max": 0.6,          # server colour ms (pack + H.264) at a quarter of the pixels / whole
    "still_psnr_gap_db_max": 1.0,          # rebuilt after 4 still frames vs whole, equal bitrate
    "moving_psnr_over_bilinear_db_min": 2.0,
}

_READ_FS = """
#version 410
%(frame_glsl)s
uniform vec4 u_rect;         // rect_uniform(config, "<view>.color"): what the methods read
uniform vec4 u_low_rect;     // the view's colour in the atlas
uniform vec2 u_size;         // the view's whole size
uniform ivec2 u_jitter;
uniform bool u_bilinear;     // upscale the frame's low-resolution colour bilinearly instead
out vec4 f_color;
void main() {
    vec2 q = gl_FragCoord.xy - 0.5;     // this pixel of the view, row 0 on top
    vec3 c;
    if (u_bilinear) {
        // luma sample s sits at pixel 2 s + jitter, chroma sample s at the centre of block 2 s + jitter
        vec2 j = vec2(u_jitter), low = u_low_rect.zw;
        vec2 y_at = u_low_rect.xy + clamp((q - j) / 2.0 + 0.5, vec2(0.5), low - 0.5);
        vec2 c_at = u_low_rect.xy / 2.0 + clamp((q - 2.0 * j - 0.5) / 4.0 + 0.5, vec2(0.5), low / 2.0 - 0.5);
        c = yuv_rgb(vec3(texture(u_atlas_y, y_at / u_atlas_size).r, texture(u_atlas_u, c_at / (u_atlas_size / 2.0)).r,
                         texture(u_atlas_v, c_at / (u_atlas_size / 2.0)).r));
    } else {
        c = atlas_rgb(u_rect, (q + 0.5) / u_size);
    }
    f_color = vec4(c, 1.0);
}
"""


class ViewReader:
    """Reads a view's colour as the methods see it, or a scaled frame's bilinear upscaling. GL thread."""

    def __init__(self, ctx, config):
        from pibr.client.frame_textures import bind_frame_uniforms, frame_glsl
        from pibr.client.methods.base import FULLSCREEN_VS, fullscreen_quad

        self.ctx, self.config = ctx, config
        self.prog = ctx.program(vertex_shader=FULLSCREEN_VS, fragment_shader=_READ_FS % {"frame_glsl": frame_glsl(config)})
        bind_frame_uniforms(self.prog, config)
        self.vbo, self.vao = fullscreen_quad(ctx, self.prog)
        self.targets = {}

    def read(self, view: str, frame_id: int, bilinear: bool = False) -> np.ndarray:
        """-> (h, w, 3) uint8 of ``view`` ("primary" or "extra") of the frame the textures hold (bound)."""
        from pibr.client.frame_textures import rect_uniform
        from pibr.protocol.atlas import colour_jitter

        size = self.config.primary if view == "primary" else self.config.extra
        w, h = size.width, size.height
        if view not in self.targets:
            tex = self.ctx.texture((w, h), 4)
            self.targets[view] = (tex, self.ctx.framebuffer(color_attachments=[tex]))
        tex, fbo = self.targets[view]
        fbo.use()
        self.ctx.disable(self.ctx.DEPTH_TEST | self.ctx.BLEND)
        low = self.config.atlas.rect(f"{view}.color")
        for name, value in (("u_rect", rect_uniform(self.config, f"{view}.color")),
                            ("u_low_rect", tuple(float(v) for v in low)), ("u_size", (float(w), float(h))),
                            ("u_jitter", colour_jitter(frame_id) if self.config.colour_scale != 1.0 else (0, 0)),
                            ("u_bilinear", bool(bilinear))):
            if name in self.prog:
                self.prog[name].value = value
        self.vao.render(self.ctx.TRIANGLE_STRIP)
        return np.frombuffer(fbo.read(components=3, alignment=1), np.uint8).reshape(h, w, 3)

    def release(self) -> None:
        for tex, fbo in self.targets.values():
            fbo.release()
            tex.release()
        for r in (self.vao, self.vbo, self.prog):
            r.release()


class _Stream:
    """One stream's server pipeline, decoders and client textures, sharing the scene's renderer."""

    def __init__(self, ctx, renderer, scene, server, settings):
        from pibr.client.depth_decoders import make_depth_decoder
        from pibr.client.frame_textures import FrameTextures
        from pibr.client.video import H264Decoder
        from pibr.protocol.messages import Hello
        from pibr.server.pipeline import SessionPipeline

        self.ctx = ctx
        self.pipeline = SessionPipeline(server, scene, Hello(), deterministic=True).open(ctx, renderer)
        self.session = self.pipeline.session
        self._make_decoders = lambda: (H264Decoder(self.session.atlas.width, self.session.atlas.height),
                                       make_depth_decoder(self.session))
        self.decoder, self.depth_decoder = self._make_decoders()
        self.textures = FrameTextures(ctx, self.session, settings)
        self.reader = ViewReader(ctx, self.session)
        self.frame_id = 0
        self.times = {"render_ms": [], "readback_ms": [], "pack_ms": [], "video_cpu_ms": [], "depth_cpu_ms": [],
                      "rebuild_ms": []}
        self.video_bytes = []

    def restart(self) -> None:
        """A new sequence: a fresh stream (keyframe first) and no history to rebuild from."""
        self.pipeline.restart_stream()
        self.depth_decoder.close()
        self.decoder, self.depth_decoder = self._make_decoders()
        if self.textures.rebuild is not None:
            self.textures.rebuild.reset()
        self.frame_id = 0

    def step(self, pose, t: float, keep_colour: bool):
        """Make, code, decode and upload the frame of ``pose`` -> its ProducedFrame."""
        from pibr.server.pipeline import EncodedFrame

        p = self.pipeline.produce(pose, t, frame_id=self.frame_id, keep_colour=keep_colour)
        c0 = time.process_time()
        video, key = self.pipeline.encode_video(p)
        c1 = time.process_time()
        depth = self.pipeline.encode_depth(p)
        c2 = time.process_time()
        encoded = EncodedFrame(video, key, depth, None, p.object_poses, self.pipeline.encode_motion(p))
        us = int(round(t * 1e6))
        frame = self.pipeline.frame(self.frame_id, us, us, 0, p, encoded)
        image = self.decoder.decode(video)
        distances = self.depth_decoder.decode(frame)
        self.ctx.finish()
        r0 = time.perf_counter()
        self.textures.upload(image, frame, distances)
        self.ctx.finish()
        rebuild_ms = (time.perf_counter() - r0) * 1e3
        for key_, value in (("render_ms", p.render_ms), ("readback_ms", p.readback_ms), ("pack_ms", p.pack_ms),
                            ("video_cpu_ms", (c1 - c0) * 1e3), ("depth_cpu_ms", (c2 - c1) * 1e3),
                            ("rebuild_ms", rebuild_ms)):
            self.times[key_].append(value)
        self.video_bytes.append(len(video))
        self.frame = frame
        self.frame_id += 1
        return p

    def views(self, bilinear: bool = False) -> dict:
        """view -> (h, w, 3) uint8 of the newest frame as the methods read it (or its bilinear upscaling)."""
        self.textures.use()
        names = ["primary"] + (["extra"] if self.session.extra is not None else [])
        return {v: self.reader.read(v, self.frame.frame_id, bilinear) for v in names}

    def release(self) -> None:
        self.reader.release()
        self.textures.release()
        self.pipeline.release()
        self.depth_decoder.close()


def _sequences(scene, windows, still_frames: int, moving_s: float, fps: float) -> list:
    """[(kind, window label, [poses])]: each window's first pose held, then its first ``moving_s`` seconds."""
    from pibr.common.replay import trace_poses

    out = []
    for w in windows:
        ticks, pose_at = trace_poses(scene, w.trace, w.start_s, min(moving_s, w.duration_s), fps)
        out.append(("still", w.label, [pose_at(0)] * still_frames))
        out.append(("moving", w.label, [pose_at(t) for t in ticks]))
    return out


def run_upsampling_bench(scene_spec="room", windows=None, still_frames: int = 8, moving_s: float = 3.0,
                         fps: float = 10.0, view_size=BENCH_VIEW_SIZE, depth_codec: str = "edge",
                         bitrate_kbps: float | None = None, settings=None, warm_frames: int = 4, stride: int = 1,
                         out_dir="out/bench", progress=True, result_name="upsampling.json") -> dict:
    """Every stream of :data:`STREAMS` over the sequences of ``windows`` (default: the evaluation
    windows); scores every frame of the still sequences and every ``stride``-th frame of the moving
    ones from frame ``warm_frames`` on. Writes ``out_dir/result_name``."""
    from dataclasses import asdict, replace

    from pibr.client.colour_rebuild import DEFAULT_SETTINGS
    from pibr.common.gl import create_context
    from pibr.scenes.registry import load_scene
    from pibr.server.renderer import Renderer

    windows = tuple(windows or EVALUATION_WINDOWS)
    settings = settings or DEFAULT_SETTINGS
    scene = load_scene(scene_spec)
    base = bench_server_config(view_size, fps=fps, depth_codec=depth_codec)
    if bitrate_kbps is not None:
        base = replace(base, bitrate_kbps=bitrate_kbps)
    ctx = create_context()
    renderer = Renderer(ctx, scene, base.projection, max_edge_angle_deg=base.max_edge_deg)
    streams = {name: _Stream(ctx, renderer, scene, replace(base, colour_scale=scale,
                                                           bitrate_kbps=base.bitrate_kbps * bits), settings)
               for name, scale, bits in STREAMS}
    sequences = _sequences(scene, windows, still_frames, moving_s, fps)
    scores = {kind: {name: {"rebuilt": [], "bilinear": []} for name, _, _ in STREAMS} for kind in ("still", "moving")}
    still_curve = {name: [[] for _ in range(still_frames)] for name, _, _ in STREAMS}
    total = sum(len(poses) for _, _, poses in sequences)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=total, unit="frame", desc="bench upsampling", file=sys.stderr, leave=False, disable=None)
    try:
        for kind, label, poses in sequences:
            for s in streams.values():
                s.restart()
            for k, pose in enumerate(poses):
                t = k / fps if kind == "moving" else 0.0
                truth = None
                for name, s in streams.items():
                    p = s.step(pose, t, keep_colour=truth is None)
                    truth = truth if truth is not None else p.colours
                scored = kind == "still" or (k >= warm_frames and (k - warm_frames) % stride == 0)
                if scored:
                    for name, s in streams.items():
                        rows = _score(truth, s.views())
                        if kind == "still":
                            still_curve[name][k].append(rows)
                        scores[kind][name]["rebuilt"].append(rows)
                        if s.session.colour_scale != 1.0:
                            scores[kind][name]["bilinear"].append(_score(truth, s.views(bilinear=True)))
                if bar is not None:
                    bar.update(1)
    finally:
        if bar is not None:
            bar.close()
        for s in streams.values():
            s.release()
        renderer.release()
        ctx.release()
    return _result(scene.name, windows, streams, scores, still_curve, settings, dict(
        still_frames=still_frames, moving_s=moving_s, fps=fps, view_size=list(view_size), depth_codec=depth_codec,
        bitrate_kbps=base.bitrate_kbps, warm_frames=warm_frames, stride=stride, settings=asdict(settings)), out_dir,
        result_name)


def _score(truth: dict, views: dict) -> dict:
    return {v: {"psnr": psnr(truth[v], img), "dssim": dssim(ssim(truth[v], img))} for v, img in views.items()}


def _mean(rows: list, view: str, key: str):
    values = [r[view][key] for r in rows if view in r]
    return float(np.mean(values)) if values else None


def _result(scene_name, windows, streams, scores, still_curve, settings, params, out_dir, result_name) -> dict:
    result = {"benchmark": "upsampling", "scene": scene_name, "windows": windows_json(windows, "reporting"),
              "settings": params, "goals": GOALS, "streams": {}}
    views = ["primary"] + (["extra"] if streams["whole"].session.extra is not None else [])
    for name, s in streams.items():
        times = {k: float(np.median(v)) for k, v in s.times.items() if v}
        times["colour_ms"] = times["pack_ms"] + times["video_cpu_ms"]
        times["server_ms"] = (times["render_ms"] + times["readback_ms"] + times["pack_ms"] + times["video_cpu_ms"]
                              + times["depth_cpu_ms"])
        entry = {"colour_scale": s.session.colour_scale, "video_kbps_setting": s.session.video_bitrate_kbps,
                 "atlas": [s.session.atlas.width, s.session.atlas.height], "times_ms_median": times,
                 "video_kbps": 8.0 * float(np.mean(s.video_bytes)) * params["fps"] / 1e3, "frames": len(s.video_bytes)}
        for kind in ("still", "moving"):
            entry[kind] = {v: {how: {"psnr_mean": _mean(rows, v, "psnr"), "dssim_mean": _mean(rows, v, "dssim")}
                               for how, rows in scores[kind][name].items() if rows} for v in views}
        entry["still_by_frame"] = {v: [{"psnr_mean": _mean(rows, v, "psnr"), "dssim_mean": _mean(rows, v, "dssim")}
                                       for rows in still_curve[name]] for v in views}
        result["streams"][name] = entry
    result["verdicts"] = _verdicts(result)
    write_result(out_dir, result_name, result)
    return result


def _verdicts(result: dict) -> list:
    s = result["streams"]
    whole, quarter = s["whole"], s["quarter"]
    out = []
    ratio = quarter["times_ms_median"]["colour_ms"] / whole["times_ms_median"]["colour_ms"]
    out.append({"goal": "server colour ms (pack + H.264; the views are still shaded whole) at a quarter of the "
                        "pixels / whole", "value": ratio,
                "target": f"<= {GOALS['colour_cost_ratio_max']}", "met": ratio <= GOALS["colour_cost_ratio_max"]})
    after = min(4, len(whole["still_by_frame"]["primary"])) - 1
    gap = whole["still_by_frame"]["primary"][after]["psnr_mean"] - quarter["still_by_frame"]["primary"][after]["psnr_mean"]
    out.append({"goal": f"primary view PSNR after {after + 1} still frames: whole minus rebuilt (equal bitrate)",
                "value": gap, "target": f"<= {GOALS['still_psnr_gap_db_max']} dB",
                "met": gap <= GOALS["still_psnr_gap_db_max"]})
    moving = quarter["moving"]["primary"]
    if "bilinear" in moving:
        lead = moving["rebuilt"]["psnr_mean"] - moving["bilinear"]["psnr_mean"]
        out.append({"goal": "primary view PSNR while the head moves: rebuilt minus bilinear (equal bitrate)",
                    "value": lead, "target": f">= {GOALS['moving_psnr_over_bilinear_db_min']} dB",
                    "met": lead >= GOALS["moving_psnr_over_bilinear_db_min"]})
    return out


def print_upsampling_table(r: dict) -> None:
    st = r["settings"]
    print(f"pibr bench upsampling: scene {r['scene']}, {st['view_size'][0]}x{st['view_size'][1]} primary view, "
          f"{st['depth_codec']} depth, {st['fps']:g} fps (times: this machine, this run)")
    print(f"\n{'stream':<13}{'scale':>6}{'kbps':>8}{'render':>8}{'pack':>7}{'H.264':>7}{'colour':>8}{'server':>8}"
          f"{'rebuild':>8}")
    for name, s in r["streams"].items():
        t = s["times_ms_median"]
        print(f"{name:<13}{s['colour_scale']:>6g}{s['video_kbps']:>8.0f}{t['render_ms']:>8.1f}{t['pack_ms']:>7.1f}"
              f"{t['video_cpu_ms']:>7.1f}{t['colour_ms']:>8.1f}{t['server_ms']:>8.1f}{t['rebuild_ms']:>8.1f}")
    print(f"\nprimary view against its whole colour before coding (PSNR dB / DSSIM):")
    print(f"{'stream':<13}{'still, rebuilt':>18}{'moving, rebuilt':>18}{'moving, bilinear':>18}")
    for name, s in r["streams"].items():
        def cell(kind, how):
            m = s[kind]["primary"].get(how)
            return f"{m['psnr_mean']:.2f} / {m['dssim_mean']:.4f}" if m else "-"

        print(f"{name:<13}{cell('still', 'rebuilt'):>18}{cell('moving', 'rebuilt'):>18}{cell('moving', 'bilinear'):>18}")
    print("\nstill frames, primary PSNR by frame:")
    for name, s in r["streams"].items():
        print(f"  {name:<13}" + " ".join(f"{x['psnr_mean']:.2f}" for x in s["still_by_frame"]["primary"]))
    for v in r["verdicts"]:
        print(f"goal: {v['goal']}: {v['value']:.3f} (target {v['target']}): {'met' if v['met'] else 'NOT met'}")
