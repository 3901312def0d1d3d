"""The proxy bundle of a scene: every object's original mesh, its encaging simplified mesh
(scenes/lod.py, cached on disk) and its box, zstd-compressed once per scene and cut into
``ProxyChunk`` messages for each session that asks.

An object whose proxy is not worth its triangles (scene_plan.decide_proxies: not tighter than its
box by a margin) is sent its box as its proxy level: the client draws it like any proxy."""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

from pibr.protocol.messages import ProxyChunk
from pibr.protocol.proxy import BundleInfo, ProxyObject, compress_bundle, encode_bundle, split_chunks

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ProxySettings:
    resolution: int = 128          # voxels along an object's longest side
    target_fraction: float = 0.005  # proxy triangles / original triangles


@dataclass
class ProxyBundle:
    compressed: bytes
    raw_bytes: int
    objects: int
    triangles: dict          # level -> total triangles
    seconds: float
    levels: object = field(default=None)   # scene_plan.Decision: which objects get their proxy, which their box

    def chunks(self, chunk_bytes: int) -> list[ProxyChunk]:
        parts = split_chunks(self.compressed, chunk_bytes)
        return [ProxyChunk(i, len(parts), len(self.compressed), p) for i, p in enumerate(parts)]

    def info(self, chunk_bytes: int) -> dict:
        """What the Welcome announces (protocol.proxy.BundleInfo) when sent in ``chunk_bytes`` chunks."""
        return BundleInfo(self.objects, len(self.compressed), self.raw_bytes, chunk_bytes, self.triangles).to_json()


def proxy_objects(scene, lods: dict, levels: dict) -> list[ProxyObject]:
    """Per object of ``scene`` what the client receives: its original mesh and its proxy level,
    the encaging proxy or the box as ``levels`` ({"proxy": [...], "box": [...]}) says."""
    boxed = set(levels["box"])
    objects = []
    for obj in scene.objects:
        lod = lods[obj.name]
        m = obj.mesh
        proxy = lod.box if obj.name in boxed and lod.kind != "empty" else lod.proxy
        objects.append(ProxyObject(obj.name, obj.transform, obj.is_dynamic, m.bounds().astype("f8"),
                                   (m.vertices, m.faces), (proxy.vertices, proxy.faces)))
    return objects


def build_bundle(scene, settings: ProxySettings = ProxySettings(), progress: bool = False) -> ProxyBundle:
    """LoDs for every object (from the cache when it has them), packed and compressed."""
    from pibr.scenes.lod_cache import lods_for_scene

    from .scene_plan import decide_proxies

    t0 = time.perf_counter()
    lods = lods_for_scene(scene, resolution=settings.resolution, target_fraction=settings.target_fraction,
                          progress=progress)
    levels = decide_proxies(scene, lods)
    objects = proxy_objects(scene, lods, levels.value)
    tris = {"original": sum(obj.mesh.triangle_count for obj in scene.objects),
            "proxy": sum(len(o.proxy[1]) for o in objects), "box": 12 * len(objects)}
    raw = encode_bundle(objects)
    bundle = ProxyBundle(compress_bundle(raw), len(raw), len(objects), tris, time.perf_counter() - t0, levels)
    log.info("proxies of %s: %d objects, %d -> %d triangles, %.1f MB -> %.1f MB zstd, %.1f s", scene.name,
             len(objects), tris["original"], tris["proxy"], len(raw) / 1e6, len(bundle.compressed) / 1e6,
             bundle.seconds)
    return bundle
