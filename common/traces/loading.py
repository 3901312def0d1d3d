"""Head traces by name or file: built-in recordings, synthetic traces and files in any
supported format, the format picked from a file's header line."""
from __future__ import annotations

import os
import re
from importlib import resources
from pathlib import Path

from pibr.protocol.errors import TraceError
from pibr.protocol.trace import HeadTrace

from .canonical import CANONICAL_COLUMNS, CANONICAL_HEADER, read_canonical_csv
from .importers import PRED6DOF_COLUMNS, import_pred6dof
from .lines import header_fields, iter_lines, split_fields
from .synthesis import KINDS as SYNTHETIC_KINDS, synthesize

#: The recordings shipped with pibr (``data/pred6dof``, with their licence).
_BUILTIN_DIR = "data/pred6dof"
_BUILTINS = {
    "pred6dof-1": ("1.csv", "real HoloLens head motion, walking around a virtual object, 77.7 s, "
                            "~60 Hz uneven (pred6dof 1.csv)"),
    "pred6dof-2": ("2.csv", "real HoloLens head motion, walking around a virtual object, 72.4 s, "
                            "~60 Hz uneven (pred6dof 2.csv)"),
}


def builtin_traces() -> dict[str, str]:
    """Built-in trace name -> one-line description."""
    return {name: description for name, (_, description) in _BUILTINS.items()}


def detect_format(path) -> str:
    """'canonical' or 'pred6dof' from a file's header line; TraceError for anything else."""
    first = next(iter_lines(path), None)
    if first is None:
        raise TraceError(f"{path}: empty file")
    line, text = first
    names = header_fields(text)
    if names == list(CANONICAL_COLUMNS):
        return "canonical"
    if set(PRED6DOF_COLUMNS) <= {f.lower() for f in split_fields(text, "auto")}:
        return "pred6dof"   # extra columns (velocities, ...) are ignored by the importer
    raise TraceError(
        f"{path}: line {line}: unrecognised trace header {text!r}; expected {CANONICAL_HEADER!r} "
        f"(canonical) or one with {','.join(PRED6DOF_COLUMNS)!r} (pred6dof/HoloLens). For other CSV files "
        "name the columns: pibr trace convert IN OUT --format csv --columns t=...,px=...")


#: ``synth-KIND`` or ``synth-KIND-seedN``: a synthetic trace (synthesis.py) by name.
_SYNTHETIC_NAME = re.compile(rf"synth-({'|'.join(SYNTHETIC_KINDS)})(?:-seed(\d{{1,9}}))?")
SYNTHETIC_DURATION_S = 60.0


def load_trace(spec, format: str = "auto") -> HeadTrace:
    """A head trace from a file path, a built-in name (see :func:`builtin_traces`) or a synthetic
    one by name: ``synth-walk``, ``synth-look``, ``synth-turns``, ``synth-mixed``, optionally
    with ``-seedN`` (60 s at 120 Hz, the same trace every time).

    format : 'auto' (from the header line), 'canonical' or 'pred6dof'
    """
    if format not in ("auto", "canonical", "pred6dof"):
        raise TraceError(f"unknown trace format {format!r}; expected auto, canonical or pred6dof")
    path = Path(os.fspath(spec))
    if not path.is_file():
        key = str(spec)
        synthetic = _SYNTHETIC_NAME.fullmatch(key)
        if synthetic:
            trace = synthesize(synthetic.group(1), SYNTHETIC_DURATION_S, seed=int(synthetic.group(2) or 0))
            trace.name = key
            return trace
        if key not in _BUILTINS:
            raise TraceError(f"{key!r} is neither a trace file nor a built-in trace "
                             f"(built-in: {', '.join(_BUILTINS)}; synthetic: synth-KIND[-seedN], KIND one of "
                             f"{', '.join(SYNTHETIC_KINDS)})")
        filename = _BUILTINS[key][0]
        ref = resources.files(__package__).joinpath(_BUILTIN_DIR, filename)
        with resources.as_file(ref) as builtin_path:
            trace = import_pred6dof(builtin_path)
        trace.name = key
        return trace
    if format == "auto":
        format = detect_format(path)
    if format == "canonical":
        return read_canonical_csv(path)
    return import_pred6dof(path)
