"""H.264 encoding of the atlas with libx264 through PyAV.

Zero latency (one packet out per frame in), no B-frames, a configurable bitrate held by
x264's VBV (about two frames of buffer) and keyframe interval. Encoding releases the GIL,
so the server runs it in a thread pool, never on the event loop.

x264 under so tight a VBV delivers 10-20 % less than its target (measured on the tuning
windows, room at 1024^2: 0.81-0.97 of 1 to 16 Mbit/s per group of pictures, 0.87 on average;
with the correction below 0.92-1.10, 0.99 on average). Those bits
would be lost to the colour, so the encoder asks x264 for :data:`INITIAL_TARGET_FACTOR` times
its target at first, then measures what each group of pictures delivered and asks for more (or
less) in the next one: the factor follows target/delivered with gain :data:`UNDERSHOOT_GAIN`,
within :data:`TARGET_FACTOR_RANGE`. The bitrate of an open
libx264 context cannot be raised past its VBV (libavcodec reconfigures the bitrate, not the
VBV given in x264-params), so the encoder is re-created where a keyframe falls anyway.

``deterministic=True`` encodes on one thread: measured here, two encoders fed the same
frames with x264's threading on produced different P-frames, and the virtual clock
promises bit-identical results.
"""
from __future__ import annotations

import fractions

import numpy as np

from pibr.protocol.errors import CodecError

#: How far one group of pictures corrects the next: factor *= (target / delivered) ** gain. Chosen on
#: the tuning windows (room, 1024^2 dual view, 1-16 Mbit/s): gain 1 reached 1.00 of the target on
#: average but swung to 1.08 in a group; 0.5 reached 0.97-0.99 and stayed within 1.06.
UNDERSHOOT_GAIN = 0.5
#: The factor a stream starts with, before any group was measured: the inverse of the mean share of
#: its target x264 delivered in the first group of pictures on the tuning windows (0.873: room,
#: 1024^2 dual view, 1, 2, 4, 8 and 16 Mbit/s, both tuning traces). Without it a session shorter
#: than a group (3 s at 10 fps) would keep all of x264's undershoot.
INITIAL_TARGET_FACTOR = 1.14
#: The factor on x264's target never leaves this range (a group that sends next to nothing, a
#: black screen, must not make the next one ask for ten times the rate).
TARGET_FACTOR_RANGE = (0.5, 1.5)
#: A new target within this ratio of the current one waits for the next group of pictures; beyond
#: it, the encoder starts again at once (H264Encoder.retarget).
RETARGET_KEEP = (0.8, 1.5)


class H264Encoder:
    """Stateful encoder for one session's stream of ``width`` x ``height`` yuv420p images."""

    name = "h264"

    def __init__(self, width: int, height: int, fps: float, bitrate_kbps: float = 16000.0,
                 keyint: int = 30, preset: str = "ultrafast", deterministic: bool = False):
        import av

        if width % 2 or height % 2:
            raise ValueError(f"H.264 4:2:0 needs even sizes, got {width}x{height}")
        self.width, self.height = width, height
        self.frames = 0
        self.target_kbps, self.fps, self.keyint, self.preset = float(bitrate_kbps), fps, keyint, preset
        self._threads = 1 if deterministic else 0
        #: x264's target is target_kbps times this (the undershoot correction, module docstring)
        self.target_factor = INITIAL_TARGET_FACTOR
        self._group_bits = 0
        self._group_frames = 0
        self._av = av
        self._ctx = self._context()
        self._restart = False   # a new target that cannot wait for the next group (retarget)

    def _context(self):
        self.applied_kbps = self.target_kbps   # what the running context was asked for (before the factor)
        return x264_context(self._av, self.width, self.height, "yuv420p", self.fps,
                            self.target_kbps * self.target_factor, self.keyint, self.preset, threads=self._threads)

    def _next_group(self) -> None:
        """A group of pictures ends where x264 would place its next keyframe: correct the factor by
        what it delivered and start an encoder asking for that (its first frame is the keyframe)."""
        delivered_kbps = self._group_bits * self.fps / self._group_frames / 1000.0
        if delivered_kbps > 0:
            lo, hi = TARGET_FACTOR_RANGE
            self.target_factor = min(hi, max(lo, self.target_factor
                                             * (self.applied_kbps / delivered_kbps) ** UNDERSHOOT_GAIN))
        self._ctx = self._context()
        self._group_bits = self._group_frames = 0

    def retarget(self, kbps: float, at_once: bool = False) -> None:
        """A new target for the frames to come (the stream adaptation). Within RETARGET_KEEP of the
        target x264 runs at (``applied_kbps``, not the last one asked for: small steps must not add
        up unseen) it waits for the next group of pictures, unless ``at_once``; further, x264
        starts again at the next frame: a keyframe, held to two frames of the new rate by its VBV
        (an open context's VBV cannot change, module docstring; nor, measured, does a bit_rate set
        on an open context change what x264 makes)."""
        kbps = float(kbps)
        if not kbps > 0:
            raise ValueError(f"an H.264 target must be positive, got {kbps}")
        lo, hi = RETARGET_KEEP
        if (at_once and kbps != self.applied_kbps) or not lo <= kbps / self.applied_kbps <= hi:
            self._restart = True
        self.target_kbps = kbps

    def encode(self, yuv: np.ndarray, force_keyframe: bool = False) -> tuple[bytes, bool]:
        """yuv : (1.5 H, W) uint8 yuv420p buffer -> (Annex B access unit, is keyframe)."""
        if yuv.shape != (self.height * 3 // 2, self.width):
            raise ValueError(f"expected a ({self.height * 3 // 2}, {self.width}) yuv420p buffer, got {yuv.shape}")
        if self._restart:
            self._ctx = self._context()
            self._group_bits = self._group_frames = 0
            self._restart = False
        elif self._group_frames >= self.keyint:
            self._next_group()
        frame = self._av.VideoFrame.from_ndarray(yuv, format="yuv420p")
        frame.pts = self.frames
        if force_keyframe:
            frame.pict_type = self._av.video.frame.PictureType.I
        self.frames += 1
        packets = encode_packets(self._ctx, self._av, frame, f"frame {self.frames - 1}")
        data, key = b"".join(bytes(p) for p in packets), any(p.is_keyframe for p in packets)
        if key:   # a forced keyframe starts a group too: x264 counts its keyint from there
            self._group_bits = self._group_frames = 0
        self._group_bits += 8 * len(data)
        self._group_frames += 1
        return data, key

    def close(self) -> None:
        self._ctx = None


def x264_context(av, width: int, height: int, pix_fmt: str, fps: float, kbps: float, keyint: int, preset: str,
                 threads: int):
    """A libx264 encoder context as pibr runs it: zero latency, no B-frames, full range, ``kbps``
    held by a VBV of about two frames, a keyframe every ``keyint`` frames (no scene cuts);
    ``threads`` 0 lets x264 choose (1: deterministic)."""
    ctx = av.CodecContext.create("libx264", "w")
    ctx.width, ctx.height = width, height
    ctx.pix_fmt = pix_fmt
    rate = fractions.Fraction(fps).limit_denominator(1000)
    ctx.time_base = 1 / rate
    ctx.framerate = rate
    ctx.bit_rate = int(kbps * 1000)
    ctx.gop_size = keyint
    ctx.max_b_frames = 0
    ctx.thread_count = threads
    ctx.color_range = 2  # full range (JPEG): the packer writes 0..255 luma
    vbv = max(1, int(2 * kbps / fps))
    ctx.options = {
        "preset": preset,
        "tune": "zerolatency",
        "x264-params": f"vbv-maxrate={max(1, int(kbps))}:vbv-bufsize={vbv}:keyint={keyint}:"
                       f"min-keyint={keyint}:scenecut=0:fullrange=on",
    }
    return ctx


def encode_packets(ctx, av, frame, what: str) -> list:
    """Encode one ``av.VideoFrame`` in zero-latency mode -> its packets; libx264's failures as
    CodecError naming ``what``."""
    try:
        packets = ctx.encode(frame)
    except av.error.FFmpegError as exc:
        raise CodecError(f"libx264 failed to encode {what}: {exc}") from exc
    if not packets:
        raise CodecError(f"libx264 returned no packet for {what}: is zero-latency mode on?")
    return packets
