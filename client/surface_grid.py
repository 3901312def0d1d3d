"""Surface-estimation quadtrees and the adaptive warp grid of a wide-angle distance map
(Schollmeyer et al. 2017, Sections 4.1 and 5.1), on the CPU with numba.

Input is what the client receives for one view: its decoded radial distance map (``(h, w)``,
row 0 on top, 0 = nothing there) in Reinert et al.'s wide-angle projection. Output is a
list of rectangular *cells* (1 pixel up to the tile size) with the camera-space positions
of their four corners, ready to be warped on the GPU.

Depth is compared the way it travels: as a disparity *code*, ``code = code_scale / r``
(``code_scale`` = near x code range), whose transport error is ``slack_codes`` codes. Two depths
are within that error when they differ by at most ``slack_codes * step_at(nearer)`` in distance
(``DepthQuantizer.step_at``, what the shaders forgive) -- ``slack * lo / hi`` codes for codes
``lo < hi``. 8-bit disparity is very coarse: one code is ~1 m at 5 m.

**Pixel pairs** (the partial cross-kernel of 4.1.2, per pair). Every pixel knows whether it
is connected to each of its 8 neighbours. Two pixels p, q are connected when both hold a
surface (or both sky) and either

* their depths are within the transport's error: nothing finer can be told from the codes;
* or they are collinear in 3D with a third pixel on one side along the pair's direction (row,
  column or diagonal): q lies where the line through p's other neighbour and p meets q's
  ray, or p where the line through q's other neighbour and q meets p's ray, within
  ``epsilon`` of its distance beyond the transport's error. One side is enough, so a surface
  stays connected right up to the discontinuity it touches (the *partial* kernel), and
  slanted surfaces whose neighbours differ by more than the transport's error (grazing
  floors, the edge codec's finer depth) are not split, while a pair straddling a
  discontinuity fails from both sides.

So slanted surfaces are kept whole by collinearity and discontinuities are cut by the depth
jump; a discontinuity smaller than the transport's error cannot be seen and is not cut.

*Collinear* is measured **along the tested pixel's ray**, in disparity: for a plane, 1/r is
linear in the ray direction, so with ``u_q ~ a u_A + b u_p`` (least squares) the line's code
on q's ray is ``a c_A + b c_p`` -- exact for planes, comparable with the transport's error in
codes. The textbook perpendicular distance of a point from the line through its neighbours
cannot tell a depth step from a surface: where two of the points lie at different depths the
line runs almost along the rays, and every point is within about one pixel footprint of it,
far below any useful ``epsilon * distance``. The paper tests the middle of three pixels against
its two neighbours (interpolation); here the outer pixel is tested against the line through
the other two (extrapolation), because with noisy transported depth the interpolating line
through a discontinuity is pulled towards its far side by a sloped or noisy background and
halves the step it sees, which let H.264-blurred silhouettes through as rubber sheets.

**Quadtree** (4.1.2): level 0 is a pixel, level ``k`` a node of ``2**k`` pixels square, up to
the tile. A node is *one surface* when its four children are and they are connected to each
other across their shared sides and both diagonals; its 8 connectedness bits are the AND of
its children's on each side (a diagonal bit is its corner child's). Nodes are clipped to the
image, so a view whose size is not a multiple of the tile (or smaller than it) just has
narrower cells at its right and bottom borders. The extra view's empty pixels, and those
within ``void_margin`` pixels of one, are *void*: not drawn, never part of a surface (and
with ``void_at_discontinuities``, so are pixels not connected to all their neighbours).

**Estimation error** (4.1.1, 4.1.4): a surface node's error is its children's largest plus
its own deviation from flatness: how far, relative to the distance and beyond half the
transport's error, its children's new corners (edge midpoints and centre) lie along their
rays from the two triangles through its corner pixels that the cell is drawn as. It
accumulates level by level, as in the paper.

**Grid** (4.1.4): each tile is refined top-down; a node becomes a cell when it is one surface
whose error is at most ``epsilon``, or when it is a single pixel.

**Corner depth** (5.1): a cell corner sits between four pixels. The pixels there that are
connected to the cell's own corner pixel (through sides or diagonals) form a component; the
corner takes their interpolated depth, so cells of one surface meet exactly, and at a
discontinuity it takes the cell's own pixel's depth, so foreground and background detach
instead of forming rubber sheets. Each pixel of the component offers the depth of its cell's
least-squares plane at the corner (cells of 4 x 4 pixels and more: the plane averages the
transport's noise away) or else its own; they are averaged as codes (disparity is linear for
planes). Where a corner lies inside the side of a larger cell it is connected to (a
T-junction of the adaptive grid), it is moved onto that side, so the grid has no cracks
there either.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numba import njit

#: The 8 neighbour directions (dx, dy) with y down; bit d of a connectedness mask is direction d.
DIRECTIONS = ((1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1))
E, SE, S, SW, W, NW, N, NE = range(8)
ALL_CONNECTED = 0xFF

VOID, SKY, SURFACE = 0, 1, 2

MAX_TILE = 256
#: The flatness test forgives this fraction of the transport's slack: a plane through three
#: noisy corners, tested at a noisy pixel. 0.2 gave 33 % more cells for DSSIM 0.0933 instead
#: of 0.0948 in the room at large translations (512-pixel views).
FLAT_SLACK = 0.5
#: Cells of this quadtree level and above (4 x 4 pixels) give their corners their fitted plane's depth.
PLANE_LEVEL = 2


@dataclass(frozen=True)
class SurfaceGrid:
    """The adaptive grid of one view (``n`` cells).

    cells    : (n, 4) int32, x0, y0, x1, y1 in pixels (x1, y1 exclusive), row 0 on top
    levels   : (n,) int8, quadtree level of the node the cell is (its size before clipping is 2**level)
    bits     : (n,) uint8, connectedness to the 8 neighbours (bit d: ``DIRECTIONS[d]``; 1 = connected)
    error    : (n,) float32, accumulated relative estimation error of the cell
    vertices : (n, 4, 3) float32, camera-space positions of the corners top-left, top-right,
               bottom-left, bottom-right
    """

    width: int
    height: int
    tile: int
    cells: np.ndarray
    levels: np.ndarray
    bits: np.ndarray
    error: np.ndarray
    vertices: np.ndarray

    @property
    def count(self) -> int:
        return int(self.cells.shape[0])


def check_tile(tile) -> int:
    """The tile size if it is a power of two in 2..MAX_TILE, else ValueError."""
    if not (isinstance(tile, (int, np.integer)) and 2 <= tile <= MAX_TILE and tile & (tile - 1) == 0):
        raise ValueError(f"tile must be a power of two in 2..{MAX_TILE} pixels, got {tile!r}")
    return int(tile)


def build_surface_grid(distance, tile: int, epsilon: float, code_scale: float, slack_codes: float,
                       sky_distance: float | None = None, void_margin: int = 1,
                       void_at_discontinuities: bool = False) -> SurfaceGrid:
    """The adaptive grid of a wide-angle distance map.

    distance     : (h, w) float, radial distance per pixel, row 0 on top; 0 (or not finite) = empty
    tile         : quadtree tile size in pixels (power of two)
    epsilon      : relative collinearity tolerance and estimation-error threshold
    code_scale   : depth code of distance r is ``code_scale / r`` (near x code range, disparity coding)
    slack_codes  : codes of depth-transport error to forgive
    sky_distance : where empty pixels are placed (the primary view's sky); None: empty pixels are
                   void (the extra view) and so are those within ``void_margin`` pixels of one
    void_at_discontinuities : pixels not connected to all their neighbours are void too
    """
    d = np.asarray(distance)
    if d.ndim != 2 or d.shape[0] < 1 or d.shape[1] < 1:
        raise ValueError(f"distance must have shape (h, w), got {d.shape}")
    tile = check_tile(tile)
    for name, value in (("epsilon", epsilon), ("code_scale", code_scale), ("slack_codes", slack_codes)):
        if not (math.isfinite(value) and value >= 0):
            raise ValueError(f"{name} must be finite and >= 0, got {value}")
    if code_scale <= 0:
        raise ValueError(f"code_scale must be > 0, got {code_scale}")
    sky = -1.0 if sky_distance is None else float(sky_distance)
    if sky_distance is not None and not (math.isfinite(sky) and sky > 0):
        raise ValueError(f"sky_distance must be finite and > 0, got {sky_distance}")
    d = np.ascontiguousarray(d, dtype=np.float64)
    h, w = d.shape
    dirs = pixel_directions(w, h)
    kind, code = _classify(d, sky, int(void_margin) if sky_distance is None else 0, float(code_scale))
    conn = _connectivity(kind, code, dirs, float(epsilon), float(slack_codes))
    if void_at_discontinuities:
        kind = np.where((conn != ALL_CONNECTED) & (kind == SURFACE), np.uint8(VOID), kind)
        conn = _connectivity(kind, code, dirs, float(epsilon), float(slack_codes))
    n_levels = int(tile).bit_length() - 1
    surf, bits, err, hs, ws, offs = _quadtree(kind, code, dirs, conn, n_levels, float(epsilon),
                                              FLAT_SLACK * float(slack_codes))
    cells, levels, cbits, cerr = _grid(surf, bits, err, hs, ws, offs, n_levels, float(epsilon), h, w)
    verts = _vertices(cells, levels, kind, code, dirs, conn, float(code_scale), h, w, PLANE_LEVEL)
    return SurfaceGrid(w, h, tile, cells, levels, cbits, cerr, verts)


@functools.lru_cache(maxsize=4)
def pixel_directions(width: int, height: int) -> np.ndarray:
    """(height, width, 3) float32 unit camera-space directions of the pixel centres, cached per
    size (the kernels' table: 12 MB for a 1024 x 1024 view)."""
    d = _pixel_directions(int(width), int(height))
    d.setflags(write=False)
    return d


# --------------------------------------------------------------------------------------------
# numba kernels


@njit(cache=True, nogil=True)
def _direction(px, py, w, h):
    """Unit direction of continuous pixel position (px, py) (pixel centres at +0.5): the
    wide-angle projection's inverse (pibr.protocol.projection.INVERSE)."""
    vx = 2.0 * px / w - 1.0
    vy = 1.0 - 2.0 * py / h
    ty = min(max(vy, -1.0), 1.0)
    tx = min(max(vx, -1.0), 1.0) * math.sqrt(max(1.0 - ty * ty, 0.0))
    dz = -math.sqrt(max(1.0 - tx * tx - ty * ty, 0.0))
    return tx, ty, dz


@njit(cache=True, nogil=True)
def _pixel_directions(w, h):
    out = np.empty((h, w, 3), np.float32)
    for y in range(h):
        for x in range(w):
            out[y, x, 0], out[y, x, 1], out[y, x, 2] = _direction(x + 0.5, y + 0.5, w, h)
    return out


@njit(cache=True, nogil=True)
def _classify(dist, sky_distance, void_margin, code_scale):
    """-> kind (h, w) uint8 (VOID / SKY / SURFACE), code (h, w) float64 (depth code; sky: at sky_distance)."""
    h, w = dist.shape
    kind = np.empty((h, w), np.uint8)
    code = np.zeros((h, w), np.float64)
    for y in range(h):
        for x in range(w):
            r = dist[y, x]
            if r > 0.0 and math.isfinite(r):
                kind[y, x] = SURFACE
                code[y, x] = code_scale / r
            elif sky_distance > 0.0:
                kind[y, x] = SKY
                code[y, x] = code_scale / sky_distance
            else:
                kind[y, x] = VOID
    if sky_distance <= 0.0 and void_margin > 0:
        grown = kind.copy()
        for y in range(h):
            for x in range(w):
                if kind[y, x] == VOID:
                    for yy in range(max(y - void_margin, 0), min(y + void_margin + 1, h)):
                        for xx in range(max(x - void_margin, 0), min(x + void_margin + 1, w)):
                            grown[yy, xx] = VOID
        kind = grown
    return kind, code


@njit(cache=True, nogil=True)
def _line_prediction(code, dirs, xa, ya, xb, yb, xt, yt):
    """a c_A + b c_B with u_T ~ a u_A + b u_B (least squares): the code (disparity) at which the
    ray of pixel T meets the line through the points of pixels A and B (exact for coplanar rays,
    which T's need not lie between: it extrapolates as well)."""
    ax, ay, az = float(dirs[ya, xa, 0]), float(dirs[ya, xa, 1]), float(dirs[ya, xa, 2])
    bx, by, bz = float(dirs[yb, xb, 0]), float(dirs[yb, xb, 1]), float(dirs[yb, xb, 2])
    tx, ty, tz = float(dirs[yt, xt, 0]), float(dirs[yt, xt, 1]), float(dirs[yt, xt, 2])
    g = ax * bx + ay * by + az * bz
    alpha = ax * tx + ay * ty + az * tz
    gamma = bx * tx + by * ty + bz * tz
    den = 1.0 - g * g
    if den > 1e-14:
        a = (alpha - g * gamma) / den
        b = (gamma - g * alpha) / den
    else:   # A and B along one direction (at the poles): no slope to follow
        a = 0.0
        b = 1.0
    return a * code[ya, xa] + b * code[yb, xb]


@njit(cache=True, nogil=True)
def _deviation(c, pred, slack):
    """How far, relative to its distance, a pixel of code ``c`` lies along its ray from where a
    line or plane predicts it (code ``pred``), beyond ``slack`` codes of the transport's error.
    The slack counts codes of the nearer of the two depths (``slack * step_at(nearer)`` in
    distance, as the shaders forgive), which is ``slack * lo / hi`` codes (lo, hi: the two
    codes). inf when the prediction lies behind the camera."""
    if pred <= 0.0:
        return np.inf
    lo = min(c, pred)
    hi = max(c, pred)
    return max(abs(c - pred) - slack * lo / hi, 0.0) / pred


@njit(cache=True, nogil=True)
def _collinear_pair(kind, code, dirs, w, h, x, y, dx, dy, eps, slack):
    """Two surface pixels p = (x, y), q = p + (dx, dy) further apart than the transport's error:
    does q continue the line through p's other neighbour and p, or p the line through q's
    other neighbour and q (within ``eps`` of the distance beyond ``slack`` codes)?"""
    qx = x + dx
    qy = y + dy
    ax = x - dx
    ay = y - dy
    if 0 <= ax < w and 0 <= ay < h and kind[ay, ax] == SURFACE:
        pred = _line_prediction(code, dirs, ax, ay, x, y, qx, qy)
        if _deviation(code[qy, qx], pred, slack) <= eps:
            return True
    bx = qx + dx
    by = qy + dy
    if 0 <= bx < w and 0 <= by < h and kind[by, bx] == SURFACE:
        pred = _line_prediction(code, dirs, bx, by, qx, qy, x, y)
        if _deviation(code[y, x], pred, slack) <= eps:
            return True
    return False


@njit(cache=True, nogil=True)
def _connectivity(kind, code, dirs, eps, slack):
    h, w = kind.shape
    conn = np.full((h, w), ALL_CONNECTED, np.uint8)
    for y in range(h):
        for x in range(w):
            kp = kind[y, x]
            cp = code[y, x]
            for d in range(4):   # E, SE, S, SW; the opposite bit of the neighbour is d + 4
                dx = 1 if d < 2 else (0 if d == 2 else -1)
                dy = 0 if d == 0 else 1
                qx = x + dx
                qy = y + dy
                if qx < 0 or qx >= w or qy >= h:
                    continue
                kq = kind[qy, qx]
                if kp == VOID or kq == VOID or kp != kq:
                    connected = False
                elif kp == SKY:
                    connected = True
                else:
                    cq = code[qy, qx]
                    lo = min(cp, cq)
                    hi = max(cp, cq)
                    connected = hi - lo <= slack * lo / hi   # within the transport's error
                    if not connected:
                        connected = _collinear_pair(kind, code, dirs, w, h, x, y, dx, dy, eps, slack)
                if not connected:
                    conn[y, x] &= np.uint8(~(1 << d) & 0xFF)
                    conn[qy, qx] &= np.uint8(~(1 << (d + 4)) & 0xFF)
    return conn


@njit(cache=True, nogil=True)
def _plane_basis(dirs, x1, y1, x2, y2, x3, y3):
    """For the rays of pixels 1, 2, 3: vectors e1, e2, e3 (as 9 floats) with u = (u . e1) u_1 +
    (u . e2) u_2 + (u . e3) u_3 for any direction u (the dual basis), and whether the rays span
    a plane well enough to test against (False when nearly coplanar, as at the poles)."""
    ax, ay, az = float(dirs[y1, x1, 0]), float(dirs[y1, x1, 1]), float(dirs[y1, x1, 2])
    bx, by, bz = float(dirs[y2, x2, 0]), float(dirs[y2, x2, 1]), float(dirs[y2, x2, 2])
    cx, cy, cz = float(dirs[y3, x3, 0]), float(dirs[y3, x3, 1]), float(dirs[y3, x3, 2])
    bcx, bcy, bcz = by * cz - bz * cy, bz * cx - bx * cz, bx * cy - by * cx     # b x c
    cax, cay, caz = cy * az - cz * ay, cz * ax - cx * az, cx * ay - cy * ax     # c x a
    abx, aby, abz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx     # a x b
    det = ax * bcx + ay * bcy + az * bcz
    if abs(det) < 1e-13:
        det = 1.0
        ok = False
    else:
        ok = True
    return (bcx / det, bcy / det, bcz / det, cax / det, cay / det, caz / det,
            abx / det, aby / det, abz / det, ok)


@njit(cache=True, nogil=True)
def _plane_deviation(code, dirs, basis, x1, y1, x2, y2, x3, y3, xs, ys, slack):
    """:func:`_deviation` of pixel s from the plane through the points of pixels 1, 2, 3 (the
    code at which s's ray meets it: disparity is linear in the direction for a plane)."""
    sx, sy, sz = float(dirs[ys, xs, 0]), float(dirs[ys, xs, 1]), float(dirs[ys, xs, 2])
    a = sx * basis[0] + sy * basis[1] + sz * basis[2]
    b = sx * basis[3] + sy * basis[4] + sz * basis[5]
    g = sx * basis[6] + sy * basis[7] + sz * basis[8]
    pred = a * code[y1, x1] + b * code[y2, x2] + g * code[y3, x3]
    return _deviation(code[ys, xs], pred, slack)


@njit(cache=True, nogil=True)
def _node_deviation(kind, code, dirs, x0, y0, x1, y1, xm, ym, half_slack):
    """How far a surface node (inclusive pixel bounds, split at xm, ym) departs from the two
    triangles its cell is drawn as (top-left, top-right, bottom-left and top-right,
    bottom-right, bottom-left): the largest :func:`_deviation` of its children's new corners
    (the four edge midpoints and the centre) from those triangles' planes."""
    if kind[y0, x0] == SKY:
        return 0.0
    hx = x0 < xm < x1
    hy = y0 < ym < y1
    if hx and hy:
        upper = _plane_basis(dirs, x0, y0, x1, y0, x0, y1)
        lower = _plane_basis(dirs, x1, y0, x1, y1, x0, y1)
        if upper[9] and lower[9]:
            dev = _plane_deviation(code, dirs, upper, x0, y0, x1, y0, x0, y1, xm, y0, half_slack)
            dev = max(dev, _plane_deviation(code, dirs, upper, x0, y0, x1, y0, x0, y1, x0, ym, half_slack))
            dev = max(dev, _plane_deviation(code, dirs, upper, x0, y0, x1, y0, x0, y1, xm, ym, half_slack))
            dev = max(dev, _plane_deviation(code, dirs, lower, x1, y0, x1, y1, x0, y1, xm, ym, half_slack))
            dev = max(dev, _plane_deviation(code, dirs, lower, x1, y0, x1, y1, x0, y1, x1, ym, half_slack))
            dev = max(dev, _plane_deviation(code, dirs, lower, x1, y0, x1, y1, x0, y1, xm, y1, half_slack))
            return dev
    # A node one pixel wide or high, or rays too close to coplanar (at the poles): the lines.
    dev = 0.0
    if hx:
        for y in (y0, ym, y1):
            dev = max(dev, _deviation(code[y, xm], _line_prediction(code, dirs, x0, y, x1, y, xm, y), half_slack))
    if hy:
        for x in (x0, xm, x1):
            dev = max(dev, _deviation(code[ym, x], _line_prediction(code, dirs, x, y0, x, y1, x, ym), half_slack))
    return dev


@njit(cache=True, nogil=True)
def _bit(b, d):
    return (b >> d) & 1


@njit(cache=True, nogil=True)
def _quadtree(kind, code, dirs, conn, n_levels, eps, half_slack):
    """All tiles' quadtrees as one pyramid: level k is (hs[k], ws[k]) nodes stored from offs[k]
    in the flat arrays surf (uint8), bits (uint8), err (float32)."""
    h, w = kind.shape
    hs = np.empty(n_levels + 1, np.int64)
    ws = np.empty(n_levels + 1, np.int64)
    offs = np.empty(n_levels + 1, np.int64)
    hs[0] = h
    ws[0] = w
    offs[0] = 0
    total = h * w
    for k in range(1, n_levels + 1):
        hs[k] = (hs[k - 1] + 1) // 2
        ws[k] = (ws[k - 1] + 1) // 2
        offs[k] = total
        total += hs[k] * ws[k]
    surf = np.zeros(total, np.uint8)
    bits = np.full(total, ALL_CONNECTED, np.uint8)
    err = np.zeros(total, np.float32)
    for y in range(h):
        for x in range(w):
            surf[y * w + x] = 1 if kind[y, x] != VOID else 0
            bits[y * w + x] = conn[y, x]
    cs = np.empty(4, np.uint8)
    cb = np.empty(4, np.int64)
    for k in range(1, n_levels + 1):
        s = 1 << k
        for i in range(hs[k]):
            for j in range(ws[k]):
                ce = 0.0
                for c in range(4):   # 0 top-left, 1 top-right, 2 bottom-left, 3 bottom-right
                    ci = 2 * i + (c >> 1)
                    cj = 2 * j + (c & 1)
                    if ci < hs[k - 1] and cj < ws[k - 1]:   # else outside the image: a wildcard
                        idx = offs[k - 1] + ci * ws[k - 1] + cj
                        cs[c] = surf[idx]
                        cb[c] = bits[idx]
                        ce = max(ce, err[idx])
                    else:
                        cs[c] = 1
                        cb[c] = ALL_CONNECTED
                pb = ((_bit(cb[1] & cb[3], E) << E) | (_bit(cb[3], SE) << SE) | (_bit(cb[2] & cb[3], S) << S)
                      | (_bit(cb[2], SW) << SW) | (_bit(cb[0] & cb[2], W) << W) | (_bit(cb[0], NW) << NW)
                      | (_bit(cb[0] & cb[1], N) << N) | (_bit(cb[1], NE) << NE))
                node = offs[k] + i * ws[k] + j
                bits[node] = pb
                one = (cs[0] & cs[1] & cs[2] & cs[3]) == 1
                one = one and _bit(cb[0], E) == 1 and _bit(cb[2], E) == 1 and _bit(cb[0], S) == 1
                one = one and _bit(cb[1], S) == 1 and _bit(cb[0], SE) == 1 and _bit(cb[1], SW) == 1
                if one:
                    x0 = j * s
                    y0 = i * s
                    x1 = min(x0 + s, w) - 1
                    y1 = min(y0 + s, h) - 1
                    xm = min(x0 + s // 2, x1)
                    ym = min(y0 + s // 2, y1)
                    surf[node] = 1
                    err[node] = ce + _node_deviation(kind, code, dirs, x0, y0, x1, y1, xm, ym, half_slack)
                else:
                    surf[node] = 0
                    err[node] = ce
    return surf, bits, err, hs, ws, offs


@njit(cache=True, nogil=True)
def _walk(surf, bits, err, hs, ws, offs, n_levels, eps, h, w, cells, levels, cbits, cerr, emit):
    """Refine every tile top-down; count the cells, and store them when ``emit``."""
    n = 0
    stack = np.empty((4 * n_levels + 8, 3), np.int64)
    top = n_levels
    for ti in range(hs[top]):
        for tj in range(ws[top]):
            stack[0, 0] = top
            stack[0, 1] = ti
            stack[0, 2] = tj
            sp = 1
            while sp > 0:
                sp -= 1
                k = stack[sp, 0]
                i = stack[sp, 1]
                j = stack[sp, 2]
                if i >= hs[k] or j >= ws[k]:
                    continue
                node = offs[k] + i * ws[k] + j
                if surf[node] == 1 and (k == 0 or err[node] <= eps):
                    if emit:
                        s = 1 << k
                        cells[n, 0] = j * s
                        cells[n, 1] = i * s
                        cells[n, 2] = min(j * s + s, w)
                        cells[n, 3] = min(i * s + s, h)
                        levels[n] = k
                        cbits[n] = bits[node]
                        cerr[n] = err[node]
                    n += 1
                    continue
                if k == 0:
                    continue   # a void pixel
                for c in range(3, -1, -1):
                    stack[sp, 0] = k - 1
                    stack[sp, 1] = 2 * i + (c >> 1)
                    stack[sp, 2] = 2 * j + (c & 1)
                    sp += 1
    return n


@njit(cache=True, nogil=True)
def _grid(surf, bits, err, hs, ws, offs, n_levels, eps, h, w):
    dummy_c = np.empty((0, 4), np.int32)
    dummy_l = np.empty(0, np.int8)
    dummy_b = np.empty(0, np.uint8)
    dummy_e = np.empty(0, np.float32)
    n = _walk(surf, bits, err, hs, ws, offs, n_levels, eps, h, w, dummy_c, dummy_l, dummy_b, dummy_e, False)
    cells = np.empty((n, 4), np.int32)
    levels = np.empty(n, np.int8)
    cbits = np.empty(n, np.uint8)
    cerr = np.empty(n, np.float32)
    _walk(surf, bits, err, hs, ws, offs, n_levels, eps, h, w, cells, levels, cbits, cerr, True)
    return cells, levels, cbits, cerr


# The four pixels around a corner (cx, cy): 0 (cx-1, cy-1), 1 (cx, cy-1), 2 (cx-1, cy), 3 (cx, cy);
# the pairs between them and the bit of the first pixel that connects them.
_PAIR_A = np.array([0, 2, 0, 1, 0, 1], np.int64)
_PAIR_B = np.array([1, 3, 2, 3, 3, 2], np.int64)
_PAIR_BIT = np.array([E, E, S, S, SE, SW], np.int64)
# Corner k of a cell (0 TL, 1 TR, 2 BL, 3 BR) is pixel slot 3 - k around it.


@njit(cache=True, nogil=True)
def _corner_component(kind, conn, w, h, cx, cy, own):
    """Bit mask (over the 4 pixel slots around corner (cx, cy)) of the pixels connected to ``own``."""
    present = 0
    for slot in range(4):
        px = cx - 1 + (slot & 1)
        py = cy - 1 + (slot >> 1)
        if 0 <= px < w and 0 <= py < h and kind[py, px] != VOID:
            present |= 1 << slot
    comp = 1 << own
    for _ in range(3):
        for e in range(6):
            a = _PAIR_A[e]
            b = _PAIR_B[e]
            if (present >> a) & 1 and (present >> b) & 1:
                ax = cx - 1 + (a & 1)
                ay = cy - 1 + (a >> 1)
                if (conn[ay, ax] >> _PAIR_BIT[e]) & 1 and ((comp >> a) & 1 or (comp >> b) & 1):
                    comp |= (1 << a) | (1 << b)
    return comp


@njit(cache=True, nogil=True)
def _cell_planes(cells, levels, kind, code, dirs, plane_level):
    """Per cell of level >= PLANE_LEVEL with no sky: the plane through its pixels, fitted by least
    squares as disparity linear in the ray direction (code(u) = p . u); (n, 3) float64, a flag
    per cell (False: no plane, its pixels speak for themselves) and the range of codes a
    prediction may take, (n, 2): the cell's own, widened by itself and half a code on each side
    (a corner lies half a pixel beyond the pixel centres; a wilder value means the fit is
    ill-conditioned, as close to the poles)."""
    n = cells.shape[0]
    planes = np.zeros((n, 3), np.float64)
    ok = np.zeros(n, np.bool_)
    bounds = np.zeros((n, 2), np.float64)
    for c in range(n):
        x0, y0, x1, y1 = cells[c, 0], cells[c, 1], cells[c, 2], cells[c, 3]
        if levels[c] < plane_level or kind[y0, x0] != SURFACE or x1 - x0 < 3 or y1 - y0 < 3:
            continue
        axx = axy = axz = ayy = ayz = azz = bx = by = bz = 0.0
        lo = np.inf
        hi = 0.0
        for y in range(y0, y1):
            for x in range(x0, x1):
                ux, uy, uz = float(dirs[y, x, 0]), float(dirs[y, x, 1]), float(dirs[y, x, 2])
                k = code[y, x]
                lo = min(lo, k)
                hi = max(hi, k)
                axx += ux * ux
                axy += ux * uy
                axz += ux * uz
                ayy += uy * uy
                ayz += uy * uz
                azz += uz * uz
                bx += k * ux
                by += k * uy
                bz += k * uz
        m = (x1 - x0) * (y1 - y0)
        # Cramer's rule on the normalised normal equations.
        axx /= m
        axy /= m
        axz /= m
        ayy /= m
        ayz /= m
        azz /= m
        bx /= m
        by /= m
        bz /= m
        c00 = ayy * azz - ayz * ayz
        c01 = axz * ayz - axy * azz
        c02 = axy * ayz - axz * ayy
        det = axx * c00 + axy * c01 + axz * c02
        if det < 1e-18:
            continue
        c11 = axx * azz - axz * axz
        c12 = axy * axz - axx * ayz
        c22 = axx * ayy - axy * axy
        planes[c, 0] = (c00 * bx + c01 * by + c02 * bz) / det
        planes[c, 1] = (c01 * bx + c11 * by + c12 * bz) / det
        planes[c, 2] = (c02 * bx + c12 * by + c22 * bz) / det
        bounds[c, 0] = lo - (hi - lo) - 0.5
        bounds[c, 1] = hi + (hi - lo) + 0.5
        ok[c] = True
    return planes, ok, bounds


@njit(cache=True, nogil=True)
def _vertices(cells, levels, kind, code, dirs, conn, code_scale, h, w, plane_level):
    n = cells.shape[0]
    owner = np.full((h, w), -1, np.int64)
    for c in range(n):
        for y in range(cells[c, 1], cells[c, 3]):
            for x in range(cells[c, 0], cells[c, 2]):
                owner[y, x] = c
    planes, has_plane, bounds = _cell_planes(cells, levels, kind, code, dirs, plane_level)
    pos = np.zeros((n, 4, 3), np.float64)
    top = 0
    for c in range(n):
        top = max(top, levels[c])
    # Larger cells first: a corner on a larger cell's side (a T-junction) moves onto that side.
    for level in range(top, -1, -1):
        for c in range(n):
            if levels[c] != level:
                continue
            x0, y0, x1, y1 = cells[c, 0], cells[c, 1], cells[c, 2], cells[c, 3]
            for k in range(4):
                cx = x1 if k & 1 else x0
                cy = y1 if k >> 1 else y0
                own = 3 - k
                comp = _corner_component(kind, conn, w, h, cx, cy, own)
                # A corner inside the side of a larger cell (a T-junction) moves onto that side:
                # all of it where the two are connected (no crack), only its direction where
                # they are not (they detach in depth, but meet where the view saw them).
                connected = False
                side = -1
                t = 0.0
                ka = kb = 0
                for slot in range(4):
                    py = cy - 1 + (slot >> 1)
                    px = cx - 1 + (slot & 1)
                    if slot == own or px < 0 or py < 0 or px >= w or py >= h:
                        continue
                    o = owner[py, px]
                    if o < 0 or levels[o] <= level:
                        continue
                    ox0, oy0, ox1, oy1 = cells[o, 0], cells[o, 1], cells[o, 2], cells[o, 3]
                    if (cx == ox0 or cx == ox1) and (cy == oy0 or cy == oy1):
                        continue   # a corner of that cell too: no T-junction
                    if cx == ox0 or cx == ox1:     # on its left or right side
                        ka = 0 if cx == ox0 else 1
                        kb = ka + 2
                        t = (cy - oy0) / (oy1 - oy0)
                    else:                          # on its top or bottom side
                        ka = 0 if cy == oy0 else 2
                        kb = ka + 1
                        t = (cx - ox0) / (ox1 - ox0)
                    side = o
                    connected = (comp >> slot) & 1 == 1
                    break
                if side >= 0 and connected:
                    for i in range(3):
                        pos[c, k, i] = (1.0 - t) * pos[side, ka, i] + t * pos[side, kb, i]
                    continue
                # Each pixel of the component offers its depth here: its cell's plane, or its own.
                dx, dy, dz = _direction(float(cx), float(cy), w, h)
                total = 0.0
                m = 0
                for slot in range(4):
                    if (comp >> slot) & 1:
                        py = cy - 1 + (slot >> 1)
                        px = cx - 1 + (slot & 1)
                        o = owner[py, px]
                        value = code[py, px]
                        if o >= 0 and has_plane[o]:
                            fit = planes[o, 0] * dx + planes[o, 1] * dy + planes[o, 2] * dz
                            if bounds[o, 0] <= fit <= bounds[o, 1] and fit > 0.0:
                                value = fit
                        total += value
                        m += 1
                dist = code_scale * m / total
                if side >= 0:
                    ex = (1.0 - t) * pos[side, ka, 0] + t * pos[side, kb, 0]
                    ey = (1.0 - t) * pos[side, ka, 1] + t * pos[side, kb, 1]
                    ez = (1.0 - t) * pos[side, ka, 2] + t * pos[side, kb, 2]
                    norm = math.sqrt(ex * ex + ey * ey + ez * ez)
                    if norm > 0.0:
                        dx, dy, dz = ex / norm, ey / norm, ez / norm
                pos[c, k, 0] = dx * dist
                pos[c, k, 1] = dy * dist
                pos[c, k, 2] = dz * dist
    return pos.astype(np.float32)
