"""``flow`` extrapolation: the moving objects' pixels of the newest frame warped along their
motion flow to the display time (Pajak et al. 2011, Sec. 4, "temporal upsampling": the frame
warped to the future by extrapolating its motion vectors, with the depth for occlusion).

A frame's primary view carries, per pixel, the flow of moving objects over the last server
frame interval (``MOTION_FLOW``; 0 on everything the camera alone moves). At display time
``t`` the view is extrapolated by ``steps = (t - t_frame) / interval`` intervals, bounded as
the per-object extrapolation is (:func:`~pibr.client.object_motion.damped_horizon`: full speed
for ``horizon_frames`` intervals, then slowing, never beyond 1.5 horizons; never back in time),
and every method that re-projects the primary view re-projects the extrapolated one.

Per frame (:class:`FlowFrame`, where the frame is decoded, off the event loop and the GL
thread), the **background** of the moving pixels is made up, once: every 4-connected moving
region (grown by FILL_RING pixels, which the video's chroma tints with the object's colour) is
filled by push-pull (:func:`~pibr.client.diffusion.push_pull_fast`) of colour and
disparity from the static pixels around it that lie behind its nearest point (those in front
are what hides it, not what it uncovers), disparity so that sky (0) blends in as far away. The
chosen background is cheap and blurry over large displacements; the extra view, which may
have seen what the objects hide, is not consulted (methods that draw it still do).

Per display (:meth:`FlowFrame.extrapolate`), compiled: every moving pixel is splatted to the
pixel nearest its source position plus ``steps`` times its flow. Where moving pixels meet, the
nearest wins; on the made-up background a moving pixel always wins; on a static pixel it wins
unless that pixel is nearer by more than the depth transport's error (``depth_slack``: 8-bit
disparity cannot tell an object from the wall just behind it, and an occluder in front must stay
in front). One-pixel cracks where an object stretches are closed from both sides. Vacated pixels show the
background. The result covers the smallest even-aligned rectangle holding every source and
destination; everything outside it is the frame as decoded.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .diffusion import _label_regions, push_pull_fast
from .object_motion import DEFAULT_HORIZON_FRAMES, damped_horizon

#: A static pixel this much nearer (relative disparity) than a moving region's nearest point
#: hides it, so it is no sample of the background the region uncovers.
OCCLUDER_TOLERANCE = 0.05
#: Pixels of static context around a moving region that the background fill draws from.
FILL_MARGIN = 6
#: The background is made up over the moving pixels and this many pixels around them: the
#: video's 4:2:0 chroma and its blur carry an object's colour a little past its outline.
FILL_RING = 2


@dataclass
class Extrapolated:
    """The primary view extrapolated over ``rect`` = (x0, y0, w, h) (even-aligned, view pixels).

    y : (h, w) uint8; u, v : (h / 2, w / 2) uint8; distance : (h, w) float32 (0 = sky);
    changed : (h, w) bool, pixels that differ from the frame as decoded;
    moved : (n, 2) int32 (x, y) view pixels a moving pixel landed on, moved_distance : (n,) float32.
    """

    steps: float
    rect: tuple
    y: np.ndarray
    u: np.ndarray
    v: np.ndarray
    distance: np.ndarray
    changed: np.ndarray
    moved: np.ndarray
    moved_distance: np.ndarray


def _upsample(c: np.ndarray, h: int, w: int) -> np.ndarray:
    return np.repeat(np.repeat(c, 2, axis=0), 2, axis=1)[:h, :w]


def _dilate(mask: np.ndarray, r: int) -> np.ndarray:
    """mask (h, w) bool grown by r pixels (a (2r + 1)^2 square)."""
    out = mask.copy()
    for _ in range(r):
        grown = out.copy()
        grown[1:] |= out[:-1]
        grown[:-1] |= out[1:]
        grown[:, 1:] |= grown[:, :-1].copy()
        grown[:, :-1] |= grown[:, 1:].copy()
        out = grown
    return out


def _disparity(distance: np.ndarray) -> np.ndarray:
    d = np.asarray(distance, dtype=np.float32)
    return np.where(d > 0, 1.0 / np.maximum(d, 1e-12), 0.0).astype(np.float32)


@njit(cache=True, nogil=True)
def _wins(d, zb, marked, vacated, slack):
    """Whether a moving pixel of disparity d takes a pixel (see the module docstring)."""
    if marked:
        return d > zb
    return vacated or zb <= d + slack


@njit(cache=True, nogil=True)
def _destinations(xs, ys, fx, fy, steps, h, w, dst):
    """Each moving pixel's destination (nearest pixel) into dst (n, 2) as (x, y); -> the rectangle
    (x0, y0, x1, y1), even-aligned, holding every source and every destination in the view plus
    a pixel for the cracks."""
    lo_x, lo_y, hi_x, hi_y = w, h, -1, -1
    for i in range(len(xs)):
        x = int(xs[i])
        y = int(ys[i])
        dx = int(math.floor(xs[i] + steps * fx[i] + 0.5))
        dy = int(math.floor(ys[i] + steps * fy[i] + 0.5))
        dst[i, 0] = dx
        dst[i, 1] = dy
        lo_x, hi_x = min(lo_x, x), max(hi_x, x)
        lo_y, hi_y = min(lo_y, y), max(hi_y, y)
        if 0 <= dx < w and 0 <= dy < h:
            lo_x, hi_x = min(lo_x, dx), max(hi_x, dx)
            lo_y, hi_y = min(lo_y, dy), max(hi_y, dy)
    x0 = max(lo_x - 1, 0) & ~1
    y0 = max(lo_y - 1, 0) & ~1
    x1 = min(hi_x + 2 + ((hi_x + 2) & 1), w)
    y1 = min(hi_y + 2 + ((hi_y + 2) & 1), h)
    return x0, y0, x1, y1


@njit(cache=True, nogil=True)
def _compose(dst, disp, sy, su, sv, x0, y0, slack, vacated, bg_y, bg_u, bg_v, bg_d, bg_dist, y_in, u_in, v_in,
             zb, oy, ou, ov, mark, out_y, out_u, out_v, out_dist, changed, moved, moved_dist):
    """The extrapolated view over the rectangle at (x0, y0) of out_y's shape: background, then the
    moving pixels splatted at dst (nearest wins, see _wins), one-pixel cracks closed, and the
    outputs (luma, chroma as 2 x 2 means where a pixel changed, distance, changed mask, the
    pixels a moving pixel landed on). -> how many those are (the first rows of moved)."""
    rh, rw = out_y.shape
    for y in range(rh):
        for x in range(rw):
            zb[y, x] = bg_d[y0 + y, x0 + x]
            oy[y, x] = bg_y[y0 + y, x0 + x]
            ou[y, x] = bg_u[y0 + y, x0 + x]
            ov[y, x] = bg_v[y0 + y, x0 + x]
            mark[y, x] = 0
    for i in range(len(disp)):
        px, py = dst[i, 0] - x0, dst[i, 1] - y0
        if px < 0 or px >= rw or py < 0 or py >= rh:
            continue
        d = disp[i]
        if not _wins(d, zb[py, px], mark[py, px], vacated[y0 + py, x0 + px], slack):
            continue
        zb[py, px] = d
        mark[py, px] = 1
        oy[py, px] = sy[i]
        ou[py, px] = su[i]
        ov[py, px] = sv[i]
    # cracks: a pixel no moving pixel reached between two that did (left and right, or above and
    # below, at nearly one disparity) and that they would win takes their mean
    for y in range(rh):
        for x in range(rw):
            if mark[y, x] == 1:
                continue
            for a in range(2):
                if a == 0:
                    if x == 0 or x + 1 >= rw or mark[y, x - 1] != 1 or mark[y, x + 1] != 1:
                        continue
                    ya, xa, yb, xb = y, x - 1, y, x + 1
                else:
                    if y == 0 or y + 1 >= rh or mark[y - 1, x] != 1 or mark[y + 1, x] != 1:
                        continue
                    ya, xa, yb, xb = y - 1, x, y + 1, x
                da, db = zb[ya, xa], zb[yb, xb]
                if abs(da - db) > 0.05 * max(da, db):
                    continue
                d = 0.5 * (da + db)
                if not _wins(d, zb[y, x], 0, vacated[y0 + y, x0 + x], slack):
                    continue
                oy[y, x] = 0.5 * (oy[ya, xa] + oy[yb, xb])
                ou[y, x] = 0.5 * (ou[ya, xa] + ou[yb, xb])
                ov[y, x] = 0.5 * (ov[ya, xa] + ov[yb, xb])
                zb[y, x] = d
                mark[y, x] = 2    # not a source for the cracks next to it
                break
    n = 0
    for y in range(rh):
        for x in range(rw):
            m = mark[y, x] != 0
            c = m or vacated[y0 + y, x0 + x] != 0
            changed[y, x] = c
            if m:
                out_dist[y, x] = 1.0 / zb[y, x]
                moved[n, 0] = x0 + x
                moved[n, 1] = y0 + y
                moved_dist[n] = out_dist[y, x]
                n += 1
            else:
                out_dist[y, x] = bg_dist[y0 + y, x0 + x]
            out_y[y, x] = min(max(int(math.floor(oy[y, x] + 0.5)), 0), 255) if c else y_in[y0 + y, x0 + x]
    for cy in range(rh // 2):
        for cx in range(rw // 2):
            y, x = 2 * cy, 2 * cx
            if changed[y, x] or changed[y, x + 1] or changed[y + 1, x] or changed[y + 1, x + 1]:
                mu = 0.25 * (ou[y, x] + ou[y, x + 1] + ou[y + 1, x] + ou[y + 1, x + 1])
                mv = 0.25 * (ov[y, x] + ov[y, x + 1] + ov[y + 1, x] + ov[y + 1, x + 1])
                out_u[cy, cx] = min(max(int(math.floor(mu + 0.5)), 0), 255)
                out_v[cy, cx] = min(max(int(math.floor(mv + 0.5)), 0), 255)
            else:
                out_u[cy, cx] = u_in[(y0 + y) // 2, (x0 + x) // 2]
                out_v[cy, cx] = v_in[(y0 + y) // 2, (x0 + x) // 2]
    return n


class FlowFrame:
    """The newest frame's primary view, ready to be extrapolated along its motion flow.

    y : (h, w) uint8 luma; u, v : (h / 2, w / 2) uint8 chroma; distance : (h, w) float32 radial
    distance (0 = sky); flow : (h, w, 2) float32 pixels per ``interval`` seconds; moving : (h, w)
    bool; scene_t : the frame's scene time (s); horizon_frames : see the module docstring;
    depth_slack : the depth transport's error in disparity (1 / m) that a static pixel must be
    nearer by to hide a moving one. ``count``: how many pixels move (0: extrapolation changes
    nothing).
    """

    def __init__(self, y, u, v, distance, flow, moving, scene_t: float, interval: float,
                 horizon_frames: float = DEFAULT_HORIZON_FRAMES, depth_slack: float = 0.0):
        h, w = np.shape(y)
        if np.shape(distance) != (h, w) or np.shape(flow) != (h, w, 2) or np.shape(moving) != (h, w):
            raise ValueError(f"distance (h, w), flow (h, w, 2) and moving (h, w) must match the luma's {(h, w)}")
        if h % 2 or w % 2 or np.shape(u) != (h // 2, w // 2) or np.shape(v) != np.shape(u):
            raise ValueError(f"the view's size must be even and its chroma half of it, got {(h, w)} and "
                             f"{np.shape(u)}, {np.shape(v)}")
        if not (interval > 0 and horizon_frames >= 0):
            raise ValueError("flow extrapolation needs a positive interval and horizon_frames >= 0")
        self.shape = (h, w)
        self.scene_t, self.interval = float(scene_t), float(interval)
        self.horizon = horizon_frames * interval
        self.depth_slack = float(depth_slack)
        self.y, self.u, self.v = y, u, v
        self.distance = np.asarray(distance, np.float32)
        flow = np.asarray(flow, np.float32)
        # a moving pixel whose flow is 0 (an object at rest, or its axis) stays put, and uncovers nothing
        moving = np.asarray(moving, bool) & np.all(np.isfinite(flow), axis=-1) & np.any(flow != 0, axis=-1)
        ys, xs = np.nonzero(moving)
        self.count = len(ys)
        self._last: Extrapolated | None = None
        if not self.count:
            return
        self._src = (xs.astype(np.float64), ys.astype(np.float64), flow[ys, xs, 0].astype(np.float64),
                     flow[ys, xs, 1].astype(np.float64))
        self._vacated = _dilate(moving, FILL_RING)
        self._vacated_u8 = self._vacated.view(np.uint8)
        self._y, self._u, self._v = (np.ascontiguousarray(p, np.uint8) for p in (y, u, v))
        self._prepare_background(self._vacated, moving)
        full_u, full_v = _upsample(u, h, w), _upsample(v, h, w)
        self._src_values = (self._disp[ys, xs].copy(), np.asarray(y, np.float32)[ys, xs],
                            full_u[ys, xs].astype(np.float32), full_v[ys, xs].astype(np.float32))

    def _prepare_background(self, region: np.ndarray, moving: np.ndarray) -> None:
        """Background colour (full-resolution chroma) and disparity over ``region`` (the moving
        pixels and their ring), behind every moving region's nearest point."""
        h, w = self.shape
        self._disp = _disparity(self.distance)
        bg = [np.asarray(self.y, np.float32).copy(), _upsample(self.u, h, w).astype(np.float32),
              _upsample(self.v, h, w).astype(np.float32), self._disp.copy()]
        labels = np.zeros((h, w), dtype=np.int32)
        n, boxes, _ = _label_regions(np.ascontiguousarray(~region).view(np.uint8), labels)
        for c in range(1, n + 1):
            y0, y1 = max(int(boxes[c, 0]) - FILL_MARGIN, 0), min(int(boxes[c, 1]) + FILL_MARGIN + 1, h)
            x0, x1 = max(int(boxes[c, 2]) - FILL_MARGIN, 0), min(int(boxes[c, 3]) + FILL_MARGIN + 1, w)
            own = labels[y0:y1, x0:x1] == c
            static = ~region[y0:y1, x0:x1]
            disp = self._disp[y0:y1, x0:x1]
            core = own & moving[y0:y1, x0:x1]
            nearest = float(disp[core if core.any() else own].max())
            samples = static & (disp <= nearest * (1.0 + OCCLUDER_TOLERANCE))
            if not samples.any():
                samples = static
            if not samples.any():
                continue   # nothing around it at all: the region keeps its own pixels
            for channel in bg:
                box = channel[y0:y1, x0:x1]
                filled = push_pull_fast(box, samples)
                box[own] = filled[own]
        self._bg = bg
        # a sky-like fill (disparity near 0) stays sky
        self._bg_distance = np.where(bg[3] > 1e-6, 1.0 / np.maximum(bg[3], 1e-6), 0.0).astype(np.float32)
        self._bg_distance[~region] = self.distance[~region]

    def steps(self, t: float) -> float:
        """Frame intervals to extrapolate by at scene time ``t`` (bounded; see the module docstring)."""
        return max(damped_horizon(t - self.scene_t, self.horizon), 0.0) / self.interval

    def extrapolate(self, steps: float) -> Extrapolated | None:
        """The view ``steps`` intervals after the frame; None when nothing changes (no motion, or 0 steps)."""
        if not self.count or steps <= 0:
            return None
        if self._last is not None and self._last.steps == steps:
            return self._last
        h, w = self.shape
        xs, ys, fx, fy = self._src
        dst = np.empty((len(xs), 2), dtype=np.int64)
        x0, y0, x1, y1 = _destinations(xs, ys, fx, fy, float(steps), h, w, dst)
        rh, rw = y1 - y0, x1 - x0
        zb, oy, ou, ov = (np.empty((rh, rw), np.float32) for _ in range(4))
        mark = np.empty((rh, rw), np.uint8)
        out_y = np.empty((rh, rw), np.uint8)
        out_u = np.empty((rh // 2, rw // 2), np.uint8)
        out_v = np.empty((rh // 2, rw // 2), np.uint8)
        out_dist = np.empty((rh, rw), np.float32)
        changed = np.empty((rh, rw), np.bool_)
        moved = np.empty((rh * rw, 2), np.int32)
        moved_dist = np.empty(rh * rw, np.float32)
        disp, sy, su, sv = self._src_values
        bg_y, bg_u, bg_v, bg_d = self._bg
        n = _compose(dst, disp, sy, su, sv, x0, y0, self.depth_slack, self._vacated_u8, bg_y, bg_u, bg_v, bg_d,
                     self._bg_distance, self._y, self._u, self._v, zb, oy, ou, ov, mark, out_y, out_u, out_v,
                     out_dist, changed, moved, moved_dist)
        self._last = Extrapolated(steps=steps, rect=(x0, y0, rw, rh), y=out_y, u=out_u, v=out_v, distance=out_dist,
                                  changed=changed, moved=moved[:n], moved_distance=moved_dist[:n])
        return self._last
