"""Client re-rendering methods, by name. Each is a :class:`~pibr.client.methods.base.Method`."""
from __future__ import annotations

from .base import Method
from .direction_warp import NoCompensation, RotationWarp

METHODS: dict[str, type[Method]] = {m.name: m for m in (NoCompensation, RotationWarp)}


def method_names() -> list[str]:
    return list(METHODS)


def make_method(name: str, ctx, output, config) -> Method:
    from pibr.protocol.errors import ConfigError

    if name not in METHODS:
        raise ConfigError(f"unknown method {name!r}; choose from {', '.join(METHODS)}")
    return METHODS[name](ctx, output, config)
