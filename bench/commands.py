"""What ``pibr demo``, ``pibr evaluate`` and each ``pibr bench ...`` command do with their
parsed arguments (bench/cli.py declares them): run, print the table, say what was written."""
from __future__ import annotations


def cmd_report(args) -> int:
    from .report import write_report

    print(f"written: {write_report(args.out)}")
    return 0


def with_report(command, folder_arg: str):
    """``command`` followed, when it succeeds, by the report of the folder it wrote (``args.<folder_arg>``).
    A folder with nothing to show gets no report; the command's own outputs stand either way."""
    def run(args) -> int:
        code = command(args)
        if code == 0:
            import logging

            from pibr.protocol.errors import ConfigError

            from .report import write_report

            try:
                print(f"report: {write_report(getattr(args, folder_arg))}")
            except ConfigError as exc:
                logging.getLogger(__name__).warning("no report: %s", exc)
        return code
    run.__wrapped__, run.folder_arg = command, folder_arg
    return run


def realtime_server_args(view_size, extra_view) -> tuple:
    """The server options ``pibr bench realtime`` passes on: only those the user set."""
    out = () if view_size is None else ("--view-size", "%dx%d" % tuple(view_size))
    return out + (() if extra_view is None else ("--extra-view", extra_view))


def cmd_bench_realtime(args) -> int:
    from .demo import check_inputs
    from .processes import PLACEMENTS
    from .realtime import print_realtime, run_realtime_bench

    check_inputs(args.scene, args.trace, args.start, args.duration)
    r = run_realtime_bench(out_dir=args.out, methods=args.method, depth_codecs=args.depth_codec,
                           clients=args.clients, duration_s=args.duration, scaling_duration_s=args.scaling_duration,
                           scene=args.scene, trace=args.trace, start_s=args.start, rate_hz=args.rate,
                           size=args.size, latency_ms=args.latency_ms, server_fps=args.server_fps,
                           server_args=realtime_server_args(args.view_size, args.extra_view),
                           placements=PLACEMENTS if args.placement == "both" else (args.placement,),
                           controllers={"on": (True,), "off": (False,), "both": (True, False)}[args.controllers],
                           score=not args.no_score)
    print_realtime(r)
    print(f"written: {args.out}/realtime.json")
    return 0


def cmd_bench_live(args) -> int:
    from .live_bench import run_live_bench

    r = run_live_bench(out_dir=args.out, method=args.method, size=args.size, rate_hz=args.rate,
                       duration_s=args.duration, repeats=args.repeats)
    s = r["summary"]
    print(f"\n{'':8} {'client ms p50':>14} {'p95':>8} {'missed %':>9}")
    for k in ("alone", "watched"):
        print(f"{k:8} {s[k]['client_ms_median']:14.1f} {s[k]['client_ms_p95']:8.1f} {100 * s[k]['missed_fraction']:9.1f}")
    print(f"\nwatched / alone client ms: {s['client_ms_ratio']:.3f}; the page's share of the tick time in the client: "
          f"{100 * s['loop_share_of_tick_time']:.2f} % event loop + {100 * s['thread_share_of_tick_time']:.2f} % image "
          f"thread (goal under {100 * s['goal_share']:.0f} %)")
    print(f"written: {args.out}/live.json")
    return 0


def cmd_bench_soak(args) -> int:
    from pibr.protocol.errors import ConfigError

    from .demo import check_inputs
    from .hostile import KINDS
    from .soak import print_soak, run_soak

    kinds = tuple(k.strip() for k in args.kinds.split(",") if k.strip())
    unknown = [k for k in kinds if k not in KINDS]
    if unknown:
        raise ConfigError(f"unknown hostile kind(s) {', '.join(unknown)}; kinds: {', '.join(KINDS)}")
    if args.clients < 1:
        raise ConfigError(f"--clients must be at least 1, got {args.clients}")
    check_inputs(args.scene, args.trace, 0.0, args.clients * (args.run_duration + 1.0))
    r = run_soak(args.out, duration_s=args.duration, clients=args.clients, kinds=kinds, scene=args.scene,
                 trace=args.trace, method=args.method, run_s=args.run_duration,
                 view_size="%dx%d" % args.view_size, seed=args.seed)
    print_soak(r)
    print(f"written: {args.out}/soak.json")
    return 0 if r["passed"] else 1


def cmd_bench_fuzz(args) -> int:
    from .fuzz import print_fuzz_table, replay, run_fuzz_bench

    if args.replay is not None:
        return replay(args.replay)
    r = run_fuzz_bench(parsers=args.parsers, inputs=args.inputs, seed=args.seed, timeout_s=args.timeout_s,
                       out_dir=args.out)
    print_fuzz_table(r)
    print(f"written: {args.out}/fuzz.json")
    return 0 if r["ok"] else 1


def cmd_bench_dynamic(args) -> int:
    from .dynamic_bench import DEFAULT_WINDOWS, print_dynamic_tables, run_dynamic_bench

    r = run_dynamic_bench(scenes=args.scene, windows=args.windows or DEFAULT_WINDOWS, latencies=args.latency_ms,
                          rate_hz=args.rate, stride=args.stride, view_size=args.view_size, out_size=args.size,
                          depth_codec=args.depth_codec, flow_coder=args.flow_coder,
                          event_latency_ms=args.event_latency_ms, event_stride=args.event_stride,
                          placement=placement_of(args), out_dir=args.out)
    print_dynamic_tables(r)
    print(f"written: {args.out}/dynamic.json, {args.out}/dynamic.png")
    return 0


def cmd_bench_stereo(args) -> int:
    from .stereo_bench import print_stereo, run_stereo_bench

    r = run_stereo_bench(windows=args.windows, dynamic_windows=args.dynamic_windows, methods=args.method,
                         modes=args.modes, ipd_mm=args.ipd_mm, latency_ms=args.latency_ms, rate_hz=args.rate,
                         view_size=args.view_size, out_size=args.size, stride=args.stride, flip_every=args.flip_every,
                         scenes=args.scene, out_dir=args.out, eye_fov_deg=args.eye_fov_deg)
    print_stereo(r)
    print(f"written: {args.out}/stereo.json, stereo.png, stereo-pair.png, stereo-anaglyph.png")
    return 0


def cmd_bench_predict(args) -> int:
    from .predict_bench import print_predict, run_predict_bench

    r = run_predict_bench(windows=args.windows, rate_hz=args.rate, look_aheads_ms=args.look_ahead_ms, fit=args.fit,
                          out_dir=args.out, quality=not args.no_quality, stride=args.stride)
    print_predict(r)
    name = "predict-tuning" if args.fit else "predict"
    print(f"written: {args.out}/{name}.json, {args.out}/{name}.png")
    return 0


def cmd_bench_network(args) -> int:
    from pibr.common.bandwidth import load_bandwidth_trace

    from .network_bench import print_network, run_network_bench

    from pibr.protocol.errors import ConfigError
    from pibr.server.stream_adaptation import STARTS

    for link in args.links:
        load_bandwidth_trace(link)   # a bad name or file refused before any process starts
    for start in args.adapt_start:
        if start not in STARTS:
            raise ConfigError(f"--adapt-start: {start!r} is not one of {', '.join(STARTS)}")
    if not args.static_kbps and not args.adapt_start:
        raise ConfigError("nothing to run: --static-kbps and --adapt-start are both empty")
    r = run_network_bench(out_dir=args.out, links=args.links, static_kbps=args.static_kbps,
                          adapt_starts=tuple(args.adapt_start),
                          adapt_kbps=args.adapt_kbps, method=args.method, trace=args.trace, start_s=args.start,
                          duration_s=args.duration, rate_hz=args.rate, size=args.size, view_size=args.view_size,
                          clock=args.clock, placement=args.placement)
    print_network(r)
    print(f"written: {args.out}/network.json, {args.out}/network.png")
    return 0


def cmd_bench_split(args) -> int:
    from .split_bench import print_split_table, run_split_bench

    r = run_split_bench(out_dir=args.out, duration_s=args.duration, stride=args.stride, out_size=args.size)
    print_split_table(r)
    print(f"written: {args.out}/split.json")
    return 0


def cmd_bench_pareto(args) -> int:
    from .pareto import print_pareto_table, run_pareto_bench

    result = run_pareto_bench(scenes=args.scene, methods=args.method, windows=args.windows,
                              latency_ms=args.latency_ms, rate_hz=args.rate, stride=args.stride,
                              view_size=args.view_size, out_size=args.size, speed_sizes=args.speed_sizes,
                              speed_frames=args.speed_frames, flip_every=args.flip_every,
                              depth_codec=args.depth_codec, placement=placement_of(args), out_dir=args.out)
    print_pareto_table(result)
    print(f"written: {args.out}/pareto.json, pareto.png")
    return 0


def placement_of(args):
    """Where a sweep's points run, from --workers, --ray-address and --gpus-per-worker."""
    from .cluster import Placement, import_ray

    placement = Placement(args.workers, args.ray_address, args.gpus_per_worker)
    if placement.uses_ray:
        import_ray()      # a missing extra is said before anything is measured
    elif args.gpus_per_worker:
        from pibr.protocol.errors import ConfigError

        raise ConfigError("--gpus-per-worker is what each Ray worker asks for: add --workers N or --ray-address")
    return placement


def cmd_bench_cluster(args) -> int:
    from .cluster_bench import print_cluster_table, run_cluster_bench

    r = run_cluster_bench(knobs=args.knobs, windows=args.windows, window_s=args.window_seconds, stride=args.stride,
                          out_size=args.size, workers=args.workers, out_dir=args.out)
    print_cluster_table(r)
    print(f"written: {args.out}/cluster.json")
    return 0 if all(run["same_numbers_as_in_process"] for run in r["runs"]) else 1


def cmd_bench_scoring(args) -> int:
    from .scoring_bench import print_scoring_table, run_scoring_bench

    r = run_scoring_bench(out_dir=args.out, duration_s=args.duration, size=args.size, flip_every=args.flip_every,
                          profile_ticks=args.profile_ticks)
    print_scoring_table(r)
    print(f"written: {args.out}/scoring.json")
    return 0 if r["identical_to_libraries"] else 1


def cmd_bench_trade(args) -> int:
    from .trade import KNOBS, print_trade_tables, run_trade_bench

    knobs = args.knobs or tuple(KNOBS)
    result = run_trade_bench(scenes=args.scenes, knobs=knobs, windows=args.windows, window_s=args.window_seconds,
                             stride=args.stride, out_size=args.size, flip_every=args.flip_every, seed=args.seed,
                             placement=placement_of(args), out_dir=args.out)
    print_trade_tables(result)
    print(f"written: {args.out}/trade.json, " + ", ".join(f"trade_{k}.png" for k in knobs))
    return 0


def demo_client_args(args) -> tuple:
    """The client options ``pibr demo`` passes on: only those the user set."""
    from pibr.protocol.errors import ConfigError

    if (args.ipd_mm is not None or args.anaglyph or args.eye_fov_deg is not None) and not args.stereo:
        raise ConfigError("--ipd-mm, --anaglyph and --eye-fov-deg need two eyes: add --stereo cyclops, alternate "
                          "or per-eye")
    out = ("--motion", args.motion) if args.motion else ()
    if args.stereo:
        out += ("--stereo", args.stereo)
    if args.ipd_mm is not None:
        out += ("--ipd-mm", str(args.ipd_mm))
    if args.eye_fov_deg is not None:
        out += ("--eye-fov-deg", ",".join(f"{a:g}" for a in args.eye_fov_deg))
    if args.live is not None:
        from .processes import free_port

        port = args.live or free_port()
        print(f"pibr demo: the client's live view at http://127.0.0.1:{port}/ while it streams", flush=True)
        out += ("--live", str(port))
    return out + (("--anaglyph",) if args.anaglyph else ())


def cmd_demo(args) -> int:
    from .demo import print_report, run_demo

    from pibr.scenes.registry import with_up

    client_args = demo_client_args(args)
    metrics = run_demo(out_dir=args.out, scene=with_up(args.scene, args.up), trace=args.trace, start_s=args.start,
                       duration_s=args.duration, rate_hz=args.rate, size=args.size, latency_ms=args.latency_ms,
                       methods=args.method, clock=args.clock, flip_every=args.flip_every, anchor=args.anchor,
                       server_args=("--depth-codec", args.depth_codec), client_args=client_args)
    print_report(metrics, args.out)
    return 0


def cmd_evaluate(args) -> int:
    from .evaluate import evaluate_run, summary_table

    metrics = evaluate_run(args.run, scene_spec=args.scene, flip_every=args.flip_every, workers=args.workers,
                           side_by_side=not args.no_video)
    print(summary_table(metrics))
    print(f"written: {args.run}/metrics.json, metrics_frames.csv, quality.png"
          + ("" if args.no_video else ", side_by_side.mp4"))
    return 0


def cmd_bench_server(args) -> int:
    from .pipeline_bench import bench_server, print_server_table

    result = bench_server(scene_spec=args.scene, trace=args.trace, frames=args.frames, view_size=args.view_size,
                          projections=args.projection, extra_view=args.extra_view, bitrate_kbps=args.bitrate_kbps,
                          edge_angles=args.max_edge_deg, out_dir=args.out,
                          lod={"on": (True,), "off": (False,), "both": (False, True)}[args.lod],
                          accuracy=args.accuracy, cube_scale=args.cube_scale)
    print_server_table(result)
    return 0


def cmd_bench_client(args) -> int:
    from .pipeline_bench import bench_client, print_client_table

    result = bench_client(scene_spec=args.scene, trace=args.trace, frames=args.frames, view_size=args.view_size,
                          out_size=args.size, methods=args.method, out_dir=args.out)
    print_client_table(result)
    return 0


def cmd_bench_coverage(args) -> int:
    from .coverage import print_coverage_table, run_coverage_bench

    result = run_coverage_bench(scene_spec=args.scene, windows=args.windows, latency_ms=args.latency_ms,
                                rate_hz=args.rate, view_size=args.view_size, out_size=args.size, offset=args.offset,
                                stride=args.stride, placement=placement_of(args), out_dir=args.out)
    print_coverage_table(result)
    print(f"written: {args.out}/coverage.json, {args.out}/coverage.png")
    return 0


def cmd_bench_ibr(args) -> int:
    from pibr.protocol.errors import ConfigError

    from .ibr_bench import print_ibr_tables, run_ibr_bench

    bad = [lv for lv in args.lod_levels if lv not in ("original", "proxy", "box")]
    if bad:
        raise ConfigError(f"--lod-levels: unknown level(s) {', '.join(bad)}; expected original, proxy, box")
    r = run_ibr_bench(scene_spec=args.scene, windows=args.windows, latency_ms=args.latency_ms, rate_hz=args.rate,
                      view_size=args.view_size, out_size=args.size, stride=args.stride, lod_targets=args.lod_targets,
                      lod_levels=args.lod_levels, speed_sizes=args.speed_sizes, speed_frames=args.speed_frames,
                      out_dir=args.out)
    print_ibr_tables(r)
    print(f"written: {args.out}/ibr.json")
    return 0


def cmd_bench_codec(args) -> int:
    from .codec_bench import (DEFAULT_LOG_BITS, DEFAULT_THRESHOLDS, DEFAULT_TOTALS_KBPS, print_codec_table,
                              run_codec_bench)

    opts = dict(scene_spec=args.scene, windows=args.windows, window_s=args.duration, view_size=args.view_size,
                thresholds=args.thresholds or DEFAULT_THRESHOLDS, log_bits=args.log_bits or DEFAULT_LOG_BITS,
                totals_kbps=args.totals_kbps or DEFAULT_TOTALS_KBPS, e2e_windows=args.e2e_windows,
                out_size=args.size, out_dir=args.out, plot_path=args.plot)
    if args.quick:
        opts.update(windows=args.windows[:2], window_s=min(args.duration, 1.0), view_size=(256, 256),
                    thresholds=args.thresholds or (3.5, 16.0, 64.0), e2e_windows=1, out_size=(480, 270))
    r = run_codec_bench(**opts)
    print_codec_table(r)
    print(f"written: {args.out}/codec.json, {args.out}/codec.png" + (f", {args.plot}" if args.plot else ""))
    return 0


def cmd_bench_proxy_speed(args) -> int:
    from .proxy_speed import print_table, run
    from .results import write_result

    r = run(args.sizes, args.frames, args.repeats, args.scene)
    print_table(r)
    write_result(args.out, "proxy_speed.json", {"benchmark": "proxy-speed", "scene": args.scene,
                                                 "window": "evaluation windows (speed only)", "sizes": r})
    print(f"written: {args.out}/proxy_speed.json")
    return 0


def cmd_bench_codec_speed(args) -> int:
    from .codec_speed import print_codec_speed, run_codec_speed

    r = run_codec_speed(scene_spec=args.scene, windows=args.windows, window_s=args.duration, fps=args.fps,
                        view_size=args.view_size, baseline=args.baseline, out_dir=args.out)
    print_codec_speed(r)
    print(f"written: {args.out}/codec_speed.json")
    return 0


def cmd_bench_lod(args) -> int:
    from .lod_bench import print_lod_table, run_lod_bench

    r = run_lod_bench(scene_specs=args.scene, assets=args.asset, resolution=args.resolution,
                      target_fraction=args.fraction, out_dir=args.out, use_cache=not args.no_cache)
    print_lod_table(r)
    print(f"written: {args.out}/lod.json")
    return 0


def cmd_bench_offset(args) -> int:
    from .offset_search import search_offset

    # argparse runs the type on string defaults too: the ranges arrive as lists
    r = search_offset(scene_spec=args.scene, windows=args.windows, latency_ms=args.latency_ms,
                      frames_per_window=args.frames, forward=args.forward, up=args.up, tilt=args.tilt,
                      method=args.method, view_size=args.view_size, out_size=args.size, objective=args.objective,
                      out_dir=args.out)
    b = r["best"]
    print(f"pibr bench optimize-offset: {r['method']} search, {r['evaluations']} offsets x {r['frames']} frames")
    print(f"best offset: forward {b['forward']:g} m, up {b['up']:g} m, tilt {b['tilt']:g} deg down -> "
          f"{100 * b['missing']:.2f} % missing pixels")
    print(f"use it: pibr serve --extra-offset {b['forward']:g},{b['up']:g},{b['tilt']:g}")
    print(f"written: {args.out}/offset_search.json, {args.out}/offset_search.png")
    return 0


def cmd_bench_upsampling(args) -> int:
    from dataclasses import replace

    from pibr.client.colour_rebuild import DEFAULT_SETTINGS

    from .upsampling_bench import print_upsampling_table, run_upsampling_bench

    given = {k: getattr(args, k) for k in ("spatial_sigma", "sample_sigma", "decay", "max_confidence",
                                            "depth_tolerance") if getattr(args, k) is not None}
    settings = replace(DEFAULT_SETTINGS, **given)
    for k, codec in enumerate(args.depth_codec):
        name = "upsampling.json" if len(args.depth_codec) == 1 else f"upsampling-{codec}.json"
        r = run_upsampling_bench(scene_spec=args.scene, windows=args.windows, still_frames=args.still_frames,
                                 moving_s=args.moving, fps=args.fps, view_size=args.view_size, depth_codec=codec,
                                 settings=settings, stride=args.stride, out_dir=args.out, result_name=name)
        if k:
            print()
        print_upsampling_table(r)
        print(f"written: {args.out}/{name}")
    return 0


def cmd_bench_levels(args) -> int:
    from .levels_bench import print_levels_table, run_levels_bench

    r = run_levels_bench(scene_spec=args.scene, methods=args.method, windows=args.windows, latency_ms=args.latency_ms,
                         rate_hz=args.rate, stride=args.stride, view_size=args.view_size, out_size=args.size,
                         out_dir=args.out)
    print_levels_table(r)
    print(f"written: {args.out}/levels.json (its costs_ms: pibr client --cost-table {args.out}/levels.json)")
    return 0
