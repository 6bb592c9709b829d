"""Which per-agent statements the compiled backend can fuse: a plan per `let` or assignment.

A status body's straight-line arithmetic (`let steer = (0.9 * sep + ...) / max(...)`,
`velocity = rotate(normalize(...) * cruise, normal(0, wander))`) costs one or more
whole-array passes per operator on the reference closures. The plan lowers the
statement's value into the same scalar trees as an aggregate's (`plan.Planner`), over
one agent instead of one pair, so a kernel can compute it in one loop over the agents.

Leaves:

- `("s", c)`: column `c` of the agents' table `S`. Reads of state, variables, `let`
  values, and every subexpression the trees do not cover (random draws, aggregates,
  field reads, calls an extension compiles, and the built-ins numpy computes faster
  than a scalar loop) are *hoisted*: the reference closures
  evaluate them, in source order, and hand them to the kernel as columns. Random draws
  thus come from the same per-agent streams as on the numpy backend.
- `("o", c)`: entry `c` of the statement's constants (numbers, params, status codes,
  `tick`), read as row 0 of a (1, k) table. A plan's shape holds no numbers, so programs
  that differ only in their params share compiled kernels.

A statement too small to repay a kernel, or one whose value does not depend on the
agent, raises `Unsupported` and keeps its reference closure.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from swarmdsl.compiler import ast, draws
from swarmdsl.compiler.builtins import BOOL, FUNCTIONS, KIND, NUM, STATUS, VEC
from swarmdsl.ops.operators import COMPARISONS
from swarmdsl.runtime.compiled.plan import MAX_NODES, Planner, Unsupported

# Fewer operations than this (the assignment's own `+=` included) stay on numpy: one
# or two whole-array passes cost less than gathering the columns for a kernel.
MIN_OPS = 3
# Trees (shared subtrees counted at each use) larger than this take long to compile.
MAX_TREE = 600
_VALUES = (NUM, BOOL, VEC, STATUS, KIND)
# Expression classes the trees lower (their children are lowered in turn).
_LOWERED = (ast.Vec, ast.BinOp, ast.Chain, ast.Neg, ast.Compare, ast.AndOp, ast.OrOp,
            ast.NotOp, ast.Cond)
# Name categories read per agent through the frame, as the reference closures read them.
_COLUMNS = {"local", "var", "state"}
# `^` other than `^ 2` (a product) is hoisted like a draw: numpy computes it as a column.


@dataclass
class StatementPlan:
    """One fused statement: its kernel's shape and what feeds its tables each call."""

    what: str                    # "let" or "assign"
    op: str                      # "=", "+=", "-=", "*=", "/=" ("=" for a let)
    width: int                   # result columns: 1 for a number, 2 for a vector
    value: tuple                 # (x,) or (x, y) value trees
    columns: list = field(default_factory=list)   # (expr, type): the S columns, in order
    consts: list = field(default_factory=list)    # floats, or expr for `tick`: K entries
    stages: tuple = ()           # (column, tree): shared subtrees, stored before use
    ops: int = 0

    @property
    def key(self) -> tuple:
        """The kernel's shape: equal keys compile to the same machine code."""
        return (self.what, self.op, self.width, self.value, self.stages)


class StatementPlanner(Planner):
    """The aggregate planner's lowering, with every agent-level leaf a column."""

    def __init__(self, cg):
        super().__init__(cg, wraps=False)
        self.columns: list = []
        self.consts: list = []
        self.slots: dict = {}      # resolution of a name read -> its first S column

    def statement(self, what: str, op: str, width: int, value: ast.Expr) -> StatementPlan:
        trees = self.value(value)
        if len(trees) > width:
            raise Unsupported("its value is wider than its target")
        if self.nodes > MAX_NODES:
            raise Unsupported("its expression is too large to compile")
        if not self.columns:
            raise Unsupported("its value is the same for every agent")
        stages, trees = _share(trees, sum(2 if t == VEC else 1 for _e, t in self.columns))
        every = [*trees, *(t for _c, t in stages)]
        if sum(_size(t) for t in every) > MAX_TREE:
            raise Unsupported("its expression is too large to compile")
        ops = sum(_ops(t) for t in every) + (op != "=")
        if ops < MIN_OPS:
            raise Unsupported(f"{ops} operation(s) gain nothing from a kernel")
        return StatementPlan(what, op, width, trees, self.columns, self.consts, stages, ops)

    # ---- leaves ----
    def _agent_column(self, e, vtype: str, slot=None):
        """S column(s) for a value read per agent; `slot` shares repeated reads."""
        if slot is not None and slot in self.slots:
            c = self.slots[slot]
        else:
            c = sum(2 if t == VEC else 1 for _e, t in self.columns)
            self.columns.append((e, vtype))
            if slot is not None:
                self.slots[slot] = c
        if vtype == VEC:
            return (("s", c), ("s", c + 1))
        return (("sb", c),) if vtype == BOOL else (("s", c),)

    def _const(self, value, vtype: str):
        """A K entry per occurrence (never shared by value: the shape holds no numbers)."""
        c = len(self.consts)
        self.consts.append(value)
        return (("ob", c),) if vtype == BOOL else (("o", c),)

    def _opaque(self, e):
        t = self.type_of(e)
        return self._agent_column(e, VEC if t == VEC else (BOOL if t == BOOL else NUM))

    # ---- lowering ----
    def value(self, e) -> tuple:
        self.nodes += 1
        t = self.type_of(e)
        if t not in _VALUES:
            raise Unsupported(f"it computes with {t} values")
        if isinstance(e, ast.Num):
            return self._const(float(e.value), NUM)
        if isinstance(e, ast.BoolLit):
            return self._const(1.0 if e.value else 0.0, BOOL)
        if isinstance(e, ast.Name):
            return self._name(e, t)
        if isinstance(e, ast.Attr) and self.res(e)[:1] == ("component",):
            return (self.value(e.obj)[self.res(e)[1]],)
        if (isinstance(e, _LOWERED) and not _power(e)
                and all(self.type_of(c) in _VALUES for c in e.children())):
            if draws.guarded(e, self.cg.info.params):
                # hoisted, the draw's arguments would be checked for every agent
                raise Unsupported("an `if`, `and` or `or` decides where a draw is checked")
            return self.visit(e)
        if isinstance(e, ast.Call) and self._pure(e):
            return self.visit_Call(e)
        return self._opaque(e)   # draws, aggregates, fields, extensions: numpy's value

    def _name(self, e, t: str):
        res = self.res(e)
        cat = res[0] if res else None
        if cat == "const" and isinstance(res[1], bool | int | float):
            return self._const(float(res[1]), BOOL if t == BOOL else NUM)
        if cat == "status":
            return self._const(float(self.cg.info.status_name_id(res[1])), NUM)
        if cat == "kind":   # a kind's name: its index, as the reference has it
            return self._const(float(res[1]), NUM)
        if cat == "global":
            return self._const(e, NUM)       # `tick`: read once per call
        if cat in _COLUMNS:
            return self._agent_column(e, VEC if t == VEC else (BOOL if t == BOOL else NUM),
                                      slot=tuple(res[:2]))
        return self._opaque(e)

    def _pure(self, e: ast.Call) -> bool:
        """A built-in the trees compute (no draw, no aggregate, no extension)."""
        b = FUNCTIONS.get(e.name)
        return (b is not None and b.compiled
                and not self.cg.extension_call(e.name)
                and self.res(e)[:1] not in (("agg",), ("neighbors",))
                and all(self.type_of(a) in _VALUES for a in e.args))


def _power(e) -> bool:
    """`a ^ b` other than a square (the aggregate planner lowers `^ 2` to a product)."""
    return (isinstance(e, ast.BinOp) and e.op == "^"
            and not (isinstance(e.right, ast.Num) and e.right.value == 2))


_LEAVES = {"s", "sb", "o", "ob"}
_BOOLEAN = {*(op.node for op in COMPARISONS.values()), "and", "or", "not", "sb", "ob"}


def _share(trees: tuple, first: int) -> tuple[tuple, tuple]:
    """(stages, trees): every subtree used more than once (`normalize`'s length, the
    `cos` and `sin` of `rotate`, a vector both components read) computed once per
    agent into its own S column, from `first` on, and read back as a leaf by its users.
    The lowering shares such subtrees as one tuple object; expanded, a nest of
    `rotate(normalize(...))` grows fourfold per level, and numba's compile time with
    it. Storing a float and reading it back changes no bit."""
    refs: dict = {}
    order: list = []     # unique subtrees, children before parents
    stack = [(t, False) for t in reversed(trees)]
    for t in trees:
        refs[id(t)] = refs.get(id(t), 0) + 1
    seen: set = set()
    while stack:
        t, done = stack.pop()
        if done:
            order.append(t)
            continue
        if id(t) in seen:
            continue
        seen.add(id(t))
        stack.append((t, True))
        for c in t[1:]:
            if isinstance(c, tuple):
                refs[id(c)] = refs.get(id(c), 0) + 1
                stack.append((c, False))
    stages, new = [], {}
    for t in order:
        if t[0] in _LEAVES:
            new[id(t)] = t
            continue
        rebuilt = (t[0], *(new[id(c)] if isinstance(c, tuple) else c for c in t[1:]))
        if refs[id(t)] > 1:
            col = first + len(stages)
            stages.append((col, rebuilt))
            rebuilt = ("sb" if _boolean(rebuilt) else "s", col)
        new[id(t)] = rebuilt
    return tuple(stages), tuple(new[id(t)] for t in trees)


def _boolean(tree) -> bool:
    if tree[0] == "if":
        return _boolean(tree[2])
    return tree[0] in _BOOLEAN


def _size(tree) -> int:
    return 1 + sum(_size(t) for t in tree[1:] if isinstance(t, tuple))


def _ops(tree) -> int:
    if tree[0] in _LEAVES:
        return 0
    return 1 + sum(_ops(t) for t in tree[1:] if isinstance(t, tuple))


def plan_statement(cg, st, target_type: str | None = None) -> StatementPlan:
    """The fused plan of a number or vector `let`, or of an assignment to a number or
    vector column (`target_type`), or `Unsupported` saying why there is none."""
    vtype = cg.type_of(st.value)
    if vtype not in (NUM, VEC):
        raise Unsupported(f"it computes a {vtype}")
    if isinstance(st, ast.LetStmt):
        return StatementPlanner(cg).statement("let", "=", 2 if vtype == VEC else 1,
                                              st.value)
    if target_type not in (NUM, VEC):
        raise Unsupported(f"its target holds a {target_type}")
    return StatementPlanner(cg).statement("assign", st.op, 2 if target_type == VEC else 1,
                                          st.value)
