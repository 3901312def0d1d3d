"""Scenes: the model (:mod:`.scene`), built-in scenes (:mod:`.builtin`, :mod:`.registry`), scene
descriptions and asset files (:mod:`.description`, :mod:`.loaders`, :mod:`.textures`), mesh
primitives (:mod:`.primitives`), animation, and the encaging LoD proxies (:mod:`.lod`,
:mod:`.voxelize`, :mod:`.tessellate`) with their cache (:mod:`.lod_cache`).

Imports only :mod:`pibr.protocol` (DESIGN.md, Layout).
"""
