"""The client's quality levels, kept by the deadline controller (pibr.common.quality) so every
tick is drawn in time: each tick has one output interval to draw every method the client runs,
less a margin for the rest of the tick's work (uploading a new frame, reading the images back,
handing them to the recorders), measured as it goes.

Each method has levels, best first (:func:`levels_for`): the method at full resolution, without
inpainting, at lower render scales (client/render_scale.py), with coarser proxies, and last, the
cheapest there is: ``rotation`` of the newest frame at a low scale, so that something is always
shown rather than nothing.
"""
from __future__ import annotations

from pibr.common.quality import Level

#: --deadline: auto (on for the wall clock, and for the virtual clock given a cost table), on, off.
DEADLINE_MODES = ("auto", "on", "off")


#: The last resort of every method: the newest frame turned to the current orientation, at a
#: third of the output's resolution (a full-screen pass over a ninth of the pixels).
FALLBACK = Level("rotation at 1/3", "rotation", 1 / 3)


def levels_for(method: str) -> tuple[Level, ...]:
    """The quality levels of ``method``, best first, ending with the fallback.

    ``proxy`` first leaves out inpainting (its second geometry pass), then renders fewer pixels,
    then draws coarser proxies; every other method renders fewer pixels. Chosen by measurement
    (``pibr bench levels``, room at 960x540 on llvmpipe): the proxy levels reach 0.32x the top
    level's time, where fixed costs (its passes, the proxies' vertices, the upsampling) leave
    little to gain; the fallback 0.14x. Not levels, because they were not cheaper or left holes:
    ``--no-carve`` (0.39x at 1/3, 14 % holes), the box level for every object (0.33x at 1/3,
    DSSIM 0.100 against 0.070), scales under 1/4 (1/5: 0.28x, DSSIM 0.090)."""
    if method == "proxy":
        no_inpaint = {"inpaint": False}
        coarse = {"inpaint": False, "lod_target_px": 24.0}
        return (Level("full", "proxy"), Level("no inpainting", "proxy", 1.0, no_inpaint),
                Level("3/4, no inpainting", "proxy", 0.75, no_inpaint),
                Level("1/2, no inpainting", "proxy", 0.5, no_inpaint),
                Level("1/2, coarse LoD", "proxy", 0.5, coarse),
                Level("1/3, coarse LoD", "proxy", 1 / 3, coarse), Level("1/4, coarse LoD", "proxy", 0.25, coarse),
                FALLBACK)
    if method in ("none", "rotation"):   # full-screen passes: only fewer pixels make them cheaper
        return (Level("full", method), Level("1/2", method, 0.5), Level("1/3", method, 1 / 3))
    return (Level("full", method), Level("3/4", method, 0.75), Level("1/2", method, 0.5), FALLBACK)
