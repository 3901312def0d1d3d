"""H.264 decoding of the atlas stream with PyAV, to planar YUV the GPU converts itself."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pibr.protocol.errors import CodecError


@dataclass
class YUVImage:
    """Planes of a full-range BT.601 4:2:0 image: y (H, W), u and v (H/2, W/2), uint8."""

    y: np.ndarray
    u: np.ndarray
    v: np.ndarray

    @property
    def width(self) -> int:
        return self.y.shape[1]

    @property
    def height(self) -> int:
        return self.y.shape[0]


class H264Decoder:
    """Decodes one session's access units in order. Every frame must be fed, keyframe first:
    a frame nobody will see is still decoded (the next ones refer to it), just not converted."""

    name = "h264"

    def __init__(self, width: int, height: int):
        import av

        self._av = av
        self.width, self.height = width, height
        self._ctx = av.CodecContext.create("h264", "r")
        self._ctx.thread_type = "NONE"  # frame threading would delay output by a frame per thread
        self.frames = 0
        self.converted = 0    # pictures turned into YUVImage

    def decode(self, data: bytes, convert: bool = True) -> YUVImage | None:
        """Decode one access unit; -> its picture, or None when ``convert`` is False (a stale frame
        decoded only to keep the reference chain)."""
        try:
            frames = self._ctx.decode(self._av.Packet(data))
        except self._av.error.FFmpegError as exc:
            raise CodecError(f"H.264 frame {self.frames} does not decode: {exc}") from None
        if not frames:
            raise CodecError(f"H.264 frame {self.frames} produced no picture (missing keyframe or truncated data)")
        frame = frames[-1]
        self.frames += 1
        if (frame.width, frame.height) != (self.width, self.height):
            raise CodecError(f"H.264 picture is {frame.width}x{frame.height}, the session's atlas is "
                             f"{self.width}x{self.height}")
        if not convert:
            return None
        self.converted += 1
        if frame.format.name not in ("yuv420p", "yuvj420p"):
            frame = frame.reformat(format="yuv420p")
        buf = frame.to_ndarray()
        h, w = self.height, self.width
        q = (h // 2) * (w // 2)
        flat = buf[h:].reshape(-1)
        return YUVImage(np.ascontiguousarray(buf[:h]), flat[:q].reshape(h // 2, w // 2).copy(),
                        flat[q:2 * q].reshape(h // 2, w // 2).copy())
