"""``pibr bench stereo``: two eyes from one stream, by server reference and client method.

A headset shows two images. For every displayed tick of each window, on the virtual clock's
schedule (pibr.common.link.SessionSchedule), the eyes sit half the IPD either side of the head
(protocol/stereo.py) and each server reference is streamed as a session of its own (its own
renderer output, H.264 stream and decoder):

- ``mono``: today's single view at the head's centre, from frames rendered there (the baseline
  the stereo goals are stated against);
- ``cyclops``: the same centre frames, warped into each eye (Schollmeyer et al. 2017, Sec. 5);
- ``alternate``: server tick k renders the left eye's dual view when k is even, the right eye's
  when odd; each eye re-renders from the newest frame of its own eye (half the update rate per
  eye, but a reference from the eye's own position: it converges when the head rests);
- ``per-eye``: both eyes every tick (two frames per tick: twice the server's work and bits),
  the upper bound.

Each method (``proxy``, ``gridwarp``, ``rotation`` by default) draws every eye; a method
instance serves one reference stream (cyclops: one instance draws both eyes from the frame it
holds, so gridwarp builds its grid once per reference, as Schollmeyer does). Scores per eye
against that eye's ground truth: DSSIM, PSNR, FLIP (every ``flip_every``-th scored tick), own
holes and geometric holes (server/coverage.py's one definition); per pair, the binocular
consistency of bench/stereo_metrics.py; client CPU ms per pair (both eyes) against one mono
view in the same run, server CPU ms and bits per second of each reference.

Windows: parts of the evaluation windows of bench/windows.py (disjoint from every tuning
window): a real one, a translating one (synth-walk), a turning one (synth-turns), one where the
head walks and comes to rest (found in synth-mixed by :func:`rest_window`), and the ``dynamic``
scene's moving objects (alternate updates each eye's view of them at half the rate).
"""
from __future__ import annotations

import sys
import time

import numpy as np

from pibr.common.link import SessionSchedule
from pibr.protocol.frustum import eyes_tangents
from pibr.protocol.stereo import CENTRE, DEFAULT_IPD_MM, EYES, eye_pose, frame_eyes

from .results import write_result
from .windows import Window, windows_json

MODES = ("mono", "cyclops", "alternate", "per-eye")
DEFAULT_METHODS = ("proxy", "gridwarp", "rotation")
#: The room's windows: a real trace, a walk (translation), quick turns (rotation); the window
#: where the head comes to rest is added by :func:`rest_window`.
ROOM_WINDOWS = (Window("pred6dof-1", 30.0, 4.0), Window("synth-walk", 5.0, 4.0), Window("synth-turns", 5.0, 4.0))
#: The dynamic scene where its moving objects are in view (as bench/dynamic_bench.py).
DYNAMIC_WINDOWS = (Window("pred6dof-2", 50.0, 2.0), Window("synth-turns", 5.0, 2.0))
#: The trace searched for a walk that comes to rest, and the seconds of walking and of rest kept.
REST_TRACE, REST_BEFORE_S, REST_AFTER_S = "synth-mixed", 2.5, 2.0
#: Walking and resting speeds (m/s) for :func:`rest_window`.
WALKING_M_S, RESTING_M_S = 0.5, 0.05

#: The issue's goals for proxy with cyclops references.
GOAL_DSSIM_RATIO, GOAL_PAIR_MS_RATIO, GOAL_CONSISTENCY_RATIO = 1.1, 1.6, 1.2


def rest_window(trace_name: str = REST_TRACE, before_s: float = REST_BEFORE_S, after_s: float = REST_AFTER_S) -> Window:
    """The first place in ``trace_name`` where a walk (above :data:`WALKING_M_S`) comes to rest
    (below :data:`RESTING_M_S` and staying there ``after_s`` seconds): ``before_s`` seconds of the
    walk's end and ``after_s`` of rest. A ConfigError when the trace has none."""
    from pibr.common.traces.loading import load_trace
    from pibr.protocol.errors import ConfigError

    trace = load_trace(trace_name)
    linear, _ = trace.speeds()
    t = np.asarray(trace.t[1:], np.float64)
    walked = False
    for i in range(len(linear)):
        if linear[i] > WALKING_M_S:
            walked = True
        elif walked and linear[i] < RESTING_M_S and t[i] >= before_s:
            rest = (t >= t[i]) & (t <= t[i] + after_s)
            if t[i] + after_s <= t[-1] and np.all(linear[rest] < RESTING_M_S):
                start = round(float(t[i]) - before_s, 2)
                return Window(trace_name, start, round(before_s + after_s, 2))
    raise ConfigError(f"trace {trace_name} has no walk that comes to rest for {after_s:g} s")


class _Stream:
    """One reference stream (a session of its own): the frames served so far and, per slot (the
    centre, or each eye), the newest frame received into that slot's textures."""

    def __init__(self, sim, reference: str | None, ipd_mm: float):
        from pibr.client.frame_textures import FrameTextures

        self.sim, self.reference, self.ipd_mm = sim, reference, ipd_mm
        self.slots = (CENTRE,) if reference in (None, "cyclops") else EYES
        self.textures = {self.slots[0]: sim.textures}
        for slot in self.slots[1:]:
            self.textures[slot] = FrameTextures(sim.ctx, sim.session)
        self.frames: dict = {}
        self.distances: dict = {}
        self.next_tick = None
        self.first_tick = None
        self.served = 0
        self.server_cpu_ms: list[float] = []

    def advance(self, tick: int, head_at) -> None:
        """Serve and receive every server tick up to ``tick`` (each its eyes' frames, in order);
        ``head_at(k)``: the head pose server tick k renders from."""
        start = tick - 1 if self.next_tick is None else self.next_tick   # alternate needs both eyes at once
        if self.first_tick is None:
            self.first_tick = start
        interval = 1.0 / self.sim.fps
        for k in range(start, tick + 1):
            for eye in frame_eyes(self.reference, k):
                c0 = time.process_time()
                frame, distances = self.sim.serve(k * interval, eye_pose(head_at(k), eye, self.ipd_mm))
                self.server_cpu_ms.append((time.process_time() - c0) * 1e3)
                slot = eye if eye in self.textures else CENTRE
                self.sim.receive(frame, textures=self.textures[slot])
                self.frames[slot], self.distances[slot] = frame, distances
                self.served += 1
        self.next_tick = max(tick + 1, start)

    def bits_per_second(self) -> float:
        ticks = self.next_tick - self.first_tick
        return sum(self.sim.frame_bits(i) for i in range(self.served)) * self.sim.fps / max(1, ticks)

    def release(self) -> None:
        for slot in self.slots[1:]:
            self.textures[slot].release()


def _eye_slot(stream: _Stream, eye: str) -> str:
    return eye if eye in stream.textures else CENTRE


class _Scores:
    """label -> key -> per-window lists."""

    def __init__(self):
        self.values: dict = {}

    def add(self, label: str, window: str, **values) -> None:
        w = self.values.setdefault(label, {}).setdefault(window, {})
        for k, v in values.items():
            w.setdefault(k, []).append(v)

    def mean(self, label: str, key: str, window: str | None = None):
        per = self.values.get(label, {})
        vals = [v for w, d in per.items() if window in (None, w) for v in d.get(key, [])
                if v is not None and not (isinstance(v, float) and np.isnan(v))]
        return float(np.mean(vals)) if vals else None

    def median(self, label: str, key: str):
        vals = [v for d in self.values.get(label, {}).values() for v in d.get(key, [])]
        return float(np.median(vals)) if vals else None


def run_stereo_bench(windows=None, dynamic_windows=None, methods=DEFAULT_METHODS, modes=MODES,
                     ipd_mm=DEFAULT_IPD_MM, latency_ms=128.0, rate_hz=30.0, view_size=None, out_size=(960, 540),
                     stride=4, flip_every=4, scenes=("room", "dynamic"), out_dir="out/bench", progress=True,
                     pair_png=True, eye_fov_deg=None) -> dict:
    """Every mode x method on the room's windows (default :data:`ROOM_WINDOWS` and
    :func:`rest_window`) and the dynamic scene's (:data:`DYNAMIC_WINDOWS`). Writes stereo.json,
    stereo.png and (``pair_png``) stereo-pair.png, stereo-anaglyph.png under ``out_dir``.
    ``eye_fov_deg``: (outer, inner, up, down) degrees of the left eye's asymmetric frustum, the
    right eye mirrored (protocol/frustum.py; each eye drawn and scored through its own), mono at
    the symmetric 90 degrees; None: both eyes see 90 degrees symmetrically."""
    from pibr.protocol.errors import ConfigError
    from pibr.protocol.stereo import check_ipd_mm

    from .simulation import BENCH_VIEW_SIZE, blas_on_one_thread

    check_ipd_mm(ipd_mm)
    if eye_fov_deg is not None:
        from pibr.protocol.frustum import check_eye_fov_deg

        eye_fov_deg = check_eye_fov_deg(eye_fov_deg)
    unknown = [m for m in modes if m not in MODES]
    if unknown or "mono" not in modes:
        raise ConfigError(f"modes must include mono (the baseline) and come from {', '.join(MODES)}; got "
                          f"{', '.join(modes)}")
    view_size = tuple(view_size or BENCH_VIEW_SIZE)
    plan = {}
    if "room" in scenes:
        plan["room"] = tuple(windows) if windows is not None else ROOM_WINDOWS + (rest_window(),)
    if "dynamic" in scenes:
        plan["dynamic"] = tuple(dynamic_windows) if dynamic_windows is not None else DYNAMIC_WINDOWS
    for name in scenes:
        if name not in plan:
            plan[name] = tuple(windows) if windows is not None else ROOM_WINDOWS
    schedule = SessionSchedule.round_trip(rate_hz, latency_ms)
    result = {"ipd_mm": ipd_mm, "latency_ms": latency_ms, "rate_hz": rate_hz, "view_size": list(view_size),
              "output": list(out_size), "stride": stride, "flip_every": flip_every, "modes": list(modes),
              "methods": list(methods), "scenes": {}}
    if eye_fov_deg is not None:
        result["eye_fov_deg"] = list(eye_fov_deg)
    all_windows = [w for ws in plan.values() for w in ws]
    result["windows"] = windows_json(all_windows, "reporting")
    bar = None
    if progress:
        from tqdm import tqdm

        total = sum(len(range(0, int(w.duration_s * rate_hz), stride)) for w in all_windows)
        bar = tqdm(total=total, unit="tick", desc="bench stereo", file=sys.stderr, leave=False, disable=None)
    pictures = {}
    result["blas_threads"] = 1   # the client's CPU is timed with BLAS on one thread (blas_on_one_thread)
    try:
        with blas_on_one_thread():
            for scene_name, scene_windows in plan.items():
                result["scenes"][scene_name] = _run_scene(scene_name, scene_windows, methods, modes, ipd_mm,
                                                          schedule, view_size, out_size, stride, flip_every, bar,
                                                          pictures if pair_png and not pictures else None,
                                                          eye_fov_deg)
    finally:
        if bar is not None:
            bar.close()
    result["goals"] = stereo_goals(result)
    result["alternate_against_cyclops"] = alternate_against_cyclops(result)
    write_result(out_dir, "stereo.json", result)
    from .plots import plot_stereo

    plot_stereo(result, f"{out_dir}/stereo.png")
    if pictures:
        _write_pictures(pictures, out_dir)
    return result


def _run_scene(scene_name, windows, methods, modes, ipd_mm, schedule, view_size, out_size, stride, flip_every,
               bar, pictures, eye_fov_deg=None) -> dict:
    from pibr.common.replay import trace_ticks
    from pibr.common.traces.loading import load_trace
    from pibr.scenes.registry import load_scene
    from pibr.server.coverage import camera_rays

    from .metrics import frame_metrics, nearly_uniform, pixels_per_degree
    from .simulation import Simulation, bench_server_config, geometric_holes, load_proxies
    from .stereo_metrics import binocular_pairs, stereo_consistency

    scene = load_scene(scene_name)
    proxies, bundle = load_proxies(scene) if "proxy" in methods else (None, None)
    references = {"mono": None, "cyclops": "cyclops", "alternate": "alternate", "per-eye": "per-eye"}
    stream_of = {m: ("centre" if m in ("mono", "cyclops") else m) for m in modes}
    scores = _Scores()
    ppd = pixels_per_degree(out_size[0], 90.0)
    # each eye's frustum (None: the symmetric 90 degrees) and camera rays
    frustums = eyes_tangents((CENTRE, *EYES), eye_fov_deg)
    rays_of = {e: camera_rays(*out_size, 90.0, f) for e, f in frustums.items()}
    interval_us = schedule.interval_us
    uniform = {}
    for window in windows:
        trace = load_trace(window.trace)
        ticks, pose_at = trace_ticks(scene, trace, window.start_s, window.duration_s, schedule.rate_hz)
        sims, streams, instances = {}, {}, {}
        try:
            for name in sorted(set(stream_of.values())):
                sim = Simulation(scene, bench_server_config(view_size), out_size, proxies=proxies,
                                 keep_distances=True, ctx=sims[next(iter(sims))].ctx if sims else None)
                sims[name] = sim
                streams[name] = _Stream(sim, references["cyclops" if name == "centre" else name], ipd_mm)
            for mode in modes:
                sim = sims[stream_of[mode]]
                slots = ("mono",) if mode == "mono" else (("pair",) if mode == "cyclops" else EYES)
                for method in methods:
                    for slot in slots:   # one instance per reference slot; a cyclops pair's may draw both at once
                        instances[(mode, method, slot)] = sim.make_method(method, pair_at_once=slot == "pair")
            peel = {name: bool(s.session.options.get("peel_marker")) for name, s in sims.items()}
            gt_sim = sims["centre"]
            for i, t_us in enumerate(ticks[::stride]):
                render_us, _ = schedule.frame_for(t_us)
                tick = render_us // interval_us
                for name, stream in streams.items():
                    stream.advance(tick, lambda k: pose_at(schedule.pose_for(k * interval_us)))
                head = pose_at(t_us)
                t = t_us / 1e6
                eyes = {e: eye_pose(head, e, ipd_mm) for e in EYES}
                truth = {CENTRE: gt_sim.ground_truth(head, t)}
                truth_distance = {CENTRE: gt_sim.ground_truth_distance()}
                for e in EYES:
                    truth[e] = gt_sim.ground_truth(eyes[e], t, frustums[e])
                    truth_distance[e] = gt_sim.ground_truth_distance()
                pairs = binocular_pairs(rays_of["left"], out_size, 90.0, eyes["left"], eyes["right"],
                                        truth_distance["left"], truth_distance["right"],
                                        right_frustum=frustums["right"])
                uniform[window.label] = uniform.get(window.label, 0) + nearly_uniform(truth[CENTRE])
                with_flip = flip_every > 0 and i % flip_every == 0
                geo = {}
                for mode in modes:
                    stream = streams[stream_of[mode]]
                    for e in ((CENTRE,) if mode == "mono" else EYES):
                        slot = _eye_slot(stream, e)
                        frame = stream.frames[slot]
                        pose = head if e == CENTRE else eyes[e]
                        geo[(mode, e)] = geometric_holes(rays_of[e], pose, truth_distance[e], frame,
                                                         stream.distances[slot], peel[stream_of[mode]])
                for mode in modes:
                    stream = streams[stream_of[mode]]
                    sim = stream.sim
                    for method in methods:
                        label = f"{method} {mode}"
                        shown, cpu = {}, 0.0
                        pair = instances.get((mode, method, "pair"))
                        shares = pair is not None and getattr(pair, "shares_pair", None) is not None \
                            and eye_fov_deg is None and pair.shares_pair(eyes["left"], eyes["right"])

                        def at_once():
                            # the client's default draws eye by eye (below); both eyes at once
                            # (render_pair) timed beside it, first on every other tick (what is drawn
                            # second finds the caches warm)
                            return sim.display_pair_timed(pair, eyes["left"], eyes["right"], stream.frames[CENTRE],
                                                          t, stream.textures[CENTRE])[1]
                        together = at_once() if shares and i % 2 else None
                        for e in ((CENTRE,) if mode == "mono" else EYES):
                            slot = _eye_slot(stream, e)
                            inst = instances[(mode, method, "mono" if mode == "mono" else
                                              ("pair" if mode == "cyclops" else e))]
                            pose = head if e == CENTRE else eyes[e]
                            inst.look_through(frustums[e])
                            rgb, own, ms, cpu_ms = sim.display_timed(inst, pose, stream.frames[slot], t,
                                                                     stream.textures[slot])
                            cpu += cpu_ms
                            shown[e] = rgb
                            m = frame_metrics(truth[e], rgb, ppd, with_flip)
                            holes = geo[(mode, e)]["both" if inst.uses_extra_view else "primary"]
                            scores.add(label, window.label, dssim=m["dssim"], psnr=m["psnr"], flip=m["flip"],
                                       own_holes=own, geometric_holes=holes)
                        scores.add(label, window.label, cpu_ms=cpu)
                        if shares:
                            together = at_once() if together is None else together
                            scores.add(label, window.label, cpu_ms_pair_at_once=together)
                        if mode == "mono":
                            # the one image shown to both eyes: what no disparity at all scores
                            c = stereo_consistency(shown[CENTRE], shown[CENTRE], truth["left"], truth["right"], pairs)
                        else:
                            c = stereo_consistency(shown["left"], shown["right"], truth["left"], truth["right"], pairs)
                            if pictures is not None and method == "proxy" and mode == "cyclops" and i == len(
                                    ticks[::stride]) // 2:
                                pictures.update(left=shown["left"], right=shown["right"],
                                                truth_left=truth["left"], truth_right=truth["right"],
                                                where=f"{scene.name}, {window.label}, t = {t:.2f} s")
                        scores.add(label, window.label, inconsistent=c["inconsistent"], excess=c["excess_mean"])
                if bar is not None:
                    bar.update(1)
            for name, stream in streams.items():
                scores.add(f"server {name}", window.label, bits_per_second=stream.bits_per_second(),
                           server_cpu_ms=float(np.median(stream.server_cpu_ms)),
                           frames_per_tick=stream.served / max(1, stream.next_tick - stream.first_tick))
        finally:
            for inst in instances.values():
                inst.release()
            for stream in streams.values():
                stream.release()
            ctx = None
            for sim in sims.values():
                ctx = sim.ctx
                sim.close()
            if ctx is not None:
                ctx.release()
    return _scene_result(scene, bundle, windows, methods, modes, stream_of, scores, uniform)


def _scene_result(scene, bundle, windows, methods, modes, stream_of, scores, uniform) -> dict:
    labels = [w.label for w in windows]
    out = {"scene": scene.name, "windows": labels, "nearly_uniform_ticks": uniform, "variants": {}, "server": {}}
    if bundle is not None:
        out["proxies"] = bundle.info(1 << 20)
    keys = ("dssim", "psnr", "flip", "own_holes", "geometric_holes", "inconsistent", "excess")
    for mode in modes:
        for method in methods:
            label = f"{method} {mode}"
            v = {"method": method, "mode": mode, "eyes": 1 if mode == "mono" else 2,
                 "cpu_ms_median": scores.median(label, "cpu_ms")}
            at_once = scores.median(label, "cpu_ms_pair_at_once")   # the same frames, both eyes in one pass
            if at_once is not None:
                v["cpu_ms_pair_at_once_median"] = at_once
            v.update({f"{k}_mean": scores.mean(label, k) for k in keys})
            v["per_window"] = {w: {f"{k}_mean": scores.mean(label, k, w) for k in ("dssim", "psnr", "inconsistent")}
                               for w in labels}
            out["variants"][label] = v
    for name in sorted(set(stream_of.values())):
        label = f"server {name}"
        out["server"][name] = {"modes": [m for m in modes if stream_of[m] == name],
                               "bits_per_second": scores.mean(label, "bits_per_second"),
                               "server_cpu_ms_per_frame": scores.mean(label, "server_cpu_ms"),   # of each window's median
                               "frames_per_tick": scores.mean(label, "frames_per_tick")}
    for method in methods:
        mono = out["variants"].get(f"{method} mono")
        for mode in modes:
            v = out["variants"][f"{method} {mode}"]
            if mono and mono["dssim_mean"] and v["dssim_mean"] is not None:
                v["dssim_vs_mono"] = v["dssim_mean"] / mono["dssim_mean"]
            if mono and mono["cpu_ms_median"] and v["cpu_ms_median"] is not None:
                v["cpu_ms_vs_mono"] = v["cpu_ms_median"] / mono["cpu_ms_median"]
                if v.get("cpu_ms_pair_at_once_median") is not None:
                    v["cpu_ms_pair_at_once_vs_mono"] = v["cpu_ms_pair_at_once_median"] / mono["cpu_ms_median"]
    return out


def stereo_goals(result: dict) -> dict:
    """The issue's goals for proxy with cyclops references, per scene, with the numbers."""
    out = {}
    for name, s in result["scenes"].items():
        v = s["variants"]
        cyc, per_eye = v.get("proxy cyclops"), v.get("proxy per-eye")
        if cyc is None:
            continue
        g = {}
        if cyc.get("dssim_vs_mono") is not None:
            g["dssim"] = {"ratio": cyc["dssim_vs_mono"], "goal": GOAL_DSSIM_RATIO,
                          "met": cyc["dssim_vs_mono"] <= GOAL_DSSIM_RATIO}
        if cyc.get("cpu_ms_vs_mono") is not None:
            g["ms_per_pair"] = {"ratio": cyc["cpu_ms_vs_mono"], "goal": GOAL_PAIR_MS_RATIO,
                                "met": cyc["cpu_ms_vs_mono"] <= GOAL_PAIR_MS_RATIO,
                                "pair_at_once_ratio": cyc.get("cpu_ms_pair_at_once_vs_mono")}
        if per_eye is not None and per_eye["inconsistent_mean"]:
            ratio = cyc["inconsistent_mean"] / per_eye["inconsistent_mean"]
            g["consistency"] = {"ratio": ratio, "goal": GOAL_CONSISTENCY_RATIO, "met": ratio <= GOAL_CONSISTENCY_RATIO}
        out[name] = g
    return out


def alternate_against_cyclops(result: dict) -> list[dict]:
    """Per scene, method and window: alternate's and cyclops's per-eye DSSIM and consistency, and
    which is better by DSSIM."""
    rows = []
    for name, s in result["scenes"].items():
        for method in result["methods"]:
            alt, cyc = s["variants"].get(f"{method} alternate"), s["variants"].get(f"{method} cyclops")
            if alt is None or cyc is None:
                continue
            for w in s["windows"]:
                a, c = alt["per_window"][w], cyc["per_window"][w]
                if a["dssim_mean"] is None or c["dssim_mean"] is None:
                    continue
                rows.append({"scene": name, "method": method, "window": w, "alternate_dssim": a["dssim_mean"],
                             "cyclops_dssim": c["dssim_mean"], "alternate_inconsistent": a["inconsistent_mean"],
                             "cyclops_inconsistent": c["inconsistent_mean"],
                             "better": "alternate" if a["dssim_mean"] < c["dssim_mean"] else "cyclops"})
    return rows


def _write_pictures(p: dict, out_dir: str) -> None:
    from PIL import Image

    from pibr.client.recorder import anaglyph, side_by_side

    shown = side_by_side(p["left"], p["right"])
    truth = side_by_side(p["truth_left"], p["truth_right"])
    Image.fromarray(np.concatenate([shown, np.zeros((8, shown.shape[1], 3), np.uint8), truth])).save(
        f"{out_dir}/stereo-pair.png")
    Image.fromarray(anaglyph(p["left"], p["right"])).save(f"{out_dir}/stereo-anaglyph.png")


def print_stereo(result: dict) -> None:
    for name, s in result["scenes"].items():
        print(f"\nscene {name} ({', '.join(s['windows'])}); ipd {result['ipd_mm']:g} mm, {result['latency_ms']:g} ms")
        print(f"{'variant':<22} {'DSSIM':>7} {'x mono':>7} {'PSNR':>6} {'FLIP':>6} {'incons.':>8} {'holes %':>8} "
              f"{'CPU ms':>7} {'x mono':>7}")
        for label, v in s["variants"].items():
            def f(x, fmt):
                return format(x, fmt) if x is not None else "-"
            print(f"{label:<22} {f(v['dssim_mean'], '7.4f')} {f(v.get('dssim_vs_mono'), '7.2f')} "
                  f"{f(v['psnr_mean'], '6.2f')} {f(v['flip_mean'], '6.3f')} {f(v['inconsistent_mean'], '8.4f')} "
                  f"{f(100 * v['geometric_holes_mean'] if v['geometric_holes_mean'] is not None else None, '8.2f')} "
                  f"{f(v['cpu_ms_median'], '7.1f')} {f(v.get('cpu_ms_vs_mono'), '7.2f')}")
        for ref, srv in s["server"].items():
            print(f"server {ref:<10} {srv['bits_per_second'] / 1e6:6.2f} Mbit/s, {srv['server_cpu_ms_per_frame']:.0f} "
                  f"CPU ms a frame, {srv['frames_per_tick']:.2f} frames a tick ({', '.join(srv['modes'])})")
    for name, g in result["goals"].items():
        for k, x in g.items():
            print(f"goal {name} {k}: {x['ratio']:.2f} (at most {x['goal']:g}) {'met' if x['met'] else 'NOT met'}")
