"""Built-in scenes, made procedurally (no downloaded assets): ``room`` (default), ``sphere``,
``courtyard``, ``dynamic`` (things in motion), ``empty``.

``room`` is the showcase and the stress test for image-based rendering: a 10 m x 10 m x
3.2 m gallery around a central exhibit, with occluders at several depths, thin structures
(railing balusters, lamp cables, window mullions, a tree's leaves), textured floor and
walls, moving objects (ceiling fan, pendulum), and a large window onto a landscape whose
hills stand 100-450 m away. Head traces are replayed from ``VIEWER_ORIGIN`` (standing eye
height at the origin, facing -Z); the recorded people stay within about x in [-1, 3],
z in [-1.8, 1.6], which is kept free of everything but the exhibit.

Layout (metres, +Y up; the viewer starts at (0, 1.6, 0) looking -Z)::

            z = -5  north wall: 7 m window (x -3..4) with mullions, terrace and landscape beyond
     tree (-2.4,-3.9)      ceiling fan (0.9, 2.9, -3.4)
     pillar (-1.9,-2.8)    display table (1.0,-2.3)      pillar (2.6,-2.9)
     plinth+bust (-1.6,-1.0)   EXHIBIT (0.3,-0.2)         plinth+cube (3.6,-0.6)
  partition x=-3.3     pendulum (-2.3, *, 0.2)                    bookshelves on the east wall
     (painting)          viewer origin (0, 0)                        (x 5.15..5.5)
     plinth+vase (-1.6,1.3)                  plinth+shapes (2.2,2.0)  pillar (3.9,2.1)
     pillar (-1.9,2.2)   railing z=2.6 with steps at x 0.2..1.6
            platform (y 0.45, z 2.6..5): sofa, rug, floor lamp, plant
            z = +5  south wall: window (x -1..3)
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from pibr.protocol.pose import Pose, dual_view_offset

from . import primitives as prim
from . import textures as tex
from .scene import Animation, Light, Material, Mesh, Scene, SceneObject

#: Where head traces are replayed from in ``room`` and ``sphere`` (standing eye height, facing -Z).
VIEWER_ORIGIN = Pose.make((0.0, 1.6, 0.0))
#: Centre of the region the recorded people move in; the exhibit stands here.
FOCUS_POINT = (0.3, 1.6, -0.2)
#: The ``sphere`` scene's sphere. Not at the focus point: the viewer origin is only 0.36 m
#: from it (inside a 0.4 m sphere) and the recorded people walk right through it; straight
#: ahead of the focus at z = -2.6 no trace sample comes closer than 0.45 m to its surface.
SPHERE_CENTER = (0.3, 1.6, -2.6)
SPHERE_RADIUS = 0.4
#: Interior of the room: (2, 3) min and max corners.
ROOM_BOUNDS = np.array([[-4.5, 0.0, -5.0], [5.5, 3.2, 5.0]])
#: Where eyes go when the traces are replayed (the tessellation region).
VIEW_REGION = np.array([[-1.2, 0.7, -2.0], [3.2, 1.9, 1.9]])
#: Railing balusters: square section and centre spacing, metres.
BALUSTER_WIDTH = 0.025
BALUSTER_SPACING = 0.12

_H = 3.2                 # ceiling height
_WALL = 0.2              # wall thickness
_PLATFORM_Y = 0.45
_PLATFORM_Z = 2.6        # front edge of the raised platform
_STEPS_X = (0.2, 1.6)
_PARQUET_M = 1.6         # metres per parquet texture repeat (20 cm planks)
_PLASTER_M = 2.0
_BRICK_M = 0.9


# ----------------------------------------------------------------------------- helpers

class _SceneBuilder:
    """Collects objects and shares each texture among its materials (Scene checks the names are unique)."""

    def __init__(self):
        self.objects: list[SceneObject] = []
        self._textures: dict[str, np.ndarray] = {}

    def texture(self, name: str) -> np.ndarray:
        if name not in self._textures:
            self._textures[name] = tex.TEXTURES[name]()
        return self._textures[name]

    def material(self, name: str, color=(1.0, 1.0, 1.0), texture: str | None = None) -> Material:
        return Material(name, tuple(color) + (1.0,), None if texture is None else self.texture(texture))

    def add(self, name: str, mesh: Mesh, material: Material, transform=None,
            animation: Animation | None = None) -> SceneObject:
        obj = SceneObject(name, mesh, material, np.eye(4) if transform is None else transform, animation)
        self.objects.append(obj)
        return obj


def _rgba(color) -> tuple:
    """Linear RGB (3,) in [0, 1] -> uint8 RGBA for vertex colours (they multiply linearly)."""
    c = np.clip(np.asarray(color, dtype=np.float64), 0, 1)
    return tuple(int(round(x * 255)) for x in c) + (255,)


def _basis(x_to, y_to, z_to) -> np.ndarray:
    """(4, 4) rotation sending the axes X, Y, Z to the given orthonormal directions (3,)."""
    m = np.eye(4)
    m[:3, :3] = np.stack([x_to, y_to, z_to], axis=1)
    if not np.allclose(m[:3, :3].T @ m[:3, :3], np.eye(3)) or np.linalg.det(m[:3, :3]) < 0:
        raise ValueError("_basis needs a right-handed orthonormal basis")
    return m


def _segment(p0, p1) -> np.ndarray:
    """(4, 4) placing a mesh built along +Y from the origin so it starts at p0 and points to p1."""
    return prim.compose(prim.translation(np.asarray(p0, dtype=np.float64)),
                        prim.rotation_between((0, 1, 0), np.asarray(p1, dtype=np.float64) - p0))


def _tube(radius: float, p0, p1, segments: int = 8, top_radius: float | None = None, caps: bool = False) -> Mesh:
    """Cylinder (frustum) from p0 (3,) to p1 (3,)."""
    p0, p1 = np.asarray(p0, dtype=np.float64), np.asarray(p1, dtype=np.float64)
    length = float(np.linalg.norm(p1 - p0))
    mesh = prim.cylinder(radius, length, segments, caps=caps, top_radius=top_radius)
    return prim.transform_mesh(mesh, _segment(p0, p1))


# ----------------------------------------------------------------------------- the room: shell

def _add_shell(b: _SceneBuilder) -> None:
    (x0, _, z0), (x1, _, z1) = ROOM_BOUNDS
    cx = (x0 + x1) / 2
    floor = prim.grid_plane(x1 - x0, z1 - z0, cell_size=0.5, uv_scale=_PARQUET_M)
    b.add("floor_parquet", floor, b.material("parquet", (0.88, 0.84, 0.8), "parquet"), prim.translation(cx, 0, 0))
    ceiling = prim.grid_plane(x1 - x0, z1 - z0, cell_size=1.0, uv_scale=_PLASTER_M)
    b.add("ceiling", ceiling, b.material("ceiling_paint", (0.95, 0.95, 0.93), "plaster"),
          prim.compose(prim.translation(cx, _H, 0), prim.rotation((1, 0, 0), math.pi)))
    t = _WALL
    plaster = b.material("wall_paint", (0.93, 0.9, 0.84), "plaster")
    # north wall (z = z0) with the big window: x -3.0..4.0, y 0.5..2.7
    wx0, wx1, wy0, wy1 = -3.0, 4.0, 0.5, 2.7
    north = [((x0 - t, 0, z0 - t), (x1 + t, wy0, z0)), ((x0 - t, wy1, z0 - t), (x1 + t, _H, z0)),
             ((x0 - t, wy0, z0 - t), (wx0, wy1, z0)), ((wx1, wy0, z0 - t), (x1 + t, wy1, z0))]
    b.add("wall_north", prim.merge(prim.box_between(lo, hi, _PLASTER_M, 1.0) for lo, hi in north), plaster)
    # south wall (z = z1) with a smaller window above the platform: x -1..3, y 1.3..2.8
    sx0, sx1, sy0, sy1 = -1.0, 3.0, 1.3, 2.8
    south = [((x0 - t, 0, z1), (x1 + t, sy0, z1 + t)), ((x0 - t, sy1, z1), (x1 + t, _H, z1 + t)),
             ((x0 - t, sy0, z1), (sx0, sy1, z1 + t)), ((sx1, sy0, z1), (x1 + t, sy1, z1 + t))]
    b.add("wall_south", prim.merge(prim.box_between(lo, hi, _PLASTER_M, 1.0) for lo, hi in south), plaster)
    b.add("wall_east", prim.box_between((x1, 0, z0), (x1 + t, _H, z1), _PLASTER_M, 1.0), plaster)
    b.add("wall_west_brick", prim.box_between((x0 - t, 0, z0), (x0, _H, z1), _BRICK_M, 1.0),
          b.material("brick", texture="brick"))
    # window frames: outer frame, mullions every ~1.4 m, a transom; 6 x 10 cm steel sections
    frame = []
    for (fx0, fx1, fy0, fy1, zc, n_mullions, transom) in (
            (wx0, wx1, wy0, wy1, z0 - t / 2, 4, 2.2), (sx0, sx1, sy0, sy1, z1 + t / 2, 2, None)):
        w, d = 0.06, 0.1
        frame += [((fx0, fy0, zc - d / 2), (fx1, fy0 + w, zc + d / 2)),
                  ((fx0, fy1 - w, zc - d / 2), (fx1, fy1, zc + d / 2)),
                  ((fx0, fy0, zc - d / 2), (fx0 + w, fy1, zc + d / 2)),
                  ((fx1 - w, fy0, zc - d / 2), (fx1, fy1, zc + d / 2))]
        for k in range(1, n_mullions + 1):
            xm = fx0 + (fx1 - fx0) * k / (n_mullions + 1)
            frame.append(((xm - w / 2, fy0, zc - d / 2), (xm + w / 2, fy1, zc + d / 2)))
        if transom is not None:
            frame.append(((fx0, transom - w / 2, zc - d / 2), (fx1, transom + w / 2, zc + d / 2)))
    b.add("window_frames", prim.merge(prim.box_between(lo, hi, max_cell=0.5) for lo, hi in frame),
          b.material("window_steel", (0.06, 0.065, 0.07)))
    b.add("window_sill_marble", prim.box_between((wx0 - 0.05, wy0 - 0.03, z0 - 0.02), (wx1 + 0.05, wy0, z0 + 0.12),
                                                 0.6, 0.5), b.material("sill_marble", (0.9, 0.9, 0.88), "marble"))
    # skirting boards along the walls (not across the platform, which covers the south end)
    sk, skh = 0.015, 0.08
    skirting = [((x0, 0, z0), (x1, skh, z0 + sk)),
                ((x0, 0, z0), (x0 + sk, skh, _PLATFORM_Z)), ((x1 - sk, 0, z0), (x1, skh, _PLATFORM_Z))]
    b.add("skirting_boards", prim.merge(prim.box_between(lo, hi, max_cell=0.5) for lo, hi in skirting),
          b.material("skirting_paint", (0.85, 0.85, 0.82)))


def _add_platform(b: _SceneBuilder) -> None:
    """Raised platform at the south end with steps and a railing of thin balusters."""
    (x0, _, _), (x1, _, z1) = ROOM_BOUNDS
    slab = 0.02
    tops = [prim.box_between((x0, _PLATFORM_Y - slab, _PLATFORM_Z), (x1, _PLATFORM_Y, z1), _PARQUET_M, 0.5)]
    bases = [prim.box_between((x0, 0, _PLATFORM_Z + 0.01), (x1, _PLATFORM_Y - slab, z1), _PLASTER_M, 0.5)]
    sx0, sx1 = _STEPS_X
    rise = _PLATFORM_Y / 3
    for k in (1, 2):  # two steps up to the third rise, the platform itself
        z_front = _PLATFORM_Z - 0.3 * (3 - k)
        tops.append(prim.box_between((sx0, rise * k - slab, z_front), (sx1, rise * k, _PLATFORM_Z), _PARQUET_M, 0.35))
        bases.append(prim.box_between((sx0 + 0.01, 0, z_front + 0.01), (sx1 - 0.01, rise * k - slab, _PLATFORM_Z),
                                      _PLASTER_M, 0.35))
    b.add("platform_floor", prim.merge(tops), b.material("platform_parquet", (0.88, 0.84, 0.8), "parquet"))
    b.add("platform_base", prim.merge(bases), b.material("platform_paint", (0.8, 0.78, 0.74), "plaster"))
    # railing along the platform edge, interrupted by the steps
    y0, rail_h = _PLATFORM_Y, 0.9
    zc = _PLATFORM_Z + 0.04
    runs = [(x0 + 0.05, sx0), (sx1, x1 - 0.05)]
    sizes, centers, rails = [], [], []
    post = 0.07
    for ra, rb in runs:
        n = int(math.floor((rb - ra - post) / BALUSTER_SPACING))
        xs = (ra + rb) / 2 + (np.arange(n) - (n - 1) / 2) * BALUSTER_SPACING
        xs = xs[(xs > ra + post) & (xs < rb - post)]
        bottom, top = y0 + 0.07, y0 + rail_h          # from inside the bottom rail to inside the handrail
        for x in xs:
            sizes.append((BALUSTER_WIDTH, top - bottom, BALUSTER_WIDTH))
            centers.append((x, (bottom + top) / 2, zc))
        rails += [((ra, y0 + rail_h - 0.01, zc - 0.03), (rb, y0 + rail_h + 0.04, zc + 0.03)),   # handrail
                  ((ra, y0 + 0.05, zc - 0.015), (rb, y0 + 0.09, zc + 0.015))]                    # bottom rail
        for xp in (ra, rb):
            rails.append(((xp - post / 2, y0, zc - post / 2), (xp + post / 2, y0 + rail_h + 0.08, zc + post / 2)))
    b.add("railing_balusters", prim.boxes(sizes, centers, divisions=(1, 6, 1)),
          b.material("baluster_iron", (0.03, 0.03, 0.035)))
    b.add("railing_handrails", prim.merge(prim.box_between(lo, hi, 0.5, 0.25) for lo, hi in rails),
          b.material("handrail_wood", (0.8, 0.6, 0.45), "wood"))


# ----------------------------------------------------------------------------- the room: furniture

def _add_exhibit(b: _SceneBuilder) -> None:
    """Marble pedestal (1.1 m) with a bronze torus knot on top, reaching ~1.93 m."""
    fx, _, fz = FOCUS_POINT
    pedestal = prim.merge([prim.box((0.56, 0.08, 0.56), (0, 0.04, 0), 0.8, 0.2),
                           prim.box((0.42, 0.94, 0.42), (0, 0.55, 0), 0.8, 0.2),
                           prim.box((0.5, 0.08, 0.5), (0, 1.06, 0), 0.8, 0.2)])
    b.add("exhibit_pedestal", pedestal, b.material("pedestal_marble", (0.95, 0.95, 0.95), "marble"),
          prim.translation(fx, 0, fz))
    stand = prim.merge([prim.cylinder(0.09, 0.02, 24), (prim.cylinder(0.018, 0.12, 12, caps=False),
                                                        prim.translation(0, 0.02, 0))])
    b.add("exhibit_stand", stand, b.material("stand_steel", (0.2, 0.2, 0.22)), prim.translation(fx, 1.1, fz))
    knot = prim.torus_knot(radius=0.31, tube_radius=0.052, p=2, q=3, segments=640, tube_segments=20, uv_repeat=6)
    lo, hi = knot.bounds()
    lift = 1.1 + 0.13 - lo[1] - 0.01
    # The knot's flat side faces the viewer origin, which is only 0.36 m from the focus: this
    # way the origin stays ~0.25 m clear of it (edge-on it would be inside the tube).
    to_viewer = np.array(VIEWER_ORIGIN.position) - np.array(FOCUS_POINT)
    yaw = math.atan2(to_viewer[0], to_viewer[2])
    b.add("exhibit_torus_knot", knot, b.material("knot_bronze", (0.8, 0.5, 0.26), "marble"),
          prim.compose(prim.translation(fx, lift, fz), prim.rotation((0, 1, 0), yaw)))


def _add_pillars(b: _SceneBuilder) -> None:
    mat = b.material("pillar_paint", (0.88, 0.86, 0.82), "plaster")
    for k, (x, z) in enumerate([(-1.9, -2.8), (2.6, -2.9), (3.9, 2.1), (-1.9, 2.2)], start=1):
        y0 = 0.0
        shaft = prim.cylinder(0.18, _H - y0 - 0.3, 32, caps=False, uv_scale=_PLASTER_M, height_segments=10)
        mesh = prim.merge([prim.box((0.46, 0.15, 0.46), (0, y0 + 0.075, 0), _PLASTER_M, 0.25),
                           (shaft, prim.translation(0, y0 + 0.15, 0)),
                           prim.box((0.46, 0.15, 0.46), (0, _H - 0.075, 0), _PLASTER_M, 0.25)])
        b.add(f"pillar_{k}", mesh, mat, prim.translation(x, 0, z))


def _vase_profile(height: float, belly: float, neck: float, foot: float, n: int = 28) -> np.ndarray:
    """(n + 4, 2) (radius, y) outline of a closed vase: flat foot, round belly, narrow neck, flared lip."""
    t = np.linspace(0.0, 1.0, n)
    bulge = np.sin(np.pi * np.clip(t / 0.75, 0, 1)) ** 1.2          # belly around a third of the way up
    r = foot + (belly - foot) * bulge * (1 - t) ** 0.3
    r = np.maximum(r, neck) + (t > 0.8) * ((t - 0.8) / 0.2) ** 2 * neck * 0.5   # flared lip
    r[0] = foot
    prof = np.stack([r, t * height], 1)
    return np.vstack([[0.0, 0.0], prof, [r[-1] - 0.012, height], [neck * 0.8, height - 0.05], [0.0, height - 0.05]])


def _add_plinths(b: _SceneBuilder) -> None:
    white = b.material("plinth_paint", (0.92, 0.92, 0.9), "plaster")
    plinths = {"plinth_bust": (-1.6, -1.0, 1.0), "plinth_vase": (-1.6, 1.3, 0.9),
               "plinth_shapes": (2.2, 2.0, 0.8), "plinth_cube": (3.6, -0.6, 1.05),
               "plinth_hidden_vase": (-4.0, 0.3, 1.0)}
    for name, (x, z, h) in plinths.items():
        b.add(name, prim.box((0.44, h, 0.44), (0, h / 2, 0), 1.0, 0.25), white, prim.translation(x, 0, z))
    # a marble bust: head, neck, shoulders on a round foot
    x, z, h = plinths["plinth_bust"]
    socle = prim.lathe([[0, 0], [0.1, 0], [0.1, 0.03], [0.07, 0.05], [0.05, 0.09], [0.05, 0.09], [0, 0.09]], 32)
    chest = prim.transform_mesh(prim.sphere(1.0, 32, 16), prim.compose(prim.translation(0, 0.19, 0),
                                                                       prim.scaling((0.17, 0.12, 0.095))))
    neck = prim.transform_mesh(prim.cylinder(0.045, 0.1, 20, caps=False), prim.translation(0, 0.26, 0))
    head = prim.transform_mesh(prim.sphere(1.0, 32, 16), prim.compose(prim.translation(0, 0.41, 0.01),
                                                                      prim.scaling((0.085, 0.11, 0.1))))
    bust = prim.merge([socle, chest, neck, head])
    b.add("marble_bust", bust, b.material("bust_marble", (0.97, 0.97, 0.97), "marble"),
          prim.compose(prim.translation(x, h, z), prim.rotation((0, 1, 0), math.radians(40))))
    x, z, h = plinths["plinth_vase"]
    b.add("glazed_vase", prim.lathe(_vase_profile(0.45, 0.14, 0.06, 0.08), 40),
          b.material("vase_glaze", (0.08, 0.2, 0.55)), prim.translation(x, h, z))
    x, z, h = plinths["plinth_hidden_vase"]
    b.add("hidden_vase", prim.lathe(_vase_profile(0.6, 0.12, 0.05, 0.07), 40),
          b.material("hidden_vase_glaze", (0.5, 0.12, 0.05)), prim.translation(x, h, z))
    x, z, h = plinths["plinth_shapes"]
    shapes = prim.merge([
        prim.colored(prim.torus(0.12, 0.035, 48, 16), _rgba((0.8, 0.1, 0.08))),
        prim.colored(prim.cone(0.09, 0.3, 32), _rgba((0.9, 0.75, 0.1))),           # rests in the ring
        (prim.colored(prim.sphere(0.06, 24, 12), _rgba((0.1, 0.5, 0.2))), prim.translation(0.0, 0.36, 0.0)),
    ])
    b.add("sculpture_shapes", shapes, b.material("painted_shapes"), prim.translation(x, h + 0.035, z))
    x, z, h = plinths["plinth_cube"]
    b.add("calibration_cube", prim.box((0.3, 0.3, 0.3), (0, 0.15, 0)),
          b.material("test_pattern", texture="test_pattern"),
          prim.compose(prim.translation(x, h, z), prim.rotation((0, 1, 0), math.radians(30))))


def _add_display_table(b: _SceneBuilder) -> None:
    x, z = 1.0, -2.3
    w, d, h = 1.3, 0.7, 0.8
    leg = 0.04
    parts = [prim.box((w, 0.04, d), (0, h - 0.02, 0), 1.0, 0.25)]
    for sx in (-1, 1):
        for sz in (-1, 1):
            parts.append(prim.box((leg, h - 0.04, leg), (sx * (w / 2 - 0.05), (h - 0.04) / 2, sz * (d / 2 - 0.05)),
                                  max_cell=0.15))
    b.add("display_table", prim.merge(parts), b.material("table_wood", (0.65, 0.5, 0.4), "wood"),
          prim.translation(x, 0, z))
    rng = np.random.default_rng(21)
    bowl = prim.lathe([[0, 0], [0.06, 0], [0.06, 0.01], [0.15, 0.08], [0.16, 0.09], [0.15, 0.09], [0.06, 0.03],
                       [0, 0.03]], 40)
    items = [(prim.colored(bowl, _rgba((0.85, 0.82, 0.75))), prim.translation(-0.25, 0, 0.05))]
    for k in range(5):
        a = 2 * np.pi * k / 5 + rng.uniform(-0.2, 0.2)
        col = [(0.7, 0.08, 0.05), (0.75, 0.5, 0.05), (0.3, 0.55, 0.08)][k % 3]
        r = rng.uniform(0.035, 0.045)
        items.append((prim.colored(prim.sphere(r, 20, 10), _rgba(col)),
                      prim.translation(-0.25 + 0.07 * np.cos(a), 0.03 + r, 0.05 + 0.07 * np.sin(a))))
    items.append((prim.colored(prim.cylinder(0.05, 0.28, 32, top_radius=0.03), _rgba((0.15, 0.3, 0.35))),
                  prim.translation(0.2, 0, -0.1)))
    items.append((prim.colored(prim.torus(0.07, 0.02, 32, 12), _rgba((0.6, 0.6, 0.65))),
                  prim.compose(prim.translation(0.42, 0.09, 0.12), prim.rotation((1, 0, 0), math.pi / 2))))
    b.add("table_still_life", prim.merge(items), b.material("still_life"), prim.translation(x, h, z))


def _add_partition(b: _SceneBuilder) -> None:
    """Free-standing partition wall west of the viewer, with a test-pattern painting on it."""
    x, z0, z1, h, t = -3.3, -1.4, 1.8, 2.4, 0.12
    b.add("partition_wall", prim.box_between((x - t / 2, 0, z0), (x + t / 2, h, z1), _PLASTER_M, 0.5),
          b.material("partition_paint", (0.25, 0.45, 0.5), "plaster"))
    # painting on the room side (+X face): canvas 1.1 x 0.75 in a 4 cm frame
    cz, cy, cw, ch = 0.2, 1.5, 1.1, 0.75
    face = x + t / 2
    # grid_plane: u along X, facing +Y, v along -Z -> here u along -Z, facing +X, v along +Y
    canvas = prim.transform_mesh(prim.grid_plane(cw, ch, 0.25),
                                 prim.compose(prim.translation(face + 0.021, cy, cz),
                                              _basis((0, 0, -1), (1, 0, 0), (0, -1, 0))))
    b.add("painting_canvas", canvas, b.material("painting_test_pattern", texture="test_pattern"))
    fw = 0.04
    frame = [((face, cy - ch / 2 - fw, cz - cw / 2 - fw), (face + 0.03, cy - ch / 2, cz + cw / 2 + fw)),
             ((face, cy + ch / 2, cz - cw / 2 - fw), (face + 0.03, cy + ch / 2 + fw, cz + cw / 2 + fw)),
             ((face, cy - ch / 2, cz - cw / 2 - fw), (face + 0.03, cy + ch / 2, cz - cw / 2)),
             ((face, cy - ch / 2, cz + cw / 2), (face + 0.03, cy + ch / 2, cz + cw / 2 + fw))]
    b.add("painting_frame", prim.merge(prim.box_between(lo, hi) for lo, hi in frame),
          b.material("gilt_frame", (0.6, 0.42, 0.12)))


def _add_bookshelves(b: _SceneBuilder) -> None:
    """Four shelf units along the east wall, filled with ~600 books (vertex-coloured boxes)."""
    x_back = ROOM_BOUNDS[1, 0]
    depth, height, unit_w = 0.34, 2.2, 1.35
    z_start = -3.8
    boards = np.array([0.06, 0.5, 0.94, 1.38, 1.82, 2.2])
    board_t, side_t = 0.025, 0.025
    frame = []
    for u in range(4):
        za = z_start + u * unit_w
        frame.append(((x_back - depth, 0, za), (x_back - depth + side_t, 0.06, za + unit_w)))        # kick plate
        frame.append(((x_back - 0.012, 0, za), (x_back, height, za + unit_w)))                          # back
        for zs in (za, za + unit_w - side_t):
            frame.append(((x_back - depth, 0, zs), (x_back, height + board_t, zs + side_t)))            # sides
        for y in boards:
            frame.append(((x_back - depth, y, za + side_t), (x_back, y + board_t, za + unit_w - side_t)))
    b.add("bookshelves", prim.merge(prim.box_between(lo, hi, 1.0, 0.4) for lo, hi in frame),
          b.material("shelf_wood", (0.55, 0.42, 0.35), "wood"))
    rng = np.random.default_rng(31)
    palette = np.array([(0.45, 0.05, 0.04), (0.05, 0.08, 0.3), (0.06, 0.25, 0.1), (0.6, 0.45, 0.08),
                        (0.3, 0.15, 0.06), (0.03, 0.03, 0.03), (0.75, 0.7, 0.55), (0.05, 0.3, 0.35),
                        (0.5, 0.25, 0.4), (0.7, 0.3, 0.05)])
    sizes, centers, colors = [], [], []
    for u in range(4):
        za = z_start + u * unit_w + side_t
        zb = za + unit_w - 2 * side_t
        for level in range(5):
            y = boards[level] + board_t
            gap = boards[level + 1] - y
            z = za + rng.uniform(0.0, 0.04)
            while True:
                w = rng.uniform(0.02, 0.055)
                if z + w > zb - 0.005:
                    break
                if rng.random() < 0.06:       # an empty stretch
                    z += rng.uniform(0.08, 0.2)
                    continue
                hgt = min(rng.uniform(0.17, 0.33), gap - 0.02)
                dep = rng.uniform(0.15, 0.26)
                sizes.append((dep, hgt, w))
                centers.append((x_back - 0.015 - dep / 2 - rng.uniform(0, 0.03), y + hgt / 2, z + w / 2))
                colors.append(palette[rng.integers(len(palette))] * rng.uniform(0.7, 1.15))
                z += w + rng.uniform(0.0, 0.004)
    books = prim.boxes(sizes, centers)
    vertex_colors = np.repeat(np.array([_rgba(c) for c in colors], dtype=np.uint8), 24, axis=0)
    books = Mesh(books.vertices, books.faces, books.normals, books.uvs, vertex_colors)
    b.add("books", books, b.material("book_covers"))


def _add_lounge(b: _SceneBuilder) -> None:
    """Sofa, rug and floor lamp on the platform."""
    y = _PLATFORM_Y
    x, z = -2.2, 4.4          # sofa centre, backrest towards +Z
    w, d = 2.0, 0.85
    parts = [prim.box((w, 0.2, d), (0, 0.15, 0), 0.5),                                     # base
             prim.box((w - 0.3, 0.16, d - 0.2), (0, 0.33, -0.08), 0.5),                   # seat cushions
             prim.box((w, 0.5, 0.2), (0, 0.5, d / 2 - 0.1), 0.5),                          # backrest
             prim.box((0.15, 0.38, d), (-w / 2 + 0.075, 0.44, 0), 0.5),                    # arms
             prim.box((0.15, 0.38, d), (w / 2 - 0.075, 0.44, 0), 0.5)]
    for sx in (-1, 1):
        for sz in (-1, 1):
            parts.append(prim.box((0.05, 0.05, 0.05), (sx * (w / 2 - 0.1), 0.025, sz * (d / 2 - 0.1))))
    b.add("sofa", prim.merge(parts), b.material("sofa_fabric", (0.2, 0.32, 0.45), "fabric"),
          prim.translation(x, y, z))
    b.add("rug", prim.box((2.6, 0.01, 1.7), (0, 0.005, 0), max_cell=0.4), b.material("rug", texture="carpet"),
          prim.translation(-2.0, y, 3.55))
    lamp = prim.merge([prim.colored(prim.cylinder(0.16, 0.03, 32), _rgba((0.05, 0.05, 0.05))),
                       (prim.colored(prim.cylinder(0.012, 1.45, 8, caps=False), _rgba((0.05, 0.05, 0.05))),
                        prim.translation(0, 0.03, 0)),
                       (prim.colored(prim.cylinder(0.22, 0.3, 32, caps=False, top_radius=0.16),
                                     _rgba((0.9, 0.85, 0.7))), prim.translation(0, 1.35, 0))])
    b.add("floor_lamp", lamp, b.material("floor_lamp"), prim.translation(-3.7, y, 4.5))


def _branchy_plant(rng: np.random.Generator, trunk_height: float, n_branches: int, leaves_per_branch: int,
                   leaf_size: float, spread: float) -> tuple[Mesh, Mesh]:
    """(wood, leaves) of a small tree at the origin: a tapered trunk, branches, many single leaves."""
    wood = [_tube(0.035, (0, 0, 0), (0, trunk_height, 0), 10, top_radius=0.015)]
    leaf_mats = []
    for k in range(n_branches):
        y0 = trunk_height * rng.uniform(0.45, 0.95)
        yaw = 2 * np.pi * (k / n_branches) + rng.uniform(-0.3, 0.3)
        out = np.array([np.sin(yaw), rng.uniform(0.35, 0.9), np.cos(yaw)])
        length = spread * rng.uniform(0.6, 1.0)
        p0 = np.array([0, y0, 0])
        p1 = p0 + out / np.linalg.norm(out) * length
        wood.append(_tube(0.014, p0, p1, 6, top_radius=0.005))
        for _ in range(leaves_per_branch):
            s = rng.uniform(0.25, 1.05)
            pos = p0 + (p1 - p0) * s + rng.normal(0, 0.04 * length, 3)
            m = prim.compose(prim.translation(pos),
                             prim.rotation((0, 1, 0), rng.uniform(0, 2 * np.pi)),
                             prim.rotation((1, 0, 0), rng.uniform(-0.9, 0.4)),
                             prim.rotation((0, 0, 1), rng.uniform(-0.5, 0.5)),
                             prim.scaling(leaf_size * rng.uniform(0.75, 1.25)))
            leaf_mats.append(m)
    # a crown of leaves at the top of the trunk
    for _ in range(leaves_per_branch * 2):
        pos = np.array([0, trunk_height, 0]) + rng.normal(0, 0.08, 3) * [1, 0.6, 1]
        leaf_mats.append(prim.compose(prim.translation(pos), prim.rotation((0, 1, 0), rng.uniform(0, 2 * np.pi)),
                                      prim.rotation((1, 0, 0), rng.uniform(-1.2, 0.2)),
                                      prim.scaling(leaf_size * rng.uniform(0.75, 1.25))))
    leaves = prim.instances(prim.leaf(1.0, 0.42, 4, curl=0.25, fold=0.2), np.stack(leaf_mats))
    return prim.merge(wood), leaves


def _add_plants(b: _SceneBuilder) -> None:
    bark = b.material("bark", (0.25, 0.16, 0.09))
    leaf_mat = b.material("leaves", (1.0, 1.0, 1.0), "leaf_green")
    pot_mat = b.material("terracotta_pot")
    pot_profile = np.array([[0, 0], [0.16, 0], [0.16, 0], [0.22, 0.42], [0.24, 0.44], [0.24, 0.46], [0.2, 0.46],
                            [0.2, 0.40], [0.2, 0.40], [0, 0.40]])
    pot = prim.merge([prim.colored(prim.lathe(pot_profile[:-2], 32), _rgba((0.6, 0.26, 0.14))),
                      (prim.colored(prim.cylinder(0.2, 0.005, 32, caps=True), _rgba((0.09, 0.06, 0.04))),
                       prim.translation(0, 0.395, 0))])
    for name, (x, y, z), seed, scale, n_branches, per_branch in (
            ("tree", (-2.4, 0.0, -3.9), 41, 1.0, 14, 30), ("plant", (4.6, _PLATFORM_Y, 3.5), 42, 0.6, 9, 16)):
        rng = np.random.default_rng(seed)
        wood, leaves = _branchy_plant(rng, 1.9 * scale, n_branches, per_branch, 0.13 * max(scale, 0.8),
                                      0.75 * scale)
        place = prim.translation(x, y + 0.4 * scale, z)
        b.add(f"{name}_pot", pot, pot_mat, prim.compose(prim.translation(x, y, z), prim.scaling(scale)))
        b.add(f"{name}_trunk", wood, bark, place)
        b.add(f"{name}_leaves", leaves, leaf_mat, place)


def _add_lamps(b: _SceneBuilder) -> None:
    """Pendant lamps on thin cables (8 mm diameter) from the ceiling."""
    cable_mat = b.material("cable", (0.02, 0.02, 0.02))
    shade_mat = b.material("lamp_shade")
    for k, (x, z, drop) in enumerate([(-0.6, -2.5, 1.0), (1.9, 1.0, 0.85), (-1.2, 1.0, 0.9)], start=1):
        top = _H - drop
        b.add(f"lamp_{k}_cable", prim.cylinder(0.004, drop, 8, caps=False, height_segments=4), cable_mat,
              prim.translation(x, top, z))
        canopy = prim.colored(prim.cylinder(0.04, 0.02, 16), _rgba((0.1, 0.1, 0.1)))
        cone = prim.colored(prim.cylinder(0.22, 0.28, 40, caps=False, top_radius=0.05, height_segments=3),
                            _rgba((0.75, 0.45, 0.12)))
        shade = prim.merge([
            (canopy, prim.translation(0, drop - 0.02, 0)),
            (cone, prim.translation(0, -0.28, 0)),
            (prim.colored(prim.sphere(0.05, 16, 8), _rgba((1.0, 0.97, 0.85))), prim.translation(0, -0.2, 0))])
        b.add(f"lamp_{k}_shade", shade, shade_mat, prim.translation(x, top, z))


def _add_moving(b: _SceneBuilder) -> None:
    """Ceiling fan (spins at 3 rad/s) and a pendulum (swings, 2.9 s period)."""
    fx, fy, fz = 0.9, 2.9, -3.4
    b.add("ceiling_fan_rod", prim.merge([prim.cylinder(0.012, _H - fy, 8, caps=False),
                                         (prim.cylinder(0.06, 0.04, 24), prim.translation(0, _H - fy - 0.04, 0))]),
          b.material("fan_metal", (0.15, 0.15, 0.15)), prim.translation(fx, fy, fz))
    parts = [prim.colored(prim.lathe([[0, -0.12], [0.05, -0.12], [0.11, -0.08], [0.12, -0.03], [0.1, 0.0],
                                      [0.03, 0.01], [0, 0.01]], 32), _rgba((0.15, 0.15, 0.15)))]
    blade = prim.colored(prim.box((0.62, 0.012, 0.13), (0.42, 0, 0)), _rgba((0.45, 0.3, 0.18)))
    for k in range(5):
        parts.append((blade, prim.compose(prim.rotation((0, 1, 0), 2 * np.pi * k / 5),
                                          prim.translation(0, -0.05, 0), prim.rotation((1, 0, 0), math.radians(12)))))
    b.add("ceiling_fan_rotor", prim.merge(parts), b.material("fan_rotor"), prim.translation(fx, fy, fz),
          Animation("spin", axis=(0, 1, 0), speed=3.0, pivot=(fx, fy, fz)))
    px, pz, length = -2.3, 0.2, 2.0
    bob_r = 0.12
    pendulum = prim.merge([
        prim.colored(prim.cylinder(0.006, length, 8, caps=False, height_segments=6), _rgba((0.2, 0.2, 0.2))),
        (prim.colored(prim.sphere(bob_r, 32, 16), _rgba((0.85, 0.6, 0.2))), prim.translation(0, -bob_r, 0))])
    b.add("pendulum", pendulum, b.material("pendulum_brass"), prim.translation(px, _H - length, pz),
          Animation("swing", axis=(1, 0, 0), speed=math.sqrt(9.81 / (length + bob_r)), amplitude=0.25,
                    pivot=(px, _H, pz)))
    b.add("pendulum_mount", prim.cylinder(0.05, 0.03, 24), b.material("pendulum_mount", (0.2, 0.2, 0.2)),
          prim.translation(px, _H - 0.03, pz))


# ----------------------------------------------------------------------------- outdoors

def _hills(rng: np.random.Generator, r_inner: float = 90.0, r_outer: float = 480.0,
           n_rings: int = 30, n_around: int = 256) -> Mesh:
    """Heightfield ring around the origin (vertex-coloured): flat at ``r_inner``, hills from ~120 m,
    mountains with snow beyond ~300 m. The ring closes without a seam (no duplicated column)."""
    r = r_inner * (r_outer / r_inner) ** np.linspace(0, 1, n_rings + 1) ** 1.2
    theta = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    rr, tt = np.meshgrid(r, theta, indexing="ij")          # s = r, t = theta
    ridge = np.zeros_like(rr)
    for k in range(3, 48):                                  # integer frequencies: periodic in theta
        amp = 1.0 / k ** 1.1
        ridge += amp * np.sin(k * tt + rng.uniform(0, 2 * np.pi) + rr * rng.uniform(0.003, 0.02))
    ridge = (ridge - ridge.min()) / (ridge.max() - ridge.min())
    envelope = np.clip((rr - 115.0) / 140.0, 0, 1) ** 1.5
    height = envelope * (8.0 + 75.0 * ridge ** 1.6) * (0.6 + 0.6 * np.clip((rr - 150) / 250, 0, 1)) - 0.6
    height += rng.normal(0, 0.8, height.shape) * envelope
    v = np.stack([rr * np.sin(tt), height, rr * np.cos(tt)], -1).reshape(-1, 3)
    s, t = np.meshgrid(np.arange(n_rings), np.arange(n_around), indexing="ij")
    a = s * n_around + t
    b_ = (s + 1) * n_around + t
    c = (s + 1) * n_around + (t + 1) % n_around
    d = s * n_around + (t + 1) % n_around
    faces = np.concatenate([np.stack([a, b_, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    mesh = Mesh(v, faces)
    slope = 1.0 - mesh.normals[:, 1]
    h = v[:, 1]
    grass = np.array([0.10, 0.20, 0.04])
    forest = np.array([0.04, 0.10, 0.03])
    rock = np.array([0.22, 0.2, 0.17])
    snow = np.array([0.85, 0.87, 0.9])
    w_forest = np.clip((h - 4) / 15, 0, 1)[:, None]
    col = grass * (1 - w_forest) + forest * w_forest
    w_rock = np.clip((h - 35) / 20 + slope[:] * 2, 0, 1)[:, None]
    col = col * (1 - w_rock) + rock * w_rock
    w_snow = np.clip((h - 62) / 8, 0, 1)[:, None]
    col = col * (1 - w_snow) + snow * w_snow
    # aerial perspective: far slopes fade towards a hazy blue
    haze = np.clip((np.hypot(v[:, 0], v[:, 2]) - 120) / 700, 0, 0.55)[:, None]
    col = col * (1 - haze) + np.array([0.35, 0.45, 0.6]) * haze
    colors = np.concatenate([np.clip(col * 255, 0, 255), np.full((len(v), 1), 255)], 1).astype(np.uint8)
    return Mesh(v, faces, mesh.normals, None, colors)


def _ground_ring(inner: float, outer: float, rings: int, around: int, uv_scale: float) -> Mesh:
    """Ground at y = 0 facing +Y between a square of half-size ``inner`` (the building, left
    open) and one of half-size ``outer``: concentric square rings whose width grows
    geometrically, each split into ``around`` cells (a multiple of 8, so corners are vertices).
    Cells stay roughly square and grow with distance, as the tessellation wants them."""
    if around % 8:
        raise ValueError("around must be a multiple of 8")
    half = inner * (outer / inner) ** np.linspace(0.0, 1.0, rings + 1)
    theta = 2 * np.pi * np.arange(around) / around              # from +Z towards +X
    d = np.stack([np.sin(theta), np.cos(theta)], 1)
    square = d / np.abs(d).max(axis=1, keepdims=True)           # on the unit square's outline
    xz = half[:, None, None] * square[None]                     # (rings + 1, around, 2); s = ring, t = around
    v = np.stack([xz[..., 0], np.zeros(xz.shape[:2]), xz[..., 1]], -1).reshape(-1, 3)
    s, t = np.meshgrid(np.arange(rings), np.arange(around), indexing="ij")
    a, b = s * around + t, (s + 1) * around + t
    c, e = (s + 1) * around + (t + 1) % around, s * around + (t + 1) % around
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, e], -1).reshape(-1, 3)])
    uv = np.stack([v[:, 0], -v[:, 2]], 1) / uv_scale
    return Mesh(v, faces, np.tile([0.0, 1.0, 0.0], (len(v), 1)), uv)


def _add_outdoors(b: _SceneBuilder) -> None:
    (x0, _, z0), (x1, _, z1) = ROOM_BOUNDS
    cx = (x0 + x1) / 2
    ground = _ground_ring(5.0 + _WALL, 300.0, rings=20, around=48, uv_scale=4.0)
    b.add("ground_meadow", ground, b.material("meadow", (0.9, 0.9, 0.9), "grass"), prim.translation(cx, -0.05, 0))
    b.add("terrace", prim.box_between((x0 - 0.2, -0.05, z0 - 4.0), (x1 + 0.2, 0.0, z0 - 0.2), 1.5),
          b.material("terrace_stone", (0.55, 0.53, 0.5), "plaster"))
    b.add("terrace_south", prim.box_between((x0 - 0.2, -0.05, z1 + 0.2), (x1 + 0.2, 0.0, z1 + 3.0), 1.5),
          b.material("terrace_stone_south", (0.55, 0.53, 0.5), "plaster"))
    rng = np.random.default_rng(51)
    trunks, crowns = [], []
    cone_mesh = prim.cone(1.0, 1.0, 10, cap=False)
    ball = prim.sphere(1.0, 10, 6)
    trunk = prim.cylinder(1.0, 1.0, 6, caps=False)
    placed = 0
    while placed < 46:
        dist = 14.0 + 70.0 * rng.random() ** 1.5
        ang = rng.uniform(0, 2 * np.pi)
        x, z = cx + dist * np.sin(ang), dist * np.cos(ang)
        if x0 - 4 < x < x1 + 4 and z0 - 5 < z < z1 + 4:
            continue
        placed += 1
        h = rng.uniform(5, 12)
        green = np.array([0.04, 0.12, 0.03]) * rng.uniform(0.7, 1.4)
        trunks.append(prim.colored(prim.transform_mesh(trunk, prim.compose(
            prim.translation(x, -0.05, z), prim.scaling((0.15, h * 0.45, 0.15)))), _rgba((0.2, 0.13, 0.07))))
        if rng.random() < 0.55:     # conifer: two stacked cones
            for lo, rad, hh in ((0.3, 0.33, 0.55), (0.6, 0.22, 0.4)):
                crowns.append(prim.colored(prim.transform_mesh(cone_mesh, prim.compose(
                    prim.translation(x, h * lo, z), prim.scaling((h * rad, h * hh, h * rad)))), _rgba(green)))
        else:                        # broadleaf: a squashed ball
            crowns.append(prim.colored(prim.transform_mesh(ball, prim.compose(
                prim.translation(x, h * 0.62, z), prim.scaling((h * 0.3, h * 0.32, h * 0.3)))),
                _rgba(green * [1.4, 1.3, 1.2])))
    b.add("outdoor_tree_trunks", prim.merge(trunks), b.material("outdoor_bark"))
    b.add("outdoor_tree_crowns", prim.merge(crowns), b.material("outdoor_foliage"))
    # a few houses at 40-90 m: box bodies and gabled roofs (extruded triangles)
    houses, roofs = [], []
    for k, (x, z, yaw) in enumerate([(-35, -60, 0.3), (25, -75, -0.2), (70, -40, 0.9), (-70, 20, 1.2),
                                     (40, 55, 0.1), (-25, 80, -0.4)]):
        w, d, h = rng.uniform(7, 11), rng.uniform(6, 9), rng.uniform(3.5, 6)
        place = prim.compose(prim.translation(x, -0.05, z), prim.rotation((0, 1, 0), yaw))
        houses.append(prim.colored(prim.transform_mesh(prim.box((w, h, d), (0, h / 2, 0)), place),
                                   _rgba(np.array([0.75, 0.68, 0.55]) * rng.uniform(0.8, 1.1))))
        roof = prim.extrude([[-d / 2 - 0.4, 0], [d / 2 + 0.4, 0], [0, 0.45 * d]], w + 0.6)
        # the gable outline (x, z) becomes (house z, up); the extrusion (+Y) runs along the house's x
        roof_m = prim.compose(place, prim.translation(-(w + 0.6) / 2, h, 0), _basis((0, 0, 1), (1, 0, 0), (0, 1, 0)))
        roofs.append(prim.colored(prim.transform_mesh(roof, roof_m), _rgba((0.45, 0.12, 0.07))))
    b.add("outdoor_houses", prim.merge(houses), b.material("house_render"))
    b.add("outdoor_roofs", prim.merge(roofs), b.material("roof_tiles"))
    b.add("distant_hills", _hills(np.random.default_rng(61)), b.material("hills"), prim.translation(cx, 0, 0))


# ----------------------------------------------------------------------------- scenes

def build_room() -> Scene:
    """The default scene: an exhibition room around a central sculpture, a window onto hills."""
    b = _SceneBuilder()
    _add_shell(b)
    _add_platform(b)
    _add_exhibit(b)
    _add_pillars(b)
    _add_plinths(b)
    _add_display_table(b)
    _add_partition(b)
    _add_bookshelves(b)
    _add_lounge(b)
    _add_plants(b)
    _add_lamps(b)
    _add_moving(b)
    _add_outdoors(b)
    lights = [
        Light("ambient", color=(0.92, 0.95, 1.0), intensity=0.33),
        Light("directional", color=(1.0, 0.94, 0.84), intensity=0.8, direction=(0.35, -0.75, -0.55)),
        Light("directional", color=(0.8, 0.88, 1.0), intensity=0.28, direction=(-0.6, -0.35, 0.45)),
        Light("point", color=(1.0, 0.85, 0.65), intensity=0.45, position=(-0.6, 2.0, -2.5), range=7.0),
        Light("point", color=(1.0, 0.85, 0.65), intensity=0.45, position=(1.9, 2.1, 1.0), range=7.0),
    ]
    return Scene(
        name="room",
        objects=b.objects,
        lights=lights,
        description=BUILTIN_SCENES["room"][0],
        viewer_origin=VIEWER_ORIGIN,
        near=0.1,
        far=1000.0,
        sky_color=(0.62, 0.76, 0.92),
        extra_view=True,
        # Reinert et al.'s 1.8 m up would put the extra camera above this 3.2 m ceiling;
        # 'pibr bench optimize-offset' over both pred6dof traces at 128 ms found this one.
        extra_view_offset=dual_view_offset(*ROOM_EXTRA_OFFSET),
        view_region=VIEW_REGION.copy(),
        source="builtin",
    )


#: (forward m, up m, tilt deg down) of the room's extra view, from the offset search.
ROOM_EXTRA_OFFSET = (1.5, 0.6, 30.0)


def build_sphere() -> Scene:
    """One textured sphere (radius 0.4 m) 2.6 m in front of the viewer origin, nothing else."""
    b = _SceneBuilder()
    b.add("sphere", prim.sphere(SPHERE_RADIUS, 64, 32), b.material("test_pattern", texture="test_pattern"),
          prim.translation(SPHERE_CENTER))
    return Scene(
        name="sphere",
        objects=b.objects,
        lights=[Light("ambient", intensity=0.35),
                Light("directional", direction=(0.35, -0.75, -0.55), intensity=0.8)],
        description=BUILTIN_SCENES["sphere"][0],
        viewer_origin=VIEWER_ORIGIN,
        extra_view=False,
        source="builtin",
    )


def build_empty() -> Scene:
    """No objects: every view is sky."""
    return Scene(name="empty", objects=[], description=BUILTIN_SCENES["empty"][0],
                 viewer_origin=VIEWER_ORIGIN, source="builtin")


#: The courtyard's half width (metres) to its colonnades, and their height.
COURTYARD_HALF = 20.0
COURTYARD_COLUMN_HEIGHT = 4.5


def build_courtyard() -> Scene:
    """A large open-air courtyard under open sky: paving, four colonnades 20 m out with walls
    behind them, a fountain, a statue on a plinth, planters, lamp posts and obelisks standing
    against the sky. A third of a level view is sky -- the scene for measuring what a dual view
    does where sky lies behind near things."""
    b = _SceneBuilder()
    half, h = COURTYARD_HALF, COURTYARD_COLUMN_HEIGHT
    paving = b.material("paving", (0.85, 0.82, 0.76), "brick")
    b.add("paving", prim.grid_plane(2 * half + 6, 2 * half + 6, 2.0, uv_scale=2.0), paving)
    marble = b.material("column_marble", (0.95, 0.94, 0.9), "marble")
    wall = b.material("courtyard_wall", (0.9, 0.85, 0.78), "plaster")
    for side, (axis, sign) in enumerate(((0, 1), (0, -1), (2, 1), (2, -1))):
        columns = []
        for k in range(-6, 7):
            pos = [0.0, 0.0, 0.0]
            pos[axis] = sign * half
            pos[2 - axis] = 3.0 * k
            columns.append((prim.cylinder(0.3, h, 24, caps=False, uv_scale=1.0, height_segments=6),
                            prim.translation(*pos)))
        b.add(f"colonnade_{side}", prim.merge(columns), marble)
        beam = [0.0, h + 0.3, 0.0]
        beam[axis] = sign * half
        size = [2 * half + 1.0, 0.6, 2 * half + 1.0]
        size[axis] = 1.0
        b.add(f"entablature_{side}", prim.box(tuple(size), tuple(beam), 1.0), marble)
        back = [0.0, (h + 0.6) / 2, 0.0]
        back[axis] = sign * (half + 2.5)
        size = [2 * half + 6.0, h + 0.6, 2 * half + 6.0]
        size[axis] = 0.4
        b.add(f"wall_{side}", prim.box(tuple(size), tuple(back), _PLASTER_M, 1.0), wall)
    stone = b.material("fountain_stone", (0.8, 0.8, 0.82), "marble")
    b.add("fountain_basin", prim.torus(1.6, 0.25, 48, 12), stone, prim.translation(0.0, 0.35, -7.0))
    b.add("fountain_column", prim.cylinder(0.25, 1.6, 24), stone, prim.translation(0.0, 0.0, -7.0))
    b.add("statue_plinth", prim.box((1.0, 1.2, 1.0), (0.0, 0.6, 0.0), 1.0), stone, prim.translation(5.0, 0.0, -4.0))
    b.add("statue", prim.torus_knot(0.45, 0.07), b.material("statue_bronze", (0.55, 0.4, 0.25)),
          prim.translation(5.0, 1.75, -4.0))
    planter = b.material("planter", (0.45, 0.5, 0.3), "grass")
    for k, (x, z) in enumerate(((-5.0, -3.0), (-5.0, 3.5), (6.0, 4.0))):
        b.add(f"planter_{k}", prim.box((1.6, 0.7, 1.6), (x, 0.35, z), 1.0), planter)
    # Free-standing things seen against the sky: lamp posts round the middle, two obelisks.
    iron = b.material("lamp_iron", (0.18, 0.18, 0.2))
    glass = b.material("lamp_glass", (1.0, 0.92, 0.7))
    for k, (x, z) in enumerate(((-2.5, -3.5), (3.0, -3.0), (-3.5, 2.5), (2.5, 3.5), (0.8, -9.5), (-7.5, -8.0))):
        b.add(f"lamp_post_{k}", prim.cylinder(0.06, 4.2, 12, uv_scale=1.0), iron, prim.translation(x, 0.0, z))
        b.add(f"lamp_{k}", prim.sphere(0.22, 16, 8), glass, prim.translation(x, 4.4, z))
    obelisk = b.material("obelisk_stone", (0.78, 0.74, 0.66), "marble")
    for k, (x, z) in enumerate(((-9.0, -12.0), (10.0, -11.0))):
        b.add(f"obelisk_{k}", prim.cone(0.7, 9.0, 4, uv_scale=1.0), obelisk, prim.translation(x, 0.0, z))
    return Scene(
        name="courtyard",
        objects=b.objects,
        lights=[Light("ambient", color=(0.92, 0.95, 1.0), intensity=0.35),
                Light("directional", color=(1.0, 0.95, 0.85), intensity=0.85, direction=(0.4, -0.8, -0.45))],
        description=BUILTIN_SCENES["courtyard"][0],
        viewer_origin=VIEWER_ORIGIN,
        near=0.1,
        far=1000.0,
        sky_color=(0.55, 0.72, 0.93),
        extra_view=True,
        source="builtin",
    )


#: The ``dynamic`` scene's hall: (2, 3) interior min and max corners (3 m high, the focus point
#: near its middle).
DYNAMIC_BOUNDS = np.array([[-4.0, 0.0, -4.5], [4.6, 3.0, 4.1]])


def build_dynamic() -> Scene:
    """A small hall where things move in every way extrapolation finds hard, around the point
    the recorded people walk around (the room's focus point):

    * ``spinner``: a three-armed, textured turnstile spinning steadily (2 rad/s) on a pedestal
      at the focus point;
    * ``pendulum``: swings 0.45 rad either way (period 2.7 s), reversing twice a period;
    * ``cart``: starts and stops: travels 4.4 m along the north wall at 1.8 m/s, rests 1.2 s,
      travels back (the ``travel`` animation);
    * ``ball``: flies fast (4.8 m/s) on a 3 m circle round the focus point at 2.3 m, entering
      and leaving any view;
    * ``slider``: glides along the east wall behind a pillar, hidden part of each period.

    Static context: a parquet floor, plaster and brick walls, a ceiling, two pillars, the
    pedestal and the cart's rail. Small (a few thousand triangles) so it renders quickly."""
    b = _SceneBuilder()
    (x0, _, z0), (x1, h, z1) = DYNAMIC_BOUNDS
    cx, cz, t = (x0 + x1) / 2, (z0 + z1) / 2, _WALL
    b.add("floor", prim.grid_plane(x1 - x0, z1 - z0, cell_size=0.5, uv_scale=_PARQUET_M),
          b.material("parquet", (0.88, 0.84, 0.8), "parquet"), prim.translation(cx, 0, cz))
    b.add("ceiling", prim.grid_plane(x1 - x0, z1 - z0, cell_size=1.0, uv_scale=_PLASTER_M),
          b.material("ceiling_paint", (0.95, 0.95, 0.93), "plaster"),
          prim.compose(prim.translation(cx, h, cz), prim.rotation((1, 0, 0), math.pi)))
    plaster = b.material("wall_paint", (0.93, 0.9, 0.84), "plaster")
    b.add("walls", prim.merge([prim.box_between((x0 - t, 0, z0 - t), (x1 + t, h, z0), _PLASTER_M, 1.0),
                               prim.box_between((x0 - t, 0, z1), (x1 + t, h, z1 + t), _PLASTER_M, 1.0),
                               prim.box_between((x1, 0, z0), (x1 + t, h, z1), _PLASTER_M, 1.0)]), plaster)
    b.add("wall_west_brick", prim.box_between((x0 - t, 0, z0), (x0, h, z1), _BRICK_M, 1.0),
          b.material("brick", texture="brick"))
    pillar = b.material("pillar_paint", (0.88, 0.86, 0.82), "plaster")
    for name, (x, z) in (("pillar_east", (3.5, -2.2)), ("pillar_south_west", (-2.4, 2.8))):
        b.add(name, prim.cylinder(0.25, h, 32, caps=False, uv_scale=_PLASTER_M, height_segments=6), pillar,
              prim.translation(x, 0, z))
    fx, _, fz = FOCUS_POINT
    b.add("pedestal", prim.box((0.4, 1.0, 0.4), (0, 0.5, 0), 0.8, 0.2),
          b.material("pedestal_marble", (0.95, 0.95, 0.95), "marble"), prim.translation(fx, 0, fz))
    # Moving things.
    arm = prim.box((0.36, 0.1, 0.06), (0.18, 0.0, 0.0), 0.5)
    spinner = prim.merge([prim.cylinder(0.05, 0.3, 24, uv_scale=0.5),
                          *((arm, prim.compose(prim.translation(0, 0.15, 0), prim.rotation((0, 1, 0), a)))
                            for a in (0.0, 2 * math.pi / 3, 4 * math.pi / 3))])
    b.add("spinner", spinner, b.material("spinner_pattern", texture="test_pattern"), prim.translation(fx, 1.0, fz),
          Animation("spin", axis=(0, 1, 0), speed=2.0, pivot=(fx, 1.0, fz)))
    px, pz, length, bob_r = -2.9, -2.2, 1.6, 0.14
    pendulum = prim.merge([
        prim.colored(prim.cylinder(0.008, length, 8, caps=False), _rgba((0.2, 0.2, 0.2))),
        (prim.colored(prim.sphere(bob_r, 24, 12), _rgba((0.85, 0.6, 0.2))), prim.translation(0, -bob_r, 0))])
    b.add("pendulum", pendulum, b.material("pendulum_brass"), prim.translation(px, h - length, pz),
          Animation("swing", axis=(0, 0, 1), speed=math.sqrt(9.81 / (length + bob_r)), amplitude=0.45,
                    pivot=(px, h, pz)))
    rail_z = -3.6
    b.add("rail", prim.box_between((-2.6, 0.0, rail_z - 0.25), (2.6, 0.02, rail_z + 0.25), 0.5),
          b.material("rail_steel", (0.3, 0.3, 0.32)))
    b.add("cart", prim.box((0.5, 0.35, 0.4), (0, 0.195, 0), 0.5), b.material("cart_wood", texture="wood"),
          prim.translation(-2.2, 0.0, rail_z),
          Animation("travel", axis=(1, 0, 0), speed=1.8, amplitude=4.4, rest=1.2))
    b.add("ball", prim.sphere(0.15, 24, 12), b.material("ball_pattern", texture="test_pattern"),
          prim.translation(fx, 2.3, fz), Animation("orbit", axis=(0, 1, 0), speed=1.6, radius=3.0))
    b.add("slider", prim.box((0.3, 0.6, 0.5), (0, 0.3, 0), 0.5), b.material("slider_paint", (0.2, 0.45, 0.8)),
          prim.translation(4.2, 0.8, -2.4), Animation("slide", axis=(0, 0, 1), speed=0.9, amplitude=1.4))
    return Scene(
        name="dynamic",
        objects=b.objects,
        lights=[Light("ambient", color=(0.92, 0.95, 1.0), intensity=0.35),
                Light("directional", color=(1.0, 0.94, 0.84), intensity=0.8, direction=(0.35, -0.75, -0.55)),
                Light("point", color=(1.0, 0.85, 0.65), intensity=0.4, position=(0.3, 2.6, -0.2), range=7.0)],
        description=BUILTIN_SCENES["dynamic"][0],
        viewer_origin=VIEWER_ORIGIN,
        near=0.1,
        far=100.0,
        sky_color=(0.62, 0.76, 0.92),
        extra_view=True,
        # The room's offset: the paper's 1.8 m up would put the extra camera above this ceiling.
        extra_view_offset=dual_view_offset(*ROOM_EXTRA_OFFSET),
        view_region=VIEW_REGION.copy(),
        source="builtin",
    )


#: name -> (one-line description, builder). ``room`` is the default scene.
BUILTIN_SCENES: dict[str, tuple[str, Callable[[], Scene]]] = {
    "room": ("Exhibition room around a torus-knot sculpture: pillars, plinths, bookshelves, a railing, "
             "a tree, hanging lamps, a spinning fan and a pendulum, and a window onto hills 100-450 m away",
             build_room),
    "sphere": ("A single test-pattern sphere (radius 0.4 m) 2.6 m in front of the viewer; no extra view needed",
               build_sphere),
    "courtyard": ("A large open-air courtyard under open sky: colonnades 20 m out, a fountain, a statue, "
                  "planters, lamp posts and obelisks against the sky (dual views where sky is behind near things)",
                  build_courtyard),
    "dynamic": ("A small hall where things move: a spinning turnstile, a pendulum, a cart that starts and "
                "stops, a fast ball circling the viewer, a slider passing behind a pillar (extrapolation tests)",
                build_dynamic),
    "empty": ("No objects: sky only (edge-case tests)", build_empty),
}
