"""Guard gaps: values of a variable for which no `when` leaves a status, found by
interval reasoning.

When every `when` leaving a status compares the same variable with constants (numbers
or params), the values that leave form a union of intervals. A hole in that union with
leaving values on both sides (`tries < max` and `tries > max` leave out `tries == max`)
traps an agent for good when nothing in the status changes the variable: it can never
leave. One-sided rests (`when t > 5 -> go`: wait until t passes 5) are the usual way to
wait, and are not reported. A variable that only ever holds whole numbers (a whole
initial value, changed only by whole steps) is trapped only by holes that contain a
whole number, and the warning names them.

Sound toward silence: a status with any other kind of `when`, or that changes the
variable itself, gets no warning.
"""

from __future__ import annotations

import math

from swarmdsl.compiler import ast
from swarmdsl.compiler.consteval import NotConstant, const_value

_FLIP = {"<": ">", "<=": ">=", ">": "<", ">=": "<=", "==": "==", "!=": "!="}
_INF = math.inf


def _constant(e, params):
    try:
        v = const_value(e, params)
    except (NotConstant, ArithmeticError, ValueError, TypeError, OverflowError):
        return None
    if isinstance(v, bool) or not isinstance(v, int | float) or math.isnan(v):
        return None
    return float(v)


def comparison(cond, params) -> tuple[str, list, ast.Expr] | None:
    """(variable, intervals where `cond` holds, the constant's expression) for
    `VAR op CONST` or `CONST op VAR`; intervals are (lo, lo_in, hi, hi_in)."""
    if not isinstance(cond, ast.Compare):
        return None
    op = cond.op
    if isinstance(cond.left, ast.Name) and _constant(cond.right, params) is not None:
        var, const = cond.left.id, cond.right
    elif isinstance(cond.right, ast.Name) and _constant(cond.left, params) is not None:
        var, const, op = cond.right.id, cond.left, _FLIP[op]
    else:
        return None
    c = _constant(const, params)
    pieces = {"<": [(-_INF, False, c, False)], "<=": [(-_INF, False, c, True)],
              ">": [(c, False, _INF, False)], ">=": [(c, True, _INF, False)],
              "==": [(c, True, c, True)],
              "!=": [(-_INF, False, c, False), (c, False, _INF, False)]}.get(op)
    return None if pieces is None else (var, pieces, const)


def holes(intervals: list) -> list[tuple[float, bool, float, bool]]:
    """The gaps of a union of intervals that have covered values on both sides."""
    out = []
    ordered = sorted(intervals, key=lambda iv: (iv[0], not iv[1]))
    reach, reach_in = ordered[0][2], ordered[0][3]
    for lo, lo_in, hi, hi_in in ordered[1:]:
        if lo > reach or (lo == reach and not (lo_in or reach_in)):
            out.append((reach, not reach_in, lo, not lo_in))
        if hi > reach or (hi == reach and hi_in):
            reach, reach_in = hi, hi_in
    return out


def _whole_values(hole) -> list[float]:
    lo, lo_in, hi, hi_in = hole
    first = math.ceil(lo) if lo_in else math.floor(lo) + 1
    last = math.floor(hi) if hi_in else math.ceil(hi) - 1
    return [] if first > last else [float(first), float(last)] if last - first > 1 \
        else [float(v) for v in range(int(first), int(last) + 1)]


def _assigns(node, var: str) -> list:
    """Assignments to `var` in a status body, outside `when` actions (those run only
    for agents that leave)."""
    out = []
    stack = [node]
    while stack:
        n = stack.pop()
        if isinstance(n, ast.WhenStmt):
            continue
        if isinstance(n, ast.AssignStmt) and n.target == var:
            out.append(n)
        stack.extend(c for c in n.children() if isinstance(c, ast.Node))
    return out


def _whole(kind, var: str, params) -> bool:
    """Does `var` only ever hold whole numbers (whole start, whole steps)?"""
    init = kind.vars[var].decl.value
    v = _constant(init, params)
    if v is None or not v.is_integer():
        return False
    for decl in kind.status_decls.values():
        stack = list(decl.body)
        while stack:
            n = stack.pop()
            stack.extend(c for c in n.children() if isinstance(c, ast.Node))
            if not (isinstance(n, ast.AssignStmt) and n.target == var):
                continue
            value = n.value
            if n.op == "=" and isinstance(value, ast.BinOp) and value.op in ("+", "-") \
                    and isinstance(value.left, ast.Name) and value.left.id == var:
                value = value.right
            elif n.op not in ("=", "+=", "-="):
                return False
            step = _constant(value, params)
            if step is None or not step.is_integer():
                return False
    return True


def _text(v: float) -> str:
    return str(int(v)) if v.is_integer() else f"{v:g}"


def _describe(var: str, hole, whole: bool, named: str) -> str:
    lo, lo_in, hi, hi_in = hole
    if whole:
        values = _whole_values(hole)
        if len(values) == 1 or values[0] == values[-1]:
            return f"`{var}` == {_text(values[0])}{named}"
        return f"`{var}` from {_text(values[0])} to {_text(values[-1])}"
    if lo == hi:
        return f"`{var}` == {_text(lo)}{named}"
    return (f"{_text(lo)} {'<=' if lo_in else '<'} `{var}` {'<=' if hi_in else '<'} "
            f"{_text(hi)}")


def check_gaps(chk) -> None:
    """Warn about guard gaps in every status of every kind."""
    for k in chk.kinds:
        for s, decl in k.status_decls.items():
            if getattr(decl, "final", False):
                continue
            found = _status_gap(chk, k, s, decl)
            if found is not None:
                var, text = found
                chk.warn(f"guard gap in `{k.name}.{s}`: when {text}, no `when` leaves it "
                         f"and nothing in `{s}` changes `{var}`, so agents stay for good",
                         decl.name_span, "cover the missing value in one of the `when`s "
                         "(`<=` or `>=`), or add a `when` for it")


def _status_gap(chk, k, s, decl):
    whens = [st for st in decl.body if isinstance(st, ast.WhenStmt) and st.target != s]
    if not whens:
        return None
    var, intervals, consts = None, [], {}
    for w in whens:
        got = comparison(w.cond, chk.params)
        if got is None or (var is not None and got[0] != var):
            return None
        var = got[0]
        intervals += got[1]
        c = _constant(got[2], chk.params)
        if isinstance(got[2], ast.Name):
            consts[c] = got[2].id
    if var not in k.vars or _assigns(decl, var):
        return None
    whole = _whole(k, var, chk.params)
    for hole in holes(intervals):
        if whole and not _whole_values(hole):
            continue
        lo = hole[0]
        named = f" (`{consts[lo]}`)" if hole[0] == hole[2] and lo in consts else ""
        return var, _describe(var, hole, whole, named)
    return None
