"""The one bounded JSON reader: every JSON body on the wire and every JSON file pibr reads.

Python's :mod:`json` is unbounded where a hostile peer or a careless file hurts: its decoder
recurses once per nesting level (100,000 ``[`` raise ``RecursionError``), it converts number
literals of any length (``int()`` refuses more than 4,300 digits with ``ValueError``; a
400-digit integer later overflows ``float()``), and it accepts ``NaN``, ``Infinity`` and
``-Infinity``, which pibr's own writers refuse. :func:`loads` enforces these limits and
raises :class:`~pibr.protocol.errors.JSONError` (a ``ValueError``) naming the problem and
where; callers turn it into their own documented error (``MalformedMessage``,
``SceneError``, ``ConfigError``). :func:`check_tree` applies the same value limits to a tree
another parser built (TOML from :mod:`tomllib`), naming the path of the bad value.

=================  ===========  ==============================================================
limit              default      how
=================  ===========  ==============================================================
nesting depth      32           brackets counted outside strings *before* ``json.loads`` runs,
                                so the recursive decoder never goes deep (JSON and TOML text)
number literal     100 chars    ``parse_int`` / ``parse_float`` hooks see the literal before
                                ``int()`` / ``float()`` do; :func:`check_tree`: integers of
                                more than 100 digits
non-finite         refused      ``NaN``, ``Infinity``, ``-Infinity`` and literals that overflow
                                a float (``1e400``)
text size          16 MiB       checked first; callers pass tighter limits (wire bodies 1 MiB)
=================  ===========  ==============================================================
"""
from __future__ import annotations

import json
import math
import re

import numpy as np

from .errors import JSONError

MAX_DEPTH = 32
MAX_NUMBER_CHARS = 100
MAX_TEXT_BYTES = 16 * 1024 * 1024

#: A JSON string (escapes included); linear-time on any input (no nested quantifiers).
_JSON_STRING = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*"', re.S)
#: What may hold brackets in TOML without nesting anything: strings and comments.
_TOML_SKIP = re.compile(r'"""[^\\]*?(?:\\.[^\\]*?)*?"""|\'\'\'.*?\'\'\'|"[^"\\\n]*(?:\\.[^"\\\n]*)*"'
                        r"|'[^'\n]*'|#[^\n]*", re.S)
_SCAN_CHUNK = 1 << 20
_OPEN = (ord("["), ord("{"))
_CLOSE = (ord("]"), ord("}"))


def loads(data, *, what: str = "JSON", max_depth: int = MAX_DEPTH, max_number_chars: int = MAX_NUMBER_CHARS,
          max_bytes: int = MAX_TEXT_BYTES):
    """Parse JSON ``data`` (str, or UTF-8 bytes) within the limits in the module docstring.

    ``what`` names the document in error messages (a file, a message). Raises JSONError.
    """
    encoded = isinstance(data, (bytes, bytearray, memoryview))
    syntax = "not UTF-8 JSON" if encoded else "not valid JSON"
    if encoded:
        if len(data) > max_bytes:
            raise JSONError(f"{what}: {len(data)} bytes exceed the limit of {max_bytes}")
        try:
            text = bytes(data).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise JSONError(f"{what}: {syntax} ({exc.reason} at byte {exc.start})") from None
    else:
        text = data
        if len(text) > max_bytes:
            raise JSONError(f"{what}: {len(text)} characters exceed the limit of {max_bytes}")
    _check_depth(_JSON_STRING.sub('""', text), max_depth, what)   # JSON strings hold no raw line breaks

    def number(literal: str, kind):
        if len(literal) > max_number_chars:
            return _Refused(f"a number of {len(literal)} characters ({literal[:20]}...) exceeds the limit of "
                            f"{max_number_chars}")
        value = kind(literal)
        if kind is float and not math.isfinite(value):
            return _Refused(f"the number {literal[:40]} overflows a 64-bit float")
        return value

    try:
        tree = json.loads(text, parse_int=lambda s: number(s, int), parse_float=lambda s: number(s, float),
                          parse_constant=lambda s: _Refused(f"{s} is not a finite number (JSON has none)"))
    except json.JSONDecodeError as exc:
        raise JSONError(f"{what}: {syntax} ({exc})") from None
    # The hooks marked refused numbers rather than raising, so the error can name their path.
    check_tree(tree, what=what, max_depth=max_depth, max_number_chars=max_number_chars)
    return tree


class _Refused:
    """Stands in for a number literal :func:`loads` refuses, until :func:`check_tree` finds its path."""

    def __init__(self, reason: str):
        self.reason = reason


def check_toml_depth(text: str, *, what: str = "TOML", max_depth: int = MAX_DEPTH) -> None:
    """Raise JSONError when TOML ``text`` nests arrays / inline tables deeper than ``max_depth``
    (run it before :mod:`tomllib`, whose parser recurses per level)."""
    _check_depth(_TOML_SKIP.sub(lambda m: "\n" * m.group().count("\n"), text), max_depth, what)


def check_tree(value, *, what: str = "document", max_depth: int = MAX_DEPTH,
               max_number_chars: int = MAX_NUMBER_CHARS) -> None:
    """Raise JSONError for a parsed tree of dicts and lists that nests deeper than ``max_depth``,
    holds a non-finite float or an integer of more than ``max_number_chars`` digits. Iterative,
    so any depth is safe to check; the message names the value's path, e.g. ``objects[2].size[0]``."""
    too_big = 10 ** max_number_chars
    stack = [(value, "", 1)]
    while stack:
        v, path, depth = stack.pop()
        where = f"{what}: {path or 'the top level'}"
        if isinstance(v, (dict, list)):
            if depth > max_depth:
                raise JSONError(f"{where}: nested deeper than {max_depth} levels")
            items = v.items() if isinstance(v, dict) else enumerate(v)
            for k, child in items:
                sub = f"{path}[{k}]" if isinstance(v, list) else (f"{path}.{k}" if path else str(k))
                stack.append((child, sub, depth + 1))
        elif isinstance(v, _Refused):
            raise JSONError(f"{where}: {v.reason}")
        elif isinstance(v, float):
            if not math.isfinite(v):
                raise JSONError(f"{where}: {v} is not a finite number")
        elif isinstance(v, int) and not isinstance(v, bool):
            if abs(v) >= too_big:
                raise JSONError(f"{where}: an integer of more than {max_number_chars} digits")


def _check_depth(blanked: str, max_depth: int, what: str) -> None:
    """``blanked``: a text with its strings (and comments) removed but its line breaks kept."""
    depth = 0
    for start in range(0, len(blanked), _SCAN_CHUNK):
        # Latin-1 with replacement keeps one byte per character, so indices stay character offsets.
        a = np.frombuffer(blanked[start:start + _SCAN_CHUNK].encode("latin-1", "replace"), np.uint8)
        step = ((a == _OPEN[0]) | (a == _OPEN[1])).astype(np.int32) - ((a == _CLOSE[0]) | (a == _CLOSE[1]))
        level = depth + np.cumsum(step)
        over = np.flatnonzero(level > max_depth)
        if over.size:
            line = blanked.count("\n", 0, start + int(over[0])) + 1
            raise JSONError(f"{what}: nested deeper than {max_depth} levels (line {line})")
        if level.size:
            depth = int(level[-1])
