"""Client re-rendering methods, by name. Each is a :class:`~pibr.client.methods.base.Method`."""
from __future__ import annotations

import inspect

from .base import Method
from .direction_warp import NoCompensation, RotationWarp
from .homography import HomographyWarp
from .mesh_warp import CoarseMeshWarp, MeshWarp
from .proxy import ProxyIBR
from .splat import PointSplat

METHODS: dict[str, type[Method]] = {m.name: m for m in (NoCompensation, RotationWarp, HomographyWarp, PointSplat,
                                                        MeshWarp, CoarseMeshWarp, ProxyIBR)}


def method_names() -> list[str]:
    return list(METHODS)


def needs_proxies(names) -> bool:
    return any(METHODS[n].needs_proxies for n in names if n in METHODS)


def method_options(name: str) -> tuple[str, ...]:
    """The knobs (keyword arguments) method ``name`` takes."""
    params = inspect.signature(METHODS[name].__init__).parameters
    return tuple(p for p in params if p not in ("self", "ctx", "output", "config", "proxies"))


def make_method(name: str, ctx, output, config, proxies=None, **options) -> Method:
    """``options`` holds knobs of any method (tau, step, ...); each method takes its own."""
    from pibr.protocol.errors import ConfigError

    if name not in METHODS:
        raise ConfigError(f"unknown method {name!r}; choose from {', '.join(METHODS)}")
    cls = METHODS[name]
    own = {k: v for k, v in options.items() if k in method_options(name) and v is not None}
    if cls.needs_proxies:
        return cls(ctx, output, config, proxies=proxies, **own)
    return cls(ctx, output, config, **own)
