"""``pibr bench server`` and ``pibr bench client``: ms per frame by stage, and bitrate.

Both run the real pipeline in one process (no sockets, so the numbers are the stages'
own cost): the server's session pipeline (server/pipeline.py: renderer, atlas packer, libx264
and, as a session of that scene needs, the depth and motion encoders) along a real head
trace; the client's H.264 decoder, texture upload and each method's display pass on the
stream the server pipeline produced. Timings here are noisy: compare within one run.
"""
from __future__ import annotations

import time

import numpy as np

from pibr.protocol.messages import Hello, OutputConfig, PayloadKind

from .results import write_result
from .simulation import BENCH_VIEW_SIZE, bench_server_config


def _poses(scene, trace_spec: str, count: int, fps: float, start_s: float = 10.0):
    from pibr.common.traces.loading import load_trace
    from pibr.common.traces.placement import placement

    trace = load_trace(trace_spec)
    start = min(start_s, max(0.0, trace.duration - count / fps))
    origin = placement(trace, start, scene.viewer_origin)
    return [(start + k / fps, origin.compose(trace.pose_at(start + k / fps))) for k in range(count)]


def _median(xs) -> float:
    return float(np.median(xs)) if len(xs) else float("nan")


def _distance_disagreement(reference: np.ndarray, distance: np.ndarray, tolerance: float = 0.01) -> float:
    """Fraction of pixels whose distance is more than ``tolerance`` (relative) off the reference,
    or sky (0) in one of the two images only. Both (h, w) float."""
    sky_r, sky_d = reference <= 0, distance <= 0
    off = np.abs(distance - reference) > tolerance * np.maximum(reference, 1e-9)
    return float(np.mean((sky_r != sky_d) | (~sky_r & ~sky_d & off)))


#: Edge angle of the reference render that ``--max-edge-deg`` variants are compared with.
REFERENCE_EDGE_DEG = 2.0


def bench_server(scene_spec="room", trace="pred6dof-1", frames=40, view_size=BENCH_VIEW_SIZE,
                 projections=("vertex", "tess"), extra_view="auto", bitrate_kbps=16000.0, out_dir="out/bench",
                 fps=10.0, edge_angles=None, lod=(True,), accuracy=False, cube_scale=0.75) -> dict:
    """Server ms per frame by stage and bitrate, per projection, edge angle, LOD and extra view.

    ``lod``: draw each object's pre-tessellated copy for the eye's distance (True) or the copy for
    the whole viewing region (False); several to compare. With ``accuracy``, several
    ``edge_angles`` or ``lod`` settings, or an edge angle that is not the default, each variant's
    primary view is also compared with a vertex-projection render at :data:`REFERENCE_EDGE_DEG`
    (whole-region copies): colour PSNR and the fraction of pixels whose distance is more than
    1 % off (or sky on one side only). ``cube_scale``: face size of projection "cube" as a
    fraction of the view width (server/cube_faces.py).
    """
    from pibr.common.gl import create_context
    from pibr.scenes.registry import load_scene
    from pibr.server.pipeline import SessionPipeline
    from pibr.server.render_target import RenderTarget
    from pibr.server.renderer import MAX_EDGE_ANGLE_DEG, Renderer

    from .metrics import psnr

    scene = load_scene(scene_spec)
    poses = _poses(scene, trace, frames + 3, fps)
    ctx = create_context()
    extras = ["off", "on"] if extra_view == "both" else [extra_view]
    edge_angles = tuple(edge_angles or (MAX_EDGE_ANGLE_DEG,))
    reference = None
    lod = tuple(lod)
    if accuracy or edge_angles != (MAX_EDGE_ANGLE_DEG,) or len(lod) > 1:
        reference = (Renderer(ctx, scene, "vertex", max_edge_angle_deg=REFERENCE_EDGE_DEG, lod=False),
                     RenderTarget(ctx, *view_size))
    rows = []
    for projection, angle in ((p, a) for p in projections for a in edge_angles):
        t0 = time.perf_counter()
        renderer = Renderer(ctx, scene, projection, max_edge_angle_deg=angle, cube_scale=cube_scale)
        setup_s = time.perf_counter() - t0
        for use_lod, extra in ((u, e) for u in lod for e in extras):
            renderer.lod = use_lod
            cfg = bench_server_config(view_size, scene=scene_spec, extra_view=extra, projection=projection,
                                      bitrate_kbps=bitrate_kbps, fps=fps, max_edge_deg=angle)
            pipeline = SessionPipeline(cfg, scene, Hello(), deterministic=True).open(ctx, renderer)
            spec = pipeline.spec
            stages = {"render": [], "readback": [], "pack": [], "encode": []}
            sizes, totals, keys = [], [], []   # H.264 bytes, every payload's, keyframe or not
            accuracy = {"psnr": [], "off": []}
            for i, (t, pose) in enumerate(poses):
                p = pipeline.produce(pose, t)
                te = time.perf_counter()
                encoded = pipeline.encode(p)
                encode_ms = (time.perf_counter() - te) * 1e3
                if i < 3:
                    continue  # warm-up: shader compilation, encoder start
                if reference is not None and extra == extras[0]:
                    ref_renderer, ref_target = reference
                    ref_renderer.render_wide(ref_target, pose, t)
                    accuracy["psnr"].append(psnr(ref_target.read_color(), pipeline.producer.primary.read_color()))
                    accuracy["off"].append(_distance_disagreement(ref_target.read_distance(),
                                                                  pipeline.producer.primary.read_distance()))
                stages["render"].append(p.render_ms)
                stages["readback"].append(p.readback_ms)
                stages["pack"].append(p.pack_ms)
                stages["encode"].append(encode_ms)
                sizes.append(len(encoded.video))
                totals.append(encoded.nbytes)
                keys.append(encoded.keyframe)
            pipeline.release()
            total = [sum(v) for v in zip(*stages.values())]
            rows.append({
                "projection": projection, "max_edge_deg": angle, "lod": use_lod,
                "cube_scale": cube_scale if projection == "cube" else None,
                "extra_view": spec.extra_size is not None,
                "psnr_vs_reference_db": _median(accuracy["psnr"]) if accuracy["psnr"] else None,
                "distance_off_fraction": float(np.mean(accuracy["off"])) if accuracy["off"] else None,
                "view_size": list(view_size), "atlas": [spec.layout.width, spec.layout.height],
                **{f"{k}_ms": _median(v) for k, v in stages.items()}, "total_ms": _median(total),
                "kbps": float(np.mean(sizes) * 8 * fps / 1000), "frame_bytes_mean": float(np.mean(sizes)),
                "total_kbps": float(np.mean(totals) * 8 * fps / 1000),   # with depth, poses and motion
                "keyframe_bytes": float(np.mean([s for s, k in zip(sizes, keys) if k])) if any(keys) else None,
                "triangles": scene.triangle_count, "rasterised_triangles":
                    renderer.tessellated_triangles if projection == "vertex" else scene.triangle_count,
                "renderer_setup_s": setup_s, "frames": len(total),
            })
        renderer.release()
    if reference is not None:
        reference[0].release()
        reference[1].release()
    ctx.release()
    result = {"scene": scene.name, "trace": trace, "fps": fps, "bitrate_target_kbps": bitrate_kbps,
              "reference_edge_deg": REFERENCE_EDGE_DEG if reference is not None else None, "rows": rows}
    write_result(out_dir, "bench_server.json", result)
    return result


def print_server_table(result: dict) -> None:
    print(f"pibr bench server: scene {result['scene']}, {result['fps']:g} fps, target "
          f"{result['bitrate_target_kbps']:g} kbit/s (median ms per frame)")
    accuracy = result.get("reference_edge_deg") is not None
    head = f"{'projection':>10} {'edge':>5} {'lod':>3} {'extra':>5} {'atlas':>9} {'render':>7} {'readback':>8} {'pack':>6} " \
           f"{'encode':>7} {'total':>7} {'kbit/s':>8} {'triangles':>10}"
    if accuracy:
        head += f" {'PSNR ref':>8} {'>1% off':>8}"
    print(head)
    print("-" * len(head))
    for r in result["rows"]:
        name = r["projection"] + (f"@{r['cube_scale']:g}" if r.get("cube_scale") else "")
        line = (f"{name:>10} {r.get('max_edge_deg', 0):4g}° {('on' if r.get('lod') else 'off'):>3} "
                f"{('on' if r['extra_view'] else 'off'):>5} "
                f"{r['atlas'][0]:>4}x{r['atlas'][1]:<4} {r['render_ms']:7.1f} {r['readback_ms']:8.1f} "
                f"{r['pack_ms']:6.1f} {r['encode_ms']:7.1f} {r['total_ms']:7.1f} {r['kbps']:8.0f} "
                f"{r['rasterised_triangles']:>10}")
        if accuracy and r["psnr_vs_reference_db"] is not None:
            line += f" {r['psnr_vs_reference_db']:8.2f} {100 * r['distance_off_fraction']:7.3f}%"
        print(line)
    if accuracy:
        print(f"PSNR ref, >1% off: primary view against a vertex-projection render with "
              f"{result['reference_edge_deg']:g}° edges (colour PSNR; pixels whose distance is more than 1 % off)")
    print("triangles: pre-tessellated for an eye anywhere in the viewing region; with lod on, each object "
          "is drawn from a coarser copy when the eye is farther from it")


def bench_client(scene_spec="room", trace="pred6dof-1", frames=40, view_size=BENCH_VIEW_SIZE, out_size=(960, 540),
                 methods=("none", "rotation"), out_dir="out/bench", fps=10.0, rate_hz=60.0,
                 extra_view="auto") -> dict:
    from pibr.client.frame_textures import FrameTextures
    from pibr.client.methods import make_method
    from pibr.client.output_target import OutputTarget
    from pibr.client.video import H264Decoder
    from pibr.common.gl import create_context
    from pibr.scenes.registry import load_scene
    from pibr.server.pipeline import SessionPipeline

    scene = load_scene(scene_spec)
    poses = _poses(scene, trace, frames, fps)
    ctx = create_context()
    cfg = bench_server_config(view_size, scene=scene_spec, extra_view=extra_view, fps=fps)
    pipeline = SessionPipeline(cfg, scene, Hello(), deterministic=True).open(ctx)
    session = pipeline.session
    stream = []
    for k, (t, pose) in enumerate(poses):
        p = pipeline.produce(pose, t)
        stream.append(pipeline.frame(k, int(t * 1e6), int(t * 1e6), k, p, pipeline.encode(p)))
    pipeline.release()

    out = OutputConfig(out_size[0], out_size[1], 90.0, rate_hz)
    decoder = H264Decoder(session.atlas.width, session.atlas.height)
    textures = FrameTextures(ctx, session)
    proxies = None
    from pibr.client.methods import needs_proxies

    if needs_proxies(methods):
        from .simulation import load_proxies

        proxies, _ = load_proxies(scene, progress=False)
    ms = [make_method(m, ctx, out, session, proxies=proxies) for m in methods]
    target = OutputTarget(ctx, *out_size)
    stages = {"decode": [], "upload": []}
    display = {m: [] for m in methods}
    readback = []
    ticks_per_frame = int(round(rate_hz / fps))
    for k, frame in enumerate(stream):
        t0 = time.perf_counter()
        image = decoder.decode(frame.payload(PayloadKind.H264_ATLAS))
        t1 = time.perf_counter()
        textures.upload(image, frame)
        ctx.finish()
        t2 = time.perf_counter()
        if k >= 2:
            stages["decode"].append((t1 - t0) * 1e3)
            stages["upload"].append((t2 - t1) * 1e3)
        for j in range(ticks_per_frame):
            t_out, pose = poses[min(k + 1, len(poses) - 1)]  # the display has moved on since the render
            for name, m in zip(methods, ms):
                target.begin()
                t3 = time.perf_counter()
                m.render(pose, frame, textures, t_out)
                ctx.finish()
                t4 = time.perf_counter()
                target.read()
                t5 = time.perf_counter()
                if k >= 2:
                    display[name].append((t4 - t3) * 1e3)
                    readback.append((t5 - t4) * 1e3)
    for m in ms:
        m.release()
    textures.release()
    target.release()
    ctx.release()
    result = {"scene": scene.name, "atlas": [session.atlas.width, session.atlas.height],
              "output": list(out_size), "rate_hz": rate_hz, "fps": fps,
              "decode_ms": _median(stages["decode"]), "upload_ms": _median(stages["upload"]),
              "display_ms": {m: _median(v) for m, v in display.items()}, "readback_ms": _median(readback),
              "frames": len(stages["decode"])}
    write_result(out_dir, "bench_client.json", result)
    return result


def print_client_table(result: dict) -> None:
    print(f"pibr bench client: atlas {result['atlas'][0]}x{result['atlas'][1]}, output "
          f"{result['output'][0]}x{result['output'][1]} (median ms)")
    print(f"  per server frame ({result['fps']:g}/s): decode {result['decode_ms']:.1f}, "
          f"upload {result['upload_ms']:.1f}")
    for m, v in result["display_ms"].items():
        print(f"  per output tick ({result['rate_hz']:g}/s): display '{m}' {v:.1f}")
    print(f"  read back for recording (not part of display): {result['readback_ms']:.1f}")
