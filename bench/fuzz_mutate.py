"""Mutations of valid inputs for ``pibr bench fuzz``: bytes, text and JSON/TOML structure.

Every function takes a :class:`random.Random` and returns new bytes; the same generator state
gives the same mutant, so an input is reproduced from its parser, seed and index alone.

* :func:`havoc` stacks 1-6 byte-level operations: bit flips, random bytes, interesting
  integers (8-64 bits, both byte orders), insertions, deletions, chunk duplication and swaps,
  truncation and splices with another seed; on text also interesting tokens (``NaN``,
  ``1e400``, 400 and 5,000 digits, deep brackets, quotes, NUL, ...) in place of numbers.
* :func:`overwrite_fields` writes interesting integers and doubles into the known count,
  length, size and value fields of a binary format (where havoc would rarely land).
* :func:`mutate_tree` changes one node of a parsed JSON/TOML tree (a value made huge, negative,
  non-finite, deeply nested, of the wrong type, a key dropped or added, a list grown); the
  tree is then written back with :func:`dump_json` or :func:`dump_toml`, which write raw
  tokens (a 5,000-digit integer, ``NaN``) that Python's writers refuse.
"""
from __future__ import annotations

import json
import math
import re

INTERESTING_INTS = (0, 1, 2, 3, 7, 8, 15, 16, 31, 32, 63, 64, 100, 127, 128, 255, 256, 511, 512, 1000, 1023, 1024,
                    4095, 4096, 8191, 8192, 8193, 16383, 16384, 32767, 32768, 65535, 65536, 10**6, 2**24, 2**31 - 1,
                    2**31, 2**32 - 1, 2**32, 2**53 + 1, 2**62, 2**63 - 1, 2**63, 2**64 - 1)

INTERESTING_DOUBLES = (0.0, -0.0, 1.0, -1.0, 0.5, 3.0, 4.9e-324, 1e-320, 1e-12, 1e9, 1e10, 2.0**53, 1e300, 1e308,
                       -1e308, math.inf, -math.inf, math.nan)

#: Tokens that have broken number and text parsers (as bytes, spliced into text inputs).
INTERESTING_TOKENS = tuple(t.encode("utf-8") if isinstance(t, str) else t for t in (
    "0", "-0", "-1", "1", "2", "1.5", "-1e-300", "4.9e-324", "1e308", "1.8e308", "1e400", "-1e400", "1e-400",
    "NaN", "-NaN", "nan", "Infinity", "-Infinity", "inf", "-inf", "9" * 20, "9" * 400, "9" * 5000, "1" * 4301,
    "0." + "0" * 400 + "1", "2147483648", "4294967296", "9223372036854775807", "9223372036854775808",
    "-9223372036854775809", "18446744073709551616", "0x7fffffff", "1_000", "+1", ".5", "5.", "1e", "--1",
    "true", "false", "null", "[]", "{}", '""', "[" * 64, "]" * 64, "{" * 64, "[" * 5000, "[[x]]", "[x]",
    '"', "'", "'''", '"""', "\\", "\\u0000", "\\ud800", "\\", ",", ":", "=", "#", "\n", "\r\n", "\t", " ", "\x00",
    b"\xff", b"\xc3", b"\xef\xbb\xbf", "é", "\u2028", "²", "٣", "A" * 300, "A" * 70000,
))

#: Replacement values for one node of a tree; a ``RawToken`` is written as it is.
_NUMBER = re.compile(rb"-?[0-9]+(?:\.[0-9]+)?(?:[eE][-+]?[0-9]+)?")


class RawToken:
    """A value written verbatim by :func:`dump_json` / :func:`dump_toml` (e.g. a 5,000-digit integer)."""

    def __init__(self, text: str):
        self.text = text


def _interesting_values(rng) -> list:
    deep = rng.choice((33, 200, 5000))
    return [0, -1, 1, -10**9, 10**9, 2**31, 2**63, 2**64, 10**20, RawToken("9" * 400), RawToken("9" * 5000),
            RawToken("-" + "9" * 320), 1e308, -1e308, 4.9e-324, RawToken("1e400"), RawToken("NaN"),
            RawToken("Infinity"), RawToken("-Infinity"), 0.5, -0.0, True, False, None, "", "x" * 5000, "\x00", "é",
            [], {}, [0], [[0]],
            {"x": 1}, RawToken("[" * deep + "]" * deep), RawToken('{"a":' * deep + "1" + "}" * deep),
            [1e308, 1e308, 1e308], [1, 0, 1e308, 0], [0, 0, 0, 0], list(range(50)), [RawToken("NaN")] * 3]


# ---------------------------------------------------------------------------------- bytes

def havoc(rng, data: bytes, others=(), text: bool = False) -> bytes:
    """1-6 stacked byte operations on ``data``; ``others``: seeds to splice from; ``text``:
    also tokens in place of numbers and at random places."""
    buf = bytearray(data)
    ops = _TEXT_OPS if text else _BINARY_OPS
    for _ in range(rng.choice((1, 1, 2, 2, 3, 4, 6))):
        rng.choice(ops)(rng, buf, others)
    return bytes(buf)


def _pos(rng, buf, end_ok=False) -> int:
    n = len(buf) + (1 if end_ok else 0)
    return rng.randrange(n) if n else 0


def _flip_bit(rng, buf, _):
    if buf:
        buf[_pos(rng, buf)] ^= 1 << rng.randrange(8)


def _random_byte(rng, buf, _):
    if buf:
        buf[_pos(rng, buf)] = rng.randrange(256)


def _interesting_int(rng, buf, _):
    if not buf:
        return
    width = rng.choice((1, 2, 4, 8))
    v = rng.choice(INTERESTING_INTS) * rng.choice((1, 1, -1))
    raw = (v % (1 << (8 * width))).to_bytes(width, rng.choice(("little", "big")))
    at = _pos(rng, buf)
    buf[at:at + width] = raw


def _insert_bytes(rng, buf, _):
    at = _pos(rng, buf, True)
    buf[at:at] = bytes(rng.randrange(256) for _ in range(rng.choice((1, 2, 4, 16))))


def _delete(rng, buf, _):
    if buf:
        at = _pos(rng, buf)
        del buf[at:at + rng.choice((1, 2, 4, 16, 128, len(buf)))]


def _duplicate(rng, buf, _):
    if buf:
        at = _pos(rng, buf)
        chunk = buf[at:at + rng.choice((1, 4, 16, 64, 512))]
        to = _pos(rng, buf, True)
        buf[to:to] = chunk * rng.choice((1, 1, 2, 8))


def _swap(rng, buf, _):
    n = rng.choice((1, 4, 16))
    if len(buf) >= 2 * n:
        a, b = sorted(rng.sample(range(len(buf) - n + 1), 2))
        if b - a >= n:
            buf[a:a + n], buf[b:b + n] = buf[b:b + n], buf[a:a + n]


def _truncate(rng, buf, _):
    if buf:
        del buf[_pos(rng, buf):]


def _splice(rng, buf, others):
    """The head of this input and the tail of another seed, or another seed's chunk inserted."""
    if not others:
        return
    other = rng.choice(others)
    if not other:
        return
    if rng.random() < 0.5:
        cut = _pos(rng, buf, True)
        buf[cut:] = other[rng.randrange(len(other)):]
    else:
        at = rng.randrange(len(other))
        to = _pos(rng, buf, True)
        buf[to:to] = other[at:at + rng.choice((4, 16, 64, 256))]


def _token_for_number(rng, buf, _):
    numbers = list(_NUMBER.finditer(buf))
    if numbers:
        m = rng.choice(numbers)
        buf[m.start():m.end()] = rng.choice(INTERESTING_TOKENS)
    else:
        _insert_token(rng, buf, _)


def _insert_token(rng, buf, _):
    at = _pos(rng, buf, True)
    token = rng.choice(INTERESTING_TOKENS)
    if rng.random() < 0.5:
        buf[at:at] = token
    else:
        buf[at:at + rng.choice((1, 2, 8))] = token


_TEXT_BYTES = b"0123456789.-+eE,;: \t\n[]{}\"'=#xyzabc_\\"


def _random_char(rng, buf, _):
    if buf:
        buf[_pos(rng, buf)] = rng.choice(_TEXT_BYTES)


def _insert_chars(rng, buf, _):
    at = _pos(rng, buf, True)
    buf[at:at] = bytes(rng.choice(_TEXT_BYTES) for _ in range(rng.choice((1, 2, 4, 16))))


def _duplicate_line(rng, buf, _):
    lines = bytes(buf).split(b"\n")
    if lines:
        i = rng.randrange(len(lines))
        lines.insert(rng.randrange(len(lines) + 1), lines[i])
        buf[:] = b"\n".join(lines)


_BINARY_OPS = (_flip_bit, _flip_bit, _random_byte, _interesting_int, _interesting_int, _insert_bytes, _delete,
               _duplicate, _swap, _truncate, _splice)
#: Text keeps mostly to characters that mean something to the parsers (random bytes are
#: mostly invalid UTF-8, refused before any parsing).
_TEXT_OPS = (_flip_bit, _random_char, _random_char, _insert_chars, _delete, _duplicate, _swap, _truncate, _splice,
             _token_for_number, _token_for_number, _token_for_number, _insert_token, _insert_token, _duplicate_line)


def overwrite_fields(rng, data: bytes, fields) -> bytes:
    """1-3 of ``fields`` ((offset, size, "u" or "f"): little-endian unsigned integers or
    float64) overwritten with interesting values."""
    import struct

    buf = bytearray(data)
    for _ in range(rng.choice((1, 1, 2, 3))):
        offset, size, kind = rng.choice(fields)
        if offset + size > len(buf):
            continue
        if kind == "f":
            buf[offset:offset + 8] = struct.pack("<d", rng.choice(INTERESTING_DOUBLES))
        else:
            old = int.from_bytes(buf[offset:offset + size], "little")
            v = rng.choice(INTERESTING_INTS + (old + 1, old - 1, old * 2, old // 2, old + 2**(8 * size - 1)))
            buf[offset:offset + size] = (v % (1 << (8 * size))).to_bytes(size, "little")
    return bytes(buf)


# ---------------------------------------------------------------------------------- trees

def mutate_tree(rng, tree):
    """A copy of a JSON-like tree (dicts, lists, scalars) with one node changed."""
    tree = _copy(tree)
    nodes = []   # (container, key) of every value below the root
    stack = [tree]
    while stack:
        c = stack.pop()
        items = c.items() if isinstance(c, dict) else enumerate(c) if isinstance(c, list) else ()
        for k, v in items:
            nodes.append((c, k))
            stack.append(v)
    if not nodes:
        return rng.choice(_interesting_values(rng))
    c, k = rng.choice(nodes)
    action = rng.random()
    if action < 0.55:
        c[k] = rng.choice(_interesting_values(rng))
    elif action < 0.65:
        if isinstance(c, dict):
            del c[k]
        else:
            c.pop(k)
    elif action < 0.75:          # a sibling copied into a new slot (a repeated object, a longer vector)
        if isinstance(c, dict):
            c[rng.choice(("x", k + "_", "name", "kind", "segments", "radius", "size"))] = _copy(c[k])
        else:
            c.insert(k, _copy(c[k]))
    elif action < 0.85:          # the value wrapped or grown
        v = c[k]
        c[k] = [v] if rng.random() < 0.5 else ([v] * rng.choice((2, 4, 100)) if not isinstance(v, list)
                                               else v * rng.choice((2, 50)))
    else:                        # a number nudged to a boundary
        v = c[k]
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            c[k] = rng.choice((v * 10**6, -v, v + 1, v - 1, v * 1e300 if isinstance(v, float) else v ** 3, 0))
        else:
            c[k] = rng.choice(INTERESTING_INTS)
    return tree


def _copy(v):
    return json.loads(json.dumps(v)) if not _has_raw(v) else v


def _has_raw(v) -> bool:
    stack = [v]
    while stack:
        x = stack.pop()
        if isinstance(x, RawToken):
            return True
        if isinstance(x, dict):
            stack.extend(x.values())
        elif isinstance(x, list):
            stack.extend(x)
    return False


def dump_json(tree) -> bytes:
    """JSON text of ``tree``; RawTokens and non-finite floats written verbatim."""
    return _dump(tree, _json_scalar, lambda k: json.dumps(str(k)), ":", "null").encode("utf-8", "surrogatepass")


def dump_toml(tree: dict) -> bytes:
    """TOML text of a dict: scalars first, then ``[table]`` and ``[[array of tables]]``
    sections, anything deeper inline; RawTokens written verbatim."""
    lines, sections = [], []
    for k, v in tree.items():
        if isinstance(v, dict):
            sections.append(f"\n[{_toml_key(k)}]")
            sections += [f"{_toml_key(kk)} = {_toml_value(vv)}" for kk, vv in v.items()]
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            for x in v:
                sections.append(f"\n[[{_toml_key(k)}]]")
                sub = [f"\n[{_toml_key(k)}.{_toml_key(kk)}]\n" + "\n".join(
                    f"{_toml_key(a)} = {_toml_value(b)}" for a, b in vv.items())
                       for kk, vv in x.items() if isinstance(vv, dict)]
                sections += [f"{_toml_key(kk)} = {_toml_value(vv)}" for kk, vv in x.items() if not isinstance(vv, dict)]
                sections += sub
        else:
            lines.append(f"{_toml_key(k)} = {_toml_value(v)}")
    return "\n".join(lines + sections).encode("utf-8", "surrogatepass") + b"\n"


def _json_scalar(v) -> str:
    if isinstance(v, float) and not math.isfinite(v):
        return "NaN" if math.isnan(v) else ("Infinity" if v > 0 else "-Infinity")
    try:
        return json.dumps(v)
    except ValueError:   # an integer past int -> str's 4300-digit limit
        return "1" * 5000


def _toml_key(k) -> str:
    k = str(k)
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k)


def _toml_scalar(v) -> str:
    if v is None:
        return '""'           # TOML has no null
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float) and not math.isfinite(v):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
    return json.dumps(v) if isinstance(v, str) else _json_scalar(v)


def _toml_value(v) -> str:
    return _dump(v, _toml_scalar, _toml_key, " = ", '""')


def _dump(tree, scalar, key, colon: str, null: str) -> str:
    """Iterative writer (trees may be deep): containers, RawTokens and scalars."""
    out = []
    stack = [tree]
    while stack:
        v = stack.pop()
        if isinstance(v, _Text):
            out.append(v.text)
        elif isinstance(v, RawToken):
            out.append(v.text)
        elif isinstance(v, dict):
            parts = [_Text("{")]
            for i, (k, x) in enumerate(v.items()):
                if i:
                    parts.append(_Text(", "))
                parts += [_Text(key(k) + colon), x]
            parts.append(_Text("}"))
            stack.extend(reversed(parts))
        elif isinstance(v, list):
            parts = [_Text("[")]
            for i, x in enumerate(v):
                if i:
                    parts.append(_Text(", "))
                parts.append(x)
            parts.append(_Text("]"))
            stack.extend(reversed(parts))
        elif v is None:
            out.append(null)
        else:
            out.append(scalar(v))
    return "".join(out)


class _Text:
    def __init__(self, text: str):
        self.text = text
