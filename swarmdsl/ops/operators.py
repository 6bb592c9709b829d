"""The operators: one row each, holding its type rule and its three evaluators.

- `fold`: the value on constants (params, sizes, counts), on Python numbers, so whole
  numbers stay exact; `consteval.py` adds the refusals (division by zero, overflow).
- `numpy`: the ufunc the reference closures apply to whole arrays.
- `scalar`: one float at a time, as the numba kernels compile it (`node` names it in
  their scalar trees).
- `family`: the precedence level whose long chains the parser flattens (`sum`,
  `product`; `compiler/nesting.py`), None for `^` (right-associative, never chained).
- `kilobot`: the exported C of numbers, a template of the operands' C (`{0}`, `{1}`),
  and `kilobot_vec` the C of vectors by operand types (the `kb_v*` helpers of the
  exported preamble); operand types missing there are a located refusal.
  `kilobot_helper`: the C function a form needs, added to the exported preamble.

All three agree bit for bit (`tests/test_ops_rows.py`). `%` is the floored modulo of
Python and numpy: the result takes the divisor's sign (`-7 % 3 == 2`, `-7.5 % 2 ==
0.5`, `7 % -3 == -2`), `x % 0`, `inf % y` and NaN give NaN (docs/language.md). numba's
`%` on floats is that modulo with numpy's bits; its `np.mod` is not (it gives +0.0 where
numpy gives -0.0).
"""

from __future__ import annotations

import operator
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from swarmdsl.ops import portable
from swarmdsl.ops.targets import Refused
from swarmdsl.ops.types import BOOL, KIND, NUM, STATUS, VEC


@dataclass(frozen=True)
class Operator:
    symbol: str
    node: str                 # its name in the kernels' scalar trees
    numpy: Callable           # ufunc over arrays
    fold: Callable            # on Python numbers
    scalar: Callable          # on one float, compiled by numba
    types: dict               # operand types (a tuple) -> result type
    kilobot: str | Refused | None = None    # C template of numbers' operands {0}, {1}
    kilobot_vec: dict = field(default_factory=dict)   # operand types -> C template
    batch: bool | Refused = True            # elementwise: each replica's rows alone
    family: str | None = None               # its precedence level's chain (`nesting.py`)
    kilobot_helper: str = ""                # C its form needs in the exported preamble


_SUM = {(NUM, NUM): NUM, (VEC, VEC): VEC}


def _fold_pow(a, b):
    """`a ^ b` on constants: whole numbers to a whole power stay exact (counts, sizes),
    the rest is the kernels' own `pow` (`portable.py`), so folding and running agree."""
    if isinstance(a, int) and isinstance(b, int) and b >= 0:
        return a ** b
    return portable.pow(float(a), float(b))

ARITHMETIC: dict[str, Operator] = {op.symbol: op for op in [
    Operator("+", "add", np.add, operator.add, lambda a, b: a + b, _SUM,
             "({0} + {1})", {(VEC, VEC): "kb_vadd({0}, {1})"}, family="sum"),
    Operator("-", "sub", np.subtract, operator.sub, lambda a, b: a - b, _SUM,
             "({0} - {1})", {(VEC, VEC): "kb_vsub({0}, {1})"}, family="sum"),
    Operator("*", "mul", np.multiply, operator.mul, lambda a, b: a * b,
             {(NUM, NUM): NUM, (NUM, VEC): VEC, (VEC, NUM): VEC}, "({0} * {1})",
             {(VEC, NUM): "kb_vmul({0}, {1})", (NUM, VEC): "kb_vmul({1}, {0})"},
             family="product"),
    Operator("/", "div", np.true_divide, operator.truediv, lambda a, b: a / b,
             {(NUM, NUM): NUM, (VEC, NUM): VEC}, "({0} / {1})",
             {(VEC, NUM): "kb_vdiv({0}, {1})"}, family="product"),
    Operator("%", "mod", np.mod, operator.mod, lambda a, b: a % b, {(NUM, NUM): NUM},
             "kb_mod({0}, {1})", family="product"),
    Operator("^", "pow", portable.pow_array, _fold_pow, portable.pow, {(NUM, NUM): NUM},
             "kb_pow({0}, {1})"),
]}

_ORDERED = {(NUM, NUM): BOOL}
_EQUALITY = {(t, t): BOOL for t in (NUM, BOOL, STATUS, KIND, VEC)}

COMPARISONS: dict[str, Operator] = {op.symbol: op for op in [
    Operator("<", "lt", np.less, operator.lt, lambda a, b: a < b, _ORDERED, "({0} < {1})"),
    Operator("<=", "le", np.less_equal, operator.le, lambda a, b: a <= b, _ORDERED,
             "({0} <= {1})"),
    Operator(">", "gt", np.greater, operator.gt, lambda a, b: a > b, _ORDERED, "({0} > {1})"),
    Operator(">=", "ge", np.greater_equal, operator.ge, lambda a, b: a >= b, _ORDERED,
             "({0} >= {1})"),
    Operator("==", "eq", np.equal, operator.eq, lambda a, b: a == b, _EQUALITY,
             "({0} == {1})"),
    Operator("!=", "ne", np.not_equal, operator.ne, lambda a, b: a != b, _EQUALITY,
             "({0} != {1})"),
]}

NEGATE = Operator("-", "neg", np.negative, operator.neg, lambda a: -a,
                  {(NUM,): NUM, (VEC,): VEC}, "(-{0})", {(VEC,): "kb_vneg({0})"})
