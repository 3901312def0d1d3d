"""What a session will send, decided from the server's settings, the scene and the client's Hello,
through the scene plan (scene_plan.py), which also travels in ``SessionConfig.options["plan"]``."""
from __future__ import annotations

from pibr.protocol.atlas import ALIGN, build_layout
from pibr.protocol.depth_codecs import depth_codec
from pibr.protocol.errors import ConfigError
from pibr.protocol.messages import Hello
from pibr.protocol.session import SessionConfig, ViewConfig

from .config import PAPER_EXTRA_OFFSET, ServerConfig, extra_offset_pose
from .producer import ProducerSpec
from .rate_control import server_levels
from .quadtree import ROOT_TILE as QUADTREE_ROOT_TILE
from .scene_plan import Decision, ScenePlan, decide_proxies, make_plan


def extra_offset_for(cfg: ServerConfig, scene):
    """The server's override, else the scene's own offset, else Reinert et al.'s."""
    if cfg.extra_offset is not None:
        return extra_offset_pose(*cfg.extra_offset)
    if scene.extra_view_offset is not None:
        return scene.extra_view_offset
    return extra_offset_pose(*PAPER_EXTRA_OFFSET)


def extra_view_size(view_size: tuple, scale: float) -> tuple[int, int]:
    """The extra view's (w, h): ``scale`` of the primary's, each side a multiple of the atlas
    alignment (at least one)."""
    return tuple(max(ALIGN, int(round(side * scale / ALIGN)) * ALIGN) for side in view_size)


def bandwidth_for(cfg: ServerConfig, hello: Hello) -> float | None:
    """The tighter of the client's stated bandwidth and the server's cap (kbit/s), None when neither is set."""
    stated = [b for b in (hello.bandwidth_kbps or None, cfg.bandwidth_kbps) if b is not None]
    return min(stated) if stated else None


def scene_plan(cfg: ServerConfig, scene, hello: Hello, coverage: dict | None = None,
               proxies: Decision | None = None) -> ScenePlan:
    """The plan of one session: ``coverage`` is the extra view's measurement (scene_plan.cached_extra_view;
    None: not measured), ``proxies`` the bundle's proxy/box decision (None: no proxies sent)."""
    return make_plan(scene, extra_view_mode=cfg.extra_view, coverage=coverage,
                     proxies=proxies if proxies is not None else decide_proxies(scene, None),
                     output=hello.output, view_size=cfg.view_size, asked_codec=hello.depth_codec,
                     server_codec=cfg.depth_codec, bandwidth_kbps=bandwidth_for(cfg, hello),
                     video_kbps=cfg.bitrate_kbps, edge_kbps=cfg.edge.kbps)


def plan_session(cfg: ServerConfig, scene, hello: Hello, proxies: dict | None = None, coverage: dict | None = None,
                 proxy_levels: Decision | None = None) -> tuple[SessionConfig, ProducerSpec]:
    """The session's parameters and its producer's spec, as :func:`scene_plan` decides them.

    proxies : the bundle's announcement (BundleInfo JSON) or None; proxy_levels : the bundle's
    proxy/box decision; coverage : the extra view's measurement (needed for ``extra_view`` auto to
    be measured rather than the scene's own setting)."""
    if hello.depth_codec:
        depth_codec(hello.depth_codec)   # ConfigError naming the choices
    if proxies is not None and proxy_levels is None:   # a bundle built by the caller (benchmarks)
        proxy_levels = Decision(None, "proxies sent as the caller built them: their levels are not planned here")
    plan = scene_plan(cfg, scene, hello, coverage, proxy_levels if proxies is not None else None)
    codec = depth_codec(plan.depth_codec.value["codec"])
    video_kbps = float(plan.depth_codec.value["video_kbps"])
    use_extra = bool(plan.extra_view.value)
    pw, ph = plan.view_size.value
    extra_size = extra_view_size((pw, ph), cfg.extra_scale) if use_extra else None
    offset = extra_offset_for(cfg, scene) if use_extra else None
    layout = build_layout((pw, ph), extra_size, depth_in_atlas=codec.in_atlas, colour_scale=cfg.colour_scale)
    quantizer = codec.quantizer(scene.near, scene.far)
    # A scene with nothing moving sends no motion at all. One that moves sends its objects'
    # transforms and their motion flow with every frame, whatever the depth codec.
    motion = bool(plan.motion.value)
    options = {"projection": cfg.projection, "plan": plan.to_json()}
    if cfg.rate_control == "on" and hello.clock == "real":
        # the frames' levels (server/rate_control.py), which each frame names by index
        options["server_levels"] = [lv.name for lv in server_levels(use_extra)]
    if use_extra:   # whether the extra view's sky (distance 0) is sky, not also peeled pixels
        options["peel_marker"] = bool(cfg.peel_marker)
    if cfg.predict != "none":   # frames rendered for the predicted pose; the client reports display ages
        options["predict"] = cfg.predict
    if cfg.adapt == "on":   # the client reports what arrives; frames say what the adaptation chose
        options["adapt"] = True
    if hello.stereo:   # the eyes the frames are rendered for (protocol/stereo.py)
        if hello.stereo != "cyclops" and cfg.colour_scale != 1.0:
            raise ConfigError(f"stereo {hello.stereo} interleaves the eyes' views in one stream; colour at scale "
                              f"{cfg.colour_scale:g} rebuilds each frame from the one before of the same view "
                              f"(serve with --colour-scale 1, or ask for cyclops)")
        options["stereo"] = {"reference": hello.stereo, "ipd_mm": hello.ipd_mm}
    quadtree = hello.quadtree_threshold > 0   # a quadtree payload in every frame, built from the float distances
    if quadtree:
        options["quadtree"] = {"threshold": hello.quadtree_threshold, "tile": QUADTREE_ROOT_TILE}
    config = SessionConfig(
        scene=scene.info(), clock=hello.clock, server_fps=cfg.fps,
        server_delay_us=int(round(cfg.server_delay_ms * 1000)),
        primary=ViewConfig(pw, ph), extra=ViewConfig(*extra_size) if extra_size else None,
        extra_offset=offset, atlas=layout, video_bitrate_kbps=video_kbps, keyint=cfg.keyint,
        depth_codec=codec.name, depth_bits=quantizer.bits, depth_min_code=quantizer.min_code,
        motion=motion, proxies=proxies, options=options, colour_scale=cfg.colour_scale)
    # depth in the atlas is packed from the views' distances; depth of its own is coded from them (float)
    spec = ProducerSpec((pw, ph), layout, quantizer if codec.in_atlas else None, cfg.projection, extra_size, offset,
                        keep_distance=not codec.in_atlas or quadtree, motion_dt=1.0 / cfg.fps if motion else None,
                        object_poses=motion,
                        low_colour=8 if not codec.in_atlas and cfg.edge.perceptual else 0,
                        mark_peeled=bool(cfg.peel_marker), colour_scale=cfg.colour_scale)
    return config, spec
