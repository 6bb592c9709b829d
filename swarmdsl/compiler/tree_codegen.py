"""Checked behaviour trees -> runtime tree nodes (`runtime/trees.py`).

Leaves reuse the ordinary closures: a condition is `codegen.expr`, an action leaf is
the action statement's closure run for the leaf's rows, an assignment is the
assignment statement. Each stateful node gets its memory columns from the program's
`Layout`, and a program hook adds the runtime extension that creates them.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

import numpy as np

from swarmdsl.compiler import ast, codegen, limits, nan_guard, program
from swarmdsl.compiler.batching import per_replica
from swarmdsl.compiler.builtins import REGION
from swarmdsl.compiler.consteval import const_value
from swarmdsl.compiler.facts import NodeTable
from swarmdsl.compiler.tree_ast import (
    AssignLeaf,
    Composite,
    Decorator,
    Forever,
    Subtree,
    TreeResult,
    TreeStmt,
)
from swarmdsl.compiler.tree_long import long_action

# The runtime's tree nodes and the analyses that label them load when a program with a
# tree is compiled: checking a program without one does not pay for them.
if TYPE_CHECKING:
    from swarmdsl.runtime import trees as rt


def layout_of(prog) -> rt.Layout:
    from swarmdsl.runtime import trees as rt

    layout = getattr(prog, "tree_layout", None)
    if layout is None:
        layout = prog.tree_layout = rt.Layout()
        prog.tree_index = []     # (kind, status, Tree) per compiled tree, for the tools
        prog.tree_leaf_names = []   # "LINE:COL text" per leaf id - 1
        prog.tree_leaf_paths = []   # "root > ... > leaf" labels per leaf id - 1
    return layout


class _Builder:
    def __init__(self, gen, kind, status: str):
        self.gen, self.kind, self.status = gen, kind, status
        self.info = gen.info.extra["trees"]
        self.layout = layout_of(gen.program)
        self.tree = self.layout.new_tree()
        self.nodes = 0
        self.leaves: list[rt.Node] = []
        self.outcomes = NodeTable()     # AST node -> results it can give
        self.path: list[str] = []    # labels from the root to the node being built
        self.bindings: list[dict[str, str]] = []   # named trees' params -> argument text

    def root(self, n) -> rt.Node:
        from swarmdsl.compiler.tree_outcomes import outcomes

        outcomes(n, self.gen.info.params, memo=self.outcomes)
        return self.build(n)

    def _index(self) -> int:
        self.nodes += 1
        return self.nodes - 1

    def count(self, e: ast.Expr, span):
        if isinstance(e, Forever):      # a count no run reaches
            return lambda f: np.inf
        fn = self.gen.expr(e)
        return _whole(fn, span)

    def build(self, n) -> rt.Node:
        from swarmdsl.compiler.labels import describe

        self.path.append(describe(n, self.gen.program.source, self.info.leaves)[0])
        node = self._build(n)
        self.path.pop()
        node.can_run = "R" in self.outcomes.get(n, "R")
        return node

    def _build(self, n) -> rt.Node:
        from swarmdsl.runtime import trees as rt

        i = self._index()
        L, t = self.layout, self.tree
        if isinstance(n, Subtree):
            params = self.info.decls[n.name].params
            self.bindings.append({p: _arg_text(self.gen.program.source, a)
                                  for p, a in zip(params, n.args, strict=True)})
            try:
                return rt.Subtree(n.name, self.build(n.root), n.span)
            finally:
                self.bindings.pop()
        if isinstance(n, Composite):     # each kind's node is its row's (runtime/trees.py)
            row = rt.composite_row(n.kind)
            kids = [self.build(c) for c in n.kids]
            k = None if n.threshold is None else int(const_value(n.threshold,
                                                                 self.gen.info.params))
            return row.make(L, t, i, kids, k, n.reactive, n.span)
        if isinstance(n, Decorator):
            row = rt.decorator_row(n.kind)
            child = self.build(n.child)
            count = self.count(n.count, n.count.span) if row.counted else None
            return row.make(L, t, i, child, count, n.span)
        return self._leaf(n, i)

    def _leaf(self, n, i) -> rt.Node:
        from swarmdsl.compiler.labels import guard_text
        from swarmdsl.runtime import tree_leaves as leaf

        gen, where = self.gen, (self.kind, self.status)
        if isinstance(n, AssignLeaf):
            node = leaf.Action(gen.stmt(n.stmt, *where), n.span)
        else:
            what, payload = self.info.leaves[n]
            if what == "cond":
                node = leaf.Condition(gen.expr(n.expr), n.span)
            elif what == "action":
                node = leaf.Action(gen.stmt(payload, *where), n.span)
            else:
                node = self._long(n.expr, i)
        self.leaves.append(node)
        names = self.gen.program.tree_leaf_names
        text = guard_text(self.gen.program.source, n.span, 10**6)
        for binding in reversed(self.bindings):     # a named tree's leaf, as this use
            text = _with_arguments(text, binding)   # runs it: `move_to(home, 2)`, not `p`
        names.append(f"{n.span.line}:{n.span.col} "
                     f"{text if len(text) <= 60 else text[:59] + '…'}")
        node.leaf_id = len(names)      # 0 means "no leaf" in recordings
        self.gen.program.tree_leaf_paths.append(" > ".join(self.path))
        return node

    def target(self, e: ast.Expr):
        """For a long action's row: a `move_to` target's closure (`move_target`)."""
        return move_target(self.gen, e)

    def _long(self, e: ast.Call, i) -> rt.Node:
        """A long action's leaf: its row's (`tree_long.py`)."""
        return long_action(e.name).build(self, e, i)


def _arg_text(source: str, e: ast.Expr) -> str:
    """An argument of a named tree's use as written, bracketed unless it is one token
    (so `p * 2` with `p = a + b` reads `(a + b) * 2`)."""
    from swarmdsl.compiler.labels import guard_text

    text = guard_text(source, e.span, 10**6)
    return text if re.fullmatch(r"[\w.]+", text) or _one_group(text) else f"({text})"


def _one_group(text: str) -> bool:
    """`(...)` or `name(...)` whose first opening bracket closes at the very end."""
    start = text.find("(")
    if start < 0 or not re.fullmatch(r"\w*", text[:start]):
        return False
    depth = 0
    for i, ch in enumerate(text[start:], start):
        depth += (ch == "(") - (ch == ")")
        if depth == 0:
            return i == len(text) - 1
    return False


def _with_arguments(text: str, binding: dict[str, str]) -> str:
    """A leaf's text with a named tree's parameters replaced by this use's arguments
    (whole names only, not a field `other.p`): two uses of `visit(p)` recorded as
    `move_to(p, ...)` in `tree_leaf` could not be told apart."""
    if not binding:
        return text
    pattern = r"(?<![\w.])(" + "|".join(map(re.escape, binding)) + r")(?!\w)"
    return re.sub(pattern, lambda m: binding[m.group(1)], text)


def move_target(gen, e: ast.Expr):
    """A `move_to` target: a point, or a region's nearest point, as an objective's
    (inside the region, the agent's own position: it has arrived)."""
    fn = gen.expr(e)
    if gen.type_of(e) != REGION:
        return fn
    from swarmdsl.compiler.lang_objectives import region_target

    return lambda f: region_target(f, fn(f), np.asarray(f.state("pos"), dtype=np.float64))


def _whole(fn, span):
    """A per-agent count of ticks or runs: rounded down. NaN, infinity and values beyond
    the documented limit (the runtime keeps counts and deadlines as 64-bit integers)
    are located runtime errors naming the agent."""
    limit = limits.upper("tree count")

    def count(f):
        v = np.asarray(fn(f), dtype=np.float64)
        bad = ~(np.abs(v) <= limit)              # NaN, infinite or too large
        if bad.any():
            bad = np.broadcast_to(bad, (f.n,)) & f.active
            if bad.any():
                row = int(np.flatnonzero(bad)[0])
                got = float(np.broadcast_to(v, (f.n,))[row])
                hint = (f"a tree's count must be finite and at most {limit:,} in size "
                        "(docs/limits.md)")
                if got == np.inf:
                    hint += "; for no limit write `repeat forever` or `retry forever`"
                raise nan_guard.nan_error(f, row, span, "the count", hint,
                                          badness=f"{got:g}")
        return np.floor(v)
    return count


def _tree_stmt(gen, st: TreeStmt, kind, status):
    from swarmdsl.runtime import trees as rt

    b = _Builder(gen, kind, status)
    root = b.root(gen.info.extra["trees"].roots[st])
    tree = rt.Tree(b.layout, b.tree, root, st.span)
    tree.leaves = b.leaves
    gen.program.tree_index.append((kind.name, status, tree))
    return tree


def _tree_result(gen, e: TreeResult):
    from swarmdsl.runtime import trees as rt

    code = {"succeeded": rt.SUCCESS, "failed": rt.FAILURE, "running": rt.RUNNING}[e.state]
    return lambda f: f.locals[rt.RESULT_KEY] == code


def _add_memory(info, prog, gen) -> None:
    layout = getattr(prog, "tree_layout", None)
    if layout is not None:
        from swarmdsl.runtime import trees as rt

        make = per_replica(lambda sim, _l=layout: rt.TreeMemory(sim, _l))
        make.tree_memory = True   # agent columns only: the whole-tick kernel keeps them
        prog.extensions.append(make)


codegen.STMT_CODEGEN[TreeStmt] = _tree_stmt
codegen.EXPR_CODEGEN[TreeResult] = _tree_result
program.PROGRAM_HOOKS.append(_add_memory)
