"""Behaviour trees in the checker: named trees, what each leaf is, argument checks.

A leaf `name(args)` is, in this order: a long action (`move_to`, `wait`, `retrace`,
`follow`), a named tree (expanded in place, its parameters replaced by the caller's
argument expressions), an action statement (`deposit`, `broadcast`, ...), or else a
condition. Every use of a named tree is a fresh copy of its nodes, checked in the
scope of the kind and status that uses it, so one tree serves several kinds. What the
checker learns is kept in `checker.extra["trees"]` for codegen and the tools.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

from swarmdsl.compiler import ast, checker, columns, draws, limits, typing_rules
from swarmdsl.compiler.actions import ACTIONS, declare_statement
from swarmdsl.compiler.builtins import (
    AGGREGATES,
    BOOL,
    FUNCTIONS,
    NUM,
    Refused,
    declare_calls,
)
from swarmdsl.compiler.consteval import NotConstant, const_value
from swarmdsl.compiler.facts import NodeTable
from swarmdsl.compiler.nesting import MAX_NESTING
from swarmdsl.compiler.options import refuse_negative
from swarmdsl.compiler.tree_ast import (
    LONG_ACTIONS,
    AssignLeaf,
    Composite,
    Decorator,
    Forever,
    Leaf,
    Subtree,
    TreeDecl,
    TreeNode,
    TreeResult,
    TreeStmt,
)
from swarmdsl.compiler.tree_long import LONG, long_action
from swarmdsl.errors import did_you_mean

ERR = checker.ERR
columns.REQUESTED_COLUMNS[columns.LEAF_RECORDED] = (
    "each agent's active tree leaf (with `--tree-leaf`)")
columns.REQUESTED_COLUMNS[columns.RESULT_RECORDED] = (
    "each agent's tree result, running, success or failure (with `--tree-leaf`)")
MAX_TREE_NODES = 10_000      # nodes one status's tree may expand to (named trees included)
MAX_PARALLEL_CHILDREN = 31   # a parallel keeps two bits per child in one int64 column

@dataclass
class TreesInfo:
    decls: dict[str, TreeDecl] = field(default_factory=dict)
    used: set = field(default_factory=set)
    # TreeStmt -> expanded root; Leaf -> ("cond"|"action"|"long", payload)
    roots: NodeTable = field(default_factory=NodeTable)
    leaves: NodeTable = field(default_factory=NodeTable)
    keep: list = field(default_factory=list)       # keeps expanded nodes (and their ids) alive


def trees_info(chk) -> TreesInfo:
    return chk.extra.setdefault("trees", TreesInfo())


# ---- declarations ----

def _collect(chk) -> None:
    info = trees_info(chk)
    for d in chk.tree.decls_of(TreeDecl):
        if d.name in info.decls:
            continue  # reported by the duplicate-name check
        if d.name in LONG_ACTIONS or d.name in ACTIONS or d.name in FUNCTIONS:
            chk.fail(f"tree `{d.name}` has the name of a built-in action or function",
                     d.name_span, "choose another name")
        seen = set()
        for p, span in zip(d.params, d.param_spans, strict=True):
            if p in seen:
                chk.fail(f"tree `{d.name}` has two parameters named `{p}`", span)
            seen.add(p)
        info.decls[d.name] = d


def _unused(chk) -> None:
    info = trees_info(chk)
    for name, d in info.decls.items():
        if name not in info.used:
            chk.warn(f"tree `{name}` is never used", d.name_span)


checker.DECL_HOOKS.append(_collect)
checker.PROGRAM_CHECK_HOOKS.append(_unused)


# ---- the tree statement and `tree succeeded` ----

def _tree_stmt(chk, st: TreeStmt, scope, k, in_when: bool) -> None:
    if in_when:
        chk.fail("`tree` is not allowed in a transition's actions", st.span)
        return
    if getattr(scope, "tree", None) is not None:
        chk.fail(f"a status has one `tree`; this status already has one (line "
                 f"{scope.tree.span.line})", st.span,
                 "put both in one `sequence { }` or `parallel K { }`")
        return
    expander = _Expander(chk, scope, k)
    root = expander.node(st.root, ())
    info = trees_info(chk)
    info.roots[st] = root
    info.keep.append(root)
    scope.tree = st
    scope.tree_root = root
    from swarmdsl.compiler.tree_outcomes import check_tree

    check_tree(chk, root)


_STATE_WORD = {"succeeded": "succeed", "failed": "fail"}


def _tree_result(chk, e: TreeResult, scope) -> str:
    if getattr(scope, "tree", None) is None:
        word = {"succeeded": "on success", "failed": "on failure"}.get(e.state)
        what = f"`tree {e.state}`" + (f" (or `{word}`)" if word else "")
        return chk.fail(f"{what} needs a `tree` earlier in this status", e.span,
                        "write the `tree` first; its result is this tick's")
    chk.facts.set_name(e, ("tree_result", e.state))
    if e.state in _STATE_WORD:
        from swarmdsl.compiler.tree_outcomes import outcomes

        if _STATE_WORD[e.state][0].upper() not in outcomes(scope.tree_root, chk.params):
            never = "this transition never fires" if getattr(chk, "in_condition", False) \
                else f"`tree {e.state}` is always false here"
            chk.fail(f"the tree of this status can never {_STATE_WORD[e.state]}, so "
                     f"{never}", e.span, f"see the tree on line {scope.tree.span.line}")
    return BOOL


def _forever(chk, e: Forever, scope) -> str:
    return chk.fail(f"`forever` is a count of {_forever_words()} only", e.span)


def _decorator_row(kind: str):
    """The row of a decorator kind (`runtime/trees.py`): its count's rule is there."""
    from swarmdsl.runtime.trees import decorator_row

    return decorator_row(kind)


def _forever_words() -> str:
    """The decorators whose count may be `forever`, as a message names them."""
    from swarmdsl.runtime.trees import DECORATORS

    words = [f"`{r.name}`" for r in DECORATORS.values() if r.forever]
    return " and ".join(words) if len(words) < 3 else ", ".join(words[:-1]) + \
        f" and {words[-1]}"


checker.STMT_RULES[TreeStmt] = _tree_stmt
declare_statement(TreeStmt, "`tree NODE`: a behaviour tree ticked where it stands",
                  batch=True,   # its memory is agent columns (`runtime/trees.py`)
                  kilobot=Refused("behaviour trees are not translated to C yet"))
checker.EXPR_RULES[TreeResult] = _tree_result
checker.EXPR_RULES[Forever] = _forever


# ---- long actions outside trees ----

def _long_in_expr(name):
    def rule(chk, call, scope):
        for a in call.args:
            chk.expr(a, scope)
        return chk.fail(f"`{name}` is a long action: it runs over several ticks and can "
                        "only be a leaf of a `tree`, not part of a condition or value",
                        call.span, "use it as a tree leaf; test a condition instead here")
    return rule


for _name in LONG_ACTIONS:
    if _name not in typing_rules.CALL_RULES and _name not in FUNCTIONS:
        typing_rules.CALL_RULES[_name] = _long_in_expr(_name)
for _row in LONG.values():   # its batch and Kilobot forms are its row's
    declare_calls((_row.name,), batch=_row.batch, kilobot=_row.kilobot)


# ---- expansion ----

class _Expander:
    """Checks one status's tree, expanding named trees into fresh checked copies."""

    err = ERR     # the type of an argument that already has its diagnostic

    def __init__(self, chk, scope, kind):
        self.chk, self.scope, self.kind = chk, scope, kind
        self.count = 0
        self.too_big = False

    def node(self, n: TreeNode, stack: tuple[str, ...], depth: int = 0) -> TreeNode:
        self.count += 1
        if (self.count > MAX_TREE_NODES or depth > MAX_NESTING) and not self.too_big:
            self.too_big = True
            self.chk.fail(f"this tree is too large: over {MAX_TREE_NODES:,} nodes or "
                          f"{MAX_NESTING} levels once named trees are expanded", n.span)
        if self.too_big:
            return n
        if isinstance(n, Composite):
            return self._composite(n, stack, depth)
        if isinstance(n, Decorator):
            if n.count is not None:
                self._count(n.count, f"the count of `{n.kind}`",
                            forever=_decorator_row(n.kind).forever)
            child = self.node(n.child, stack, depth + 1)
            return Decorator(n.span, n.kind, n.kw_span, n.count, child)
        if isinstance(n, AssignLeaf):
            self.chk.assign(n.stmt, self.scope, self.kind)
            return n
        return self._leaf(n, stack, depth)

    def _composite(self, n: Composite, stack, depth) -> TreeNode:
        chk = self.chk
        word = ("reactive " if n.reactive else "") + n.kind
        if not n.kids:
            chk.fail(f"`{word}` needs at least one child", n.span)
        if n.kind == "parallel":
            if len(n.kids) > MAX_PARALLEL_CHILDREN:
                chk.fail(f"a `parallel` takes at most {MAX_PARALLEL_CHILDREN} children, "
                         f"got {len(n.kids)}", n.kw_span,
                         "group some of them in a `sequence`")
            if isinstance(n.threshold, Forever):
                self._count(n.threshold, "the success threshold of `parallel`")
                k = None
            else:
                k = chk._const(n.threshold, "the success threshold of `parallel`")
            if k is not None and (isinstance(k, bool) or not isinstance(k, int | float)
                                  or k != int(k) or not 1 <= k <= max(len(n.kids), 1)):
                chk.fail(f"`parallel K` needs a whole number K from 1 to the number of "
                         f"children ({len(n.kids)}), got {k}", n.threshold.span)
        kids = tuple(self.node(c, stack, depth + 1) for c in n.kids)
        return Composite(n.span, n.kind, n.reactive, n.kw_span, n.threshold, kids)

    def _count(self, e: ast.Expr, what: str, forever: bool = False) -> None:
        """A count of ticks or runs: `forever` where `forever` says so; a constant one
        finite, whole and within the documented limit (the runtime keeps counts and
        deadlines as 64-bit integers)."""
        chk = self.chk
        if isinstance(e, Forever):
            if not forever:
                chk.fail(f"`forever` is a count of {_forever_words()} only, not {what}",
                         e.span, "give a number of ticks")
            return
        if chk.expect(e, NUM, self.scope, what) != NUM:
            return
        try:
            v = const_value(e, chk.params)
        except (NotConstant, ArithmeticError, ValueError, TypeError):
            return
        if isinstance(v, bool) or not isinstance(v, int | float):
            return
        if not math.isfinite(v):
            chk.fail(f"{what} must be a finite number, got {v}", e.span,
                     "for no limit write `repeat forever` or `retry forever`" if forever
                     else f"counts are limited to {limits.upper('tree count'):,} "
                          "(docs/limits.md)")
        elif abs(v) > limits.upper("tree count"):
            chk.fail(f"{what} is too large: {limits.over('tree count', abs(v))}", e.span,
                     "for no limit write `repeat forever` or `retry forever`" if forever
                     else "see docs/limits.md")
        elif v != int(v):
            chk.fail(f"{what} must be a whole number of ticks, got {v}", e.span)

    def _leaf(self, n: Leaf, stack, depth) -> TreeNode:
        chk, info = self.chk, trees_info(self.chk)
        e = n.expr
        if isinstance(e, ast.Call) and e.each is None and e.default is None:
            if e.name in LONG_ACTIONS:
                self._long(e)
                info.leaves[n] = ("long", e.name)
                return n
            if e.name in info.decls:
                return self._subtree(n, e, stack, depth)
            if e.name in ACTIONS:
                st = ast.ActionStmt(e.span, e.name, e.name_span, e.args)
                chk.action(st, self.scope, self.kind)
                info.leaves[n] = ("action", st)
                info.keep.append(st)
                return n
            known = (FUNCTIONS.keys() | AGGREGATES.keys() | typing_rules.CALL_RULES.keys()
                     | {"neighbors", "neighbours"})
            if e.name not in known:
                for a in e.args:
                    chk.expr(a, self.scope)
                cands = list(info.decls) + list(ACTIONS) + list(LONG_ACTIONS) + list(known)
                chk.fail(f"unknown tree, action or condition `{e.name}`", e.name_span,
                         did_you_mean(e.name, cands))
                return n
        if isinstance(e, ast.Name) and e.id in info.decls:
            chk.fail(f"`{e.id}` is a tree; use it as `{e.id}(...)`", e.span)
            return n
        chk.expect(e, BOOL, self.scope, "a condition leaf")
        info.leaves[n] = ("cond", None)
        return n

    def _subtree(self, n: Leaf, e: ast.Call, stack, depth) -> TreeNode:
        chk, info = self.chk, trees_info(self.chk)
        decl = info.decls[e.name]
        info.used.add(e.name)
        if e.name in stack:
            path = " -> ".join((*stack[stack.index(e.name):], e.name))
            chk.fail(f"tree `{e.name}` uses itself ({path})", e.span,
                     "a tree cannot contain itself")
            return n
        if len(e.args) != len(decl.params):
            for a in e.args:
                chk.expr(a, self.scope)
            want = ", ".join(decl.params)
            chk.fail(f"tree `{e.name}` takes {len(decl.params)} argument"
                     f"{'s' if len(decl.params) != 1 else ''} ({want}), got {len(e.args)}",
                     e.span, f"declared on line {decl.span.line}: `tree {e.name}({want})`")
            return n
        for a in e.args:  # each argument is checked where it is written, once
            chk.expr(a, self.scope)
        mapping = dict(zip(decl.params, e.args, strict=True))
        body = substitute(decl.root, mapping)
        draws.check_constant_draws(chk, body)   # as it runs: with this call's arguments
        root = self.node(body, (*stack, e.name), depth + 1)
        return Subtree(n.span, e.name, e.args, root)

    def refuse_negative(self, e: ast.Expr, what: str) -> None:
        """For a long action's row: `what` refused when a constant below 0."""
        refuse_negative(self.chk, e, what)

    def uses_fields(self) -> None:
        """For a long action's row: the program reads its fields (`follow`)."""
        from swarmdsl.compiler.lang_fields import env_info

        env_info(self.chk).used = True

    def _long(self, e: ast.Call) -> None:
        """A long action's arguments: their count here, the rest by its row
        (`tree_long.py`)."""
        chk, scope = self.chk, self.scope
        row = long_action(e.name)
        if not row.lo <= len(e.args) <= row.hi:
            for a in e.args:
                chk.expr(a, scope)
            lo, hi = row.lo, row.hi
            chk.fail(f"`{e.name}` takes {lo if lo == hi else f'{lo} to {hi}'} argument"
                     f"{'s' if hi != 1 else ''}: `{row.usage}`", e.span)
            return
        row.check(self, e)


def substitute(node, mapping: dict):
    """A fresh copy of `node` (new ids, same spans) with parameter names replaced by
    fresh copies of their argument expressions. Iterative over tuples, recursive only
    along the (nesting-limited) depth of the tree."""
    if isinstance(node, ast.Name) and node.id in mapping:
        return substitute(mapping[node.id], {})
    if isinstance(node, tuple):
        return tuple(substitute(x, mapping) for x in node)
    if not isinstance(node, ast.Node):
        return node
    values = {f.name: substitute(getattr(node, f.name), mapping) for f in fields(node)}
    return type(node)(**values)

