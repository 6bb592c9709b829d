"""What a behaviour tree can return, known before the program runs.

`outcomes(node)` is the set of results a node can ever give, among "S" (success), "F"
(failure) and "R" (running), from constants and the leaves' kinds alone (a composite's
and a decorator's rule is its row's, `runtime/trees.py` `COMPOSITES`, `DECORATORS`) (a condition
that `guards.truth` settles, an action that always succeeds, `move_to` that never
fails, ...). Every answer is sound: a result left out can never happen. The checker
uses it for unreachable children (after a `fallback` child that never fails, or a
`sequence` child that never succeeds) and for transitions that wait on a result the
tree can never give.
"""

from __future__ import annotations

from swarmdsl.compiler.consteval import NotConstant, const_value
from swarmdsl.compiler.guards import truth
from swarmdsl.compiler.tree_ast import (
    LONG_ACTIONS,
    AssignLeaf,
    Composite,
    Decorator,
    Forever,
    Leaf,
    Subtree,
)
from swarmdsl.compiler.tree_long import long_action

ALL = frozenset("SFR")


def _const(e, params):
    if e is None:
        return None
    if isinstance(e, Forever):
        return float("inf")
    try:
        v = const_value(e, params)
    except (NotConstant, ArithmeticError, ValueError, TypeError, OverflowError):
        return None
    return v if isinstance(v, int | float) and not isinstance(v, bool) else None


def outcomes(node, params: dict, warn=None, memo=None) -> frozenset:
    """The results `node` can give; `warn(message, span)` hears about unreachable
    children (pass None to ask without reporting); `memo`, a `facts.NodeTable` if
    given, receives every node's results."""
    got = _outcomes(node, params, warn, memo)
    if memo is not None:
        memo[node] = got
    return got


def _outcomes(node, params, warn, memo) -> frozenset:
    if isinstance(node, Subtree):
        return outcomes(node.root, params, warn, memo)
    if isinstance(node, AssignLeaf):
        return frozenset("S")
    if isinstance(node, Leaf):
        return _leaf(node, params)
    if isinstance(node, Decorator):
        return _decorator(node, params, warn, memo)
    if isinstance(node, Composite):
        return _composite(node, params, warn, memo)
    return ALL


def _leaf(node: Leaf, params) -> frozenset:
    from swarmdsl.compiler import ast
    from swarmdsl.compiler.actions import ACTIONS

    e = node.expr
    if isinstance(e, ast.Call) and e.each is None and e.default is None:
        if e.name in LONG_ACTIONS:          # its row's rule (`tree_long.py`)
            return long_action(e.name).outcomes(e, lambda x: _const(x, params))
        if e.name in ACTIONS:
            return frozenset("S")
    t = truth(e, params)
    if t is None:
        return frozenset("SF")
    return frozenset("S" if t else "F")


def _decorator(node: Decorator, params, warn, memo) -> frozenset:
    from swarmdsl.runtime.trees import decorator_row

    child = outcomes(node.child, params, warn, memo)
    row = decorator_row(node.kind)      # a kind without a row is a bug, not "anything"
    return row.outcomes(child, _const(node.count, params) if row.counted else None)


def _composite(node: Composite, params, warn, memo) -> frozenset:
    from swarmdsl.runtime.trees import composite_row

    results = [outcomes(c, params, warn, memo) for c in node.kids]
    if not results:
        return ALL

    def unreachable(i: int, word: str) -> None:
        if warn is not None:
            warn(f"this child can never run: the one before it never {word}, so the "
                 f"`{node.kind}` stops there", node.kids[i].span)

    k = _const(node.threshold, params) if node.threshold is not None else None
    return composite_row(node.kind).outcomes(results, k, unreachable)


def check_tree(chk, root) -> None:
    """Warnings for unreachable children, once per place in the source."""
    seen = chk.extra.setdefault("tree_warnings", set())

    def warn(message, span):
        if (message, span) not in seen:
            seen.add((message, span))
            chk.warn(message, span)

    outcomes(root, chk.params, warn)

