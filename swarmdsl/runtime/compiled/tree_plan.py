"""A `tree` statement as one step of the whole-tick plan (`tick_plan.py`), walked per
agent by `tree_kernel.py`.

The plan walks the checked tree (`info.extra["trees"].roots`) beside the runtime tree
the compiler built from it (`program.tree_index`), which holds what the reference
decided: each node's memory columns, whether a walk keeps its running child
(`stateful`), which children can run, parallel's threshold. Leaves become statement
steps of their own (a condition's value, an assignment, `move_to`'s target, tolerance
and speed), run when the walk reaches them.

Step: `("bt", root, stamp, clocks, result, tick, flag, leaf, code)`: the tree's stamp
column (-1: a tree that keeps nothing), its cooldowns' deadline columns, the scratch
column of its result (what `tree succeeded` reads), the state-table column of the tick,
the scratch cell `S[0, flag]` noting that the statement ran this tick (for the agents
that leave the status: `TickPlan.settles`), and the state-table columns of each agent's
active leaf and result (`trees.record_active_leaf`). Nodes (`tree_kernel._node`), each
leaf's last item its leaf id:

- `("walk", fallback, stateful, stamp, value, ((child, can_run), ...))`
- `("par", k, reactive, stamp, value, children, halted stamps)`
- `("inv", 0 invert | 1 force success | 2 force failure, child)`
- `("rep", retry, stamp, value, count, child)`, `("timeout", stamp, value, count,
  child, halted stamps)`, `("cool", deadline, count, child)`
- `("cond", steps, col)`, `("act", steps)`, `("wait", stamp, value, count)`,
  `("move", steps, tx, ty, tol, speed or -1, wraps, width, height, and the state
  table's columns of position, velocity and max speed)`

Not planned (`Unsupported`, the run keeps its per-tick path): an action leaf other
than an assignment, `retrace` and `follow` (fields and path memories), a `move_to` at
a region, a count that is not a constant (the reference checks a count for every agent
ticking the tree, not only those reaching the node), and a draw whose arguments are not
constants (its arguments are likewise checked for all of them).
"""

from __future__ import annotations

import math

from swarmdsl import limits
from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import REGION
from swarmdsl.compiler.consteval import NotConstant, const_value
from swarmdsl.runtime.compiled.plan import Unsupported
from swarmdsl.runtime.trees import LEAF_COLUMN, RESULT_COLUMN

_MODES = {"invert": 0, "force success": 1, "force failure": 2}


def memory_trees(program, kind: str, status: str) -> list:
    """The runtime trees of status `status` of `kind` that keep memory between ticks."""
    return [t for k, s, t in getattr(program, "tree_index", ()) if (k, s) == (kind, status)
            and t.memory]


def runtime_tree(program, st):
    """The runtime tree the compiler built for `tree` statement `st`."""
    for _k, _s, tree in getattr(program, "tree_index", ()):
        if tree.span == st.span:
            return tree
    raise Unsupported(f"internal: no compiled tree for the `tree` at line {st.span.line}")


class TreePlanner:
    """Plans one `tree` statement of a status body (`tick_plan._Body`)."""

    def __init__(self, tick, body):
        self.tick, self.body = tick, body
        self.info = tick.info.extra["trees"]
        self.at = tick.layout.at

    def step(self, st) -> tuple:
        tree = runtime_tree(self.tick.program, st)
        root = self.node(self.info.roots[st], tree.root)
        stamp = self.at(tree.stamp) if tree.memory else -1
        clocks = tuple(self.at(c) for c in tree.clocks)
        result = self.body.column()
        flag = self.tick.tree_flag(self.body, stamp) if tree.memory else -1
        return ("bt", root, stamp, clocks, result, self.tick.const("tick"), flag,
                self.at(LEAF_COLUMN), self.at(RESULT_COLUMN))

    def node(self, n, rt) -> tuple:
        from swarmdsl.compiler.tree_ast import Composite, Decorator, Subtree

        if isinstance(n, Subtree):
            return self.node(n.root, rt.root)
        if isinstance(n, Composite):
            kids = tuple(self.node(a, r) for a, r in zip(n.kids, rt.kids, strict=True))
            if n.kind == "parallel":
                halts = tuple(c for r in rt.kids for c in self.stamps(r))
                return ("par", rt.k, rt.reactive, self.at(rt.stamp), self.at(rt.value),
                        kids, halts)
            memory = rt.stateful
            return ("walk", rt.fallback, memory, self.at(rt.stamp) if memory else -1,
                    self.at(rt.value) if memory else -1,
                    tuple((k, r.can_run) for k, r in zip(kids, rt.kids, strict=True)))
        if isinstance(n, Decorator):
            child = self.node(n.child, rt.child)
            if n.kind in _MODES:
                return ("inv", _MODES[n.kind], child)
            count = self.count(n.count)
            if n.kind in ("repeat", "retry"):
                return ("rep", n.kind == "retry", self.at(rt.stamp), self.at(rt.value),
                        count, child)
            if n.kind == "timeout":
                return ("timeout", self.at(rt.stamp), self.at(rt.value), count, child,
                        self.stamps(rt.child))
            if n.kind == "cooldown":
                return ("cool", self.at(rt.ready), count, child)
            raise Unsupported(f"the tree node `{n.kind}`{_line(n)}")
        return (*self._leaf(n, rt), rt.leaf_id)

    def _leaf(self, n, rt) -> tuple:
        from swarmdsl.compiler.tree_ast import AssignLeaf

        if isinstance(n, AssignLeaf):
            return ("act", self.leaf(lambda inner: self.tick.assign(inner, n.stmt)))
        what, payload = self.info.leaves[n]
        if what == "cond":
            col = []
            steps = self.leaf(lambda inner: col.append(self.condition(inner, n.expr)))
            return ("cond", steps, col[0])
        if what == "action":
            return ("act", self.leaf(lambda inner: self.tick.statement(inner, payload)))
        if payload == "wait":
            return ("wait", self.at(rt.stamp), self.at(rt.value), self.count(n.expr.args[0]))
        if payload == "move_to":
            return self.move_to(n.expr)
        raise Unsupported(f"the long action `{payload}`{_line(n)}")

    def leaf(self, plan) -> tuple:
        """The steps `plan(inner)` adds to a body of the leaf's own (the status body's
        lets and neighbour sets in scope), run when the walk reaches the leaf."""
        inner = self.tick.inner_body(self.body)
        inner.in_tree = True
        plan(inner)
        return tuple(inner.steps)

    def condition(self, inner, e) -> int:
        got = inner.store(self.tick.lower(inner, e), boolean=True)
        return got[0][1]

    def move_to(self, call: ast.Call) -> tuple:
        args = call.args
        if self.tick.cg.type_of(args[0]) == REGION:
            raise Unsupported(f"`move_to` at a region{_line(call)}")
        cols = []

        def plan(inner):
            for a in args:
                cols.extend(leaf[1] for leaf in inner.store(self.tick.lower(inner, a)))
        steps = self.leaf(plan)
        tx, ty, tol, *speed = cols
        world = self.tick.program.world
        return ("move", steps, tx, ty, tol, speed[0] if speed else -1, self.tick.wraps,
                float(world.width), float(world.height), self.at("pos"), self.at("vel"),
                self.at("max_speed"))

    def count(self, e) -> int:
        """The state-table column of a constant count, rounded down as the reference's
        `_whole` rounds it (`forever`: infinity)."""
        from swarmdsl.compiler.tree_ast import Forever

        if isinstance(e, Forever):
            return self.tick.const(math.inf)
        try:
            v = float(const_value(e, self.tick.info.params))
        except (NotConstant, ArithmeticError, ValueError, TypeError):
            raise Unsupported(f"a tree count that is not a constant{_line(e)}") from None
        if not abs(v) <= limits.upper("tree count"):
            raise Unsupported(f"a tree count out of range{_line(e)}")
        return self.tick.const(float(math.floor(v)))

    def stamps(self, rt) -> tuple:
        """The stamp columns a halt of node `rt`'s subtree forgets (`Node.halt`)."""
        out = []
        stack = [rt]
        while stack:
            node = stack.pop()
            if node.stateful:
                out.append(self.at(node.stamp))
            stack.extend(node.children())
        return tuple(out)


def _line(node) -> str:
    span = getattr(node, "span", None)
    return f" at line {span.line}" if span is not None else ""
