"""An expression tree's compiled function: built as one Python function from a fixed
vocabulary (nothing of a program's text becomes code), computing what the reference
computes, and keyed on disk by everything it is made of."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from swarmdsl.ops.scalars import scalar
from swarmdsl.runtime.compiled import tree_functions
from swarmdsl.runtime.compiled.disk_cache import fingerprint

pytest.importorskip("numba")


def _plain(tree):
    """The tree's function over the rows' plain Python scalars (no numba)."""
    return tree_functions.build(tree, scalar, lambda op: (lambda x, y: x and y) if op == "and"
                                else (lambda x, y: x or y))


S = np.array([[3.0, -2.0, 0.0], [1.5, 4.0, 1.0]])
O = np.array([[0.5, 7.0, 1.0], [-1.0, 2.0, 0.0]])


def _call(fn, r=1, j=0, d=2.5, dx=1.5, dy=-2.0):
    return fn(S, O, r, j, d, dx, dy)


@pytest.mark.parametrize(("tree", "expected"), [
    (("add", ("s", 0), ("o", 1)), 1.5 + 7.0),
    (("mul", ("d",), ("dx",)), 2.5 * 1.5),
    (("if", ("sb", 2), ("s", 1), ("o", 0)), 4.0),
    (("if", ("ob", 2), ("zero",), ("dy",)), 0.0),
    (("not", ("sb", 2)), False),
    (("and", ("sb", 2), ("ob", 2)), True),
    (("or", ("sb", 2), ("true",)), True),
    (("sqrt", ("add", ("mul", ("dx",), ("dx",)), ("mul", ("dy",), ("dy",)))), 2.5),
    (("min", ("o", 1), ("s", 1)), 4.0),
])
def test_a_tree_computes_what_its_rows_compute(tree, expected):
    assert _call(_plain(tree)) == expected


def test_only_the_branch_taken_is_evaluated():
    # a division by zero in the branch not taken is never computed
    hits = []

    def counting(op):
        fn = scalar(op)
        return lambda *a: hits.append(op) or fn(*a)

    fn = tree_functions.build(("if", ("true",), ("s", 0), ("div", ("s", 0), ("zero",))),
                              counting, None)
    assert _call(fn) == 1.5 and hits == []


def test_the_code_holds_only_its_fixed_names_and_integer_columns():
    fn = _plain(("add", ("hypot", ("s", 1), ("o", 2)), ("abs", ("dx",))))
    code = fn.__code__
    assert code.co_varnames == tree_functions.ARGS
    assert all(name.startswith("f") and name[1:].isdigit() for name in code.co_names)
    assert {c for c in code.co_consts if c is not None} <= {1, 2}


@pytest.mark.parametrize("column", ["__import__('os')", 1.0, True, None])
def test_a_column_that_is_not_an_int_is_refused(column):
    with pytest.raises(TypeError, match="column number"):
        _plain(("s", column))


def test_an_unknown_operator_is_refused():
    with pytest.raises(KeyError):
        _plain(("system", ("s", 0)))


@given(st.integers(0, 40), st.integers(0, 40))
def test_trees_apart_only_in_a_column_get_their_own_keys(a, b):
    one = fingerprint(_plain(("add", ("s", a), ("o", 1))))
    two = fingerprint(_plain(("add", ("s", b), ("o", 1))))
    assert one is not None and (one == two) == (a == b)


def test_the_compiled_function_agrees_with_the_plain_one():
    from swarmdsl.runtime.compiled.jit import njit
    from swarmdsl.runtime.compiled.kernels import node

    tree = ("if", ("sb", 2), ("atan2", ("s", 1), ("o", 0)), ("pow", ("d",), ("dy",)))
    compiled = njit(node(tree).py_func)
    for r, j in ((0, 0), (1, 1), (1, 0)):
        got, want = _call(compiled, r, j), _call(_plain(tree), r, j)
        assert got == want or (math.isnan(got) and math.isnan(want))
