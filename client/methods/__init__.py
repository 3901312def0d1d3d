"""Client re-rendering methods, by name. Each is a :class:`~pibr.client.methods.base.Method`."""
from __future__ import annotations

import inspect

from .base import Method
from .direction_warp import NoCompensation, RotationWarp
from .grid_warp import GridWarp
from .homography import HomographyWarp
from .iterative_warp import IterativeWarp
from .mesh_warp import CoarseMeshWarp, MeshWarp
from .proxy import ProxyIBR
from .quadtree_warp import QuadtreeWarp
from .splat import PointSplat

METHODS: dict[str, type[Method]] = {m.name: m for m in (NoCompensation, RotationWarp, HomographyWarp, PointSplat,
                                                        MeshWarp, CoarseMeshWarp, QuadtreeWarp, IterativeWarp,
                                                        GridWarp, ProxyIBR)}


def method_names() -> list[str]:
    return list(METHODS)


def needs_proxies(names) -> bool:
    return any(METHODS[n].needs_proxies for n in names if n in METHODS)


def quadtree_threshold(names, options: dict) -> float:
    """What the client asks the server for in ``Hello.quadtree_threshold``: 0 unless a method in
    ``names`` needs the views' quadtrees, else the ``threshold`` option or that method's default."""
    wanted = [n for n in names if getattr(METHODS.get(n), "needs_quadtree", False)]
    if not wanted:
        return 0.0
    if options.get("threshold") is not None:
        return float(options["threshold"])
    return float(inspect.signature(METHODS[wanted[0]].__init__).parameters["threshold"].default)


def method_options(name: str) -> tuple[str, ...]:
    """The keyword arguments method ``name`` takes: its knobs, and for ``proxy`` the session's
    pose history (``poses``) and a benchmark's ``oracle_pose``."""
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
