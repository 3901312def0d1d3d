"""Where a view is drawn: colour, radial distance and, for moving scenes, motion, read back on the
CPU in the layouts the packer, the benchmarks and the ground truth use."""
from __future__ import annotations

import numpy as np
from numba import njit


#: every float16 bit pattern -> its float32 value (numpy's exact conversion)
_HALF_TO_FLOAT = np.arange(1 << 16, dtype=np.uint32).astype(np.uint16).view(np.float16).astype(np.float32)


@njit(cache=True, nogil=True)
def _moving_motion(raw, half_to_float, motion, moving):
    """raw (h, w, 4) uint16 half floats (dx, dy, index, moving flag) -> motion (h, w, 2) float32,
    0 where the flag is not above 0.5, and moving (h, w) bool."""
    h, w = moving.shape
    for j in range(h):
        for i in range(w):
            # flag > 0.5 on the bits: above 0x3800 (0.5), up to 0x7c00 (+inf; NaN and negatives above)
            m = 0x3800 < raw[j, i, 3] <= 0x7C00
            moving[j, i] = m
            if m:
                motion[j, i, 0] = half_to_float[raw[j, i, 0]]
                motion[j, i, 1] = half_to_float[raw[j, i, 1]]
            else:
                motion[j, i, 0] = np.float32(0.0)
                motion[j, i, 1] = np.float32(0.0)


class RenderTarget:
    """Colour (RGBA8) + radial distance (R32F, 0 = sky) + depth buffer of ``width`` x ``height``;
    with ``motion``, also the motion of moving objects (RGBA16F: dx, dy pixels, object index,
    moving flag), in a framebuffer of its own on the same depth buffer (Renderer._draw_motion)."""

    def __init__(self, ctx, width: int, height: int, motion: bool = False):
        self.ctx, self.width, self.height = ctx, width, height
        self.color = ctx.texture((width, height), 4)
        self.distance = ctx.texture((width, height), 1, dtype="f4")
        self.motion = ctx.texture((width, height), 4, dtype="f2") if motion else None
        for t in (self.color, self.distance, self.motion):
            if t is not None:
                t.filter = (ctx.NEAREST, ctx.NEAREST)
                t.repeat_x = t.repeat_y = False
        self.depth = ctx.depth_renderbuffer((width, height))
        self.fbo = ctx.framebuffer(color_attachments=[self.color, self.distance], depth_attachment=self.depth)
        self.motion_fbo = self.all_fbo = None   # all_fbo: the three, for a pass that writes all at once
        if motion:
            self.motion_fbo = ctx.framebuffer(color_attachments=[self.motion], depth_attachment=self.depth)
            self.motion_fbo.depth_mask = False   # it only tests the main pass's depth (and its clear keeps it)
            self.all_fbo = ctx.framebuffer(color_attachments=[self.color, self.distance, self.motion],
                                           depth_attachment=self.depth)

    def read_color(self) -> np.ndarray:
        """(height, width, 3) uint8, row 0 on top."""
        data = self.fbo.read(components=3, attachment=0, alignment=1)
        return np.frombuffer(data, np.uint8).reshape(self.height, self.width, 3)

    def read_distance(self) -> np.ndarray:
        """(height, width) float32 radial distance, 0 where nothing was hit."""
        data = self.fbo.read(components=1, attachment=1, dtype="f4", alignment=1)
        return np.frombuffer(data, np.float32).reshape(self.height, self.width)

    def read_rgba_into(self, out: np.ndarray) -> np.ndarray:
        """Colour into ``out``, (height, width, 4) uint8 C-contiguous, row 0 on top (alpha 255):
        the texture's own format, so the read is a copy with no conversion."""
        self._check_out(out, (self.height, self.width, 4), np.uint8)
        self.fbo.read_into(out, components=4, attachment=0, alignment=1)
        return out

    def read_distance_into(self, out: np.ndarray) -> np.ndarray:
        """:meth:`read_distance` into ``out``, (height, width) float32 C-contiguous."""
        self._check_out(out, (self.height, self.width), np.float32)
        self.fbo.read_into(out, components=1, attachment=1, dtype="f4", alignment=1)
        return out

    @staticmethod
    def _check_out(out: np.ndarray, shape: tuple, dtype) -> None:
        if out.shape != shape or out.dtype != dtype or not out.flags.c_contiguous:
            raise ValueError(f"need a C-contiguous {shape} {np.dtype(dtype).name} array, got {out.shape} {out.dtype}")

    def read_motion(self) -> tuple[np.ndarray, np.ndarray]:
        """(motion (height, width, 2) float32 pixels, moving (height, width) bool)."""
        data = self.motion_fbo.read(components=4, dtype="f2", alignment=1)
        m = np.frombuffer(data, np.float16).reshape(self.height, self.width, 4).astype(np.float32)
        return np.ascontiguousarray(m[:, :, :2]), m[:, :, 3] > 0.5

    def read_moving_motion(self) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`read_motion` with the motion zeroed where nothing moves: (motion (height, width, 2)
        float32, moving (height, width) bool), new arrays. One pass over the raw half floats."""
        data = self.motion_fbo.read(components=4, dtype="f2", alignment=1)
        raw = np.frombuffer(data, np.uint16).reshape(self.height, self.width, 4)
        motion = np.empty((self.height, self.width, 2), np.float32)
        moving = np.empty((self.height, self.width), np.bool_)
        _moving_motion(raw, _HALF_TO_FLOAT, motion, moving)
        return motion, moving

    def read_moving_index(self) -> np.ndarray:
        """(height, width) int32: the scene index of the moving object each pixel shows, -1 elsewhere."""
        data = self.motion_fbo.read(components=4, dtype="f2", alignment=1)
        m = np.frombuffer(data, np.float16).reshape(self.height, self.width, 4).astype(np.float32)
        return np.where(m[:, :, 3] > 0.5, np.rint(m[:, :, 2]), -1).astype(np.int32)

    def release(self) -> None:
        for r in (self.fbo, self.motion_fbo, self.all_fbo, self.color, self.distance, self.depth, self.motion):
            if r is not None:
                r.release()
