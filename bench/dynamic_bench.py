"""``pibr bench dynamic``: moving objects brought to the display time, method by method.

What a client can do about objects that moved since the server rendered its newest frame,
measured against ground truth (the full scene at the display pose *and* time) on scenes that
move (``dynamic``, and the ``room`` with its fan and pendulum), at several round trips:

* ``proxy`` with each ``--motion`` mode: ``static`` (where the newest frame saw the objects, a
  lower bound), ``velocity`` and ``accel`` (the objects' transforms on the wire extrapolated),
  ``flow`` (Pajak et al.'s per-pixel warp along the decoded motion flow) and ``oracle`` (the
  scene's own animation, which no real client has: the upper bound);
* ``rotation`` without and with ``flow``: the flow warp needs no proxy.

Scores per method and latency: DSSIM and PSNR over the whole frame and over the pixels of
moving objects only (a ground-truth mask of which moving object each pixel shows at the display
pose), client ms per displayed frame (the display pass, and for ``flow`` the per-frame motion
decode and background fill separately), motion bits per server frame (object poses, flow).

**Events.** Around a reversal (the pendulums' turning points) and a stop (the cart's), a fixed
head pose looks at the object and every tick is scored over that object's pixels: the plot
``dynamic.png`` shows each method's error over time there.

**Flow coding.** Every server frame's rendered flow is also coded with both flow coders
(protocol/motion_flow.py: ``blocks``, the mask plus 8 x 8 block means, and ``edges``, Pajak
et al.'s edge samples diffused on the client) and decoded: bits per frame and endpoint error
(pixels) against the renderer's flow over the moving pixels and over all pixels.

Windows default to parts of the evaluation windows of bench/windows.py (disjoint from every
tuning window); the event probes are synthetic fixed poses. Nothing here was tuned on them.
"""
from __future__ import annotations

import math
import sys
import time

import numpy as np

from pibr.common.link import SessionSchedule
from pibr.common.replay import display_samples

from .metrics import masked_metrics
from .results import write_result
from .windows import Window, windows_json

#: label -> (method, options)
VARIANTS = {
    "static": ("proxy", {"motion": "static"}),
    "velocity": ("proxy", {"motion": "velocity"}),
    "accel": ("proxy", {"motion": "accel"}),
    "flow": ("proxy", {"motion": "flow"}),
    "oracle": ("proxy", {"motion": "oracle"}),
    "rotation": ("rotation", {"motion": "static"}),
    "rotation+flow": ("rotation", {"motion": "flow"}),
}
DEFAULT_SCENES = ("dynamic", "room")
DEFAULT_LATENCIES = (64.0, 128.0, 256.0)
#: Parts of evaluation windows where the dynamic scene's moving objects are in view.
DEFAULT_WINDOWS = (Window("pred6dof-2", 50.0, 2.0), Window("synth-turns", 5.0, 2.0))
#: Seconds shown before and after an event.
EVENT_BEFORE, EVENT_AFTER = 0.5, 1.0


def motion_events(animation, t0: float, t1: float) -> list[tuple[float, str]]:
    """[(time, kind)] in [t0, t1] where an animation reverses (``swing``, ``slide``: kind
    "reversal") or stops and starts (``travel``: "stop", "start")."""
    out = []
    if animation.kind in ("swing", "slide") and animation.speed:
        w = abs(animation.speed)
        k = math.ceil(((t0 * w + animation.phase) - math.pi / 2) / math.pi)
        while True:
            t = (math.pi / 2 + k * math.pi - animation.phase) / w
            if t > t1:
                break
            if t >= t0:
                out.append((t, "reversal"))
            k += 1
    elif animation.kind == "travel":
        leg = animation.amplitude / animation.speed
        cycle = 2 * (leg + animation.rest)
        marks = ((animation.rest, "start"), (animation.rest + leg, "stop"), (2 * animation.rest + leg, "start"),
                 (cycle, "stop"))
        base = math.floor((t0 + animation.phase) / cycle) * cycle - animation.phase
        while base <= t1:
            for offset, kind in marks:
                if t0 <= base + offset <= t1:
                    out.append((base + offset, kind))
            base += cycle
    return out


def event_probes(scene, kinds=("reversal", "stop"), after: float = 1.5) -> list[dict]:
    """For each moving object with a reversal or a stop, its first such event after ``after``
    seconds: {object, index, kind, t, pose} with a fixed head pose at the scene's viewer origin
    looking at where the object is around then."""
    from pibr.protocol.pose import Pose

    eye = np.asarray(scene.viewer_origin.p, np.float64)
    out = []
    for i, o in enumerate(scene.objects):
        if not o.is_dynamic:
            continue
        events = [e for e in motion_events(o.animation, after, after + 10.0) if e[1] in kinds]
        if not events:
            continue
        t, kind = events[0]
        centre = np.mean([o.world_bounds(t + dt).mean(axis=0) for dt in np.linspace(-EVENT_BEFORE, EVENT_AFTER, 7)],
                         axis=0)
        out.append({"object": o.name, "index": i, "kind": kind, "t": t, "pose": Pose.look_at(eye, centre)})
    return out


def _event_samples(probe, rate_hz: float, schedule: SessionSchedule, stride: int = 1) -> list:
    tick = 1.0 / rate_hz
    n0, n1 = int(math.ceil((probe["t"] - EVENT_BEFORE) / tick)), int(math.floor((probe["t"] + EVENT_AFTER) / tick))
    out = []
    for n in range(n0, n1 + 1):
        t_us = int(round(n * tick * 1e6))
        render_us, _ = schedule.frame_for(t_us)
        out.append((t_us / 1e6, probe["pose"], render_us / 1e6, probe["pose"]))
    return out[::stride]


class _Series:
    """Per-method lists of per-sample values."""

    def __init__(self):
        self.values: dict = {}

    def add(self, label: str, **values) -> None:
        s = self.values.setdefault(label, {})
        for k, v in values.items():
            s.setdefault(k, []).append(v)

    def mean(self, label: str, key: str):
        vals = [v for v in self.values.get(label, {}).get(key, []) if v is not None and not np.isnan(v)]
        return float(np.mean(vals)) if vals else None


def _flow_coding(true_flow, coders, decoders, stats) -> None:
    """Code one frame's rendered flow with each coder, decode, and add bits and endpoint errors."""
    from pibr.protocol.motion_flow import encode_motion_flow

    flow, moving = true_flow
    truth = np.where(moving[..., None], flow, 0.0)
    for coder in coders:
        t0 = time.perf_counter()
        payload, _ = encode_motion_flow(flow, moving, coder)
        t1 = time.perf_counter()
        decoded, _ = decoders[coder].decode(payload)
        t2 = time.perf_counter()
        epe = np.linalg.norm(decoded - truth, axis=-1)
        s = stats.setdefault(coder, {"bits": [], "epe_moving_sum": 0.0, "moving_pixels": 0, "epe_all": [],
                                     "encode_ms": [], "decode_ms": [], "frames_moving": 0, "bits_moving": []})
        s["bits"].append(8 * len(payload))
        s["epe_all"].append(float(epe.mean()))
        s["encode_ms"].append((t1 - t0) * 1e3)
        s["decode_ms"].append((t2 - t1) * 1e3)
        if moving.any():
            s["frames_moving"] += 1
            s["bits_moving"].append(8 * len(payload))
            s["epe_moving_sum"] += float(epe[moving].sum())
            s["moving_pixels"] += int(moving.sum())


def _flow_summary(stats: dict) -> dict:
    out = {}
    for coder, s in stats.items():
        out[coder] = {"frames": len(s["bits"]), "frames_with_motion": s["frames_moving"],
                      "bits_per_frame": float(np.mean(s["bits"])),
                      "bits_per_frame_with_motion": float(np.mean(s["bits_moving"])) if s["bits_moving"] else None,
                      "epe_moving_px": s["epe_moving_sum"] / s["moving_pixels"] if s["moving_pixels"] else None,
                      "epe_all_px": float(np.mean(s["epe_all"])),
                      "encode_ms_median": float(np.median(s["encode_ms"])),
                      "decode_ms_median": float(np.median(s["decode_ms"]))}
    return out


class _Session:
    """One scene's session for a point: the simulation, every variant's method, the flow coders'
    decoders and their statistics over the frames this session made."""

    def __init__(self, worker, scene_spec, view_size, out_size, depth_codec, flow_coder, variants, warm_window):
        from pibr.client.motion_flow import MotionFlowDecoder
        from pibr.protocol.motion_flow import DEFAULT_FLOW_CODER, FLOW_CODERS

        from .simulation import Simulation, bench_server_config, load_proxies

        self.scene = scene = worker.scene(scene_spec)
        proxies = worker.cache("dynamic-proxies")
        if scene_spec not in proxies:
            proxies[scene_spec] = load_proxies(scene, progress=False)[0]
        server = bench_server_config(view_size, depth_codec=depth_codec, flow_coder=flow_coder or DEFAULT_FLOW_CODER)
        self.sim = Simulation(scene, server, out_size, proxies=proxies[scene_spec], ctx=worker.ctx, flow_frames=True,
                              moving_truth=True)
        self.coders = FLOW_CODERS
        self.decoders = {c: MotionFlowDecoder(*view_size) for c in FLOW_CODERS}
        self.flow_stats: dict = {}
        self.made: set = set()
        self.methods = {}
        try:
            self.methods = {label: self.sim.make_method(name, **opts) for label, (name, opts) in variants.items()}
            # warm-up: shader compilation and the kernels' first calls count against no method
            first = display_samples(scene, warm_window.trace, warm_window.start_s, 0.2,
                                    SessionSchedule.round_trip(30.0))
            self.show(first[-1], lambda ids: {"moving": ids >= 0})
        except BaseException:
            self.close()
            raise
        self.sim.flow_decode_ms.clear()
        self.sim.flow_prepare_ms.clear()
        self.made.clear()
        self.flow_stats.clear()
        self.poses0, self.flows0 = len(self.sim.pose_bytes), len(self.sim.flow_bytes)   # after the warm-up's frame

    def show(self, sample, masks) -> dict:
        """label -> masked metrics and ms of one displayed sample."""
        sim = self.sim
        t_disp, display, t_render, rendered = sample
        frame = sim.frame_at(t_render, rendered)
        if frame.frame_id not in self.made:
            self.made.add(frame.frame_id)
            if sim.true_flow is not None:
                _flow_coding(sim.true_flow, self.coders, self.decoders, self.flow_stats)
        gt = sim.ground_truth(display, t_disp)
        ids = sim.ground_truth_moving()
        out = {}
        for label, m in self.methods.items():
            rgb, holes, ms = sim.display(m, display, frame, t_disp)
            out[label] = dict(masked_metrics(gt, rgb, masks(ids)), ms=ms)
        return out

    def close(self) -> None:
        for m in self.methods.values():
            m.release()
        self.sim.close()


def measure_latency(worker, scene_spec, latency_ms, windows, rate_hz, stride, view_size, out_size, depth_codec,
                    flow_coder, variants) -> dict:
    """Every variant at one round trip on one scene's windows, a session of its own; with the
    flow coders' raw statistics of the frames it made. A :class:`~.cluster.Point`."""
    session = _Session(worker, scene_spec, view_size, out_size, depth_codec, flow_coder, variants, windows[0])
    sim = session.sim
    try:
        schedule = SessionSchedule.round_trip(rate_hz, latency_ms)
        series = _Series()
        for w in windows:
            for sample in display_samples(session.scene, w.trace, w.start_s, w.duration_s, schedule)[::stride]:
                for label, values in session.show(sample, lambda ids: {"moving": ids >= 0}).items():
                    series.add(label, **values)
        poses, flows = sim.pose_bytes[session.poses0:], sim.flow_bytes[session.flows0:]
        pose_bits = 8 * float(np.mean(poses)) if poses else 0.0
        flow_bits = 8 * float(np.mean(flows)) if flows else 0.0
        decode_ms = float(np.median(sim.flow_decode_ms)) if sim.flow_decode_ms else 0.0
        prepare_ms = float(np.median(sim.flow_prepare_ms)) if sim.flow_prepare_ms else 0.0
    finally:
        session.close()
    per = {}
    for label, (name, opts) in variants.items():
        uses_flow = opts.get("motion") == "flow"
        per[label] = {
            "method": name, "options": opts,
            "dssim": series.mean(label, "dssim"), "psnr": series.mean(label, "psnr"),
            "dssim_moving": series.mean(label, "dssim_moving"), "psnr_moving": series.mean(label, "psnr_moving"),
            "frames": len(series.values[label]["dssim"]),
            "frames_with_moving_pixels": int(np.sum(~np.isnan(series.values[label]["dssim_moving"]))),
            "client_ms_median": float(np.median(series.values[label]["ms"])),
            "per_server_frame_ms": {"flow_decode": decode_ms, "flow_background": prepare_ms} if uses_flow else {},
            "motion_bits_per_frame": (pose_bits if name == "proxy" else 0.0) + (flow_bits if uses_flow else 0.0),
        }
    return {"latency": {"pose_bits_per_frame": pose_bits, "flow_bits_per_frame": flow_bits, "methods": per},
            "flow_stats": session.flow_stats}


def measure_events(worker, scene_spec, event_latency_ms, event_stride, windows, rate_hz, view_size, out_size,
                   depth_codec, flow_coder, variants) -> dict:
    """Error over time around the scene's reversals and stops, a fixed pose looking at the object,
    a session of its own; with the flow coders' raw statistics. A :class:`~.cluster.Point`."""
    session = _Session(worker, scene_spec, view_size, out_size, depth_codec, flow_coder, variants, windows[0])
    events = []
    try:
        schedule = SessionSchedule.round_trip(rate_hz, event_latency_ms)
        for probe in event_probes(session.scene):
            series = _Series()
            times = []
            index = probe["index"]
            for sample in _event_samples(probe, rate_hz, schedule, event_stride):
                for label, values in session.show(sample, lambda ids: {"object": ids == index}).items():
                    series.add(label, **values)
                times.append(sample[0] - probe["t"])
            events.append({
                "object": probe["object"], "kind": probe["kind"], "t": probe["t"], "latency_ms": event_latency_ms,
                "pose": probe["pose"].as_array().tolist(), "times": times,
                "methods": {label: {"dssim_object": series.values[label]["dssim_object"],
                                    "psnr_object": series.values[label]["psnr_object"],
                                    "dssim_object_mean": series.mean(label, "dssim_object"),
                                    "psnr_object_mean": series.mean(label, "psnr_object")}
                            for label in variants}})
    finally:
        session.close()
    return {"events": events, "flow_stats": session.flow_stats}


def _merge_flow_stats(parts: list) -> dict:
    """The flow coders' statistics of several sessions, as if gathered in one (in the given order)."""
    out: dict = {}
    for stats in parts:
        for coder, s in stats.items():
            o = out.setdefault(coder, {k: ([] if isinstance(v, list) else 0) for k, v in s.items()})
            for k, v in s.items():
                o[k] = o[k] + v
    return out


def _scene_points(scene, scene_spec, windows, latencies, rate_hz, stride, view_size, out_size, depth_codec,
                  flow_coder, event_latency_ms, event_stride, variants) -> list:
    """One point per round trip, and one for the events."""
    from .cluster import Point

    common = dict(scene_spec=scene_spec, windows=tuple(windows), rate_hz=rate_hz, view_size=tuple(view_size),
                  out_size=tuple(out_size), depth_codec=depth_codec, flow_coder=flow_coder, variants=variants)
    points = []
    for latency_ms in latencies:
        ticks = sample_count(scene, windows, (latency_ms,), rate_hz, stride, events=False)
        points.append(Point(measure_latency, dict(common, latency_ms=latency_ms, stride=stride), cost=ticks,
                            ticks=ticks, name=f"{scene.name} {latency_ms:g} ms"))
    schedule = SessionSchedule.round_trip(rate_hz, event_latency_ms)
    ticks = sum(len(_event_samples(p, rate_hz, schedule, event_stride)) for p in event_probes(scene))
    points.append(Point(measure_events, dict(common, event_latency_ms=event_latency_ms, event_stride=event_stride),
                        cost=ticks, ticks=ticks, name=f"{scene.name} events"))
    return points


def _scene_result(scene, latencies, parts) -> dict:
    """One scene's result from its points' (in :func:`_scene_points`' order)."""
    moving = [o.name for o in scene.objects if o.is_dynamic]
    return {"scene": scene.name, "moving_objects": moving,
            "latency": {f"{latency_ms:g}": part["latency"] for latency_ms, part in zip(latencies, parts)},
            "events": parts[-1]["events"], "series": {},
            "flow_coding": _flow_summary(_merge_flow_stats([part["flow_stats"] for part in parts]))}


def sample_count(scene, windows, latencies, rate_hz, stride, event_stride=1, events=True) -> int:
    """Displayed samples a run scores on ``scene`` (for a progress bar)."""
    n = 0
    for latency_ms in latencies:
        schedule = SessionSchedule.round_trip(rate_hz, latency_ms)
        n += sum(len(display_samples(scene, w.trace, w.start_s, w.duration_s, schedule)[::stride])
                 for w in windows)
    if not events:
        return n
    schedule = SessionSchedule.round_trip(rate_hz)
    return n + sum(len(_event_samples(p, rate_hz, schedule, event_stride)) for p in event_probes(scene))


def run_dynamic_bench(scenes=DEFAULT_SCENES, windows=DEFAULT_WINDOWS, latencies=DEFAULT_LATENCIES, rate_hz=30.0,
                      stride=3, view_size=(512, 512), out_size=(480, 270), depth_codec="h264", flow_coder=None,
                      event_latency_ms=128.0, event_stride=2, placement=None, out_dir="out/bench",
                      progress=True) -> dict:
    """See the module docstring; writes ``dynamic.json`` and ``dynamic.png`` into ``out_dir``.
    Each (scene, round trip) and each scene's events is one point, a session of its own, run where
    ``placement`` says (default this process; :class:`~.cluster.Placement`)."""
    from pibr.protocol.motion_flow import DEFAULT_FLOW_CODER
    from pibr.scenes.registry import load_scene

    from .cluster import Placement, run_points

    placement = placement or Placement()
    loaded = {spec: load_scene(spec) for spec in scenes}
    static = [s.name for s in loaded.values() if not s.is_dynamic]
    if static:
        from pibr.protocol.errors import ConfigError

        raise ConfigError(f"scene(s) {', '.join(static)} have nothing moving; choose scenes that move (dynamic, room)")
    planned = {spec: _scene_points(scene, spec, tuple(windows), latencies, rate_hz, stride, view_size, out_size,
                                   depth_codec, flow_coder, event_latency_ms, event_stride, VARIANTS)
               for spec, scene in loaded.items()}
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=sum(p.ticks for points in planned.values() for p in points), unit="frame",
                   desc="bench dynamic", file=sys.stderr, leave=False, disable=None)
    t0 = time.perf_counter()
    try:
        ran = {}
        parts = iter(run_points([p for points in planned.values() for p in points], placement, bar, ran=ran))
        per_scene = {scene.name: _scene_result(scene, latencies, [next(parts) for _ in planned[spec]])
                     for spec, scene in loaded.items()}
    finally:
        if bar is not None:
            bar.close()
    result = {"latencies_ms": list(latencies), "rate_hz": rate_hz, "server_fps": 10.0, "stride": stride,
              "event_stride": event_stride,
              "view_size": list(view_size), "output": list(out_size), "depth_codec": depth_codec,
              "flow_coder": flow_coder or DEFAULT_FLOW_CODER,
              "windows": windows_json(windows, "reporting"),
              "event_probes": "synthetic: a fixed head pose at the scene's viewer origin looking at the object, "
                              f"{EVENT_BEFORE:g} s before to {EVENT_AFTER:g} s after its first reversal or stop "
                              "after 1.5 s",
              "placement": placement.to_json(ran), "scenes": per_scene, "seconds": time.perf_counter() - t0}
    write_result(out_dir, "dynamic.json", result)
    import os

    from .plots import plot_dynamic

    plot_dynamic(result, os.path.join(out_dir, "dynamic.png"))
    return result


def print_dynamic_tables(r: dict) -> None:
    w = r["windows"]
    used = ", ".join("{trace}@{start_s:g}+{duration_s:g}".format(**x) for x in w["used"])
    relation = "disjoint from" if w["disjoint_from_tuning"] else "OVERLAPPING"
    print(f"pibr bench dynamic: {r['depth_codec']} depth, {r['flow_coder']} flow, view {r['view_size'][0]}x"
          f"{r['view_size'][1]}, output {r['output'][0]}x{r['output'][1]}, windows {used} ({relation} the tuning "
          "windows)")

    def f(v, spec):
        return "-" if v is None else format(v, spec)

    for scene, s in r["scenes"].items():
        print(f"\n{scene} (moving: {', '.join(s['moving_objects'])})")
        print(f"  {'latency':>7} {'method':<14}{'DSSIM':>8}{'PSNR':>7}{'DSSIM mov':>10}{'PSNR mov':>9}{'ms':>7}"
              f"{'motion b/frame':>15}")
        for latency, L in s["latency"].items():
            for label, m in L["methods"].items():
                print(f"  {latency:>7} {label:<14}{f(m['dssim'], '.4f'):>8}{f(m['psnr'], '.2f'):>7}"
                      f"{f(m['dssim_moving'], '.4f'):>10}{f(m['psnr_moving'], '.2f'):>9}{m['client_ms_median']:>7.1f}"
                      f"{m['motion_bits_per_frame']:>15.0f}")
        for e in s["events"]:
            means = ", ".join(f"{k} {f(v['dssim_object_mean'], '.4f')}" for k, v in e["methods"].items())
            print(f"  {e['object']} {e['kind']} at {e['t']:.2f} s ({e['latency_ms']:g} ms), object DSSIM: {means}")
        print("  flow coding:")
        for coder, c in s["flow_coding"].items():
            print(f"    {coder:<7} {c['bits_per_frame']:>9.0f} bits/frame ({f(c['bits_per_frame_with_motion'], '.0f')} "
                  f"with motion), EPE moving {f(c['epe_moving_px'], '.3f')} px, all {c['epe_all_px']:.4f} px, "
                  f"encode {c['encode_ms_median']:.1f} ms, decode {c['decode_ms_median']:.1f} ms "
                  f"({c['frames']} frames)")
