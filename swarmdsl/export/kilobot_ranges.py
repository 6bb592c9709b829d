"""Which numbers a Kilobot message can carry: the range each broadcast value may take,
found by interval arithmetic over the checked program, against the 16-bit whole
numbers a message sends.

A message sends a number rounded to a whole one from -32768 to 32767 (2 bytes): a value
beyond saturates at that end. The language declares no range, so the exporter bounds
each value it sends from what it is made of: constants and params, `tick` (up to the
world's `steps`), ids, measured distances (0 to 255 mm), received values (16-bit), counts
of the neighbour table, draws, and variables (their initial value and every value
assigned them, to a fixed point; one that can keep growing is unbounded). A value it
cannot show to fit is warned about at the broadcast, located: it may be sent saturated.
A belief is unbounded here (odometry carries it anywhere), so a program sending
positions is told that one beyond 32.7 m from its origin saturates.
"""

from __future__ import annotations

import math

from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import NUM, VEC
from swarmdsl.errors import SwarmError

LOW, HIGH = -32768, 32767
_ALL = (-math.inf, math.inf)
_ROUNDS = 12         # passes to a fixed point (what still grows every 4 is widened)


def _hull(*ranges):
    return (min(r[0] for r in ranges), max(r[1] for r in ranges))


def _mul(a, b):
    products = [x * y if not (x == 0 or y == 0) else 0.0 for x in a for y in b]
    return (min(products), max(products))


class _Ranges:
    """Interval arithmetic over one kind's expressions (numbers; a vector a pair)."""

    def __init__(self, info, kind, robots: int):
        self.info, self.kind, self.robots = info, kind, robots
        self.vars = {}                  # variable name -> range so far
        self.lets: dict[str, tuple] = {}

    def res(self, node) -> tuple:
        return self.info.facts.name_of(node, ("",))

    def num(self, e) -> tuple:
        """The range of a number-valued expression (unbounded when unknown)."""
        try:
            r = self._num(e)
        except (ArithmeticError, ValueError):
            return _ALL
        return _ALL if any(math.isnan(x) for x in r) else r

    def _num(self, e) -> tuple:
        if isinstance(e, ast.Num):
            return (float(e.value), float(e.value))
        if isinstance(e, ast.Name):
            res = self.res(e)
            if res[0] == "const":
                v = float(res[1])
                return (v, v)
            if res[0] == "var":
                return self.vars.get(e.id, _ALL)
            if res[0] == "local":
                return self.lets.get(e.id, _ALL)
            if res[0] == "global" and e.id == "tick":
                return (0.0, float(self.info.world.steps))
            if res[0] == "state" and res[1] in ("id", "index"):
                return (0.0, float(max(self.robots - 1, 0)))
            if res[0] == "pair" and e.id == "dist":
                return (0.0, 255.0)
            return _ALL
        if isinstance(e, ast.Attr):
            if self.res(e)[0] == "msg_value":
                return (float(LOW), float(HIGH))
            return _ALL
        if isinstance(e, ast.Neg):
            lo, hi = self.num(e.operand)
            return (-hi, -lo)
        if isinstance(e, ast.BinOp):
            return self._op(e.op, self.num(e.left), self.num(e.right))
        if isinstance(e, ast.Chain):
            r = self.num(e.first)
            for op, term in e.rest:
                r = self._op(op, r, self.num(term))
            return r
        if isinstance(e, ast.Cond):
            return _hull(self.num(e.then), self.num(e.orelse))
        if isinstance(e, ast.Call):
            return self._call(e)
        return _ALL

    def _op(self, op, a, b) -> tuple:
        if op == "+":
            return (a[0] + b[0], a[1] + b[1])
        if op == "-":
            return (a[0] - b[1], a[1] - b[0])
        if op == "*":
            return _mul(a, b)
        if op == "%" and b[0] > 0:
            return (0.0, b[1])
        if op == "%" and b[1] < 0:
            return (b[0], 0.0)
        if op == "/" and (b[0] > 0 or b[1] < 0):
            return _mul(a, (1 / b[1], 1 / b[0]))
        return _ALL

    def _call(self, e: ast.Call) -> tuple:
        res = self.res(e)
        if res[0] == "agg":
            if e.name == "count":
                return (0.0, 8.0)             # the neighbour table's entries
            parts = [self.num(e.each)] if e.each is not None else [_ALL]
            if e.default is not None:
                parts.append(self.num(e.default))
            if e.name in ("min", "max", "mean", "nearest"):
                return _hull(*parts)
            if e.name == "sum":
                lo, hi = parts[0]
                return _hull((min(8 * lo, 0.0), max(8 * hi, 0.0)), *parts[1:])
            return _ALL
        if res[0] != "func":
            return _ALL
        args = [self.num(a) for a in e.args]
        name = e.name
        if name in ("random", "chance"):
            return (0.0, 1.0)
        if name == "uniform":
            return _hull(*args)
        if name == "min":
            return (min(args[0][0], args[1][0]), min(args[0][1], args[1][1]))
        if name == "max":
            return (max(args[0][0], args[1][0]), max(args[0][1], args[1][1]))
        if name == "clamp":
            return (max(min(args[0][0], args[2][0]), args[1][0]),
                    min(max(args[0][1], args[1][1]), args[2][1]))
        if name in ("floor", "ceil", "round"):
            return (math.floor(args[0][0]), math.ceil(args[0][1]))
        if name == "abs":
            lo, hi = args[0]
            return (0.0 if lo <= 0 <= hi else min(abs(lo), abs(hi)), max(abs(lo), abs(hi)))
        if name == "sign":
            return (-1.0, 1.0)
        if name in ("sin", "cos"):
            return (-1.0, 1.0)
        if name == "atan2":
            return (-math.pi, math.pi)
        return _ALL

    def settle(self) -> None:
        """Each variable's (and `let`'s) range: its initial value's and every value
        assigned to it, to a fixed point. A bound still moving after a few passes is
        widened to infinity; then passes from the initial values narrow what the
        assignments bound (`n = min(n + 1, 100)` ends within 0..100)."""
        assigns, lets = [], []
        for decl in self.kind.status_decls.values():
            for node in ast.walk(decl):
                if isinstance(node, ast.AssignStmt) and self.res(node)[0] == "var":
                    assigns.append(node)
                elif isinstance(node, ast.LetStmt):
                    lets.append(node)
        init = {v.name: self.num(v.decl.value) for v in self.kind.vars.values()
                if v.type == NUM}
        self.vars = dict(init)
        for n in range(_ROUNDS):
            fresh = self._fresh(init, assigns, lets)
            grown = {k: _hull(self.vars.get(k, r), r) for k, r in fresh.items()}
            if grown == {**self.vars, **self.lets}:
                break
            if n >= 3:          # still growing: widen the bounds that move
                old = {**self.vars, **self.lets}
                grown = {k: (r[0] if k not in old or r[0] >= old[k][0] else -math.inf,
                             r[1] if k not in old or r[1] <= old[k][1] else math.inf)
                         for k, r in grown.items()}
            self._store(grown)
        else:
            self._store(dict.fromkeys({**self.vars, **self.lets}, _ALL))
            return
        for _ in range(3):      # narrowing: from the initial values again
            self._store(self._fresh(init, assigns, lets))

    def _store(self, ranges: dict) -> None:
        self.vars = {k: r for k, r in ranges.items() if k in self.vars}
        self.lets = {k: r for k, r in ranges.items() if k not in self.vars}

    def _fresh(self, init: dict, assigns, lets) -> dict:
        """The ranges the initial values and one pass of the assignments give, read
        with the current ranges."""
        out = dict(init)
        for let in lets:
            value = self.num(let.value)
            out[let.name] = _hull(out[let.name], value) if let.name in out else value
        for st in assigns:
            if st.target not in init:
                continue
            value = self.num(st.value)
            if st.op != "=":
                value = self._op(st.op[0], self.vars.get(st.target, _ALL), value)
            out[st.target] = _hull(out[st.target], value)
        return out


def saturation_warnings(info, robots: int) -> list[SwarmError]:
    """A located warning for each message value the exporter cannot show to fit a
    message's 16-bit whole numbers, at its first such broadcast (and how many more)."""
    found: dict[str, list] = {}
    for kind in info.kinds:
        ranges = _Ranges(info, kind, robots)
        ranges.settle()
        for decl in kind.status_decls.values():
            for node in ast.walk(decl):
                if isinstance(node, ast.ActionStmt) and node.name == "broadcast" \
                        and len(node.args) == 2:
                    r = _sent(info, ranges, node.args[1])
                    if r is not None:
                        found.setdefault(node.args[0].id, []).append((node.args[1], r))
    out = []
    for name, sites in found.items():
        value, _ = sites[0]
        lo, hi = _hull(*(r for _v, r in sites))
        seen = "any number" if (lo, hi) == _ALL else f"from {lo:g} to {hi:g}"
        more = len(sites) - 1
        also = f" (and at {more} more broadcast{'s' * (more != 1)} of it)" if more else ""
        out.append(SwarmError(
            f"`{name}` is sent as whole numbers from {LOW} to {HIGH}; the values sent "
            f"may be {seen}{also}, and beyond that range the robot sends the nearest end "
            "(target kilobot)", value.span,
            f"bound it (`clamp(x, {LOW}, {HIGH})`) or send it in coarser units",
            severity="warning"))
    return sorted(out, key=lambda w: (w.span.line, w.span.col))


def _sent(info, ranges: _Ranges, value) -> tuple | None:
    """The range of a broadcast value when it may not fit a message, else None."""
    t = info.facts.type_of(value)
    if t == NUM:
        parts = [ranges.num(value)]
    elif t == VEC and isinstance(value, ast.Vec):
        parts = [ranges.num(value.x), ranges.num(value.y)]
    elif t == VEC:
        parts = [_ALL]
    else:
        return None
    if all(LOW - 0.5 < lo and hi < HIGH + 0.5 for lo, hi in parts):
        return None
    return _hull(*parts)
