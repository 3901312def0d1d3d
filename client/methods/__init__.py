"""Client re-rendering methods, by name. Each is a :class:`~pibr.client.methods.base.Method`."""
from __future__ import annotations

from .base import Method
from .direction_warp import NoCompensation, RotationWarp
from .proxy import ProxyIBR

METHODS: dict[str, type[Method]] = {m.name: m for m in (NoCompensation, RotationWarp, ProxyIBR)}


def method_names() -> list[str]:
    return list(METHODS)


def needs_proxies(names) -> bool:
    return any(METHODS[n].needs_proxies for n in names if n in METHODS)


def make_method(name: str, ctx, output, config, proxies=None, **options) -> Method:
    """``options`` (e.g. tau, lod_target_px) go to the methods that take them."""
    from pibr.protocol.errors import ConfigError

    if name not in METHODS:
        raise ConfigError(f"unknown method {name!r}; choose from {', '.join(METHODS)}")
    cls = METHODS[name]
    if cls.needs_proxies:
        return cls(ctx, output, config, proxies=proxies, **options)
    return cls(ctx, output, config)
