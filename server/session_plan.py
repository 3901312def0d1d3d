"""What a session will send, decided from the server's settings, the scene and the client's Hello."""
from __future__ import annotations

from pibr.protocol.atlas import ALIGN, build_layout
from pibr.protocol.depth import h264_quantizer
from pibr.protocol.errors import ConfigError
from pibr.protocol.messages import Hello
from pibr.protocol.session import SessionConfig, ViewConfig

from .config import PAPER_EXTRA_OFFSET, ServerConfig, extra_offset_pose
from .depth_stream import edge_quantizer
from .pipeline import ProducerSpec
from .quadtree import ROOT_TILE as QUADTREE_ROOT_TILE


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


def plan_session(cfg: ServerConfig, scene, hello: Hello, proxies: dict | None = None) -> tuple[SessionConfig, ProducerSpec]:
    depth_codec = hello.depth_codec or cfg.depth_codec
    if depth_codec not in ("h264", "edge"):
        raise ConfigError(f"unknown depth codec {depth_codec!r}; choose h264 or edge")
    use_extra = cfg.extra_view == "on" or (cfg.extra_view == "auto" and scene.extra_view)
    pw, ph = cfg.view_size
    extra_size = extra_view_size(cfg.view_size, cfg.extra_scale) if use_extra else None
    offset = extra_offset_for(cfg, scene) if use_extra else None
    edge = depth_codec == "edge"
    layout = build_layout((pw, ph), extra_size, depth_in_atlas=not edge)
    quantizer = edge_quantizer(scene.near, scene.far) if edge else h264_quantizer(scene.near, scene.far)
    # A scene with nothing moving sends no motion at all. One that moves sends its objects'
    # transforms and their motion flow with every frame, whatever the depth codec.
    motion = scene.is_dynamic
    options = {"projection": cfg.projection}
    if use_extra:   # whether the extra view's sky (distance 0) is sky, not also peeled pixels
        options["peel_marker"] = bool(cfg.peel_marker)
    quadtree = hello.quadtree_threshold > 0   # a quadtree payload in every frame, built from the float distances
    if quadtree:
        options["quadtree"] = {"threshold": hello.quadtree_threshold, "tile": QUADTREE_ROOT_TILE}
    config = SessionConfig(
        scene=scene.info(), clock=hello.clock, server_fps=cfg.fps,
        server_delay_us=int(round(cfg.server_delay_ms * 1000)),
        primary=ViewConfig(pw, ph), extra=ViewConfig(*extra_size) if extra_size else None,
        extra_offset=offset, atlas=layout, video_bitrate_kbps=cfg.bitrate_kbps, keyint=cfg.keyint,
        depth_codec=depth_codec, depth_bits=quantizer.bits, depth_min_code=quantizer.min_code,
        motion=motion, proxies=proxies, options=options)
    spec = ProducerSpec((pw, ph), layout, None if edge else quantizer, cfg.projection, extra_size, offset,
                        keep_distance=edge or quadtree, motion_dt=1.0 / cfg.fps if motion else None,
                        object_poses=motion,
                        low_colour=8 if edge and cfg.edge.perceptual else 0, mark_peeled=bool(cfg.peel_marker))
    return config, spec
