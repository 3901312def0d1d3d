"""What the benchmarks that compare methods share: a method with its knobs (:class:`Variant`),
the zero-latency oracle's label, the Pareto front of speed against quality, and the methods
scored at every point of a sweep."""
from __future__ import annotations

from dataclasses import dataclass, field

#: The label of the zero-latency oracle (the server's frame at the display pose itself).
ORACLE = "oracle (zero latency)"


@dataclass(frozen=True)
class Variant:
    """One point of the chart: a method with its knobs."""

    label: str
    method: str
    options: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"method": self.method, "options": self.options}


def pareto_front(points: dict) -> list[str]:
    """Labels of the points (label -> (ms, dssim)) no other point beats on both, fastest first."""
    order = sorted(points, key=lambda k: (points[k][0], points[k][1]))
    front, best = [], float("inf")
    for k in order:
        if points[k][1] < best:
            front.append(k)
            best = points[k][1]
    return front


def sweep_labels(rows: list) -> list:
    """The methods scored at every point of one knob's sweep (the default point also carries the
    client knobs' proxy variants, which the other points lack), in their order."""
    return [label for label in rows[0]["methods"] if all(label in row["methods"] for row in rows)]
