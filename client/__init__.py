"""The client (``pibr client``): replays a head trace against a server and re-renders its current
view at a fixed output rate.

:mod:`.app` runs the session over :mod:`.connection` (the sans-I/O rules are
:mod:`pibr.protocol.sides`) with its settings (:mod:`.config`); frames are decoded by
:mod:`.video` and the depth decoder of the session's codec (:mod:`.depth_decoders`,
:mod:`.diffusion`), their motion flow by :mod:`.motion_flow`, and uploaded by
:mod:`.frame_textures`; the re-rendering methods are chosen by name (:mod:`.methods`), ``proxy``
with :mod:`.lod_select`, :mod:`.object_motion` and :mod:`.back_faces`; :mod:`.recorder` keeps
what was shown.

The client knows only what it receives: it imports :mod:`pibr.protocol` and :mod:`pibr.common`,
never the scenes, the server or the benchmarks (DESIGN.md, Layout).
"""
