"""Importers: other head-trace formats -> :class:`~pibr.protocol.trace.HeadTrace`.

Conventions are converted here, once: timestamps to seconds from the start, the recording's
axes to pibr's (right-handed, +Y up, the head looking along -Z at identity) with
:func:`axis_conversion`, Euler angles to quaternions. Every importer records what it assumed
(units, axes, delimiters, ignored columns, where positions came from) in the trace's
``assumptions``, which ``pibr trace show`` prints so a user can check them.

Shapes of real recordings this takes, one command each (see ``pibr trace convert --help``):

* HoloLens / Unity logs (``timestamp,x,y,z,qx,qy,qz,qw``, left-handed, +Y up), with any extra
  columns (velocities, speeds): ``--format pred6dof``, the extra columns ignored by name;
* a header delimited differently from its rows (``Time x y z alpha beta gamma`` over
  comma-separated rows): the default ``--delimiter auto`` splits each line on what it uses;
* Euler angles about named axes in a named order (``--columns rz=alpha,rx=beta,ry=gamma
  --rotation euler --euler zxy``), a Z-up world (``--up z``) and another identity forward
  (``--forward``);
* orientation-only (3-DoF) traces, e.g. 360-video studies: no position columns, and
  ``--positions fixed`` (the head stays at the origin) or ``--positions neck`` (a seated
  head-neck model: the eyes 10 cm above and 8 cm in front of a fixed neck pivot);
* positions in a game world's absolute coordinates: ``--recentre`` (first position to the
  origin) or ``--recentre yaw`` (and the first heading along -Z).
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from .errors import TraceError
from .pose import quat_conjugate, quat_from_euler, quat_from_matrix, quat_multiply, quat_rotate
from .trace import (PRED6DOF_COLUMNS, TIMESTAMP_RANGE, HeadTrace, check_quaternion, iter_lines,
                    parse_number, row_error)

log = logging.getLogger(__name__)

#: Seconds per unit of each supported timestamp unit.
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9, "ticks": 1e-7}

#: Largest 0-based column index ``--columns`` takes.
MAX_COLUMN_INDEX = 100_000

#: Gaps between samples longer than this are noted in the trace's warnings (tracking loss).
GAP_WARNING_S = 0.1

_POSITION_KEYS = ("px", "py", "pz")
_QUAT_KEYS = ("qw", "qx", "qy", "qz")
#: Euler angle columns: the angle about the recording's x, y or z axis. yaw, pitch and roll
#: are the same for a +Y-up recording: about Y, X and Z.
_EULER_KEYS = ("rx", "ry", "rz")
_EULER_ALIASES = {"pitch": "rx", "yaw": "ry", "roll": "rz"}

_AXES = {"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1)}
#: The identity head's forward direction when --forward is not given, by handedness and up axis.
DEFAULT_FORWARD = {("right", "y"): "-z", ("left", "y"): "z", ("right", "z"): "y", ("left", "z"): "y"}
#: Seated head-neck model (head coordinates: +Y up, -Z forward): the eyes relative to the pivot.
NECK_TO_EYES = np.array([0.0, 0.10, -0.08])
POSITION_MODES = ("columns", "fixed", "neck")


def _axis(name: str) -> np.ndarray:
    name = name.strip().lower().lstrip("+")
    sign = -1.0 if name.startswith("-") else 1.0
    key = name.lstrip("-")
    if key not in _AXES:
        raise TraceError(f"unknown axis {name!r}; expected x, y or z with an optional sign, e.g. -z")
    return sign * np.array(_AXES[key], dtype=np.float64)


def axis_conversion(handedness: str = "right", up: str = "y", forward: str | None = None) -> np.ndarray:
    """(3, 3) matrix taking a recording's coordinates to pibr's.

    The recording's world has ``up`` as its up axis and a head at identity orientation looks
    along ``forward`` (default :data:`DEFAULT_FORWARD`); its right is forward x up
    (right-handed) or up x forward (left-handed). pibr: right +X, up +Y, forward -Z."""
    if handedness not in ("right", "left"):
        raise TraceError(f"unknown handedness {handedness!r}; expected 'right' or 'left'")
    u = _axis(up)
    if forward is None:
        forward = DEFAULT_FORWARD.get((handedness, up.strip().lower().lstrip("+")))
        if forward is None:
            raise TraceError(f"give --forward for an up axis of {up!r}")
    f = _axis(forward)
    if abs(float(u @ f)) > 0.5:
        raise TraceError(f"the forward axis {forward!r} must be perpendicular to the up axis {up!r}")
    right = np.cross(f, u) if handedness == "right" else np.cross(u, f)
    source = np.column_stack([right, u, f])
    target = np.column_stack([[1.0, 0, 0], [0, 1.0, 0], [0, 0, -1.0]])
    return target @ source.T


def convert_axes(positions: np.ndarray, orientations: np.ndarray, m: np.ndarray):
    """Positions (n, 3) and head orientations (n, 4) (w, x, y, z) from a recording's axes to
    pibr's with ``m`` (:func:`axis_conversion`): p' = m p, R' = m R m^T. A mirroring ``m``
    (det -1, a handedness change) acts on rotations as its negative, a proper rotation."""
    proper = m if np.linalg.det(m) > 0 else -m
    c = quat_from_matrix(proper)
    q = quat_multiply(quat_multiply(np.broadcast_to(c, orientations.shape), orientations),
                      np.broadcast_to(quat_conjugate(c), orientations.shape))
    return np.asarray(positions, dtype=np.float64) @ m.T, q


def _describe_axes(handedness: str, up: str, forward: str | None) -> dict:
    forward = forward or DEFAULT_FORWARD.get((handedness, up.strip().lower().lstrip("+")), "?")
    changed = (handedness, up.strip().lower().lstrip("+"), forward.strip().lower().lstrip("+")) != ("right", "y", "-z")
    text = f"{handedness}-handed, +{up.strip().lower().lstrip('+')} up, head looking along {forward} at identity"
    return {"axes": text + (" (converted to pibr's: right-handed, +Y up, looking along -Z)" if changed
                            else " (pibr's own)")}


def split_fields(text: str, delimiter: str | None) -> list[str]:
    """Fields of one line. ``delimiter`` 'auto': commas if the line has any, else semicolons,
    else tabs, else any whitespace (so a header and its rows may use different ones); None:
    any whitespace; otherwise that string."""
    if delimiter == "auto":
        delimiter = next((d for d in (",", ";", "\t") if d in text), None)
    return [f.strip().strip("\"'").strip() for f in text.split(delimiter)]


def import_pred6dof(path, time_unit: str | None = None) -> HeadTrace:
    """Import a pred6dof / HoloLens / Unity recording with columns ``timestamp, x, y, z, qx, qy,
    qz, qw`` (found by name, any order, case-insensitive; other columns such as velocities are
    ignored), in Unity's left-handed world (+Y up, +Z forward).

    timestamp: integers are .NET DateTime ticks (100 ns), decimals seconds, unless
    ``time_unit`` says otherwise. Repeated timestamps: the later samples are dropped and
    counted in ``trace.warnings``; a timestamp earlier than its predecessor raises TraceError.
    """
    if time_unit is not None and time_unit not in TIME_UNITS:
        raise TraceError(f"unknown time unit {time_unit!r}; expected one of {', '.join(TIME_UNITS)}")
    lines = iter_lines(path)
    first = next(lines, None)
    expected = ",".join(PRED6DOF_COLUMNS)
    if first is None:
        raise TraceError(f"{path}: empty file, expected a header with {expected!r}")
    line, text = first
    header = split_fields(text, "auto")
    lower = [h.lower() for h in header]
    missing = [c for c in PRED6DOF_COLUMNS if c not in lower]
    if missing:
        raise row_error(path, line, f"a pred6dof / HoloLens header needs the columns {expected!r}; "
                                    f"{', '.join(missing)} missing in {text!r}")
    index = [lower.index(c) for c in PRED6DOF_COLUMNS]
    ignored = [h for i, h in enumerate(header) if i not in index]
    stamps, lines_used, rows = [], [], []
    duplicates = []
    for line, text in lines:
        fields = split_fields(text, "auto")
        if len(fields) != len(header):
            raise row_error(path, line, f"has {len(fields)} columns, the header has {len(header)}")
        stamp = _parse_time(path, line, fields[index[0]])
        x, y, z, qx, qy, qz, qw = (parse_number(path, line, c, fields[i])
                                   for c, i in zip(PRED6DOF_COLUMNS[1:], index[1:]))
        check_quaternion(path, line, (qw, qx, qy, qz))
        if stamps and stamp <= stamps[-1]:
            if stamp < stamps[-1]:
                raise row_error(path, line, f"time goes backwards: {fields[index[0]]!r} is before line "
                                            f"{lines_used[-1]}")
            duplicates.append(line)
            continue
        stamps.append(stamp)
        lines_used.append(line)
        rows.append((x, y, z, qw, qx, qy, qz))
    if not rows:
        raise TraceError(f"{path}: no samples after the header")
    kinds = [isinstance(s, int) for s in stamps]
    integer = all(kinds)
    if any(kinds) and not integer:
        bad = kinds.index(False) if kinds[0] else kinds.index(True)
        raise row_error(path, lines_used[bad], f"timestamp {stamps[bad]!r} mixes decimal and integer timestamps "
                                               "(integers are ticks, decimals seconds)")
    unit = time_unit or ("ticks" if integer else "s")
    # Integer stamps (6e17 ticks do not fit a float's 53 bits) subtract exactly before scaling.
    t = np.array([float((s - stamps[0]) * TIME_UNITS[unit]) for s in stamps])
    data = np.array(rows, dtype=np.float64)
    conversion = axis_conversion("left", "y", "z")
    positions, orientations = convert_axes(data[:, :3], data[:, 3:], conversion)
    warnings = []
    if duplicates:
        shown = ", ".join(map(str, duplicates[:10])) + (", ..." if len(duplicates) > 10 else "")
        plural = "s" if len(duplicates) > 1 else ""
        warnings.append(f"{path}: dropped {len(duplicates)} sample{plural} repeating the previous "
                        f"timestamp (line{plural} {shown})")
    warnings += _gap_warnings(path, t, lines_used)
    for w in warnings:
        log.warning(w)
    assumptions = {"format": "pred6dof / HoloLens (Unity)",
                   "time": f"column {header[index[0]]!r} in {_UNIT_NAMES[unit]}"
                           + ("" if time_unit else " (from its " + ("integer" if integer else "decimal") + " values)"),
                   **_describe_axes("left", "y", "z"), "units": "metres",
                   "positions": "columns x, y, z"}
    if ignored:
        assumptions["ignored columns"] = ", ".join(ignored)
    return HeadTrace.from_samples(t, positions, orientations, Path(path).stem, warnings, assumptions)


_UNIT_NAMES = {"s": "seconds", "ms": "milliseconds", "us": "microseconds", "ns": "nanoseconds",
               "ticks": ".NET ticks (100 ns)"}


def import_csv(path, columns: dict, time_unit: str = "s", rotation: str = "quat",
               quat_order: str = "wxyz", euler_order: str = "yxz", degrees: bool = True,
               handedness: str = "right", delimiter: str | None = "auto", skip_rows: int = 0,
               duplicates: str = "error", name: str | None = None, up: str = "y", forward: str | None = None,
               positions: str = "columns", recentre: str | None = None) -> HeadTrace:
    """Import a plain CSV (or whitespace-separated) trace whose columns the caller names.

    columns : maps ``t``, ``px``, ``py``, ``pz`` and either ``qw``, ``qx``, ``qy``, ``qz``
        (rotation='quat') or Euler angles ``rx``, ``ry``, ``rz`` (the angle about the
        recording's x, y, z axis; ``pitch``, ``yaw``, ``roll`` are the same names for a
        +Y-up recording) (rotation='euler') to a header name (str) or a 0-based column index
        (int). If every value is an index the file has no header; otherwise the first line
        after ``skip_rows`` is the header. Columns not named are ignored. Shorthands: ``p`` =
        first of three consecutive x, y, z columns; ``q`` = first of four consecutive
        quaternion columns in ``quat_order`` ('wxyz' or 'xyzw'), or a list of four names or
        indices in that order. Without position columns, ``positions`` says what to do.
    time_unit : s, ms, us, ns or ticks (100 ns); integer stamps are re-based exactly.
    euler_order : the axes in the order the rotations are applied, intrinsically (each about
        the already rotated axes), e.g. 'yxz' (yaw, pitch, roll) or 'zxy'. ``degrees`` False
        means radians.
    handedness, up, forward : the recording's axes (see :func:`axis_conversion`), converted.
    delimiter : 'auto' (per line; see :func:`split_fields`), None (any whitespace) or a string.
    skip_rows : physical lines to skip before the header (or the data, without a header).
    duplicates : 'error' (raise on a repeated timestamp) or 'drop' (keep the first).
    positions : 'columns' (read them), 'fixed' (an orientation-only trace: the head stays at
        the origin) or 'neck' (orientation only, positions from a seated head-neck model).
    recentre : None, 'position' (first position to the origin) or 'yaw' (and first heading
        along -Z), after the axes are converted.
    """
    if time_unit not in TIME_UNITS:
        raise TraceError(f"unknown time unit {time_unit!r}; expected one of {', '.join(TIME_UNITS)}")
    if rotation not in ("quat", "euler"):
        raise TraceError(f"unknown rotation {rotation!r}; expected 'quat' or 'euler'")
    if quat_order not in ("wxyz", "xyzw"):
        raise TraceError(f"unknown quaternion order {quat_order!r}; expected 'wxyz' or 'xyzw'")
    if duplicates not in ("error", "drop"):
        raise TraceError(f"duplicates must be 'error' or 'drop', got {duplicates!r}")
    if positions not in POSITION_MODES:
        raise TraceError(f"positions must be one of {', '.join(POSITION_MODES)}, got {positions!r}")
    if recentre not in (None, "position", "yaw"):
        raise TraceError(f"recentre must be 'position' or 'yaw', got {recentre!r}")
    euler_order = euler_order.lower()
    if rotation == "euler" and (len(euler_order) != 3 or sorted(euler_order) != ["x", "y", "z"]):
        raise TraceError(f"Euler order must name x, y and z once each (e.g. 'yxz' or 'zxy'), got {euler_order!r}")
    if skip_rows < 0:
        raise TraceError(f"skip_rows must be >= 0, got {skip_rows}")
    conversion = axis_conversion(handedness, up, forward)

    spec = _expand_columns(columns, rotation, quat_order, positions)
    lines = ((n, text) for n, text in iter_lines(path) if n > skip_rows)
    header = None
    header_split = None
    if not all(isinstance(v, int) for v in spec.values()):
        first = next(lines, None)
        if first is None:
            raise TraceError(f"{path}: no header line after skipping {skip_rows} lines")
        header = split_fields(first[1], delimiter)
        header_split = _delimiter_name(first[1], delimiter)
    index = _resolve_columns(path, spec, header)
    needed = max(index.values()) + 1
    keys = list(index)
    value_keys = [k for k in keys if k != "t"]
    scale = TIME_UNITS[time_unit]

    t_first = None
    times, rows, lines_used, dropped = [], [], [], []
    row_split = None
    last = None
    for line, text in lines:
        fields = split_fields(text, delimiter)
        if row_split is None:
            row_split = _delimiter_name(text, delimiter)
        if header is not None and len(fields) != len(header):
            raise row_error(path, line, f"has {len(fields)} columns, the header has {len(header)}"
                                        + _delimiter_hint(delimiter, text, len(header)))
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
    n = len(rows)
    if rotation == "quat":
        orientations = np.column_stack([data[k] for k in _QUAT_KEYS])
    else:
        angles = np.column_stack([data["r" + axis] for axis in euler_order])
        if degrees:
            angles = np.radians(angles)
        orientations = quat_from_euler(angles, euler_order)
    xyz = np.column_stack([data[k] for k in _POSITION_KEYS]) if positions == "columns" else np.zeros((n, 3))
    xyz, orientations = convert_axes(xyz, orientations, conversion)
    if positions == "neck":
        xyz = quat_rotate(orientations, NECK_TO_EYES) - NECK_TO_EYES
    t = np.array(times, dtype=np.float64)
    warnings = []
    if dropped:
        warnings.append(f"{path}: dropped {len(dropped)} sample{'s' if len(dropped) > 1 else ''} "
                        f"repeating the previous timestamp (first on line {dropped[0]})")
    warnings += _gap_warnings(path, t, lines_used)
    for w in warnings:
        log.warning(w)
    assumptions = {"format": "csv, columns named by the user",
                   "time": f"column {_column_label('t', spec, header)!r} in {_UNIT_NAMES[time_unit]}",
                   **_describe_axes(handedness, up, forward), "units": "metres"}
    if rotation == "quat":
        assumptions["rotation"] = "quaternion " + ", ".join(_column_label(k, spec, header) for k in _QUAT_KEYS) + \
                                  " (w, x, y, z)"
    else:
        assumptions["rotation"] = (f"Euler angles in {'degrees' if degrees else 'radians'}, applied intrinsically "
                                   "in the order " + " then ".join(
                                       f"{a} ({_column_label('r' + a, spec, header)})" for a in euler_order))
    if positions == "columns":
        assumptions["positions"] = "columns " + ", ".join(_column_label(k, spec, header) for k in _POSITION_KEYS)
    elif positions == "fixed":
        assumptions["positions"] = "none in the file (orientation only): the head stays at the origin"
    else:
        assumptions["positions"] = ("none in the file (orientation only): a seated head-neck model, the eyes "
                                    f"{NECK_TO_EYES[1] * 100:.0f} cm above and {-NECK_TO_EYES[2] * 100:.0f} cm "
                                    "in front of a fixed pivot")
    if header is not None:
        ignored = [h for i, h in enumerate(header) if i not in index.values()]
        if ignored:
            assumptions["ignored columns"] = ", ".join(ignored)
    if header_split is None or header_split == row_split:
        assumptions["delimiter"] = row_split
    else:
        assumptions["delimiter"] = f"{header_split} (header), {row_split} (rows)"
    trace = HeadTrace.from_samples(t, xyz, orientations, name or Path(path).stem, warnings, assumptions)
    if recentre is not None:
        trace = trace.recentred(yaw=recentre == "yaw")
    return trace


def _delimiter_name(text: str, delimiter) -> str:
    if delimiter == "auto":
        delimiter = next((d for d in (",", ";", "\t") if d in text), None)
    return {",": "comma", ";": "semicolon", "\t": "tab", None: "whitespace"}.get(delimiter, repr(delimiter))


def _delimiter_hint(delimiter, text: str, columns: int) -> str:
    """A hint when splitting each line on what it uses would have matched the header."""
    if delimiter == "auto" or len(split_fields(text, "auto")) != columns:
        return ""
    return (f" when split on {_delimiter_name(text, delimiter)}; split on {_delimiter_name(text, 'auto')} it has "
            "the header's count: --delimiter auto splits each line on what it uses")


def parse_columns(text: str) -> dict:
    """``"t=time,px=x,q=4"`` -> ``{"t": "time", "px": "x", "q": 4}`` (digits become indices)."""
    out = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        key, sep, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key or not value:
            raise TraceError(f"bad column mapping {item!r}: expected KEY=COLUMN, e.g. t=time or px=1")
        if value.isascii() and value.isdigit():   # str.isdigit() also takes digits int() refuses ("²")
            if len(value) > len(str(MAX_COLUMN_INDEX)) or int(value) > MAX_COLUMN_INDEX:
                raise TraceError(f"bad column mapping {item[:40]!r}: a column index is at most {MAX_COLUMN_INDEX}")
            value = int(value)
        out[key] = value
    return out


# --------------------------------------------------------------------------------- internals


def _expand_columns(columns: dict, rotation: str, quat_order: str, positions: str = "columns") -> dict:
    """Validate the caller's mapping and expand the p/q shorthands and Euler aliases to one key
    per value."""
    columns = {_EULER_ALIASES.get(k, k): v for k, v in columns.items()}
    rotation_keys = _QUAT_KEYS if rotation == "quat" else _EULER_KEYS
    allowed = {"t", "p", *_POSITION_KEYS, *rotation_keys} | ({"q"} if rotation == "quat" else set())
    unknown = sorted(set(columns) - allowed)
    if unknown:
        raise TraceError(f"unknown column key(s) {', '.join(unknown)} for rotation={rotation!r}; "
                         f"expected {', '.join(sorted(allowed))}"
                         + (" (Euler angles: rx, ry, rz or pitch, yaw, roll)" if rotation == "euler" else ""))
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
    given_positions = [k for k in _POSITION_KEYS if k in spec]
    if positions == "columns":
        if not given_positions:
            raise TraceError("no position columns (px, py, pz): for an orientation-only (3-DoF) trace say "
                             "--positions fixed (the head stays at the origin) or --positions neck (a seated "
                             "head-neck model)")
        required = ("t", *_POSITION_KEYS, *rotation_keys)
    else:
        if given_positions:
            raise TraceError(f"--positions {positions} is for traces without positions, but "
                             f"{', '.join(given_positions)} are mapped")
        required = ("t", *rotation_keys)
    missing = [k for k in required if k not in spec]
    if missing:
        raise TraceError(f"missing column mapping for {', '.join(missing)} (rotation={rotation!r}); "
                         "e.g. t=time,px=x,py=y,pz=z," +
                         ("qw=qw,qx=qx,qy=qy,qz=qz" if rotation == "quat" else "rx=pitch,ry=yaw,rz=roll"))
    for k, v in spec.items():
        bad_index = isinstance(v, int) and not 0 <= v <= MAX_COLUMN_INDEX
        if isinstance(v, bool) or not isinstance(v, (int, str)) or bad_index:
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
    """An int when the field is an integer literal (kept exact; 64-bit, as ticks and epoch
    nanoseconds are), else a finite float."""
    try:
        stamp = int(text)   # ValueError past 4300 digits too: then float() says it is infinite
    except ValueError:
        return parse_number(path, line, "t", text)
    if not TIMESTAMP_RANGE[0] <= stamp <= TIMESTAMP_RANGE[1]:
        raise row_error(path, line, f"column 't': integer timestamp {text[:30]!r}{'...' if len(text) > 30 else ''} "
                                    "does not fit 64 bits")
    return stamp


def _gap_warnings(path, t: np.ndarray, lines: list[int]) -> list[str]:
    steps = np.diff(t)
    long = np.flatnonzero(steps > GAP_WARNING_S)
    if not long.size:
        return []
    worst = long[np.argmax(steps[long])]
    return [f"{path}: {long.size} gaps longer than {GAP_WARNING_S * 1e3:.0f} ms between samples; "
            f"the longest is {steps[worst] * 1e3:.1f} ms before line {lines[worst + 1]}"]
