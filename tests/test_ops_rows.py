"""Every operator and built-in is one row (`swarmdsl/ops/`) holding all its evaluators:
constant folding, the numpy closures, the numba scalar tree and its type rule. Here
every row's evaluators are cross-checked on edge values (negatives, zeros of both
signs, NaN, infinities, huge, tiny): numba's result is numpy's to the bit (or both
NaN); the folder gives numpy's bits too, or refuses where numpy's value is not finite
(constants must be finite, docs/limits.md)."""

from __future__ import annotations

import itertools
import math
import struct
from types import SimpleNamespace

import numpy as np
import pytest

from swarmdsl.compiler import ast
from swarmdsl.compiler.consteval import const_value
from swarmdsl.compiler.errors import Span
from swarmdsl.ops.functions import FUNCTIONS, PRIMITIVES, Builtin
from swarmdsl.ops.operators import ARITHMETIC, COMPARISONS, NEGATE
from swarmdsl.ops.types import BOOL, NUM, VEC

EDGES = [-math.inf, -1e308, -7.5, -7.0, -3.0, -2.5, -1.0, -0.5, -1e-300, -5e-324, -0.0,
         0.0, 5e-324, 1e-300, 0.5, 1.0, 2.5, 3.0, 7.5, math.pi, 1e308, math.inf, math.nan]
# vector arguments take their components from fewer values (4 components a pair)
VEC_EDGES = [-math.inf, -7.5, -1.0, -0.0, 0.0, 5e-324, 2.5, 1e308, math.nan]
_SPAN = Span("ops.swarm", 1, 1, 1, 2)
_PURE = [b for b in FUNCTIONS.values() if not b.random]


def _bits(v) -> bytes:
    return struct.pack("<d", float(v))


def _same(a, b) -> bool:
    """Bit for bit, or both NaN (a NaN's payload is no one's business)."""
    return (a != a and b != b) or _bits(a) == _bits(b)


def _grid(params) -> list[tuple]:
    """Every combination of edge values for arguments of types `params` (components
    of vectors flattened): rows of floats."""
    per = [EDGES if t == NUM else VEC_EDGES for t in params for _ in range(2 if t == VEC
                                                                            else 1)]
    return list(itertools.product(*per))


def _arrays(params, grid) -> list[np.ndarray]:
    """The numpy closures' arguments: (M,) per number, (M, 2) per vector."""
    cols, c, table = [], 0, np.array(grid, dtype=float).reshape(len(grid), -1)
    for t in params:
        w = 2 if t == VEC else 1
        cols.append(table[:, c] if w == 1 else table[:, c:c + 2].copy())
        c += w
    return cols


def _leaves(params) -> list[tuple]:
    """The scalar trees of the arguments: columns of the neighbour table `O`."""
    out, c = [], 0
    for t in params:
        out.append((("o", c), ("o", c + 1)) if t == VEC else (("o", c),))
        c += 2 if t == VEC else 1
    return out


def _numba(trees, grid) -> np.ndarray:
    """`trees` compiled as the kernels compile them, evaluated on each row of `grid`."""
    from swarmdsl.runtime.compiled.jit import njit
    from swarmdsl.runtime.compiled.kernels import node

    fx = node(trees[0])
    fy = node(trees[-1])

    @njit(error_model="numpy")
    def run(O, out):
        S = np.zeros((1, 1))
        for j in range(O.shape[0]):
            out[j, 0] = fx(S, O, 0, j, 0.0, 0.0, 0.0)
            out[j, 1] = fy(S, O, 0, j, 0.0, 0.0, 0.0)

    O = np.array(grid, dtype=float).reshape(len(grid), -1)
    out = np.empty((len(grid), 2))
    run(O, out)
    return out[:, :len(trees)]


def _numpy(row: Builtin, grid) -> np.ndarray:
    with np.errstate(all="ignore"):
        got = row.numpy(SimpleNamespace(n=len(grid)), *_arrays(row.params, grid))
    return np.asarray(got, dtype=float).reshape(len(grid), -1)


def _disagreements(a: np.ndarray, b: np.ndarray, grid) -> list:
    return [(args, x, y) for args, xs, ys in zip(grid, a, b, strict=True)
            for x, y in zip(xs, ys, strict=True) if not _same(x, y)][:5]


def _fold(expr: ast.Expr, args) -> float | None:
    """The folder's value of `expr` over names a0, a1, ... bound to `args`; None when it
    refuses (an error a user would see)."""
    try:
        return const_value(expr, {f"a{i}": v for i, v in enumerate(args)})
    except (ArithmeticError, ValueError):
        return None


def _names(n: int) -> tuple:
    return tuple(ast.Name(_SPAN, f"a{i}") for i in range(n))


def _fold_disagreements(expr, grid, reference: np.ndarray) -> list:
    """Where the folder's value is not numpy's: it must give the same bits, or refuse
    a value numpy does not give as a finite number."""
    bad = []
    for args, want in zip(grid, reference[:, 0], strict=True):
        got = _fold(expr, args)
        if got is None and not math.isfinite(want):
            continue
        if got is None or not _same(float(got), want):
            bad.append((args, got, want))
    return bad[:5]


def _every_evaluation() -> list:
    """(name, argument types, scalar trees, numpy's function of the argument arrays) for
    every built-in and operator the kernels compute."""
    out = []
    for b in _PURE:
        out.append((b.name, b.params, b.trees(*_leaves(b.params)),
                    lambda n, *args, b=b: b.numpy(SimpleNamespace(n=n), *args)))
    for op in (*ARITHMETIC.values(), *COMPARISONS.values()):
        out.append((op.symbol, (NUM, NUM), ((op.node, ("o", 0), ("o", 1)),),
                    lambda n, a, b, op=op: op.numpy(a, b)))
    out.append(("unary -", (NUM,), ((NEGATE.node, ("o", 0)),),
                lambda n, a: NEGATE.numpy(a)))
    return out


@pytest.mark.parametrize(("name", "params", "trees", "numpy"), _every_evaluation(),
                         ids=[e[0] for e in _every_evaluation()])
def test_the_numba_scalar_tree_gives_numpys_bits(name, params, trees, numpy):
    pytest.importorskip("numba")
    grid = _grid(params)
    with np.errstate(all="ignore"):
        ref = np.asarray(numpy(len(grid), *_arrays(params, grid)), dtype=float)
    assert _disagreements(_numba(trees, grid), ref.reshape(len(grid), -1), grid) == []


def test_every_builtin_has_a_compiled_form_but_the_draws():
    assert [b.name for b in FUNCTIONS.values() if not b.compiled] == [
        b.name for b in FUNCTIONS.values() if b.random]


@pytest.mark.parametrize("row", [b for b in _PURE if b.foldable], ids=lambda b: b.name)
def test_a_builtin_folds_to_numpys_bits_or_refuses_what_numpy_cannot_give(row):
    grid = _grid(row.params)
    call = ast.Call(_SPAN, row.name, _SPAN, _names(len(row.params)), None, None)
    assert _fold_disagreements(call, grid, _numpy(row, grid)) == []


@pytest.mark.parametrize("op", [*ARITHMETIC.values(), *COMPARISONS.values()],
                         ids=lambda op: op.node)
def test_an_operator_folds_to_numpys_bits_or_refuses_what_numpy_cannot_give(op):
    grid = _grid((NUM, NUM))
    a, b = _arrays((NUM, NUM), grid)
    with np.errstate(all="ignore"):
        ref = np.asarray(op.numpy(a, b), dtype=float).reshape(-1, 1)
    l, r = _names(2)
    expr = (ast.BinOp(_SPAN, op.symbol, l, r) if op.symbol in ARITHMETIC
            else ast.Compare(_SPAN, op.symbol, l, r))
    assert _fold_disagreements(expr, grid, ref) == []


def test_negation_folds_to_numpys_bits():
    grid = _grid((NUM,))
    with np.errstate(all="ignore"):
        ref = NEGATE.numpy(_arrays((NUM,), grid)[0]).reshape(-1, 1)
    assert _fold_disagreements(ast.Neg(_SPAN, _names(1)[0]), grid, ref) == []


@pytest.mark.parametrize("row", _PURE, ids=lambda b: b.name)
def test_a_builtins_evaluators_give_the_type_its_rule_names(row):
    """numpy's array and the scalar trees have the shape of the row's result type;
    a row folds exactly when numbers go in and a number comes out."""
    grid = _grid(row.params)[:7]
    with np.errstate(all="ignore"):
        got = np.asarray(row.numpy(SimpleNamespace(n=len(grid)), *_arrays(row.params, grid)))
    assert got.shape == ((len(grid), 2) if row.result == VEC else (len(grid),))
    assert got.dtype == (np.bool_ if row.result == BOOL else np.float64)
    assert len(row.trees(*_leaves(row.params))) == (2 if row.result == VEC else 1)
    assert row.foldable == (row.result == NUM and set(row.params) <= {NUM})


@pytest.mark.parametrize("op", ARITHMETIC.values(), ids=lambda op: op.node)
def test_an_operators_type_rule_is_what_numpy_computes(op):
    """Each operand pair the rule accepts gives an array of the type it names (a number
    beside a vector broadcasts over its components, as the closures apply it)."""
    shapes = {NUM: (3, 1), VEC: (3, 2)}
    for (a, b), result in op.types.items():
        with np.errstate(all="ignore"):
            got = op.numpy(np.full(shapes[a], 2.0), np.full(shapes[b], 3.0))
        assert got.shape[-1] == (2 if result == VEC else 1), (a, b)


def test_no_row_takes_a_name_the_scalar_trees_already_use():
    nodes = [op.node for op in (*ARITHMETIC.values(), *COMPARISONS.values(), NEGATE)]
    structure = {"s", "sb", "o", "ob", "d", "dx", "dy", "zero", "true", "if", "and", "or",
                 "not"}
    names = [*nodes, *FUNCTIONS, *PRIMITIVES]
    assert len(names) == len(set(names)) and not set(names) & structure


@pytest.mark.parametrize(("text", "value"), [("-7 % 3", 2), ("-7.5 % 2", 0.5),
                                             ("7 % -3", -2), ("7.5 % -2", -0.5)])
def test_modulo_is_floored_when_folded_as_when_run(text, value):
    """`%` takes the divisor's sign, as numpy and Python have it, in a param as in an
    agent's variable on both backends (the folder used C's fmod: -7 % 3 was -1)."""
    from swarmdsl.compiler import compile_source
    from swarmdsl.runtime.simulation import Simulation

    left, right = text.split(" % ")
    src = f"""param p = {text}
agent a {{
  count 3
  var u = index - index + {left}
  var v = 0
  status s {{ v = u % ({right}) + 0 * u + p - p }}
}}
"""
    prog = compile_source(src, "mod.swarm")
    assert prog.params["p"] == value
    backends = ["numpy"] + (["numba"] if _has_numba() else [])
    for backend in backends:
        sim = Simulation(prog, 0, backend=backend)
        sim.run(1)
        assert np.array_equal(sim.agents.cols["v"], [value] * 3), backend


def _has_numba() -> bool:
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


ADDED = """
agent a {
  count 40
  sense 30
  velocity (index % 3, 1)
  var s = 0
  status go { s = sum(neighbors() where twice(other.vel.x) > 1 : twice(dist) + 1) }
}
"""


@pytest.mark.parametrize("scalar", [None, lambda x: x * 2.0], ids=["numpy only", "scalar"])
def test_a_builtin_added_as_one_row_runs_inside_an_aggregate_on_both_backends(
        monkeypatch, scalar, other_backend):
    """One row is the whole edit: without a scalar form the aggregate keeps the reference
    closure on the numba backend (it raised KeyError when the kernels' tables missed
    the name), with one it runs compiled; both give numpy's values (summed in another
    order: to 1e-12)."""
    pytest.importorskip("numba")
    from conftest import run_both

    row = Builtin("twice", (NUM,), NUM, lambda f, x: x * 2.0, "x doubled", scalar=scalar)
    monkeypatch.setitem(FUNCTIONS, "twice", row)
    prog, (ref, fast) = run_both(ADDED, steps=2, other=other_backend)
    got = [sim.agents.cols["s"][np.argsort(sim.agents.cols["id"])] for sim in (ref, fast)]
    assert np.allclose(got[0], got[1], rtol=1e-12, atol=0) and got[0].max() > 0
    lines = "\n".join(fast.backend.summary(prog))
    assert ("sum: compiled" in lines) == (scalar is not None), lines


def test_hypot_is_the_length_of_x_y_without_overflow_folded_and_run():
    """`hypot(3, 4)` is 5 as a param; per agent, `hypot(1e200, y)` stays finite where
    `sqrt(x ^ 2 + y ^ 2)` is infinite, on both backends, with numpy's bits."""
    from swarmdsl.compiler import compile_source
    from swarmdsl.runtime.simulation import Simulation

    prog = compile_source("""param h = hypot(3, 4)
agent a {
  count 3
  var big = 1e200 * (index + 1)
  var r = 0
  status s { r = hypot(big, -big) * 1 + 0 * h }
}
""", "hypot.swarm")
    assert prog.params["h"] == 5.0
    want = np.hypot(1e200 * np.arange(1, 4), -1e200 * np.arange(1, 4))
    assert np.isfinite(want).all()
    for backend in ["numpy"] + (["numba"] if _has_numba() else []):
        sim = Simulation(prog, 0, backend=backend)
        sim.run(1)
        got = sim.agents.cols["r"][np.argsort(sim.agents.cols["id"])]
        assert np.array_equal(got, want), backend
