"""What the arguments of a random draw must be: `chance(p)`, `normal(mean, sd)`,
`uniform(lo, hi)`.

Out of range they do not fail by themselves: `chance(2)` is simply always true,
`chance(NaN)` always false, `normal(0, -1)` draws as `normal(0, 1)` mirrored and
`uniform(5, 1)` draws from (1, 5]. So a constant argument is refused by the checker,
and a value known only per agent is checked before the draw, on the agents that make
it, and refused as a located error naming the draw, the value and the agent. The check
reads the arguments only: the draws made, and their order, are those of a program
without it (both backends draw through these closures).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from swarmdsl.compiler import ast, checker, nan_guard
from swarmdsl.compiler.consteval import NotConstant, const_value, walk_with_params
from swarmdsl.errors import SwarmRuntimeError

NAN_HINT = "guard the division, square root or log that produced it"
INF_HINT = "guard the division or log that produced it"


@dataclass(frozen=True)
class Rule:
    """One condition on a draw's arguments: `bad(*args)` is true where it is broken;
    `arg` the argument it is about (the message quotes it), None for all of them."""

    needs: str
    bad: object
    hint: str
    arg: int | None


@dataclass(frozen=True)
class Draw:
    signature: str
    params: tuple[str, ...]
    rules: tuple[Rule, ...]


DRAWS = {
    "chance": Draw("chance(p)", ("p",), (
        Rule("0 <= p <= 1", lambda p: (p < 0) | (p > 1),
             "a probability is from 0 to 1: `chance(clamp(p, 0, 1))` keeps it there", 0),)),
    "normal": Draw("normal(mean, sd)", ("mean", "sd"), (
        Rule("sd >= 0", lambda mean, sd: sd < 0,
             "a standard deviation is 0 or more: `normal(mean, abs(sd))`", 1),
        Rule("a finite mean", lambda mean, sd: np.isinf(mean), INF_HINT, 0),
        Rule("a finite sd", lambda mean, sd: np.isinf(sd), INF_HINT, 1))),
    "uniform": Draw("uniform(lo, hi)", ("lo", "hi"), (
        Rule("lo <= hi", lambda lo, hi: lo > hi,
             "put the smaller bound first: `uniform(min(a, b), max(a, b))`", None),
        Rule("finite bounds", lambda lo, hi: np.isinf(lo) | np.isinf(hi), INF_HINT,
             None))),
}


def number(x) -> str:
    """A value as a message says it: 2, -0.5, NaN, inf."""
    x = float(x)
    return "NaN" if math.isnan(x) else f"{x:g}"


def fault(name: str, values) -> tuple[str, str, int | None] | None:
    """(what is wrong, hint, index of the argument at fault or None for several) for one
    set of argument values of draw `name`, or None when they are fine."""
    draw = DRAWS[name]
    for i, v in enumerate(values):
        if math.isnan(v):
            return f"the {draw.params[i]} of `{draw.signature}` is NaN", NAN_HINT, i
    for rule in draw.rules:
        if bool(rule.bad(*values)):
            at = rule.arg
            quoted = range(len(values)) if at is None else (at,)
            got = " and ".join(f"{draw.params[i]} = {number(values[i])}" for i in quoted)
            return f"`{draw.signature}` needs {rule.needs}, got {got}", rule.hint, at
    return None


def _fine(name: str, args) -> bool:
    """Whether every row's arguments are fine, in a few whole-array reductions (min and
    max propagate NaN): the common case costs no per-row mask."""
    if any(np.size(a) == 0 for a in args):
        return True   # no agent (or pair) draws
    with np.errstate(invalid="ignore"):
        if name == "chance":
            p = args[0]
            return bool(np.min(p) >= 0) and bool(np.max(p) <= 1)
        if name == "normal":
            mean, sd = args
            return bool(np.isfinite(np.min(mean)) and np.isfinite(np.max(mean))
                        and np.min(sd) >= 0 and np.isfinite(np.max(sd)))
        lo, hi = args
        return bool(np.isfinite(np.min(lo)) and np.isfinite(np.max(lo))
                    and np.isfinite(np.min(hi)) and np.isfinite(np.max(hi))
                    and np.min(hi - lo) >= 0)


def _first_bad_row(name: str, args, n: int, active) -> int | None:
    """The first running row whose arguments break a rule, or None."""
    arrays = [np.broadcast_to(np.asarray(a, dtype=np.float64), (n,)) for a in args]
    bad = np.zeros(n, dtype=bool)
    with np.errstate(invalid="ignore"):
        for a in arrays:
            bad |= np.isnan(a)
        for rule in DRAWS[name].rules:
            bad |= np.asarray(rule.bad(*arrays), dtype=bool)
    bad &= active
    rows = np.flatnonzero(bad)
    return int(rows[0]) if rows.size else None


def _active(f, n: int):
    """The frame's rows whose draws count: running, and on the side of every `if`,
    `and` and `or` they take; for a pair frame, also its agent's."""
    out = np.ones(n, dtype=bool)
    owner, seg = getattr(f, "owner", None), getattr(f, "seg", None)
    if owner is not None and seg is not None:
        for rows in (getattr(owner, "active", None), getattr(owner, "draw_live", None)):
            if rows is not None and np.shape(rows) == (int(owner.n),):
                out &= np.take(rows, seg)
    else:
        rows = getattr(f, "active", None)
        if rows is not None and np.shape(rows) == (n,):
            out &= rows
    rows = getattr(f, "draw_live", None)
    if rows is not None and np.shape(rows) == (n,):
        out &= rows
    return out


def _describe(f, row: int) -> str:
    owner, seg = getattr(f, "owner", None), getattr(f, "seg", None)
    if owner is not None and seg is not None:   # a pair: the agent whose neighbour it is
        return nan_guard.describe(owner, int(seg[row]))
    return nan_guard.describe(f, row)


def checked_at_run(e: ast.Expr, params) -> bool:
    """Whether `e` is a draw whose arguments are checked per agent: some are not
    constant (constant ones the checker has checked)."""
    if not (isinstance(e, ast.Call) and e.name in DRAWS and e.each is None
            and e.default is None):
        return False
    try:
        for a in e.args:
            const_value(a, params)
    except (NotConstant, ArithmeticError, ValueError, TypeError):
        return True   # a fault computing it is NaN or inf at run time: checked there
    return False


def reaches(params, *exprs) -> bool:
    """Whether a draw checked per agent is in one of `exprs`."""
    return any(checked_at_run(n, params) for e in exprs for n in ast.walk(e))


def guarded(e: ast.Expr, params) -> bool:
    """Whether `e` is an `if`, `and` or `or` that selects the rows where a draw checked
    per agent counts."""
    if isinstance(e, ast.Cond):
        return reaches(params, e.then, e.orelse)
    if isinstance(e, ast.AndOp | ast.OrOp):
        return reaches(params, e.right)
    if isinstance(e, ast.Chain) and e.rest[0][0] in ("and", "or"):
        return reaches(params, *(t for _op, t in e.rest))
    return False


def live(f, rows, fn):
    """`fn(f)` with the draws under it checked on `rows` only.

    Both branches of an `if`, and both sides of `and`/`or`, are computed for every
    agent; a draw on the side an agent does not take is thrown away, so its arguments
    there are no fault (`if sd > 0 then normal(0, sd) else 0`). Evaluating the same
    closures in the same order keeps the draws what they were.
    """
    rows = np.broadcast_to(np.asarray(rows, dtype=bool), (int(f.n),))
    prev = getattr(f, "draw_live", None)
    f.draw_live = rows if prev is None else prev & rows
    try:
        return fn(f)
    finally:
        f.draw_live = prev


def checked(name: str, call: ast.Call, kernel, params):
    """Kernel `kernel` of draw `name`, refusing arguments that break its rules."""
    if not checked_at_run(call, params):
        return kernel
    spans = [a.span for a in call.args]

    def draw(f, *args):
        if not _fine(name, args):
            n = max(int(getattr(f, "n", 1)), *(np.size(a) for a in args))
            row = _first_bad_row(name, args, n, _active(f, n))
            if row is not None:
                values = [float(np.broadcast_to(a, (n,))[row]) for a in args]
                what, hint, at = fault(name, values)
                span = call.span if at is None else spans[at]
                raise SwarmRuntimeError(f"{what} for {_describe(f, row)}", span, hint)
        return kernel(f, *args)
    return draw


def check_constant_draws(chk, root=None) -> None:
    """PROGRAM_CHECK_HOOKS entry: a draw whose arguments are all constant is checked
    before the run, where it is written. Also called on each use of a named tree, its
    parameters replaced by the call's arguments (`t(0 - 1)` makes `normal(0, sd)` a
    constant draw the run does not check)."""
    for node, params in walk_with_params(chk.tree if root is None else root, chk.params):
        if not (isinstance(node, ast.Call) and node.name in DRAWS
                and len(node.args) == len(DRAWS[node.name].params)
                and node.each is None and node.default is None):
            continue
        try:
            values = [const_value(a, params) for a in node.args]
        except (NotConstant, ArithmeticError, ValueError, TypeError):
            continue
        if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in values):
            continue
        problem = fault(node.name, [float(v) for v in values])
        if problem is not None:
            what, hint, at = problem
            chk.fail(what, node.span if at is None else node.args[at].span, hint)


checker.PROGRAM_CHECK_HOOKS.append(check_constant_draws)
