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


#: Options an asset file's spec may carry after a '#': ``statue.obj#up=z,units=cm``.
ASSET_OPTIONS = {"up": ("y", "z", "auto"), "units": None, "split": None}


def asset_spec(path: str, **options) -> str:
    """``path`` with asset options (None values left out) appended as the registry reads them."""
    given = {k: v for k, v in options.items() if v is not None}
    return path + ("#" + ",".join(f"{k}={v}" for k, v in given.items()) if given else "")


def with_up(spec: str, up: str | None) -> str:
    """``spec`` with an asset's up axis (``--up`` of the command line); None leaves it alone.
    SceneError when ``spec`` is no asset file (built-in scenes and descriptions have their own)."""
    if up is None:
        return spec
    from .loaders import is_asset_path

    if spec in _builtins() or not is_asset_path(spec.partition("#")[0]):
        raise SceneError(f"--up applies to an asset file, not to {spec!r} (a scene description sets 'up' per asset)")
    return asset_spec(spec, up=up)


def _split_options(spec: str) -> tuple[str, dict]:
    """``file.obj#up=z,units=cm`` -> ("file.obj", {"up": "z", "units": "cm"})."""
    path, sep, tail = spec.rpartition("#")
    if not sep or "=" not in tail or not path:
        return spec, {}
    options = {}
    for item in tail.split(","):
        key, eq, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not eq or key not in ASSET_OPTIONS:
            raise SceneError(f"scene {spec!r}: unknown asset option {item!r}; expected up=y|z|auto, units=NAME "
                             "or split=TRIANGLES")
        if key == "split":
            if not value.isdigit():
                raise SceneError(f"scene {spec!r}: split must be a whole number of triangles (0: none), got {value!r}")
            options[key] = int(value)
            continue
        choices = ASSET_OPTIONS[key]
        if choices is not None and value not in choices:
            raise SceneError(f"scene {spec!r}: {key} must be one of {', '.join(choices)}, got {value!r}")
        options[key] = value
    return path, options


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
    spec, options = _split_options(spec)
    path = Path(spec).expanduser()
    if not path.is_file():
        if path.suffix or os.sep in spec or "/" in spec:
            raise SceneError(f"scene file {spec!r} does not exist")
        raise SceneError(f"unknown scene {spec!r}; built-in scenes: {', '.join(sorted(builtins))} "
                         "(or give a .toml/.json scene description or an asset file)")
    resolved = path.resolve()
    key = (asset_spec(str(resolved), **options), resolved.stat().st_mtime_ns)
    if is_description_path(resolved):
        if options:
            raise SceneError(f"scene {spec!r}: asset options ({', '.join(options)}) go on the assets inside a "
                             "scene description, not on the description")
        return key, lambda: load_description(path)
    return key, lambda: load_asset_scene(path, **options)


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
