"""What every command line shares: argparse types for the text forms of :mod:`.address` and for
numbers, and :func:`config_from_args`, which maps parsed arguments onto a settings dataclass.

Each type raises ``argparse.ArgumentTypeError`` with the reason, which argparse prints with the
option's name.
"""
from __future__ import annotations

import argparse
import dataclasses
import math

from pibr.protocol.errors import ConfigError

from .address import parse_size


def size(text: str) -> tuple[int, int]:
    """``WxH`` (or ``N`` for N x N) -> (width, height)."""
    try:
        return parse_size(text)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def eye_fov(text: str) -> tuple[float, float, float, float]:
    """``OUTER,INNER,UP,DOWN`` degrees of the left eye's frustum (protocol/frustum.py)."""
    from pibr.protocol.frustum import check_eye_fov_deg

    try:
        return check_eye_fov_deg(text)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def number(text: str, kind=float) -> float:
    """A finite number (``kind`` int: a whole one)."""
    try:
        v = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {'an integer' if kind is int else 'a number'}, got {text!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return v


def positive(text: str) -> float:
    v = number(text)
    if v <= 0:
        raise argparse.ArgumentTypeError(f"must be positive, got {text}")
    return v


def non_negative(text: str) -> float:
    v = number(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return v


def positive_int(text: str) -> int:
    v = number(text, int)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {text}")
    return v


def non_negative_int(text: str) -> int:
    v = number(text, int)
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return v


def fraction(text: str) -> float:
    """A number in (0, 1]."""
    v = number(text)
    if not 0 < v <= 1:
        raise argparse.ArgumentTypeError(f"must be in (0, 1], got {text}")
    return v


def _parts(text: str) -> list[str]:
    return [part.strip() for part in text.split(",") if part.strip()]


def sizes(text: str) -> tuple:
    """``WxH,WxH,...`` ('' for none)."""
    return tuple(size(part) for part in _parts(text))


def positives(text: str) -> tuple:
    """Positive numbers separated by commas ('' for none)."""
    return tuple(positive(part) for part in _parts(text))


def positive_ints(text: str) -> tuple:
    """Whole numbers of at least 1 separated by commas ('' for none)."""
    return tuple(positive_int(part) for part in _parts(text))


def names_or_none(text: str) -> tuple:
    """Names separated by commas ('' for none)."""
    return tuple(_parts(text))


def names(text: str) -> tuple:
    """Names separated by commas, at least one."""
    out = names_or_none(text)
    if not out:
        raise argparse.ArgumentTypeError("name at least one")
    return out


def offset(text: str) -> tuple[float, float, float]:
    """The extra view's offset ``FORWARD,UP,TILT_DEG`` (metres, metres, degrees)."""
    try:
        parts = tuple(float(x) for x in text.split(","))
    except ValueError:
        parts = ()
    if len(parts) != 3 or not all(math.isfinite(p) for p in parts):
        raise argparse.ArgumentTypeError(f"expected FORWARD,UP,TILT_DEG (metres, metres, degrees), got {text!r}")
    return parts


def config_from_args(cls, args: argparse.Namespace, **overrides):
    """A ``cls`` (a dataclass of settings) from parsed arguments: every field whose name is an
    argument's destination takes its value (tuples for lists), ``overrides`` win. The fields no
    argument names keep their defaults."""
    given = vars(args)
    values = {}
    for f in dataclasses.fields(cls):
        if f.name in overrides:
            values[f.name] = overrides[f.name]
        elif f.name in given:
            v = given[f.name]
            values[f.name] = tuple(v) if isinstance(v, list) else v
    unknown = set(overrides) - {f.name for f in dataclasses.fields(cls)}
    if unknown:
        raise TypeError(f"{cls.__name__} has no field(s) {', '.join(sorted(unknown))}")
    return cls(**values)
