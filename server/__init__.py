"""The rendering server (``pibr serve``) and the latency relay (``pibr relay``).

A session's frames come from one pipeline (:mod:`.pipeline`), built from the server's settings
(:mod:`.config`), the scene and the client's Hello through the session plan (:mod:`.scene_plan`,
:mod:`.session_plan`): the frame producer (:mod:`.producer`: :mod:`.renderer` with
:mod:`.shaders` into :mod:`.render_target`, :mod:`.packer`), the H.264 encoder (:mod:`.video`),
the depth encoder of the session's codec (:mod:`.depth_encoders`, :mod:`.edge_extract`), the
quadtrees (:mod:`.quadtree`), object poses and motion flow (:mod:`.object_poses`,
:mod:`.motion_flow`). :mod:`.app` and :mod:`.session` run it over asyncio, sharing the GL
thread and encoder pool fairly (:mod:`.fair_queue`); :mod:`.relay` injects latency.
:mod:`.coverage` is the geometric definition of a hole, which the plan measures with.

Imports :mod:`pibr.protocol`, :mod:`pibr.common` and :mod:`pibr.scenes` (DESIGN.md, Layout).
"""
