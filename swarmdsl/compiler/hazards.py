"""Divisions that turn into NaN when an agent has no neighbours, found before running.

`count(S)` and `sum(S : ...)` are 0 over an empty neighbour set, and so are `mean`,
`min` and `max` without an `else`. Dividing by one of them gives NaN or inf for an
agent that senses nobody: a runtime fault, or worse a silent one. Two warnings:

- the division runs for agents whose set can be empty (no earlier `when` of the status
  sends them away when it is empty, and it is not inside `if ... then ... else`);
- a `let` computes such a division *before* a `when` that sends the empty-set agents
  away, and its value is read only after that `when`: moved below it, the `when` would
  have guarded it (a `when` skips the rest of the body for the agents it moves).

Sound toward silence: a divisor the analysis cannot read as an aggregate of a
neighbour set (`max(count(S), 1)`, a param, a variable) is never warned about.
"""

from __future__ import annotations

from swarmdsl.compiler import ast
from swarmdsl.compiler.ast import shape

_ZERO_WHEN_EMPTY = ("count", "sum", "mean", "min", "max")


def _set_key(e, sets: dict) -> object | None:
    """The key of a neighbour-set expression (a `let` bound to one is resolved)."""
    if isinstance(e, ast.Name) and e.id in sets:
        return sets[e.id]
    if isinstance(e, ast.Call) and e.name in ("neighbors", "neighbours"):
        return shape(e)
    if isinstance(e, ast.Where):
        inner = _set_key(e.source, sets)
        return None if inner is None else ("where", inner, shape(e.cond))
    return None


def zero_when_empty(e, sets: dict) -> object | None:
    """The set key when `e` is an aggregate that is 0 over an empty set, else None."""
    if not isinstance(e, ast.Call) or e.name not in _ZERO_WHEN_EMPTY or len(e.args) != 1:
        return None
    if e.default is not None:
        return None                      # `else` says what an empty set gives
    if e.name in ("sum", "mean", "min", "max") and e.each is None:
        return None
    return _set_key(e.args[0], sets)


def empties(cond, sets: dict) -> set:
    """Keys of the sets for which `cond` holds whenever they are empty (`count(S) == 0`,
    `count(S) < 1`, `not any(S)`, or a disjunction with one of those): agents past a
    `when cond` have those sets non-empty."""
    if isinstance(cond, ast.OrOp):
        return empties(cond.left, sets) | empties(cond.right, sets)
    if isinstance(cond, ast.NotOp) and isinstance(cond.operand, ast.Call) \
            and cond.operand.name == "any" and len(cond.operand.args) == 1:
        key = _set_key(cond.operand.args[0], sets)
        return {key} if key is not None else set()
    if isinstance(cond, ast.Compare):
        left, right, op = cond.left, cond.right, cond.op
        if isinstance(left, ast.Num):
            left, right = right, left
            op = {"<": ">", "<=": ">=", ">": "<", ">=": "<="}.get(op, op)
        if isinstance(left, ast.Call) and left.name == "count" and len(left.args) == 1 \
                and isinstance(right, ast.Num):
            c = right.value
            if (op == "==" and c == 0) or (op == "<" and c > 0) or (op == "<=" and c >= 0):
                key = _set_key(left.args[0], sets)
                return {key} if key is not None else set()
    return set()


def _divisions(e, sets: dict):
    """(division node, set key) for each risky division in `e`, outside `if` branches."""
    if isinstance(e, ast.Cond):
        yield from _divisions(e.test, sets)
        return
    if isinstance(e, ast.BinOp) and e.op in ("/", "%"):
        key = zero_when_empty(e.right, sets)
        if key is not None:
            yield e, key
    for child in e.children():
        if isinstance(child, ast.Expr):
            yield from _divisions(child, sets)


def _reads(stmt, name: str) -> bool:
    stack = [stmt]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.Name) and node.id == name:
            return True
        stack.extend(node.children())
    return False


def check_divisions(chk) -> None:
    """Warn about divisions by aggregates of neighbour sets that can be empty."""
    for k in chk.kinds:
        for decl in k.status_decls.values():
            _check_body(chk, decl.body)


def _check_body(chk, body) -> None:
    sets: dict[str, object] = {}
    guarded: set = set()              # sets whose empty agents left through a `when`
    pending: list = []                # (let, division, key) not yet read
    for i, stmt in enumerate(body):
        if isinstance(stmt, ast.WhenStmt):
            gone = empties(stmt.cond, sets)
            for let, div, key in list(pending):
                if key in gone and not any(_reads(s, let.name) for s in body[pending_at(
                        body, let) + 1:i]):
                    chk.warn(f"`{let.name}` divides by an aggregate of a neighbour set "
                             "that can be empty (NaN for an agent with no neighbours); "
                             f"the `when` on line {stmt.span.line} sends those agents away, "
                             f"but `{let.name}` is computed before it", div.span,
                             f"move `let {let.name}` below the `when` on line "
                             f"{stmt.span.line}")
                    pending.remove((let, div, key))
            for s in stmt.body:           # actions of the agents that fired
                _warn_unguarded(chk, s, sets, guarded)
            guarded |= gone
            continue
        if isinstance(stmt, ast.LetStmt):
            risky = [(d, key) for d, key in _divisions(stmt.value, sets) if key not in guarded]
            key = _set_key(stmt.value, sets)
            if key is not None:
                sets[stmt.name] = key
            if risky and any(_later_when_guards(body[i + 1:], sets, k) for _d, k in risky):
                pending += [(stmt, d, k) for d, k in risky]
                continue
        _warn_unguarded(chk, stmt, sets, guarded)
    for _let, div, _key in pending:
        _warn(chk, div)


def pending_at(body, stmt) -> int:
    return next(i for i, s in enumerate(body) if s is stmt)


def _later_when_guards(rest, sets, key) -> bool:
    return any(isinstance(s, ast.WhenStmt) and key in empties(s.cond, sets) for s in rest)


def _warn_unguarded(chk, stmt, sets, guarded) -> None:
    exprs = []
    stack = [stmt]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.WhenStmt):
            continue                   # nested conditions are not statements' values
        if isinstance(node, ast.Expr):
            exprs.append(node)
            continue
        stack.extend(node.children())
    for e in exprs:
        for div, key in _divisions(e, sets):
            if key not in guarded:
                _warn(chk, div)


def _warn(chk, div) -> None:
    chk.warn("this divides by an aggregate of a neighbour set, which is 0 when the agent "
             "has no neighbours in range (NaN or inf)", div.right.span,
             "guard it: `max(count(near), 1)`, `mean(... else 0)`, or a `when` before it "
             "that leaves when the set is empty")
