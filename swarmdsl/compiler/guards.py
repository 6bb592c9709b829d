"""What can be known about a `when` condition before the program runs.

`truth(expr, params)` is True or False when the condition is settled by constants and
simple contradictions (`x > 5 and x < 3`, `c and not c`, `status == a and status == b`),
None otherwise. `disjoint(a, b, params)` says two conditions can never hold together.
Every answer is sound: None ("don't know") is the fallback, never a guess.
"""

from __future__ import annotations

import math

from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import AGGREGATES, FUNCTIONS
from swarmdsl.compiler.consteval import NotConstant, const_value
from swarmdsl.compiler.tree_ast import TreeResult

_FLIP = {"<": ">", "<=": ">=", ">": "<", ">=": "<=", "==": "==", "!=": "!="}
_NEGATE = {"<": ">=", "<=": ">", ">": "<=", ">=": "<", "==": "!=", "!=": "=="}
_SYMBOLIC = ("status", "kind", "other.status", "other.kind")


def truth(e: ast.Expr, params: dict) -> bool | None:
    """True/False when the condition's value is known without running, else None."""
    v = _const(e, params)
    if isinstance(v, bool):
        return v
    if isinstance(e, ast.NotOp):
        t = truth(e.operand, params)
        return None if t is None else not t
    if isinstance(e, ast.AndOp):
        a, b = truth(e.left, params), truth(e.right, params)
        if a is False or b is False:
            return False
        if a is True and b is True:
            return True
        return False if _contradictory(_conjuncts(e), params) else None
    if isinstance(e, ast.OrOp):
        a, b = truth(e.left, params), truth(e.right, params)
        if a is True or b is True:
            return True
        if a is False and b is False:
            return False
    return None


def disjoint(a: ast.Expr, b: ast.Expr, params: dict) -> bool:
    """True when `a and b` can never hold."""
    return truth(ast.AndOp(a.span, a, b), params) is False


def _const(e, params):
    try:
        return const_value(e, params)
    except (NotConstant, ArithmeticError, ValueError, TypeError, OverflowError):
        return None


def _conjuncts(e):
    if isinstance(e, ast.AndOp):
        return _conjuncts(e.left) + _conjuncts(e.right)
    return [e]


def _contradictory(atoms, params) -> bool:
    intervals: dict[str, list] = {}
    flags: dict[str, set] = {}
    symbols: dict[str, set] = {}
    for a in atoms:
        negated = False
        while isinstance(a, ast.NotOp):
            a, negated = a.operand, not negated
        if isinstance(a, ast.Compare):
            op = _NEGATE[a.op] if negated else a.op
            if _symbolic_equality(a, op, symbols):
                continue
            bound = _bound(a, op, params)
            if bound is not None:
                key, iv = bound
                cur = intervals.get(key, [-math.inf, True, math.inf, True])
                intervals[key] = _intersect(cur, iv)
            continue
        if isinstance(a, TreeResult):   # this tick's tree result has one value
            if not negated:
                symbols.setdefault("tree result", set()).add(a.state)
            continue
        key = _key(a)
        if key is not None:
            flags.setdefault(key, set()).add(not negated)
    if any(len(v) > 1 for v in flags.values()) or any(len(v) > 1 for v in symbols.values()):
        return True
    return any(_empty(iv) for iv in intervals.values())


def _symbolic_equality(c: ast.Compare, op: str, symbols: dict) -> bool:
    if op != "==":
        return False
    left, right = _key(c.left), _key(c.right)
    for term, other in ((left, c.right), (right, c.left)):
        if term in _SYMBOLIC and isinstance(other, ast.Name):
            symbols.setdefault(term, set()).add(other.id)
            return True
    return False


def _bound(c: ast.Compare, op: str, params):
    lv, rv = _const(c.left, params), _const(c.right, params)
    if _is_number(rv) and lv is None:
        key, value = _key(c.left), float(rv)
    elif _is_number(lv) and rv is None:
        key, value, op = _key(c.right), float(lv), _FLIP[op]
    else:
        return None
    if key is None or op == "!=" or math.isnan(value):
        return None
    inf = math.inf
    iv = {"<": [-inf, True, value, False], "<=": [-inf, True, value, True],
          ">": [value, False, inf, True], ">=": [value, True, inf, True],
          "==": [value, True, value, True]}[op]
    return key, iv


def _is_number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _intersect(a, b):
    lo, lo_in = (a[0], a[1]) if a[0] > b[0] else (b[0], b[1]) if b[0] > a[0] else \
        (a[0], a[1] and b[1])
    hi, hi_in = (a[2], a[3]) if a[2] < b[2] else (b[2], b[3]) if b[2] < a[2] else \
        (a[2], a[3] and b[3])
    return [lo, lo_in, hi, hi_in]


def _empty(iv) -> bool:
    lo, lo_in, hi, hi_in = iv
    return lo > hi or (lo == hi and not (lo_in and hi_in))


def _deterministic(name: str) -> bool:
    """Calls that give the same value twice in one tick (not random, not extensions)."""
    if name in FUNCTIONS:
        return not FUNCTIONS[name].random
    return name in AGGREGATES or name in ("neighbors", "neighbours")


def _key(e) -> str | None:
    """A span-free text for simple terms (names, attributes, calls of them), else None."""
    if isinstance(e, ast.Name):
        return e.id
    if isinstance(e, ast.Num):
        return repr(e.value)
    if isinstance(e, ast.Attr):
        inner = _key(e.obj)
        return None if inner is None else f"{inner}.{e.name}"
    if isinstance(e, ast.Call) and e.each is None and e.default is None:
        if not _deterministic(e.name):
            return None
        args = [_key(a) for a in e.args]
        if any(a is None for a in args):
            return None
        return f"{e.name}({', '.join(args)})"
    if isinstance(e, ast.BinOp | ast.Compare):
        a, b = _key(e.left), _key(e.right)
        return None if a is None or b is None else f"({a} {e.op} {b})"
    if isinstance(e, ast.Neg):
        inner = _key(e.operand)
        return None if inner is None else f"-{inner}"
    return None
