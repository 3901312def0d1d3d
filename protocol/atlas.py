"""The video atlas: where each view's colour and 8-bit disparity sit in the one H.264 image.

Reinert et al. pack every transmitted image into one rectangle so a single video stream
carries them. Layouts (W x H primary view, extra view at W/2 x H/2)::

    primary only, depth in atlas      primary + extra, depth in atlas
    +---------+---------+             +---------+---------+------+
    | P.color | P.depth |             | P.color | P.depth | E.col|
    +---------+---------+             |         |         +------+
                                      |         |         | E.dep|
                                      +---------+---------+------+

    with the edge codec carrying depth, only the colour rectangles remain.

Depth rectangles hold the disparity code in luma (chroma 128); the packer writes luma
directly, so no RGB conversion touches depth. Rectangle corners and sizes are multiples of
16 so no H.264 macroblock straddles two rectangles.
"""
from __future__ import annotations

from dataclasses import dataclass

from .errors import MalformedMessage

ALIGN = 16
RECT_NAMES = ("primary.color", "primary.depth", "extra.color", "extra.depth")


@dataclass(frozen=True)
class AtlasLayout:
    """``width`` x ``height`` atlas; ``rects`` maps a name in RECT_NAMES to (x, y, w, h), y from the top."""

    width: int
    height: int
    rects: dict

    def __post_init__(self):
        if self.width % ALIGN or self.height % ALIGN or self.width <= 0 or self.height <= 0:
            raise ValueError(f"atlas size must be positive multiples of {ALIGN}, got {self.width}x{self.height}")
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
        try:
            rects = {str(k): tuple(int(x) for x in v) for k, v in o["rects"].items()}
            if any(len(v) != 4 for v in rects.values()):
                raise ValueError("an atlas rectangle needs 4 integers")
            return cls(int(o["width"]), int(o["height"]), rects)
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise MalformedMessage(f"Welcome.config.atlas: {exc}") from None


def check_view_size(width: int, height: int, what: str = "view") -> None:
    if width % (2 * ALIGN) or height % (2 * ALIGN) or width < 2 * ALIGN or height < 2 * ALIGN:
        raise ValueError(f"{what} size must be positive multiples of {2 * ALIGN} (so the extra view's half size "
                         f"stays aligned), got {width}x{height}")


def build_layout(primary: tuple, extra: tuple | None, depth_in_atlas: bool) -> AtlasLayout:
    """Atlas for a primary view of size (w, h), an optional extra view of size (w2, h2)."""
    pw, ph = primary
    rects = {"primary.color": (0, 0, pw, ph)}
    x = pw
    if depth_in_atlas:
        rects["primary.depth"] = (x, 0, pw, ph)
        x += pw
    width, height = x, ph
    if extra is not None:
        ew, eh = extra
        rects["extra.color"] = (x, 0, ew, eh)
        if depth_in_atlas:
            if 2 * eh <= ph:
                rects["extra.depth"] = (x, eh, ew, eh)
            else:
                rects["extra.depth"] = (x + ew, 0, ew, eh)
                width += ew
        width += ew
        height = max(height, eh if "extra.depth" not in rects or rects["extra.depth"][1] == 0 else 2 * eh)
    return AtlasLayout(width, height, rects)
