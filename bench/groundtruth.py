"""Ground truth: the full scene rendered in a perspective camera at each displayed pose and time."""
from __future__ import annotations

import numpy as np

from pibr.protocol.pose import Pose


class GroundTruth:
    """Renders ``width`` x ``height`` perspective views (horizontal FOV ``fov_deg``) of ``scene``.

    Creates its own GL context on the calling thread (bench code is synchronous).
    """

    def __init__(self, scene, width: int, height: int, fov_deg: float, ctx=None):
        from pibr.common.gl import create_context
        from pibr.server.render_target import RenderTarget
        from pibr.server.renderer import Renderer

        self._own_ctx = ctx is None
        self.ctx = create_context() if ctx is None else ctx
        self.scene, self.fov_deg = scene, fov_deg
        self.renderer = Renderer(self.ctx, scene, wide=False)
        self.target = RenderTarget(self.ctx, width, height)

    def render(self, pose: Pose, t: float, frustum=None) -> np.ndarray:
        """(height, width, 3) uint8 view at ``pose`` and scene time ``t`` seconds, through ``frustum``
        ((left, right, down, up) tangents: an eye's, protocol/frustum.py) when given."""
        with self.ctx:  # another context may have been made current on this thread since
            self.renderer.render_perspective(self.target, pose, t, self.fov_deg, frustum)
            return self.target.read_color().copy()

    def distance(self) -> np.ndarray:
        """(height, width) float32 radial distance of the last view rendered (0 = sky)."""
        with self.ctx:
            return self.target.read_distance().copy()

    def close(self) -> None:
        with self.ctx:
            self.target.release()
            self.renderer.release()
        if self._own_ctx:
            self.ctx.release()
