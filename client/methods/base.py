"""What every client re-rendering method provides."""
from __future__ import annotations

import dataclasses

import numpy as np

from pibr.protocol.frustum import half_and_centre
from pibr.protocol.messages import OutputConfig
from pibr.protocol.pose import Pose
from pibr.protocol.session import SessionConfig

FULLSCREEN_VS = """
#version 410
in vec2 in_pos;
void main() { gl_Position = vec4(in_pos, 0.0, 1.0); }
"""


def output_tan_half(output: OutputConfig) -> tuple[float, float]:
    """Half the width and height of the output camera's image plane at distance 1 (for a
    symmetric frustum, tan of half its horizontal and vertical field of view)."""
    return half_and_centre(output.tangents())[0]


def output_tan_centre(output: OutputConfig) -> tuple[float, float]:
    """Where the output camera's image centre lies on its image plane at distance 1: (0, 0) for
    a symmetric frustum (a ray through ndc (x, y) is (centre + (x, y) * tan_half, -1))."""
    return half_and_centre(output.tangents())[1]


class Method:
    """A way to turn the newest server frame into the current output image.

    Subclasses draw into the bound output framebuffer (RGBA8, row 0 on top; alpha 0 marks the
    method's own holes: pixels where it accepted no sample of a transmitted view, whatever colour
    it then shows there; see README "Reading the metrics") on the client's GL thread.
    """

    name = "?"
    needs_proxies = False
    #: Needs every frame to carry the views' depth quadtrees (Hello.quadtree_threshold).
    needs_quadtree = False
    #: Draws from the extra view as well as the primary (instances may say otherwise: it also
    #: depends on whether the session has one). Benchmarks count geometric holes against the
    #: views a method uses.
    uses_extra_view = False
    #: Points, triangles or quads drawn in the last render (0 for full-screen passes).
    last_primitives = 0
    #: How moving objects are brought to the display time (the ``motion`` knob): ``flow`` warps
    #: the primary view's moving pixels along their motion flow (client/flow_warp.py) for every
    #: method that re-projects the primary view; the per-object modes need proxies.
    motion = "static"

    def __init__(self, ctx, output: OutputConfig, config: SessionConfig):
        self.ctx, self.output, self.config = ctx, output, config

    def look_through(self, frustum) -> None:
        """Draw the renders that follow through ``frustum`` ((left, right, down, up) tangents: one
        eye's, protocol/frustum.py; None: the output's symmetric one), on the same pixels."""
        frustum = None if frustum is None else tuple(float(v) for v in frustum)
        if frustum != self.output.frustum:
            self.output = dataclasses.replace(self.output, frustum=frustum)
            self._frustum_changed()

    def _frustum_changed(self) -> None:
        """Bring what depends on the output camera's frustum (projection, ray uniforms) to
        ``self.output``; every method whose drawing depends on it says how."""
        raise NotImplementedError(f"{self.name} cannot draw through an asymmetric frustum")

    def set_motion(self, motion: str) -> None:
        """Take the ``motion`` knob: ``flow``, or a per-object mode (static, velocity, accel,
        oracle), which a method without proxies has no objects for: it shows them where the
        frame does."""
        from pibr.protocol.errors import ConfigError

        from ..object_motion import MOTION_MODES

        if motion not in MOTION_MODES:
            raise ConfigError(f"unknown motion extrapolation {motion!r}; choose from {', '.join(MOTION_MODES)}")
        self.motion = motion

    def flow_time(self, scene_t: float) -> float | None:
        """The time to extrapolate the primary view to (``textures.use(...)``): ``scene_t`` under
        ``flow``, else None (the frame as decoded)."""
        return scene_t if self.motion == "flow" else None

    def render(self, out_pose: Pose, frame, textures, scene_t: float = 0.0) -> None:
        """Draw the view at ``out_pose`` from ``frame`` (protocol Frame) whose atlas is in ``textures``;
        ``scene_t`` is the scene time of the display (where moving objects' proxies are)."""
        raise NotImplementedError

    def release(self) -> None:
        pass


def fullscreen_quad(ctx, prog):
    vbo = ctx.buffer(np.array([-1, -1, 1, -1, -1, 1, 1, 1], dtype="f4").tobytes())
    return vbo, ctx.vertex_array(prog, [(vbo, "2f", "in_pos")])
