"""Which parts of which head traces serve tuning, and which serve reporting.

Every default pibr chose by measurement (the room's extra-view offset, the depth slack of
proxy IBR and of the warps, the LoD target, the edge codec's settings, the homography's plane
distance, the extra view's void margin) was fitted on the **tuning windows** below, and only
there. Benchmarks report on the **evaluation windows**: later, disjoint parts of both shared
traces and synthetic traces of three kinds (walking, looking around, fast turns), so a default
fitted to the shared traces shows up as such. Every benchmark's JSON says which windows it
used and whether any of them overlaps a tuning window.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

from pibr.protocol.errors import ConfigError


@dataclass(frozen=True)
class Window:
    """``duration_s`` seconds of trace ``trace`` (a built-in, synthetic or file name) from ``start_s``."""

    trace: str
    start_s: float
    duration_s: float

    @property
    def end_s(self) -> float:
        return self.start_s + self.duration_s

    def overlaps(self, other: "Window") -> bool:
        return self.trace == other.trace and self.start_s < other.end_s and other.start_s < self.end_s

    @property
    def label(self) -> str:
        return f"{self.trace} {self.start_s:g}-{self.end_s:g} s"

    def to_json(self) -> dict:
        return asdict(self)


#: Where defaults were fitted (everything measured before the split was declared used these
#: seconds of the shared traces: 10-18 s for the offset, slack, LoD and codec, 20-22 s of
#: pred6dof-1 for the warps' extra-view margin).
TUNING_WINDOWS = (Window("pred6dof-1", 10.0, 12.0), Window("pred6dof-2", 10.0, 12.0))

#: Where benchmarks report: disjoint from every tuning window.
EVALUATION_WINDOWS = (
    Window("pred6dof-1", 30.0, 8.0), Window("pred6dof-1", 50.0, 8.0),
    Window("pred6dof-2", 30.0, 8.0), Window("pred6dof-2", 50.0, 8.0),
    Window("synth-walk", 5.0, 8.0), Window("synth-look", 5.0, 8.0), Window("synth-turns", 5.0, 8.0),
)

WINDOW_SETS = {"evaluation": EVALUATION_WINDOWS, "tuning": TUNING_WINDOWS}


def overlapping_tuning(windows) -> list[Window]:
    """The windows of ``windows`` that overlap a tuning window."""
    return [w for w in windows if any(w.overlaps(t) for t in TUNING_WINDOWS)]


def windows_json(windows, purpose: str) -> dict:
    """What a benchmark's JSON records about its windows."""
    overlap = overlapping_tuning(windows)
    return {"purpose": purpose, "used": [w.to_json() for w in windows],
            "tuning": [w.to_json() for w in TUNING_WINDOWS],
            "overlaps_tuning": [w.to_json() for w in overlap],
            "disjoint_from_tuning": not overlap}


def describe_windows(recorded: dict) -> str:
    """One line for a table's head from :func:`windows_json`'s record: the windows used and how
    they stand to the tuning windows."""
    used = ", ".join("{trace}@{start_s:g}+{duration_s:g}".format(**x) for x in recorded["used"])
    relation = "disjoint from" if recorded["disjoint_from_tuning"] else "OVERLAPPING"
    return f"windows {used} ({relation} the tuning windows)"


def parse_windows(text: str) -> tuple[Window, ...]:
    """``evaluation``, ``tuning``, or ``TRACE@START+DURATION[,...]`` (seconds)."""
    text = text.strip()
    if text in WINDOW_SETS:
        return WINDOW_SETS[text]
    out = []
    for part in text.split(","):
        try:
            trace, span = part.strip().rsplit("@", 1)
            start, duration = (float(x) for x in span.split("+"))
        except ValueError:
            raise ConfigError(f"expected 'evaluation', 'tuning' or TRACE@START+DURATION[,...], got {part!r}") \
                from None
        if not (trace and start >= 0 and duration > 0):
            raise ConfigError(f"window {part!r}: need a trace, a start >= 0 and a positive duration")
        out.append(Window(trace, start, duration))
    return tuple(out)
