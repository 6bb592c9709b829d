"""The premise of an implication-shaped property expression, read off its syntax.

`invariant safe: not carrying or speed < 2` (or `status != crowded or ...`, or `if
carrying then speed < 2 else true`) holds trivially on every agent whose premise is
false. Who counts how often a premise held (the tester's coverage, `testing/premises.py`,
and the whole-tick kernel's compiled checks, `runtime/compiled/tick_checks.py`, which
must count it alike) reads the premise here, once.

The premise is a top-level `or` whose disjuncts include a negation (`not X`, `A != B`):
the premise is that every such disjunct is false (when every disjunct is one, all but
the last: `not A or not B` reads as A -> not B); or an `if P then Q else true`: the
premise is P.
"""

from __future__ import annotations

from swarmdsl.compiler import ast


def premise_nodes(expr: ast.Expr) -> tuple[list[ast.Expr], bool] | None:
    """(nodes, negate) of an implication-shaped expression's premise, or None: the
    premise held when every node is false (`negate`) or when the one node is true."""
    if isinstance(expr, ast.Cond) and isinstance(expr.orelse, ast.BoolLit) \
            and expr.orelse.value is True:
        return [expr.test], False
    disjuncts = _disjuncts(expr)
    if len(disjuncts) < 2:
        return None
    negative = [d for d in disjuncts if isinstance(d, ast.NotOp)
                or (isinstance(d, ast.Compare) and d.op == "!=")]
    if len(negative) == len(disjuncts):     # `not A or not B`: A -> not B
        negative = negative[:-1]
    if not negative:
        return None
    return negative, True


def reads_previous(nodes) -> bool:
    """Whether any of `nodes` calls `previous` (a premise that does is not counted: a
    second evaluation would share the property's memory of the last tick)."""
    return any(isinstance(n, ast.Call) and n.name == "previous"
               for node in nodes for n in ast.walk(node))


def _disjuncts(expr: ast.Expr) -> list[ast.Expr]:
    if isinstance(expr, ast.OrOp):
        return _disjuncts(expr.left) + _disjuncts(expr.right)
    if isinstance(expr, ast.Chain) and expr.rest and all(op == "or" for op, _ in expr.rest):
        return [expr.first, *(term for _, term in expr.rest)]
    return [expr]
