"""The video atlas: where each view's colour and 8-bit disparity sit in the one H.264 image.

Reinert et al. pack every transmitted image into one rectangle so a single video stream
carries them. Layouts (W x H primary view, extra view at W/2 x H/2)::

    primary only, depth in atlas      primary + extra, depth in atlas
    +---------+---------+             +---------+---------+------+
    | P.color | P.depth |             | P.color | P.depth | E.col|
    +---------+---------+             |         |         +------+
                                      |         |         | E.dep|
                                      +---------+---------+------+

    with the edge codec carrying depth, only the colour rectangles remain. At colour scale 0.5
    each colour rectangle is half its view's width and height (depth stays whole).

Depth rectangles hold the disparity code in luma (chroma 128); the packer writes luma
directly, so no RGB conversion touches depth. Rectangle corners and sizes are multiples of
16 so no H.264 macroblock straddles two rectangles.

Size limits, the same for the server's settings and for a Welcome the client receives (a
hostile server cannot make the client allocate more than the largest real session needs)::

    view side       <= MAX_VIEW_SIDE (8192, the edge codec's and quadtree's limit)
    view pixels     <= MAX_VIEW_PIXELS (4096 x 4096)
    atlas side      <= MAX_ATLAS_SIDE (2.5 x 8192: primary colour + depth + the half-size extra view)
    atlas pixels    <= MAX_ATLAS_PIXELS (2.5 x MAX_VIEW_PIXELS, the largest view's atlas)
"""
from __future__ import annotations

from dataclasses import dataclass

from .errors import MalformedMessage

ALIGN = 16
RECT_NAMES = ("primary.color", "primary.depth", "extra.color", "extra.depth")
MAX_VIEW_SIDE = 8192
MAX_VIEW_PIXELS = 4096 * 4096
MAX_ATLAS_SIDE = MAX_VIEW_SIDE * 5 // 2
MAX_ATLAS_PIXELS = MAX_VIEW_PIXELS * 5 // 2


@dataclass(frozen=True)
class AtlasLayout:
    """``width`` x ``height`` atlas; ``rects`` maps a name in RECT_NAMES to (x, y, w, h), y from the top."""

    width: int
    height: int
    rects: dict

    def __post_init__(self):
        if self.width % ALIGN or self.height % ALIGN or self.width <= 0 or self.height <= 0:
            raise ValueError(f"atlas size must be positive multiples of {ALIGN}, got {self.width}x{self.height}")
        if max(self.width, self.height) > MAX_ATLAS_SIDE or self.width * self.height > MAX_ATLAS_PIXELS:
            raise ValueError(f"atlas size {self.width}x{self.height} exceeds the limit of {MAX_ATLAS_SIDE} per side "
                             f"and {MAX_ATLAS_PIXELS} pixels")
        for name, r in self.rects.items():
            if name not in RECT_NAMES:
                raise ValueError(f"unknown atlas rectangle {name!r}")
            x, y, w, h = r
            if w <= 0 or h <= 0 or x < 0 or y < 0 or x + w > self.width or y + h > self.height:
                raise ValueError(f"atlas rectangle {name} {r} lies outside the {self.width}x{self.height} atlas")

    def rect(self, name: str):
        return self.rects.get(name)

    def to_json(self) -> dict:
        return {"width": self.width, "height": self.height, "rects": {k: list(v) for k, v in self.rects.items()}}

    @classmethod
    def from_json(cls, o) -> "AtlasLayout":
        """Layout from its JSON form; MalformedMessage naming the field for anything but
        integers that obey the limits above."""
        p = "Welcome.config.atlas"
        if not isinstance(o, dict) or not isinstance(o.get("rects"), dict):
            raise MalformedMessage(f"{p}: must be an object with width, height and rects")
        width, height = _integer(o, "width", p), _integer(o, "height", p)
        rects = {}
        for name, r in o["rects"].items():
            if not (isinstance(r, list) and len(r) == 4 and all(_is_int(x) for x in r)):
                raise MalformedMessage(f"{p}.rects.{name:.40}: must be 4 integers [x, y, w, h], got {r!r:.60}")
            rects[name] = tuple(r)
        try:
            return cls(width, height, rects)
        except ValueError as exc:
            raise MalformedMessage(f"{p}: {exc}") from None


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _integer(o: dict, key: str, path: str) -> int:
    v = o.get(key)
    if not _is_int(v):
        raise MalformedMessage(f"{path}: field {key!r} must be an integer, got {v!r:.60}")
    return v


def check_view_size(width: int, height: int, what: str = "view") -> None:
    """ValueError unless ``width`` x ``height`` is a primary view size a session may have."""
    if width % (2 * ALIGN) or height % (2 * ALIGN) or width < 2 * ALIGN or height < 2 * ALIGN:
        raise ValueError(f"{what} size must be positive multiples of {2 * ALIGN} (so the extra view's half size "
                         f"stays aligned), got {width}x{height}")
    if max(width, height) > MAX_VIEW_SIDE or width * height > MAX_VIEW_PIXELS:
        raise ValueError(f"{what} size {width}x{height} exceeds the limit of {MAX_VIEW_SIDE} per side and "
                         f"{MAX_VIEW_PIXELS} pixels ({int(MAX_VIEW_PIXELS ** 0.5)}x{int(MAX_VIEW_PIXELS ** 0.5)})")


#: Scales a session may send its views' colour at (``SessionConfig.colour_scale``): 0.5 sends
#: half the width and height and the client rebuilds the rest (client/colour_rebuild.py; Pajak
#: et al. 2011, Sec. 3.3).
COLOUR_SCALES = (1.0, 0.5)
#: What a frame at colour scale 0.5 sends, cycling with the frame id: with jitter (jx, jy), pixel
#: (i, j) of the view's half-size colour rectangle holds the luma of the view's pixel
#: (2 i + jx, 2 j + jy), and chroma sample (i, j) of the rectangle the chroma of the view's 2x2
#: block (2 i + jx, 2 j + jy) (the average of its four pixels, as 4:2:0 at scale 1 sends every
#: block). Every pixel's luma and every block's chroma of a still view is sent once in four
#: frames, the diagonal first so that two frames already sample both rows and both columns.
COLOUR_JITTER = ((0, 0), (1, 1), (1, 0), (0, 1))


def colour_jitter(frame_id: int) -> tuple:
    """(x, y) in 0..1: the jitter of frame ``frame_id`` at colour scale 0.5 (COLOUR_JITTER)."""
    return COLOUR_JITTER[frame_id % len(COLOUR_JITTER)]


def colour_size(view: tuple, colour_scale: float) -> tuple:
    """(w, h) of a view's colour rectangle at ``colour_scale`` (one of COLOUR_SCALES)."""
    if colour_scale not in COLOUR_SCALES:
        raise ValueError(f"colour scale must be one of {', '.join(f'{s:g}' for s in COLOUR_SCALES)}, "
                         f"got {colour_scale!r:.40}")
    step = int(round(1.0 / colour_scale))
    w, h = view
    if w % (2 * step) or h % (2 * step):
        raise ValueError(f"a {w}x{h} view cannot send its colour at scale {colour_scale:g}: its sides must be "
                         f"multiples of {2 * step} (4:2:0 chroma)")
    return w // step, h // step


def _aligned(n: int) -> int:
    return -(-n // ALIGN) * ALIGN


def build_layout(primary: tuple, extra: tuple | None, depth_in_atlas: bool,
                 colour_scale: float = 1.0) -> AtlasLayout:
    """Atlas for a primary view of size (w, h), an optional extra view of size (w2, h2), colour
    at ``colour_scale`` of each view's size (depth always at full size). Every rectangle starts
    on a multiple of ALIGN."""
    pw, ph = primary
    pcw, pch = colour_size(primary, colour_scale)
    rects = {"primary.color": (0, 0, pcw, pch)}
    x, height = _aligned(pcw), pch
    if depth_in_atlas:
        rects["primary.depth"] = (x, 0, pw, ph)
        x, height = x + _aligned(pw), max(height, ph)
    width = x
    if extra is not None:
        ew, eh = extra
        ecw, ech = colour_size(extra, colour_scale)
        rects["extra.color"] = (x, 0, ecw, ech)
        width = x + _aligned(ecw)
        if depth_in_atlas:
            if _aligned(ech) + eh <= height:     # under the extra colour
                rects["extra.depth"] = (x, _aligned(ech), ew, eh)
                width = x + max(_aligned(ecw), _aligned(ew))
            else:                                # beside it
                rects["extra.depth"] = (width, 0, ew, eh)
                width += _aligned(ew)
                height = max(height, eh)
        height = max(height, ech)
    return AtlasLayout(_aligned(width), _aligned(height), rects)
