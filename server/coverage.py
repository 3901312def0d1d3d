"""Which displayed pixels the transmitted views cover: the geometric definition of a hole.

For a displayed pose the ground-truth renderer gives, per output pixel, the surface point
the viewer sees (or sky). A pixel is *covered* when some transmitted view shows that same
point: its back-projection into the view lands on a texel (any of the four around it)
whose stored distance matches the point's distance within a relative tolerance — the same
test depth peeling uses. Sky is covered where a view shows sky in that direction; a peeled
view vouches for sky only when it marks what it peeled away apart from sky (protocol/depth.py;
the server's default).

The server measures with it whether a scene's extra view buys coverage (scene_plan.py); the
benchmarks (bench/coverage.py and others) use the same machinery, so both count holes alike.
Which frame a displayed pose sees comes from the session's schedule (pibr.common.replay).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from pibr.protocol.frustum import rays as frustum_rays
from pibr.protocol.frustum import symmetric
from pibr.protocol.pose import Pose
from pibr.protocol.projection import EPS, FORWARD

#: Relative distance tolerance of the coverage test (as depth peeling's, see renderer.py).
COVERAGE_TOLERANCE = 0.03


def project_to_view(points: np.ndarray, view_pose: Pose):
    """World points (n, 3) -> (t' (n, 2), distance (n,), in front (n,) bool) in a wide-angle view."""
    local = (points - view_pose.p) @ view_pose.rotation()
    tx, ty, r = FORWARD.numpy(px=local[:, 0], py=local[:, 1], pz=local[:, 2])
    return np.stack([tx, ty], axis=1), r, local[:, 2] <= 0.0


@njit(cache=True, nogil=True, inline="always")
def _project(px, py, pz):
    """FORWARD (protocol/projection.py) of one camera-space point -> (t'_x, t'_y, r), the same
    float64 operations numpy performs on arrays (tests/server/test_coverage.py: to the bit)."""
    m = max(max(abs(px), abs(py)), max(abs(pz), EPS))
    qx = px / m
    qy = py / m
    qz = pz / m
    qn = math.sqrt(qx * qx + qy * qy + qz * qz)
    r = m * qn
    ty = min(max(qy / max(qn, EPS), -1.0), 1.0)
    tx = min(max(qx / max(math.sqrt(qx * qx + qz * qz), EPS), -1.0), 1.0)
    return tx, ty, r


@njit(cache=True, nogil=True)
def _matches(local, distance, tolerance):
    """(n,) bool: camera-space points local (n, 3) of a view that its distance map (h, w) shows."""
    h, w = distance.shape
    out = np.zeros(local.shape[0], np.bool_)
    for k in range(local.shape[0]):
        if not local[k, 2] <= 0.0:
            continue
        tx, ty, r = _project(local[k, 0], local[k, 1], local[k, 2])
        x0 = np.int64(math.floor((tx + 1.0) * 0.5 * w - 0.5))
        y0 = np.int64(math.floor((1.0 - ty) * 0.5 * h - 0.5))
        for dx, dy in ((0, 0), (1, 0), (0, 1), (1, 1)):
            d = distance[min(max(y0 + dy, 0), h - 1), min(max(x0 + dx, 0), w - 1)]
            if d > 0 and abs(d - r) < tolerance * r:
                out[k] = True
                break
    return out


@njit(cache=True, nogil=True)
def _sky(local, distance):
    """(n,) bool: camera-space directions local (n, 3) along which the view shows sky."""
    h, w = distance.shape
    out = np.zeros(local.shape[0], np.bool_)
    for k in range(local.shape[0]):
        if not local[k, 2] <= 0.0:
            continue
        tx, ty, _ = _project(local[k, 0], local[k, 1], local[k, 2])
        x = min(max(np.int64((tx + 1.0) * 0.5 * w), 0), w - 1)
        y = min(max(np.int64((1.0 - ty) * 0.5 * h), 0), h - 1)
        out[k] = distance[y, x] == 0
    return out


def matches_view(points, view_pose: Pose, distance: np.ndarray, tolerance: float) -> np.ndarray:
    """(n,) True where the view's distance map (h, w), row 0 on top, shows the point."""
    local = (points - view_pose.p) @ view_pose.rotation()
    return _matches(np.ascontiguousarray(local, np.float64), distance, float(tolerance))


def sky_in_view(directions: np.ndarray, view_pose: Pose, distance: np.ndarray) -> np.ndarray:
    """(n,) True where the view shows sky along world directions (n, 3)."""
    local = directions @ view_pose.rotation()
    return _sky(np.ascontiguousarray(local, np.float64), distance)


def camera_rays(width: int, height: int, fov_deg: float, frustum=None) -> np.ndarray:
    """Unit directions (width * height, 3) of a perspective camera's pixel centres, row 0 on top,
    in camera space (looking along -Z); ``fov_deg`` is horizontal, or ``frustum`` ((left, right,
    down, up) tangents, protocol/frustum.py) sets the view when given."""
    return frustum_rays(symmetric(fov_deg, width, height) if frustum is None else frustum, width, height)


def displayed_points(rays: np.ndarray, pose: Pose, distance: np.ndarray):
    """What a perspective view at ``pose`` shows: world points (n, 3), sky (n,), world directions
    (n, 3), from its camera rays (n, 3) and ground-truth radial distance (h, w), 0 = sky."""
    r = distance.reshape(-1).astype(np.float64)
    dirs = rays @ pose.rotation().T
    return pose.p + dirs * r[:, None], r == 0, dirs


def uncovered(points, sky, dirs, views, tolerance: float = COVERAGE_TOLERANCE,
              peeled_marked: bool = True) -> np.ndarray:
    """(n,) True where no transmitted view saw what the displayed pixel shows: the one
    geometric definition of a hole, the same for every method.

    points, dirs : (n, 3) world points and directions of the displayed pixels (ground truth);
    sky : (n,) the pixel shows sky; views : [(pose, distance map (h, w), peeled)]. A view
    vouches for sky where it stores sky (distance 0); a depth-peeled view only if it marks the
    pixels it peeled away apart (``peeled_marked``: a negative distance, protocol/depth.py
    PEELED), else its 0 may be a surface the primary shows."""
    return uncovered_by_views(points, sky, dirs, views, tolerance, peeled_marked)[-1]


def uncovered_by_views(points, sky, dirs, views, tolerance: float = COVERAGE_TOLERANCE,
                       peeled_marked: bool = True) -> list:
    """:func:`uncovered` by the first view, the first two, ... : one (n,) mask per view, each
    pixel tested against a view only while no earlier view covers it."""
    covered = np.zeros(len(points), bool)
    geo = ~sky
    out = []
    for pose, dist, peeled in views:
        todo = geo & ~covered
        covered[todo] = matches_view(points[todo], pose, dist, tolerance)
        if not peeled or peeled_marked:
            s = sky & ~covered
            covered[s] = sky_in_view(dirs[s], pose, dist)
        out.append(~covered)
    return out


class CoverageProbe:
    """Renders ground truth and wide-angle views of one scene at small sizes, on this thread."""

    def __init__(self, scene, view_size=(512, 512), out_size=(320, 180), fov_deg=90.0, projection="vertex",
                 tolerance=COVERAGE_TOLERANCE, ctx=None, mark_peeled: bool = True, renderer=None, frustum=None):
        """``renderer``: a :class:`~pibr.server.renderer.Renderer` of ``scene`` on ``ctx`` to share (the
        server's); it stays its owner's to release. None: the probe makes its own. ``frustum``: the
        displayed camera's (left, right, down, up) tangents (an eye's, protocol/frustum.py), else
        ``fov_deg`` sets it."""
        from pibr.common.gl import create_context
        from pibr.server.render_target import RenderTarget
        from pibr.server.renderer import PEEL_TOLERANCE, Renderer

        self._own = ctx is None
        self.ctx = create_context() if ctx is None else ctx
        self.scene, self.fov_deg, self.projection, self.tolerance = scene, fov_deg, projection, tolerance
        self.mark_peeled = mark_peeled   # peeled views mark what they peeled (as the server does by default)
        self.peel_tolerance = PEEL_TOLERANCE
        self._own_renderer = renderer is None
        with self._current():
            # its own renderer draws distances only (the probe reads nothing else): the same bits
            self.renderer = Renderer(self.ctx, scene, projection, shade=False) if renderer is None else renderer
            self.primary = RenderTarget(self.ctx, *view_size)
            self.extra = RenderTarget(self.ctx, view_size[0] // 2, view_size[1] // 2)
            self.gt = RenderTarget(self.ctx, *out_size)
        self.frustum = frustum
        self._dirs = camera_rays(*out_size, fov_deg, frustum)

    # Every GL entry point makes this probe's own context current first (``with self.ctx``):
    # another context created on the same thread since would otherwise receive the calls. A
    # context it was given is its owner's, current on the owner's thread (the server's GL
    # thread): leaving ``with ctx`` would make it not current there, so it is used as it is.
    def _current(self):
        import contextlib

        return self.ctx if self._own else contextlib.nullcontext()

    def display_points(self, pose: Pose, t: float):
        """Ground truth at the displayed pose: world points (n, 3), sky mask (n,), world directions (n, 3)."""
        with self._current():
            self.renderer.render_perspective(self.gt, pose, t, self.fov_deg, self.frustum)
            distance = self.gt.read_distance()
        return displayed_points(self._dirs, pose, distance)

    def render_primary(self, pose: Pose, t: float) -> np.ndarray:
        with self._current():
            self.renderer.render_wide(self.primary, pose, t, self.projection)
            return self.primary.read_distance().copy()

    def load_primary(self, distance: np.ndarray) -> None:
        """Put a primary distance map rendered earlier back where peeling reads it."""
        with self._current():
            self.primary.distance.write(np.ascontiguousarray(distance, np.float32).tobytes())

    def render_extra(self, primary_pose: Pose, offset: Pose, t: float, peel: bool) -> np.ndarray:
        """The extra view's distance map; the primary must be the last one rendered."""
        peel_arg = (self.primary, primary_pose, self.peel_tolerance) if peel else None
        with self._current():
            self.renderer.render_wide(self.extra, primary_pose.compose(offset), t, self.projection, peel=peel_arg,
                                      mark_peeled=self.mark_peeled)
            return self.extra.read_distance().copy()

    def missing(self, points, sky, dirs, views) -> tuple[float, float]:
        """(fraction of all pixels, fraction of pixels showing geometry) no view covers.

        views: [(pose, distance map, peeled)]."""
        holes = uncovered(points, sky, dirs, views, self.tolerance, self.mark_peeled)
        geo = ~sky
        n_geo = int(geo.sum())
        geo_missing = float((geo & holes).sum() / n_geo) if n_geo else 0.0
        return float(holes.mean()), geo_missing

    def close(self) -> None:
        with self._current():
            if self._own_renderer:
                self.renderer.release()
            for t in (self.primary, self.extra, self.gt):
                t.release()
        if self._own:
            self.ctx.release()
