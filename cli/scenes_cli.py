"""``pibr scenes``: the scenes package's listing and summaries (scenes/cli.py), and ``--plan NAME``:
what the server would model for that scene and a client, and why (server/scene_plan.py). It lives
here because the plan is the server's and scenes/ must not import the server."""
from __future__ import annotations

import json


def register(subparsers) -> None:
    from pibr.common import arguments
    from pibr.protocol.depth_codecs import AUTO, DEPTH_CODECS
    from pibr.scenes import cli as scenes_cli

    p = scenes_cli.register(subparsers)
    g = p.add_argument_group("plan (--plan SPEC)")
    g.add_argument("--plan", metavar="SPEC",
                   help="print the server's plan for this scene: extra view (measured coverage), motion, proxy or "
                        "box per object, view size for the output, depth codec for the bandwidth")
    g.add_argument("--output", type=arguments.size, default=(960, 540), metavar="WxH",
                   help="the client's output size (default 960x540)")
    g.add_argument("--fov", type=float, default=90.0, help="the client's horizontal field of view, degrees (default 90)")
    g.add_argument("--bandwidth-kbps", type=float, default=0.0, metavar="KBPS",
                   help="the bandwidth the client states (default 0: none)")
    g.add_argument("--extra-view", choices=("auto", "on", "off"), default="auto", help="as 'pibr serve' (default auto)")
    g.add_argument("--depth-codec", choices=(AUTO, *DEPTH_CODECS), default=AUTO,
                   help="as 'pibr serve' (default auto)")
    g.add_argument("--view-size", type=arguments.size, default=None, metavar="WxH", help="as 'pibr serve' (default: for the output)")
    g.add_argument("--bitrate-kbps", type=float, default=16000.0, help="as 'pibr serve' (default 16000)")
    g.add_argument("--edge-kbps", type=float, default=0.0, help="as 'pibr serve' (default 0: a fixed threshold)")
    p.set_defaults(func=run)


def run(args) -> int:
    if not args.plan:
        from pibr.scenes import cli as scenes_cli

        return scenes_cli.run(args)
    from pibr.scenes.registry import with_up

    plan = plan_for(with_up(args.plan, args.up), output=args.output, fov_deg=args.fov,
                    bandwidth_kbps=args.bandwidth_kbps, extra_view=args.extra_view, depth_codec=args.depth_codec,
                    view_size=args.view_size, bitrate_kbps=args.bitrate_kbps, edge_kbps=args.edge_kbps)
    if args.json:
        print(json.dumps(plan, indent=2))
    else:
        from pibr.server.scene_plan import format_plan

        print(format_plan(plan))
    return 0


def plan_for(spec: str, output=(960, 540), fov_deg: float = 90.0, bandwidth_kbps: float = 0.0,
             extra_view: str = "auto", depth_codec: str = "auto", view_size=None, bitrate_kbps: float = 16000.0,
             edge_kbps: float = 0.0, progress: bool = True) -> dict:
    """The plan a server with these settings makes for ``spec`` and a client with this output and
    bandwidth that asks for proxies, as JSON (what the client's session.json records)."""
    from pibr.protocol.errors import ConfigError, MalformedMessage
    from pibr.common.gl import create_context
    from pibr.protocol.messages import Hello, OutputConfig
    from pibr.scenes.lod_cache import lods_for_scene
    from pibr.scenes.registry import load_scene
    from pibr.server.config import ServerConfig
    from pibr.server.scene_plan import cached_extra_view, decide_proxies
    from pibr.server.session_plan import extra_offset_for, scene_plan

    from pibr.server.config import EdgeSettings

    cfg = ServerConfig(extra_view=extra_view, depth_codec=depth_codec, view_size=view_size, bitrate_kbps=bitrate_kbps,
                       edge=EdgeSettings(kbps=edge_kbps))
    try:   # the bounds a Hello from a client would be held to
        hello = Hello.parse(Hello(output=OutputConfig(output[0], output[1], fov_deg), want_proxies=True,
                                  bandwidth_kbps=bandwidth_kbps).serialize())
    except MalformedMessage as exc:
        raise ConfigError(f"bad client settings: {exc}") from None
    scene = load_scene(spec)
    settings = cfg.proxy_settings
    lods = lods_for_scene(scene, resolution=settings.resolution, target_fraction=settings.target_fraction,
                          progress=progress)
    coverage = None
    if cfg.extra_view == "auto":
        ctx = create_context()
        try:
            coverage = cached_extra_view(ctx, scene, extra_offset_for(cfg, scene), cfg.projection)
        finally:
            ctx.release()
    plan = scene_plan(cfg, scene, hello, coverage, decide_proxies(scene, lods)).to_json()
    plan["lod"] = lod_distances(scene, lods, plan["proxies"]["value"])
    return plan


def lod_distances(scene, lods: dict, levels: dict, target_px: float | None = None) -> dict:
    """What a client's LoD selection (client/lod_select.py) draws of each object, by distance:
    {"target_px", "angle_rad", "reason", "objects": {name: {"original_within_m", "level_within_m"}}}
    (the original mesh nearer than the first, the object's proxy level -- its encaging proxy or its
    box, as ``levels`` says -- nearer than the second, its box beyond)."""
    from pibr.client.lod_select import DEFAULT_TARGET_PX, REFERENCE_FOCAL_PX, switch_distances
    from pibr.server.proxies import proxy_objects

    target = DEFAULT_TARGET_PX if target_px is None else target_px
    objects = proxy_objects(scene, lods, levels)
    d = switch_distances(objects, target)
    return {"target_px": target, "angle_rad": round(target / REFERENCE_FOCAL_PX, 6),
            "reason": f"--lod-pixels {target:g}: the finest level whose mean edge subtends {target:g} px of a 960-px-wide "
                      f"90-degree output ({target / REFERENCE_FOCAL_PX:.4f} rad), at every output size",
            "objects": {o.name: {"original_within_m": round(float(a), 3), "level_within_m": round(float(b), 3)}
                        for o, (a, b) in zip(objects, d)}}
