"""The values a metric can take, read off its checked expression, for plots' axes.

A plot that draws a fraction's spread as mean +- sd ran from -0.15 to 1.10; a band,
a point or an axis must stay within what the metric can be. This is interval
arithmetic over the metric's expression, conservative: a bound is given only where
the expression guarantees it (a condition or `mean` of one: [0, 1]; `count`: >= 0;
`length(mean(normalize(vel)))`: [0, 1]; `count(C) / count()` and `largest_cluster(R)
/ count()`: [0, 1]; params and numbers: their values), and left open (None) where it
cannot know. `plot` clips to the bounds it is given and to the data elsewhere.
"""

from __future__ import annotations

import math

from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import BOOL, VEC
from swarmdsl.compiler.facts import Facts
from swarmdsl.compiler.visit import Visitor

INF = math.inf
FULL = (-INF, INF)
UNIT = (0.0, 1.0)
_NON_NEGATIVE = {"sqrt", "exp", "hypot", "distance", "length", "abs"}
_MONOTONE = {"floor": math.floor, "ceil": math.ceil, "round": round}


def metric_bounds(expr: ast.Expr, facts: Facts,
                  params: dict) -> tuple[float | None, float | None]:
    """(low, high) of a checked metric expression: the least and most it can be,
    None where it is not known."""
    lo, hi = _Ranges(facts, params).of(expr)
    if not lo <= hi:    # an empty or NaN range: know nothing rather than something wrong
        return None, None
    return (None if lo == -INF else float(lo)), (None if hi == INF else float(hi))


class _Ranges(Visitor):
    """The interval of each expression class (`visit_<Class>`); the classes in
    `REFUSED` have no bound this knows of (conditions are caught by type first)."""

    REFUSED = frozenset({"BoolLit", "StrLit", "Vec", "Compare", "AndOp", "OrOp",
                         "NotOp", "Where", "FieldAt", "TreeResult", "Forever"})

    def __init__(self, facts: Facts, params: dict):
        self.facts, self.params = facts, params

    def of(self, e: ast.Expr) -> tuple[float, float]:
        """The interval of a number (a condition: [0, 1])."""
        if self.facts.type_of(e) == BOOL:
            return UNIT
        return self.visit(e)

    def refuse(self, e: ast.Expr) -> tuple[float, float]:
        return FULL

    def visit_Num(self, e: ast.Num) -> tuple[float, float]:
        return float(e.value), float(e.value)

    def visit_Name(self, e: ast.Name) -> tuple[float, float]:
        v = self.params.get(e.id) if e.id in self.params else None
        if isinstance(v, int | float) and not isinstance(v, bool):
            return float(v), float(v)
        return (0.0, INF) if e.id == "speed" else FULL

    def visit_Neg(self, e: ast.Neg) -> tuple[float, float]:
        lo, hi = self.of(e.operand)
        return -hi, -lo

    def visit_Cond(self, e: ast.Cond) -> tuple[float, float]:
        return _union(self.of(e.then), self.of(e.orelse))

    def visit_Attr(self, e: ast.Attr) -> tuple[float, float]:
        if e.name not in ("x", "y"):
            return FULL
        b = self.norm(e.obj)
        return -b, b

    def visit_BinOp(self, e: ast.BinOp) -> tuple[float, float]:
        return self._binop(e.op, e.left, e.right)

    def visit_Chain(self, e: ast.Chain) -> tuple[float, float]:
        if any(op not in "+-*" for op, _ in e.rest):
            return FULL
        acc = self.of(e.first)
        for op, term in e.rest:
            acc = _arith(op, acc, self.of(term))
        return acc

    def visit_Call(self, e: ast.Call) -> tuple[float, float]:
        return self._call(e)

    def _binop(self, op: str, left: ast.Expr, right: ast.Expr) -> tuple[float, float]:
        if op == "/" and self._share(left, right):
            return UNIT
        a, b = self.of(left), self.of(right)
        if op in "+-*":
            return _arith(op, a, b)
        if op == "/" and (b[0] > 0 or b[1] < 0):
            qs = [x / y for x in a for y in b if math.isfinite(x) and math.isfinite(y)]
            if len(qs) == 4:
                return min(qs), max(qs)
            if a[0] >= 0 and b[0] > 0:
                return 0.0, INF
        if op == "%" and b[0] == b[1] and b[0] > 0:     # floored: [0, c]
            return 0.0, b[0]
        return FULL

    def _share(self, left: ast.Expr, right: ast.Expr) -> bool:
        """`count(C) / count()` or `largest_cluster(R, ...) / count()`: a part of the
        agents over all of them (both reduce over the same agents: the metric's)."""
        if not (isinstance(right, ast.Call) and right.name == "count" and not right.args
                and self._agg(right) == "count"):
            return False
        if isinstance(left, ast.Call) and left.name == "count" and \
                self._agg(left) == "count":
            return True
        return isinstance(left, ast.Call) and left.name == "largest_cluster" and \
            self.facts.name_of(left, ())[:1] == ("swarm_measure",)

    def _agg(self, e: ast.Call) -> str | None:
        res = self.facts.name_of(e)
        return res[1] if res is not None and res[0] == "swarm_agg" else None

    def _call(self, e: ast.Call) -> tuple[float, float]:
        agg = self._agg(e)
        if agg is not None:
            if agg == "count":
                return 0.0, INF
            if agg in ("all", "any"):
                return UNIT
            each = self.of(e.args[0]) if e.args else FULL
            if agg == "sum":
                return (0.0, INF) if each[0] >= 0 else (-INF, 0.0) if each[1] <= 0 else FULL
            # mean, min, max: among the values; of no agents the `else` or 0
            empty = self.of(e.default) if e.default is not None else (0.0, 0.0)
            return _union(each, empty)
        if self.facts.name_of(e, ())[:1] == ("swarm_measure",):
            low = (0.0, INF)
            return _union(low, self.of(e.default)) if e.default is not None else low
        args = [self.of(a) if self.facts.type_of(a) != VEC else None for a in e.args]
        name = e.name
        if name == "length" and e.args:
            return 0.0, self.norm(e.args[0])
        if name in _NON_NEGATIVE:
            if name == "abs" and args and args[0] is not None:
                lo, hi = args[0]
                top = max(abs(lo), abs(hi))
                return (0.0 if lo <= 0 <= hi else min(abs(lo), abs(hi))), top
            return 0.0, INF
        if name in ("sin", "cos", "sign"):
            return -1.0, 1.0
        if name in ("atan2", "angle"):
            return -math.pi, math.pi
        if name in _MONOTONE and args and args[0] is not None:
            f = _MONOTONE[name]
            lo, hi = args[0]
            return (f(lo) if math.isfinite(lo) else lo), (f(hi) if math.isfinite(hi) else hi)
        if name in ("min", "max") and len(args) == 2 and None not in args:
            pick = min if name == "min" else max
            return pick(args[0][0], args[1][0]), pick(args[0][1], args[1][1])
        if name == "clamp" and len(args) == 3 and None not in args:
            return max(args[0][0], args[1][0]), min(args[0][1], args[2][1])
        if name in ("dot", "cross") and len(e.args) == 2:
            b = self.norm(e.args[0]) * self.norm(e.args[1])
            return (-b, b) if math.isfinite(b) else FULL
        return FULL

    def norm(self, e: ast.Expr) -> float:
        """The most a vector's length can be (inf where unknown)."""
        if isinstance(e, ast.Call):
            agg = self._agg(e)
            if agg == "mean" and e.args:    # a mean is no longer than its longest term
                inner = self.norm(e.args[0])
                return max(inner, self.norm(e.default)) if e.default is not None else inner
            if e.name in ("normalize", "normalise", "unit") and agg is None:
                return 1.0
            if e.name == "rotate" and e.args:
                return self.norm(e.args[0])
            if e.name == "vec" and len(e.args) == 2:
                return self._vec_norm(e.args[0], e.args[1])
            return INF
        if isinstance(e, ast.Vec):
            return self._vec_norm(e.x, e.y)
        if isinstance(e, ast.Neg):
            return self.norm(e.operand)
        if isinstance(e, ast.BinOp) and e.op in "+-":
            return self.norm(e.left) + self.norm(e.right)
        if isinstance(e, ast.BinOp) and e.op == "*":
            vec_left = self.facts.type_of(e.left) == VEC
            v, s = (e.left, e.right) if vec_left else (e.right, e.left)
            lo, hi = self.of(s)
            return self.norm(v) * max(abs(lo), abs(hi))
        if isinstance(e, ast.Cond):
            return max(self.norm(e.then), self.norm(e.orelse))
        return INF

    def _vec_norm(self, x: ast.Expr, y: ast.Expr) -> float:
        bx, by = (max(abs(v) for v in self.of(c)) for c in (x, y))
        return math.hypot(bx, by)


def _union(a: tuple[float, float], b: tuple[float, float]) -> tuple[float, float]:
    return min(a[0], b[0]), max(a[1], b[1])


def _arith(op: str, a: tuple[float, float], b: tuple[float, float]) -> tuple[float, float]:
    if op == "+":
        out = [a[0] + b[0], a[1] + b[1]]
    elif op == "-":
        out = [a[0] - b[1], a[1] - b[0]]
    else:
        products = [x * y for x in a for y in b]
        out = [min(products), max(products)]
        if any(math.isnan(p) for p in products):    # inf * 0: anything
            return FULL
    if any(math.isnan(v) for v in out):     # inf - inf: anything
        return FULL
    return out[0], out[1]


__all__ = ["metric_bounds"]
