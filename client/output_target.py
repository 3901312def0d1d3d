"""The client's output framebuffer: RGBA8 (alpha 0 = the method accepted no transmitted sample there: an own hole) + depth."""
from __future__ import annotations

import numpy as np


class OutputTarget:
    def __init__(self, ctx, width: int, height: int):
        self.ctx, self.width, self.height = ctx, width, height
        self.color = ctx.texture((width, height), 4)
        self.depth = ctx.depth_renderbuffer((width, height))
        self.fbo = ctx.framebuffer(color_attachments=[self.color], depth_attachment=self.depth)

    def begin(self) -> None:
        """Bind, set the viewport and clear to transparent black (every pixel a hole until drawn)."""
        self.fbo.use()
        self.ctx.viewport = (0, 0, self.width, self.height)
        self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)

    def read(self) -> np.ndarray:
        """(height, width, 4) uint8, row 0 on top."""
        data = self.fbo.read(components=4, alignment=1)
        return np.frombuffer(data, np.uint8).reshape(self.height, self.width, 4)

    def release(self) -> None:
        for r in (self.fbo, self.color, self.depth):
            r.release()
