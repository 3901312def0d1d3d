"""Find a scene by spec: a built-in name, a scene description file, or an asset file.

Built scenes are cached in-process by (spec, file modification time): loading the same
spec again returns the *same* :class:`Scene` object (treat it as read-only), and editing
a file makes the next load rebuild it.
"""
from __future__ import annotations

import os
import threading
from pathlib import Path

from pibr.protocol.errors import SceneError

from .scene import Scene

DEFAULT_SCENE = "room"

_cache: dict[tuple[str, int | None], Scene] = {}
_cache_lock = threading.Lock()  # the server builds scenes in executor threads


def _builtins() -> dict:
    from .builtin import BUILTIN_SCENES

    return BUILTIN_SCENES


def available_scenes() -> dict[str, str]:
    """Built-in scene name -> one-line description."""
    return {name: description for name, (description, _builder) in _builtins().items()}


def _find(spec):
    """-> (cache key, builder) for ``spec``; SceneError for an unknown name or a missing file."""
    from .description import is_description_path, load_description
    from .loaders import load_asset_scene

    spec = os.fspath(spec)
    if not isinstance(spec, str) or not spec.strip():
        raise SceneError(f"a scene spec must be a non-empty string, got {spec!r}")
    builtins = _builtins()
    if spec in builtins:
        return (spec, None), builtins[spec][1]
    path = Path(spec).expanduser()
    if not path.is_file():
        if path.suffix or os.sep in spec or "/" in spec:
            raise SceneError(f"scene file {spec!r} does not exist")
        raise SceneError(f"unknown scene {spec!r}; built-in scenes: {', '.join(sorted(builtins))} "
                         "(or give a .toml/.json scene description or an asset file)")
    resolved = path.resolve()
    key = (str(resolved), resolved.stat().st_mtime_ns)
    if is_description_path(resolved):
        return key, lambda: load_description(path)
    return key, lambda: load_asset_scene(path)


def check_scene_spec(spec) -> None:
    """Raise SceneError if ``spec`` names no built-in scene and no existing file (nothing is loaded)."""
    _find(spec)


def load_scene(spec) -> Scene:
    """The scene named by ``spec``: a built-in name (see :func:`available_scenes`), a scene
    description (``.toml`` / ``.json``, see :mod:`pibr.scenes.description`) or an asset file
    (``.obj``, ``.glb``, ``.gltf``, ``.ply``, ... see :mod:`pibr.scenes.loaders`)."""
    key, build = _find(spec)
    with _cache_lock:
        cached = _cache.get(key)
    if cached is not None:
        return cached
    scene = build()
    if not isinstance(scene, Scene):
        raise SceneError(f"scene {spec!r}: builder returned {type(scene).__name__}, not a Scene")
    with _cache_lock:
        # A file that changed replaces its older versions instead of piling them up.
        for old in [k for k in _cache if k[0] == key[0] and k != key]:
            del _cache[old]
        _cache[key] = scene
    return scene


def clear_cache() -> None:
    """Forget every built scene (tests, or to free memory)."""
    with _cache_lock:
        _cache.clear()
