"""The canonical head-trace file: CSV with the header ``t,px,py,pz,qw,qx,qy,qz``, ``t`` in
seconds from the start, positions in metres, camera-to-world unit quaternions (DESIGN.md,
Head traces). Floats are written in their shortest exact form, so write -> read is exact."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from pibr.protocol.errors import TraceError
from pibr.protocol.trace import HeadTrace

from .lines import check_quaternion, header_fields, iter_lines, parse_number, row_error

CANONICAL_COLUMNS = ("t", "px", "py", "pz", "qw", "qx", "qy", "qz")
CANONICAL_HEADER = ",".join(CANONICAL_COLUMNS)


def read_canonical_csv(path, name: str | None = None) -> HeadTrace:
    """Read a canonical ``t,px,py,pz,qw,qx,qy,qz`` file. Times are re-based to start at 0 and
    quaternions normalised. Any bad row raises TraceError naming the file and line."""
    name = name or Path(path).stem
    lines = iter_lines(path)
    first = next(lines, None)
    if first is None:
        raise TraceError(f"{path}: empty file, expected the header {CANONICAL_HEADER!r}")
    line, text = first
    if header_fields(text) != list(CANONICAL_COLUMNS):
        raise row_error(path, line, f"header must be exactly {CANONICAL_HEADER!r}, got {text!r}")
    times, rows = [], []
    last_time, last_line = None, None
    for line, text in lines:
        fields = text.split(",")
        if len(fields) != len(CANONICAL_COLUMNS):
            raise row_error(path, line, f"expected {len(CANONICAL_COLUMNS)} columns "
                                        f"({CANONICAL_HEADER}), got {len(fields)}")
        values = [parse_number(path, line, c, f) for c, f in zip(CANONICAL_COLUMNS, fields)]
        check_quaternion(path, line, values[4:])
        t = values[0]
        if last_time is not None and t <= last_time:
            if t == last_time:
                raise row_error(path, line, f"duplicate timestamp t={t!r} (same as line {last_line})")
            raise row_error(path, line, f"time is not increasing: t={t!r} after t={last_time!r} "
                                        f"on line {last_line}")
        last_time, last_line = t, line
        times.append(t)
        rows.append(values[1:])
    if not rows:
        raise TraceError(f"{path}: no samples after the header")
    data = np.array(rows, dtype=np.float64)
    return HeadTrace.from_samples(np.array(times), data[:, :3], data[:, 3:], name)


def write_canonical_csv(trace: HeadTrace, path) -> None:
    """Write ``trace`` as canonical CSV; floats are written exactly (shortest round-trip form)."""
    table = np.column_stack([trace.t, trace.positions, trace.orientations])
    out = [CANONICAL_HEADER]
    out.extend(",".join(map(repr, row)) for row in table.tolist())
    try:
        with open(path, "w", encoding="utf-8", newline="\n") as f:
            f.write("\n".join(out) + "\n")
    except OSError as exc:
        raise TraceError(f"{path}: cannot write: {exc.strerror or exc}") from exc
