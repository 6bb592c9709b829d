"""Which neighbour aggregates the compiled backend can fuse, and how: a plan per aggregate.

The plan lowers the checked AST of `AGG(source where c1 where c2 ... : each)` into scalar
expression trees (nested tuples) over five kinds of leaf:

- `("s", c)`: column `c` of the owner's table `S`. Every subexpression that depends on
  the owner only (its state, variables, `let` values, params, the tick, and pure
  built-ins of those) is *hoisted*: evaluated once per owner by the reference closures,
  not once per pair, and handed to the kernel as a column. Constants are hoisted too,
  so a plan's shape holds no numbers and programs that differ only in their params
  share compiled kernels.
- `("o", c)`: column `c` of the neighbours' table `O` (their start-of-tick state).
- `("d",)`, `("dx",)`, `("dy",)`: the pair's distance and `other.pos - pos`.

Subexpressions of the neighbour alone (`normalize(other.vel)`, `length(other.vel)`) are
hoisted the other way: column `("derived", (tree, base))` of `O` holds scalar tree
`tree` over the neighbour's own columns `base`, worked out once per agent a tick by a
compiled pass with the same functions (so the same bits), not once per pair.

Vectors are lowered to an (x, y) pair of scalar trees. Anything the kernels do not
cover (random draws per pair, fields, messages, nested aggregates, strings) raises
`Unsupported` with the reason, and that aggregate keeps the reference closure: never a
wrong answer, never an error. Building a plan imports nothing heavy.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import AGGREGATES, BOOL, FUNCTIONS, KIND, NUM, STATUS, VEC
from swarmdsl.compiler.facts import NodeTable
from swarmdsl.compiler.visit import Visitor
from swarmdsl.ops.operators import ARITHMETIC, COMPARISONS, NEGATE

# Name categories whose value depends on the owner only (safe to evaluate per owner).
_OWNER_NAMES = {"local", "var", "state", "const", "status", "kind", "global"}
# Expression trees bigger than this stay on the reference path (compile time grows
# with size; the nesting limit already keeps trees shallow).
MAX_NODES = 400
_NUMERIC = {NUM, STATUS, KIND}


# How `-v` names the expression forms the kernels do not lower (by syntax-tree class).
_UNCOMPILED = {"FieldAt": "a field read (`F at P`)", "StrLit": "a string",
               "Where": "a neighbour set"}


class Unsupported(Exception):
    """This aggregate (or a part of it) has no compiled form; the reason says why."""


@dataclass
class Plan:
    """One fused aggregate: its kernel's shape and what feeds its tables each call."""

    name: str                       # count, sum, mean, min, max, nearest, any, all, filter
    width: int                      # 1 for numbers and booleans, 2 for vectors
    cond: tuple                     # pair condition tree (all filters and-ed)
    each: tuple                     # (x,) or (x, y) value trees; () for count
    source: ast.Expr                # the innermost neighbour set (evaluated as usual)
    radius: ast.Expr | None         # `neighbors(r)`'s radius when the source is a call
    neighbors_call: bool            # the source is `neighbors(...)` itself
    hoisted: list = field(default_factory=list)   # (expr, type): the S columns
    others: list = field(default_factory=list)    # (category, column, type): O columns
    each_type: str | None = None

    @property
    def key(self) -> tuple:
        """The kernel's shape: equal keys compile to the same machine code."""
        return (self.name, self.width, self.cond, self.each)


def remap(tree: tuple, s_map, o_map) -> tuple:
    """`tree` with its owner columns (`s`, `sb`) renumbered by `s_map` and its
    neighbour columns (`o`, `ob`) by `o_map` (anything indexed by a column number): to
    read tables that several trees share, side by side."""
    op = tree[0]
    if op in ("s", "sb"):
        return (op, s_map[tree[1]])
    if op in ("o", "ob"):
        return (op, o_map[tree[1]])
    return (op, *(remap(t, s_map, o_map) if isinstance(t, tuple) else t for t in tree[1:]))


class Planner(Visitor):
    """Lowers a checked expression to scalar trees: `value` hoists what it can, and
    dispatches the rest by class (`visit_<Class>`, `visit.Visitor`)."""

    # No scalar tree per pair: the aggregate keeps its reference closure. (Numbers and
    # booleans are always hoisted as owner columns before dispatch.)
    REFUSED = frozenset({*_UNCOMPILED, "Num", "BoolLit", "TreeResult", "Forever"})

    def __init__(self, cg, wraps: bool):
        self.cg = cg
        self.wraps = wraps
        self.s_cols = NodeTable()    # hoisted expression -> its first S column
        self.s_named: dict = {}      # "limit", the own position -> its first S column
        self.s_width = 0
        self.o_cols: dict = {}       # (category, column) -> first O column
        self.o_width = 0
        self.plan: Plan | None = None
        self.nodes = 0
        self.derive = True   # hoist the neighbour's own subexpressions (`_derived`)

    def type_of(self, e) -> str:
        return self.cg.type_of(e)

    def res(self, e):
        return self.cg.facts.name_of(e, ())

    # ---- the aggregate ----
    def aggregate(self, e: ast.Call) -> Plan:
        if e.name not in AGGREGATES:
            raise Unsupported(f"`{e.name}` is not an aggregate")
        conds, src = [], e.args[0]
        while isinstance(src, ast.Where):
            conds.append(src.cond)
            src = src.source
        conds.reverse()
        call = isinstance(src, ast.Call) and self.res(src)[:1] == ("neighbors",)
        if not call and self.res(src)[:1] != ("local",):
            raise Unsupported("its neighbour set comes from an extension")
        each_type = self.type_of(e.each) if e.each is not None else None
        width = 2 if each_type == VEC else 1
        plan = Plan(e.name, width, (), (), src, src.args[0] if call and src.args else None,
                    call, each_type=each_type)
        self.plan = plan
        tree = ("true",)
        if call:  # the sense / radius limit of `neighbors(r)`, fused as a condition
            tree = ("le", ("d",), self._column("limit", NUM))
        for c in conds:
            tree = self._and(tree, self.boolean(c))
        plan.cond = tree
        if e.each is not None:
            # `nearest` evaluates its value at one pair per owner: nothing to save there
            self.derive = e.name != "nearest"
            plan.each = self.value(e.each)
        return self._sized(plan)

    def filter(self, e: ast.Where) -> Plan:
        """`SET where COND` on its own (a `let` of a filtered set): one pair condition,
        its source evaluated as usual at run time."""
        plan = self.plan = Plan("filter", 1, (), (), e.source, None, False)
        plan.cond = self.boolean(e.cond)
        return self._sized(plan)

    def _sized(self, plan: Plan) -> Plan:
        if self.nodes > MAX_NODES:
            raise Unsupported(f"its expressions are too large to compile ({self.nodes} "
                              f"nodes, limit {MAX_NODES})")
        return plan

    @staticmethod
    def _and(a, b):
        return b if a == ("true",) else ("and", a, b)

    def _column(self, key, vtype: str):
        """S column(s) for a hoisted value: `key` is an expression or "limit"."""
        plan = self.plan
        cols = self.s_named if isinstance(key, str) else self.s_cols
        if key not in cols:
            cols[key] = self.s_width
            plan.hoisted.append((key, vtype))
            self.s_width += 2 if vtype == VEC else 1
        c = cols[key]
        if vtype == VEC:
            return (("s", c), ("s", c + 1))
        return ("sb", c) if vtype == BOOL else ("s", c)

    def _other(self, cat: str, col: str, vtype: str):
        slot = (cat, col)
        if slot not in self.o_cols:
            self.o_cols[slot] = self.o_width
            self.plan.others.append((cat, col, vtype))
            self.o_width += 2 if vtype == VEC else 1
        c = self.o_cols[slot]
        if vtype == VEC:
            return (("o", c), ("o", c + 1))
        return ("ob", c) if vtype == BOOL else ("o", c)

    # ---- lowering: value(e) -> (x,) for numbers/booleans, (x, y) for vectors ----
    def boolean(self, e) -> tuple:
        return self.value(e)[0]

    def value(self, e) -> tuple:
        self.nodes += 1
        t = self.type_of(e)
        if t not in (NUM, BOOL, VEC, STATUS, KIND):
            raise Unsupported(f"it uses {t} values per pair")
        if self.owner_only(e):
            got = self._column(e, VEC if t == VEC else (BOOL if t == BOOL else NUM))
            return got if t == VEC else (got,)
        if self.derive and not isinstance(e, ast.Attr) and self.neighbour_only(e):
            got = self._derived(e, t)
            if got is not None:
                return got
        return self.visit(e)

    def refuse(self, e):
        what = _UNCOMPILED.get(type(e).__name__, "this expression")
        raise Unsupported(f"{what} has no compiled form per pair")

    def owner_only(self, e) -> bool:
        """True when `e` depends on the owner alone (no `other`, `dist` or draws)."""
        def leaf(n):
            if isinstance(n, ast.Num | ast.BoolLit):
                return True
            if isinstance(n, ast.Name):
                res = self.res(n)
                return bool(res) and res[0] in _OWNER_NAMES and self.type_of(n) in (
                    NUM, BOOL, VEC, STATUS, KIND)
            return False if isinstance(n, ast.Attr) else None
        return self._only(e, leaf, compiled=False)

    def neighbour_only(self, e) -> bool:
        """True when `e` depends on the neighbour's own columns alone: no owner value,
        no number (numbers are owner columns), no pair value, no draw. (`x ^ 2` is
        a product, and holds no number.)"""
        def leaf(n):
            if isinstance(n, ast.Attr):   # in a wrap-around world `other.pos` is a pair value
                res = self.res(n)
                return res[:1] in (("other_state",), ("other_var",)) and not (
                    self.wraps and res[1:2] == ("pos",))
            return False if isinstance(n, ast.Num | ast.BoolLit | ast.Name) else None
        return self._only(e, leaf, compiled=True)

    def _only(self, e, leaf, compiled: bool) -> bool:
        """Whether every leaf of `e` passes `leaf` (True or False; None: not a leaf) and
        every call in it is a pure built-in (with `compiled`: one the kernels compile;
        without, the reference closures compute the hoisted value)."""
        stack = [e]
        while stack:
            n = stack.pop()
            if isinstance(n, ast.Attr) and self.res(n)[:1] == ("component",):
                stack.append(n.obj)
                continue
            got = leaf(n)
            if got is not None:
                if not got:
                    return False
                continue
            if isinstance(n, ast.Call):
                if not self._pure_call(n) or compiled and not FUNCTIONS[n.name].compiled:
                    return False
                stack.extend(n.args)
            elif (isinstance(n, ast.BinOp) and n.op == "^"
                  and isinstance(n.right, ast.Num) and n.right.value == 2):
                stack.append(n.left)   # a product (visit_BinOp), not a power of 2
            elif isinstance(n, ast.Vec | ast.BinOp | ast.Chain | ast.Neg | ast.Compare
                            | ast.AndOp | ast.OrOp | ast.NotOp | ast.Cond):
                stack.extend(n.children())
            else:
                return False
        return True

    def _derived(self, e, t):
        """`e`'s value trees with each non-trivial one read from a derived column of
        `O`; None when there is nothing to save (every part is a plain column)."""
        sub = Planner(self.cg, self.wraps)
        sub.plan = Plan("derived", 1, (), (), None, None, False)
        sub.derive = False
        trees = sub.value(e)
        self.nodes += sub.nodes
        if sub.plan.hoisted or all(tree[0] in ("o", "ob") for tree in trees):
            return None
        base = tuple(sub.plan.others)
        out = []
        for tree in trees:
            if tree[0] in ("o", "ob"):   # a plain column: the neighbour's own
                at = 0
                for cat, col, vt in base:
                    w = 2 if vt == VEC else 1
                    if at <= tree[1] < at + w:
                        got = self._other(cat, col, vt)
                        out.append(got[tree[1] - at] if vt == VEC else got)
                        break
                    at += w
                continue
            vt = BOOL if t == BOOL else NUM
            out.append(self._other("derived", (tree, base), vt))
        return tuple(out)

    def _pure_call(self, n) -> bool:
        """Whether call `n` is a built-in the kernels compile: no draw, no aggregate,
        nothing an extension computes."""
        b = FUNCTIONS.get(n.name)
        return not (b is None or b.random or self.cg.extension_call(n.name)
                    or self.res(n)[:1] in (("agg",), ("neighbors",)))

    def _pos_of_other(self):
        """`other.pos`: the neighbour's nearest image in a wrap-around world."""
        if self.wraps:
            own = self._own_pos()
            return (("add", own[0], ("dx",)), ("add", own[1], ("dy",)))
        return self._other("other_state", "pos", VEC)

    def _own_pos(self):
        return self._column(_OWN_POS, VEC)

    def visit_Name(self, e):
        res = self.res(e)
        if res[:1] == ("pair",):
            return (("d",),)
        raise Unsupported(f"`{e.id}` has no compiled form per pair")

    def visit_Attr(self, e):
        res = self.res(e)
        cat = res[0] if res else None
        if cat == "component":
            return (self.value(e.obj)[res[1]],)
        if cat == "other_state" and res[1] == "pos":
            return self._pos_of_other()
        if cat in ("other_state", "other_var"):
            t = self.type_of(e)
            vt = VEC if t == VEC else (BOOL if t == BOOL else NUM)
            got = self._other(cat, res[1], vt)
            return got if vt == VEC else (got,)
        raise Unsupported(f"`.{e.name}` has no compiled form per pair")

    def visit_Vec(self, e):
        return (self.value(e.x)[0], self.value(e.y)[0])

    def _is_pos(self, e, other=False):
        return self.cg._is_pos(e, other=other)

    def visit_BinOp(self, e):
        # `other.pos - pos` and `pos - other.pos` read the pair's delta, exactly as the
        # reference closures do (codegen.visit_BinOp, PairFrame.other_minus_own_pos).
        if e.op == "-" and self._is_pos(e.left, other=True) and self._is_pos(e.right):
            return self._delta()
        if e.op == "-" and self._is_pos(e.left) and self._is_pos(e.right, other=True):
            return tuple(("sub", ("zero",), x) for x in self._delta())
        if e.op == "^" and isinstance(e.right, ast.Num) and e.right.value == 2:
            x = self.value(e.left)   # a square: one product, where pow() is a libm call
            return self._arith("mul", x, x)
        return self._arith(ARITHMETIC[e.op].node, self.value(e.left), self.value(e.right))

    def _delta(self):
        if not self.wraps:
            return (("dx",), ("dy",))
        own = self._own_pos()
        return tuple(("sub", x, o) for x, o in zip(self._pos_of_other(), own, strict=True))

    @staticmethod
    def _arith(op, a, b):
        if len(a) == 1 and len(b) == 1:
            return ((op, a[0], b[0]),)
        if len(a) == 1:
            return tuple((op, a[0], y) for y in b)
        if len(b) == 1:
            return tuple((op, x, b[0]) for x in a)
        return tuple((op, x, y) for x, y in zip(a, b, strict=True))

    def visit_Chain(self, e):
        first = self.value(e.first)
        if e.rest[0][0] in ("and", "or"):
            acc = first[0]
            for op, term in e.rest:
                acc = (op, acc, self.boolean(term))
            return (acc,)
        acc = first
        for op, term in e.rest:
            acc = self._arith(ARITHMETIC[op].node, acc, self.value(term))
        return acc

    def visit_Neg(self, e):
        return tuple((NEGATE.node, x) for x in self.value(e.operand))

    def visit_Compare(self, e):
        a, b = self.value(e.left), self.value(e.right)
        if len(a) == 2:
            if e.op == "==":
                return (("and", ("eq", a[0], b[0]), ("eq", a[1], b[1])),)
            return (("or", ("ne", a[0], b[0]), ("ne", a[1], b[1])),)
        return ((COMPARISONS[e.op].node, a[0], b[0]),)

    def visit_AndOp(self, e):
        return (("and", self.boolean(e.left), self.boolean(e.right)),)

    def visit_OrOp(self, e):
        return (("or", self.boolean(e.left), self.boolean(e.right)),)

    def visit_NotOp(self, e):
        return (("not", self.boolean(e.operand)),)

    def visit_Cond(self, e):
        t = self.boolean(e.test)
        a, b = self.value(e.then), self.value(e.orelse)
        if len(a) != len(b):
            raise Unsupported("its two branches have different types")
        return tuple(("if", t, x, y) for x, y in zip(a, b, strict=True))

    def visit_Call(self, e):
        b = FUNCTIONS.get(e.name)
        if b is None or self.cg.extension_call(e.name) or self.res(e)[:1] in (("agg",),
                                                                           ("neighbors",)):
            raise Unsupported(f"`{e.name}(...)` has no compiled form per pair")
        if b.random:
            raise Unsupported(f"`{e.name}()` draws random numbers per pair")
        if not b.compiled:
            raise Unsupported(f"`{e.name}(...)` has no compiled form")
        return b.trees(*(self.value(a) for a in e.args))


_OWN_POS = "pos"   # the S slot of the owner's own position (wrap-around `other.pos`)


def plan_aggregate(cg, e: ast.Call, wraps: bool) -> Plan:
    """The fused plan of aggregate call `e`, or `Unsupported` saying why there is none."""
    return Planner(cg, wraps).aggregate(e)


def plan_filter(cg, e: ast.Where, wraps: bool) -> Plan:
    """The fused plan of neighbour filter `e`, or `Unsupported` saying why there is none."""
    return Planner(cg, wraps).filter(e)
