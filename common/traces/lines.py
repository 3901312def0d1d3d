"""Line by line reading of head-trace text files, shared by every reader: line-numbered
errors, fields, numbers and quaternions checked as they are read."""
from __future__ import annotations

import math
from typing import Iterator

from pibr.protocol.errors import TraceError
from pibr.protocol.pose import MIN_QUAT_NORM


def row_error(path, line: int, problem: str) -> TraceError:
    """The error for one bad line of a trace file: names the file and the 1-based line."""
    return TraceError(f"{path}: line {line}: {problem}")


def iter_lines(path) -> Iterator[tuple[int, str]]:
    """(1-based line number, stripped text) of every non-blank line of a text file."""
    try:
        with open(path, encoding="utf-8-sig") as f:
            for number, line in enumerate(f, start=1):
                text = line.strip()
                if text:
                    yield number, text
    except FileNotFoundError as exc:
        raise TraceError(f"{path}: no such trace file") from exc
    except UnicodeDecodeError as exc:
        raise TraceError(f"{path}: not a text (UTF-8) file: {exc}") from exc
    except OSError as exc:
        raise TraceError(f"{path}: cannot read: {exc.strerror or exc}") from exc


def parse_number(path, line: int, column: str, text: str) -> float:
    """A finite float from one CSV field, or a line-numbered TraceError."""
    try:
        value = float(text)
    except ValueError:
        raise row_error(path, line, f"column {column!r}: {text!r} is not a number") from None
    if math.isnan(value):
        raise row_error(path, line, f"column {column!r} is NaN")
    if math.isinf(value):
        raise row_error(path, line, f"column {column!r} is infinite")
    return value


def check_quaternion(path, line: int, q) -> None:
    """Raise a line-numbered TraceError for a (near) zero quaternion (w, x, y, z)."""
    if math.sqrt(sum(c * c for c in q)) < MIN_QUAT_NORM:
        raise row_error(path, line, f"zero quaternion {tuple(q)} names no rotation")


def header_fields(text: str, delimiter: str | None = ",") -> list[str]:
    """Field names of a header line, stripped of whitespace and quotes."""
    return [f.strip().strip("\"'").strip() for f in text.split(delimiter)]


def split_fields(text: str, delimiter: str | None) -> list[str]:
    """Fields of one line. ``delimiter`` 'auto': commas if the line has any, else semicolons,
    else tabs, else any whitespace (so a header and its rows may use different ones); None:
    any whitespace; otherwise that string."""
    if delimiter == "auto":
        delimiter = next((d for d in (",", ";", "\t") if d in text), None)
    return [f.strip().strip("\"'").strip() for f in text.split(delimiter)]
