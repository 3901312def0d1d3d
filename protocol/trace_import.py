"""Importers: other head-trace formats -> :class:`~pibr.protocol.trace.HeadTrace`.

Conventions are converted here, once: timestamps to seconds from the start, Unity's
left-handed axes (+Y up, +Z forward) to pibr's right-handed ones (+Y up, camera along -Z) with
:func:`~pibr.protocol.pose.left_handed_to_right_handed`, Euler angles to quaternions.
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from .errors import TraceError
from .pose import left_handed_to_right_handed, quat_from_euler
from .trace import (PRED6DOF_COLUMNS, HeadTrace, check_quaternion, header_fields, iter_lines,
                    parse_number, row_error)

log = logging.getLogger(__name__)

#: Seconds per unit of each supported timestamp unit.
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9, "ticks": 1e-7}

#: Gaps between samples longer than this are noted in the trace's warnings (tracking loss).
GAP_WARNING_S = 0.1

_POSITION_KEYS = ("px", "py", "pz")
_QUAT_KEYS = ("qw", "qx", "qy", "qz")
_EULER_KEYS = ("yaw", "pitch", "roll")
# Euler angle about each axis: yaw turns about Y (up), pitch about X, roll about Z.
_EULER_AXIS = {"y": "yaw", "x": "pitch", "z": "roll"}


def import_pred6dof(path) -> HeadTrace:
    """Import a pred6dof / HoloLens recording: header ``timestamp,x,y,z,qx,qy,qz,qw``.

    timestamp: .NET DateTime ticks (100 ns, int64), unevenly spaced; x, y, z metres and
    qx, qy, qz, qw a unit quaternion, both in Unity's left-handed world (+y up, +z forward).
    Repeated ticks: the later samples are dropped and counted in ``trace.warnings``;
    a tick earlier than its predecessor raises TraceError.
    """
    lines = iter_lines(path)
    first = next(lines, None)
    expected = ",".join(PRED6DOF_COLUMNS)
    if first is None:
        raise TraceError(f"{path}: empty file, expected the header {expected!r}")
    line, text = first
    if [f.lower() for f in header_fields(text)] != list(PRED6DOF_COLUMNS):
        raise row_error(path, line, f"header must be {expected!r} (pred6dof), got {text!r}")
    ticks, lines_used, rows = [], [], []
    duplicates = []
    for line, text in lines:
        fields = [f.strip() for f in text.split(",")]
        if len(fields) != len(PRED6DOF_COLUMNS):
            raise row_error(path, line, f"expected {len(PRED6DOF_COLUMNS)} columns ({expected}), "
                                        f"got {len(fields)}")
        try:
            tick = int(fields[0])  # int, not float: 6e17 ticks do not fit a float's 53 bits
        except ValueError:
            raise row_error(path, line, f"timestamp {fields[0]!r} is not an integer tick count") from None
        x, y, z, qx, qy, qz, qw = (parse_number(path, line, c, f)
                                   for c, f in zip(PRED6DOF_COLUMNS[1:], fields[1:]))
        check_quaternion(path, line, (qw, qx, qy, qz))
        if ticks and tick <= ticks[-1]:
            if tick < ticks[-1]:
                raise row_error(path, line, f"time goes backwards: tick {tick} is "
                                            f"{(ticks[-1] - tick) / 1e4:.3f} ms before line {lines_used[-1]}")
            duplicates.append(line)
            continue
        ticks.append(tick)
        lines_used.append(line)
        rows.append((x, y, z, qw, qx, qy, qz))
    if not rows:
        raise TraceError(f"{path}: no samples after the header")
    data = np.array(rows, dtype=np.float64)
    t = (np.array(ticks, dtype=np.int64) - ticks[0]).astype(np.float64) * TIME_UNITS["ticks"]
    positions, orientations = left_handed_to_right_handed(data[:, :3], data[:, 3:])
    warnings = []
    if duplicates:
        shown = ", ".join(map(str, duplicates[:10])) + (", ..." if len(duplicates) > 10 else "")
        plural = "s" if len(duplicates) > 1 else ""
        warnings.append(f"{path}: dropped {len(duplicates)} sample{plural} repeating the previous "
                        f"timestamp (line{plural} {shown})")
    warnings += _gap_warnings(path, t, lines_used)
    for w in warnings:
        log.warning(w)
    return HeadTrace.from_samples(t, positions, orientations, Path(path).stem, warnings)


def import_csv(path, columns: dict, time_unit: str = "s", rotation: str = "quat",
               quat_order: str = "wxyz", euler_order: str = "yxz", degrees: bool = True,
               handedness: str = "right", delimiter: str | None = ",", skip_rows: int = 0,
               duplicates: str = "error", name: str | None = None) -> HeadTrace:
    """Import a plain CSV whose columns the caller names.

    columns : maps ``t``, ``px``, ``py``, ``pz`` and either ``qw``, ``qx``, ``qy``, ``qz``
        (rotation='quat') or ``yaw``, ``pitch``, ``roll`` (rotation='euler') to a header name
        (str) or a 0-based column index (int). If every value is an index the file has no
        header; otherwise the first line after ``skip_rows`` is the header. Shorthands:
        ``p`` = first of three consecutive x, y, z columns; ``q`` = first of four
        consecutive quaternion columns in ``quat_order`` ('wxyz' or 'xyzw'), or a list of
        four names/indices in that order.
    time_unit : s, ms, us, ns or ticks (100 ns); integer stamps are re-based exactly.
    euler_order : intrinsic axis order as in :func:`~pibr.protocol.pose.quat_from_euler`;
        yaw turns about Y, pitch about X, roll about Z. ``degrees`` False means radians.
    handedness : 'right' (pibr) or 'left' (Unity-style, +Y up, +Z forward; converted).
    delimiter : field separator; None splits on any whitespace.
    skip_rows : physical lines to skip before the header (or the data, without a header).
    duplicates : 'error' (raise on a repeated timestamp) or 'drop' (keep the first).
    """
    if time_unit not in TIME_UNITS:
        raise TraceError(f"unknown time unit {time_unit!r}; expected one of {', '.join(TIME_UNITS)}")
    if rotation not in ("quat", "euler"):
        raise TraceError(f"unknown rotation {rotation!r}; expected 'quat' or 'euler'")
    if quat_order not in ("wxyz", "xyzw"):
        raise TraceError(f"unknown quaternion order {quat_order!r}; expected 'wxyz' or 'xyzw'")
    if handedness not in ("right", "left"):
        raise TraceError(f"unknown handedness {handedness!r}; expected 'right' or 'left'")
    if duplicates not in ("error", "drop"):
        raise TraceError(f"duplicates must be 'error' or 'drop', got {duplicates!r}")
    euler_order = euler_order.lower()
    if rotation == "euler" and (len(euler_order) != 3 or sorted(euler_order) != ["x", "y", "z"]):
        raise TraceError(f"Euler order must name x, y and z once each (e.g. 'yxz'), got {euler_order!r}")
    if skip_rows < 0:
        raise TraceError(f"skip_rows must be >= 0, got {skip_rows}")

    spec = _expand_columns(columns, rotation, quat_order)
    lines = ((n, text) for n, text in iter_lines(path) if n > skip_rows)
    header = None
    if not all(isinstance(v, int) for v in spec.values()):
        first = next(lines, None)
        if first is None:
            raise TraceError(f"{path}: no header line after skipping {skip_rows} lines")
        header = header_fields(first[1], delimiter)
    index = _resolve_columns(path, spec, header)
    needed = max(index.values()) + 1
    keys = list(index)
    value_keys = [k for k in keys if k != "t"]
    scale = TIME_UNITS[time_unit]

    t_first = None
    times, rows, lines_used, dropped = [], [], [], []
    last = None
    for line, text in lines:
        fields = [f.strip().strip("\"'") for f in text.split(delimiter)]
        if header is not None and len(fields) != len(header):
            raise row_error(path, line, f"has {len(fields)} columns, the header has {len(header)}")
        if len(fields) < needed:
            raise row_error(path, line, f"has {len(fields)} columns, expected at least {needed}")
        stamp = _parse_time(path, line, fields[index["t"]])
        if t_first is None:
            t_first = stamp
        # Integer stamps (ns since an epoch, ticks) subtract exactly before scaling to seconds.
        rel = (stamp - t_first) * scale
        values = {k: parse_number(path, line, _column_label(k, spec, header), fields[index[k]])
                  for k in value_keys}
        if rotation == "quat":
            check_quaternion(path, line, [values[k] for k in _QUAT_KEYS])
        if last is not None and rel <= last[0]:
            if rel < last[0]:
                raise row_error(path, line, f"time is not increasing: {fields[index['t']]!r} is before "
                                            f"line {last[1]}")
            if duplicates == "error":
                raise row_error(path, line, f"duplicate timestamp {fields[index['t']]!r} "
                                            f"(same as line {last[1]})")
            dropped.append(line)
            continue
        last = (rel, line)
        times.append(rel)
        lines_used.append(line)
        rows.append([values[k] for k in value_keys])
    if not rows:
        raise TraceError(f"{path}: no samples")

    data = dict(zip(value_keys, np.array(rows, dtype=np.float64).T))
    positions = np.column_stack([data[k] for k in _POSITION_KEYS])
    if rotation == "quat":
        orientations = np.column_stack([data[k] for k in _QUAT_KEYS])
    else:
        angles = np.column_stack([data[_EULER_AXIS[axis]] for axis in euler_order])
        if degrees:
            angles = np.radians(angles)
        orientations = quat_from_euler(angles, euler_order)
    if handedness == "left":
        positions, orientations = left_handed_to_right_handed(positions, orientations)
    t = np.array(times, dtype=np.float64)
    warnings = []
    if dropped:
        warnings.append(f"{path}: dropped {len(dropped)} sample{'s' if len(dropped) > 1 else ''} "
                        f"repeating the previous timestamp (first on line {dropped[0]})")
    warnings += _gap_warnings(path, t, lines_used)
    for w in warnings:
        log.warning(w)
    return HeadTrace.from_samples(t, positions, orientations, name or Path(path).stem, warnings)


def parse_columns(text: str) -> dict:
    """``"t=time,px=x,q=4"`` -> ``{"t": "time", "px": "x", "q": 4}`` (digits become indices)."""
    out = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        key, sep, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key or not value:
            raise TraceError(f"bad column mapping {item!r}: expected KEY=COLUMN, e.g. t=time or px=1")
        out[key] = int(value) if value.isdigit() else value
    return out


# --------------------------------------------------------------------------------- internals


def _expand_columns(columns: dict, rotation: str, quat_order: str) -> dict:
    """Validate the caller's mapping and expand the p/q shorthands to one key per value."""
    rotation_keys = _QUAT_KEYS if rotation == "quat" else _EULER_KEYS
    allowed = {"t", "p", *_POSITION_KEYS, *rotation_keys} | ({"q"} if rotation == "quat" else set())
    unknown = sorted(set(columns) - allowed)
    if unknown:
        raise TraceError(f"unknown column key(s) {', '.join(unknown)} for rotation={rotation!r}; "
                         f"expected {', '.join(sorted(allowed))}")
    spec = {k: v for k, v in columns.items() if k not in ("p", "q")}
    for short, keys in (("p", _POSITION_KEYS), ("q", tuple("q" + c for c in quat_order))):
        if short not in columns:
            continue
        value = columns[short]
        if isinstance(value, int):
            names = [value + i for i in range(len(keys))]
        elif isinstance(value, (list, tuple)) and len(value) == len(keys):
            names = list(value)
        else:
            raise TraceError(f"column {short!r} must be the index of the first of {len(keys)} "
                             f"consecutive columns or a list of {len(keys)} columns, got {value!r}")
        for k, v in zip(keys, names):
            if k in spec:
                raise TraceError(f"column {k!r} is given twice (directly and through {short!r})")
            spec[k] = v
    missing = [k for k in ("t", *_POSITION_KEYS, *rotation_keys) if k not in spec]
    if missing:
        raise TraceError(f"missing column mapping for {', '.join(missing)} (rotation={rotation!r}); "
                         "e.g. t=time,px=x,py=y,pz=z," +
                         ("qw=qw,qx=qx,qy=qy,qz=qz" if rotation == "quat" else "yaw=yaw,pitch=pitch,roll=roll"))
    for k, v in spec.items():
        if isinstance(v, bool) or not isinstance(v, (int, str)) or (isinstance(v, int) and v < 0):
            raise TraceError(f"column for {k!r} must be a header name or a 0-based index, got {v!r}")
    return spec


def _resolve_columns(path, spec: dict, header: list[str] | None) -> dict:
    """Key -> 0-based column index."""
    index = {}
    for key, column in spec.items():
        if isinstance(column, int):
            index[key] = column
            continue
        matches = [i for i, h in enumerate(header) if h == column]
        if not matches:  # fall back to a case-insensitive match
            matches = [i for i, h in enumerate(header) if h.lower() == column.lower()]
        if len(matches) != 1:
            problem = "is not in" if not matches else "appears more than once in"
            raise TraceError(f"{path}: column {column!r} (for {key}) {problem} the header; "
                             f"available: {', '.join(header)}")
        index[key] = matches[0]
    return index


def _column_label(key: str, spec: dict, header) -> str:
    column = spec[key]
    return column if isinstance(column, str) else f"{key} (index {column})"


def _parse_time(path, line: int, text: str):
    """An int when the field is an integer literal (kept exact), else a finite float."""
    try:
        return int(text)
    except ValueError:
        return parse_number(path, line, "t", text)


def _gap_warnings(path, t: np.ndarray, lines: list[int]) -> list[str]:
    steps = np.diff(t)
    long = np.flatnonzero(steps > GAP_WARNING_S)
    if not long.size:
        return []
    worst = long[np.argmax(steps[long])]
    return [f"{path}: {long.size} gaps longer than {GAP_WARNING_S * 1e3:.0f} ms between samples; "
            f"the longest is {steps[worst] * 1e3:.1f} ms before line {lines[worst + 1]}"]
