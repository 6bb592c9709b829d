"""Behaviour-tree syntax: the AST classes of `tree` blocks and the parse-tree rules that
build them (mixed into `parse.ToAst`, so they never raise either).

A tree node is a composite (`sequence`, `fallback`, `parallel K`, each optionally
`reactive`), a decorator over one child (`invert`, `repeat N`, `retry N`, `timeout N`,
`cooldown N`, `force success`, `force failure`; `repeat forever`, `retry forever`) or
a leaf: an expression or an assignment. Whether a leaf `name(args)` is a condition, an
action, a long action or a named tree is decided by the checker, which knows the names.
What each kind of composite and decorator does is its row's (`runtime/trees.py`).
"""

from __future__ import annotations

from dataclasses import dataclass

from swarmdsl.compiler import ast, syntax_rules
from swarmdsl.compiler.tree_long import LONG
from swarmdsl.errors import Span


class TreeNode(ast.Node):
    """One node of a behaviour tree."""


# name -> (usage, minimum and maximum argument count), read off the long actions' rows
LONG_ACTIONS = {r.name: (r.usage, r.lo, r.hi) for r in LONG.values()}


@dataclass(frozen=True)
class Subtree(TreeNode):
    """A use of a named tree, after expansion: `root` is the fresh, checked copy."""

    name: str
    args: tuple[ast.Expr, ...]
    root: TreeNode


@ast.node
class Composite(TreeNode):
    """`sequence`, `fallback` or `parallel K`; `reactive` re-ticks from the first child."""

    kind: str                       # "sequence" | "fallback" | "parallel"
    reactive: bool
    kw_span: Span
    threshold: ast.Expr | None      # parallel's K
    kids: tuple[TreeNode, ...]


@ast.node
class Decorator(TreeNode):
    """`invert`, `repeat N`, `retry N`, `timeout N`, `cooldown N`, `force success|failure`."""

    kind: str
    kw_span: Span
    count: ast.Expr | None
    child: TreeNode


@ast.node
class Leaf(TreeNode):
    """An expression leaf: a condition, or a call the checker resolves to an action, a
    long action or a named tree."""

    expr: ast.Expr


@ast.node
class AssignLeaf(TreeNode):
    """An assignment used as an action leaf: succeeds at once."""

    stmt: ast.AssignStmt


@ast.node
class TreeStmt(ast.Stmt):
    """`tree NODE` inside a status body: ticks once per tick where it stands."""

    root: TreeNode


@ast.node
class TreeResult(ast.Expr):
    """`tree succeeded`, `tree failed`, `tree running`: this tick's result of the tree."""

    state: str


@ast.node
class TreeDecl(ast.Node):
    """`tree NAME(p, q) { NODE }` at top level: a named, parameterised tree."""

    name: str
    name_span: Span
    params: tuple[str, ...]
    param_spans: tuple[Span, ...]
    root: TreeNode


@ast.node
class Forever(ast.Expr):
    """The count `forever` of `repeat` and `retry` (py_trees' and BehaviorTree.CPP's
    N = -1): no number of runs ends it. Not a constant value: the checker allows it
    only as such a count, the outcome analysis and the compiler read it as infinity."""


_OUTCOME_STATE = {"success": "succeeded", "failure": "failed"}


@syntax_rules.register
class TreeToAst:
    """Parse-tree -> AST rules for trees; a mixin of `parse.ToAst` (same conventions)."""

    def tree_decl(self, meta, c):
        name = c[0]
        params = [p for p in c[1:-1] if p is not None]
        return TreeDecl(self._s(meta), str(name), self._t(name),
                        tuple(str(p) for p in params), tuple(self._t(p) for p in params),
                        c[-1])

    def tree_stmt(self, meta, c):
        return TreeStmt(self._s(meta), c[0])

    def on_stmt(self, meta, c):
        """`on success -> X { ... }` is `when tree succeeded -> X { ... }`."""
        outcome, target = c[0], c[1]
        body = c[2] if len(c) > 2 and c[2] is not None else ()
        cond = TreeResult(self._t(outcome), _OUTCOME_STATE[str(outcome)])
        return ast.WhenStmt(self._s(meta), cond, str(target), self._t(target), tuple(body))

    def tree_composite(self, meta, c):
        reactive, kw = c[0], c[1]
        rest = list(c[2:])
        threshold = rest.pop(0) if str(kw) == "parallel" else None
        return Composite(self._s(meta), str(kw), reactive is not None, self._t(kw),
                         threshold, tuple(x for x in rest if isinstance(x, TreeNode)))

    def tree_decorator(self, meta, c):
        kw = c[0]
        if str(kw) == "force":
            return Decorator(self._s(meta), f"force {c[1]}", self._t(kw), None, c[2])
        if str(kw) == "invert":
            return Decorator(self._s(meta), "invert", self._t(kw), None, c[1])
        return Decorator(self._s(meta), str(kw), self._t(kw), c[1], c[2])

    def tree_count(self, meta, c):
        return c[0]

    def forever(self, meta, c):
        return Forever(self._s(meta))

    def tree_leaf(self, meta, c):
        return Leaf(self._s(meta), c[0])

    def tree_assign(self, meta, c):
        stmt = ast.AssignStmt(self._s(meta), str(c[0]), self._t(c[0]), str(c[1]), c[2])
        return AssignLeaf(self._s(meta), stmt)

    def tree_result(self, meta, c):
        return TreeResult(self._s(meta), str(c[0]))


def walk(node: TreeNode):
    """Every node of a tree, parents before children, without recursion."""
    stack = [node]
    while stack:
        n = stack.pop()
        yield n
        if isinstance(n, Composite):
            stack.extend(reversed(n.kids))
        elif isinstance(n, Decorator):
            stack.append(n.child)
