"""Comparisons that cannot go both ways: a warning where one side is NaN, or `inf` (or
`-inf`) against a value that is never infinite, so the comparison always gives the same
answer and the branch it guards is dead or always taken.

Two cases, both silent at run time:
- a constant side that is NaN (`inf - inf`, `0 * inf`): NaN is unequal to everything,
  itself included, so `==`, `<`, `<=`, `>`, `>=` are never true and `!=` always is;
- `inf` against a reading whose value is never infinite. `age(M, point)` of a cell never
  seen was `inf` and is now 10^15 (a number a `var` can hold), so a program written for
  the old meaning, `age(spots, p) == inf`, silently takes the other branch; `known(M,
  point)` is the test it meant. Extensions register such readings in `FINITE_READINGS`.

Only what is sure is said: a side that is not a known reading or constant could be
infinite (a variable can overflow), and no warning is given for it.
"""

from __future__ import annotations

import math

from swarmdsl.compiler import ast
from swarmdsl.compiler.consteval import NotConstant, const_value

# call name -> fn(checker, call) -> (what the reading is, hint) when `call` is that
# reading (never infinite), or None. Filled by the modules that add readings.
FINITE_READINGS: dict = {}

# For a finite x: the value of `x OP inf` (with -inf: of `x OP -inf`).
_AGAINST_INF = {"==": False, "!=": True, "<": True, "<=": True, ">": False, ">=": False}
_AGAINST_MINUS_INF = {"==": False, "!=": True, "<": False, "<=": False, ">": True,
                      ">=": True}
_MIRRORED = {"==": "==", "!=": "!=", "<": ">", "<=": ">=", ">": "<", ">=": "<="}


def check_comparison(checker, e: ast.Compare) -> None:
    """Warn at `e` (two numbers compared) when its answer is known whatever the run."""
    left, right = _constant(checker, e.left), _constant(checker, e.right)
    if left is not None and right is not None:
        return      # wholly constant: what it says is plain to see
    for value, side in ((left, "left"), (right, "right")):
        if value is not None and math.isnan(value):
            truth = e.op == "!="
            checker.warn(f"this comparison is always {_word(truth)}: its {side} side is "
                         "NaN (not a number), which is unequal to every number, itself "
                         "included", e.span,
                         "a value is NaN exactly when `x != x`")
            return
    for value, other, op in ((right, e.left, e.op), (left, e.right, _MIRRORED[e.op])):
        if value is None or not math.isinf(value):
            continue
        found = _finite_reading(checker, other)
        if found is None:
            continue
        what, hint = found
        truth = (_AGAINST_INF if value > 0 else _AGAINST_MINUS_INF)[op]
        checker.warn(f"this comparison is always {_word(truth)}: {what}, never "
                     f"`{'' if value > 0 else '-'}inf`", e.span, hint)
        return


def _word(truth: bool) -> str:
    return "true" if truth else "false"


def _constant(checker, e: ast.Expr) -> float | None:
    """The number `e` folds to, or None (not constant, not a number, or refused)."""
    if not isinstance(e, ast.Num | ast.Name | ast.BinOp | ast.Neg | ast.Chain | ast.Call):
        return None
    try:
        value = const_value(e, checker.params)
    except (NotConstant, ArithmeticError, ValueError, TypeError, RecursionError):
        return None
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value)


def _finite_reading(checker, e: ast.Expr) -> tuple[str, str | None] | None:
    if isinstance(e, ast.Call) and e.name in FINITE_READINGS:
        return FINITE_READINGS[e.name](checker, e)
    return None


def _count(checker, call: ast.Call):
    from swarmdsl.compiler.builtins import AGGREGATES

    if "count" not in AGGREGATES or call.each is not None:
        return None
    return "a count is a whole number", None


FINITE_READINGS["count"] = _count
