"""The bounded JSON reader: same trees as json.loads within the limits, JSONError past them, nothing else."""
import json
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pibr.protocol import bounded_json
from pibr.protocol.bounded_json import MAX_DEPTH, MAX_NUMBER_CHARS, check_toml_depth, check_tree, loads
from pibr.protocol.errors import JSONError

scalars = (st.none() | st.booleans() | st.integers(-10**30, 10**30) | st.floats(allow_nan=False, allow_infinity=False)
           | st.text(max_size=20))
trees = st.recursive(scalars, lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner,
                                                                                           max_size=4), max_leaves=30)


def _depth(v) -> int:
    if isinstance(v, dict):
        return 1 + max(map(_depth, v.values()), default=0)
    if isinstance(v, list):
        return 1 + max(map(_depth, v), default=0)
    return 0


@settings(max_examples=300, deadline=None)
@given(trees)
def test_reads_what_json_reads_within_the_limits(tree):
    text = json.dumps(tree)
    assert _depth(tree) <= MAX_DEPTH
    assert loads(text) == json.loads(text)
    assert loads(text.encode("utf-8")) == json.loads(text)


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 120), st.sampled_from(["[", '{"k":']), st.text(alphabet='[]{}"\\', max_size=30))
def test_depth_limit_counts_only_brackets_outside_strings(depth, opener, noise):
    closer = "]" if opener == "[" else "}"
    inner = json.dumps(noise)   # brackets and quotes inside a string never count
    text = opener * depth + inner + closer * depth
    if depth <= MAX_DEPTH:
        assert _depth(loads(text)) == depth
    else:
        with pytest.raises(JSONError, match=f"nested deeper than {MAX_DEPTH} levels"):
            loads(text)


@settings(max_examples=300, deadline=None)
@given(st.text(max_size=200) | st.binary(max_size=200))
def test_any_input_parses_or_raises_json_error(data):
    try:
        loads(data)
    except JSONError:
        pass


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 6000), st.booleans())
def test_number_literal_length(digits, negative):
    literal = ("-" if negative else "") + "7" * digits
    if len(literal) <= MAX_NUMBER_CHARS:
        assert loads(f'{{"n": [{literal}]}}') == {"n": [int(literal)]}
    else:
        with pytest.raises(JSONError, match=rf"n\[0\]: a number of {len(literal)} characters"):
            loads(f'{{"n": [{literal}]}}')


def test_deep_brackets_and_huge_numbers_never_reach_the_decoder():
    with pytest.raises(JSONError, match="nested deeper than 32 levels"):
        loads("[" * 100_000 + "]" * 100_000)
    with pytest.raises(JSONError, match="a number of 5000 characters"):
        loads("1" * 5000)            # int() would raise ValueError past 4300 digits
    with pytest.raises(JSONError, match=r"x: a number of 400 characters"):
        loads('{"x": ' + "9" * 400 + "}")


@pytest.mark.parametrize("text, where", [
    ('{"a": NaN}', "a: NaN is not a finite number"),
    ('{"a": [1, Infinity]}', r"a\[1\]: Infinity is not a finite number"),
    ('[-Infinity]', r"\[0\]: -Infinity is not a finite number"),
    ('{"a": {"b": 1e400}}', "a.b: the number 1e400 overflows a 64-bit float"),
    ('{"a": -1.8e308}', "a: the number -1.8e308 overflows"),
])
def test_non_finite_numbers_refused_with_their_path(text, where):
    with pytest.raises(JSONError, match=where):
        loads(text, what="doc")


def test_syntax_encoding_and_size_errors_are_json_errors():
    with pytest.raises(JSONError, match="doc: not valid JSON"):
        loads('{"a": ', what="doc")
    with pytest.raises(JSONError, match="doc: not UTF-8 JSON"):
        loads(b"\xff\xfe{}", what="doc")
    with pytest.raises(JSONError, match="exceed the limit of 10"):
        loads(b"[" + b" " * 20 + b"]", max_bytes=10)
    assert loads(b"[" + b" " * 5 + b"]", max_bytes=10) == []
    assert issubclass(JSONError, ValueError)


def test_limits_are_parameters():
    assert loads("[[[1]]]", max_depth=3) == [[[1]]]
    with pytest.raises(JSONError):
        loads("[[[1]]]", max_depth=2)
    with pytest.raises(JSONError):
        loads("[12345]", max_number_chars=4)


def test_check_tree_is_iterative_and_names_the_path():
    deep = 0
    for _ in range(100_000):   # far deeper than the recursion limit
        deep = [deep]
    with pytest.raises(JSONError, match="nested deeper than 32 levels"):
        check_tree(deep)
    with pytest.raises(JSONError, match=r"scene: objects\[1\].size\[0\]: inf is not a finite number"):
        check_tree({"objects": [{}, {"size": [math.inf]}]}, what="scene")
    with pytest.raises(JSONError, match="near: an integer of more than 100 digits"):
        check_tree({"near": 10**400})
    with pytest.raises(JSONError, match="nan is not a finite number"):
        check_tree([math.nan])
    check_tree({"a": [1, 2.5, "x", None, True, {"b": 10**99}]})


def test_toml_depth_ignores_strings_and_comments():
    check_toml_depth('a = "' + "[" * 100 + '"  # ' + "[" * 100 + "\nb = '''\n" + "{" * 100 + "\n'''\nc = [[1]]\n")
    with pytest.raises(JSONError, match=r"nested deeper than 32 levels \(line 2\)"):
        check_toml_depth("x = 1\na = " + "[" * 40 + "]" * 40)
    with pytest.raises(JSONError, match="nested deeper"):
        check_toml_depth("a = " + "{b = " * 5000 + "1" + "}" * 5000)


def test_the_limits_table_documents_the_defaults():
    doc = bounded_json.__doc__
    assert f"nesting depth      {MAX_DEPTH}" in doc and f"{MAX_NUMBER_CHARS} chars" in doc
