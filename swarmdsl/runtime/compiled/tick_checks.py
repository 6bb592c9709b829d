"""A program's invariants checked inside the whole-tick kernel, after every tick it runs.

`swarmdsl test` checks its properties after every tick (`testing/monitor.py`), so its
runs never had two ticks nobody observes, and never ran whole. The checks that can be
compiled are here instead: `plan_checks(program, tick_plan)` lowers every `invariant`
(its test, and its premise when it is implication-shaped: `compiler/implication.py`)
into the scalar trees of the tick's own planner (`tick_plan._TickPlanner`), and
`observer(plan, ...)` composes them into one jitted function that the kernel calls
after each tick commits (`tick_kernel._loop`). It counts what the monitor counts (per
property: agent-ticks checked, agent-ticks its premise held) and, at the first tick
where a checked property fails, stops the call with that tick committed: the monitor
then checks that tick itself, in Python, and builds the violation with its agents, as
it always did. So the counts, the violations and the run's state are the same whether
ticks ran whole or one by one (`tests/test_tick_checks.py`).

What compiles: per-agent and swarm invariants over the agent's state and variables,
params, `tick`, and the swarm aggregates `count`, `all`, `any`, `min`, `max` (exact
whatever the order). Refused, with the reason (the monitor checks such a property per
tick): `previous(X)` (the monitor's memory), a neighbour query (an observer's exact
neighbours, not the program's pair table), the swarm `sum` and `mean` (numpy adds
their terms pairwise: another order, other bits), and anything the tick's planner
refuses. `eventually` and `always` are not compiled: an `eventually` decided or past
its tick N checks nothing more, so the monitor asks for none (`Monitor.watchable`);
an `always` keeps its run per tick.

The checks belong to the program, not to a run: every run of the program compiles
the same kernel (a plain run passes no property to check, and the checks cost
nothing), so the tester, a plain run and the tiered start's warm-up share one machine
code on disk.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import BOOL, KIND, NUM
from swarmdsl.compiler.implication import premise_nodes, reads_previous
from swarmdsl.ops.operators import COMPARISONS
from swarmdsl.runtime.compiled.jit import njit
from swarmdsl.runtime.compiled.kernels import node
from swarmdsl.runtime.compiled.plan import Unsupported
from swarmdsl.runtime.compiled.tick_plan import (
    TickPlan,
    _Body,
    _line,
    _s_reads,
    _TickBuilder,
    _TickPlanner,
)

_JIT = {"nogil": True, "error_model": "numpy"}
_FLAT = {**_JIT, "inline": "always"}
CHECKED_TICK = "checked tick"   # a constant column: the tick being checked
SWARM = ("count", "all", "any", "min", "max")


@dataclass(frozen=True)
class Check:
    """One compiled invariant: its kind (-1: a swarm property), its test and its
    premise (a boolean tree, None when it has none or it did not compile)."""

    name: str           # qualified, as the monitor names it
    kind: int
    test: tuple
    premise: tuple | None


@dataclass
class CheckPlan:
    """A program's compiled checks and what they need of the kernel's tables."""

    checks: list[Check] = field(default_factory=list)
    refused: dict[str, str] = field(default_factory=dict)   # property -> why not
    swarm: list = field(default_factory=list)   # (aggregate, tree or None, S column)
    consts: list = field(default_factory=list)  # after the tick plan's: float or tick
    s_width: int = 0                            # S columns, the tick plan's included

    @property
    def key(self) -> tuple:
        """The shape (no numbers): equal keys compile to the same machine code."""
        return (tuple((c.kind, c.test, c.premise) for c in self.checks),
                tuple(self.swarm))

    def slot(self, name: str) -> int | None:
        for k, c in enumerate(self.checks):
            if c.name == name:
                return k
        return None


class _CheckPlanner(_TickPlanner):
    """The tick's planner over the committed state of a checked tick: `tick` is the
    tick checked, swarm aggregates loops over every agent, and what an observer reads
    differently from a status (neighbours, `previous`) is refused."""

    def __init__(self, tick: _TickBuilder, body: _Body, out: CheckPlan):
        super().__init__(tick, body)
        self.out = out

    def _const(self, value, vtype: str):
        c = self.tick.const(value if isinstance(value, float) else CHECKED_TICK)
        return (("ob", c),) if vtype == BOOL else (("o", c),)

    def value(self, e) -> tuple:
        if isinstance(e, ast.Compare) and self.type_of(e.left) == KIND:
            # `kind == rock`: the agent's kind index against the kind's
            a, b = self.value(e.left)[0], self.value(e.right)[0]
            return ((COMPARISONS[e.op].node, a, b),)
        if self.type_of(e) == KIND:
            res = self.res(e)
            if res[:2] == ("state", "kind"):
                return (self.tick.load(self.body, "kind"),)
            if res[:1] == ("kind",):
                return self._const(float(res[1]), NUM)
            raise Unsupported(f"this kind{_line(e)}")
        if isinstance(e, ast.Call):
            what = self.res(e)[:1]
            if what == ("swarm_agg",):
                return self.swarm(e, self.res(e)[1])
            if what == ("previous",):
                raise Unsupported(f"`previous(...)`{_line(e)} (the monitor keeps what "
                                  "it saw last)")
        return super().value(e)

    def aggregate(self, e: ast.Call):
        raise Unsupported(f"a neighbour query{_line(e)} (a property sees every agent "
                          "within its radius exactly, not the program's pair table)")

    def swarm(self, e: ast.Call, name: str):
        if name not in SWARM:
            raise Unsupported(f"the swarm `{name}(...)`{_line(e)} (numpy adds its terms "
                              "pairwise)")
        tree = None
        if e.args:
            inner = _CheckPlanner(self.tick, _Body(self.tick, None, ""), self.out)
            trees = inner.value(e.args[0])
            if any(_s_reads(t) for t in trees):
                raise Unsupported(f"`{name}(...)`{_line(e)}: its argument is not a value "
                                  "of each agent's own")
            tree = trees[0]
        out = self.tick.column()
        self.out.swarm.append((name, tree, out))
        return (("sb", out),) if name in ("all", "any") else (("s", out),)


def plan_checks(program, plan: TickPlan) -> CheckPlan:
    """The compiled invariants of `program`, on top of its whole-tick plan `plan` (their
    constants and scratch columns after the plan's)."""
    from swarmdsl.compiler.lang_properties import properties_of

    out = CheckPlan()
    tick = _TickBuilder(program)
    tick.consts = list(plan.consts)
    tick.s_width = plan.s_width
    for p in properties_of(program):
        info = p.info
        if info.keyword != "invariant":
            out.refused[info.qualified] = f"an `{info.keyword}` is checked in Python"
            continue
        kind = program.info.kind(info.kind) if info.kind else None
        saved = (len(tick.consts), tick.s_width, len(out.swarm))
        try:
            test = _lower(tick, kind, info.decl.expr, out)
        except Unsupported as exc:
            out.refused[info.qualified] = str(exc)
            del tick.consts[saved[0]:], out.swarm[saved[2]:]
            tick.s_width = saved[1]
            continue
        premise = None
        found = premise_nodes(info.decl.expr)
        if found is not None and not reads_previous(found[0]):
            nodes, negate = found
            saved = (len(tick.consts), tick.s_width, len(out.swarm))
            try:
                parts = [_lower(tick, kind, n, out) for n in nodes]
            except Unsupported:     # counted in Python only: such a run stays per tick
                del tick.consts[saved[0]:], out.swarm[saved[2]:]
                tick.s_width = saved[1]
            else:
                parts = [("not", t) if negate else t for t in parts]
                premise = parts[0]
                for t in parts[1:]:
                    premise = ("and", premise, t)
        out.checks.append(Check(info.qualified, -1 if p.kind_index is None
                                else p.kind_index, test, premise))
    out.consts = tick.consts[len(plan.consts):]
    out.s_width = tick.s_width
    return out


def _lower(tick: _TickBuilder, kind, expr, out: CheckPlan) -> tuple:
    body = _Body(tick, kind, "")
    planner = _CheckPlanner(tick, body, out)
    trees = planner.value(expr)
    if body.steps:      # the planner stored a value: nothing a property needs
        raise Unsupported(f"this expression{_line(expr)}")
    return trees[0]


# ---- the jitted observer: f(A, S, n, active, counts) ----
@njit(**_FLAT)
def _no_swarm(A, S, n):
    return None


@njit(**_FLAT)
def _no_check(A, S, n, active, counts):
    return False


@njit(**_FLAT)
def _never(S, T, r, j, d, dx, dy):
    return False


def _swarm_step(name, tree, out, before):
    """`before`, then swarm aggregate `name` of `tree` over every agent into column
    `out` of every row of `S`: `np.count_nonzero`, `np.all`, `np.any`, `np.min` and
    `np.max`'s values (a NaN wins the minimum and maximum, as in numpy)."""
    kind = SWARM.index(name)
    fn = node(tree) if tree is not None else _never
    counted = tree is not None

    @njit(**_FLAT)
    def step(A, S, n):
        before(A, S, n)
        if kind == 0:       # count
            c = 0
            if counted:
                for j in range(n):
                    if fn(S, A, j, j, 0.0, 0.0, 0.0):
                        c += 1
            else:
                c = n
            v = float(c)
        elif kind == 1:     # all
            v = 1.0
            for j in range(n):
                if not fn(S, A, j, j, 0.0, 0.0, 0.0):
                    v = 0.0
                    break
        elif kind == 2:     # any
            v = 0.0
            for j in range(n):
                if fn(S, A, j, j, 0.0, 0.0, 0.0):
                    v = 1.0
                    break
        else:               # min, max: the first NaN, else the least / the most
            v = fn(S, A, 0, 0, 0.0, 0.0, 0.0)
            for j in range(1, n):
                if v != v:
                    break
                x = fn(S, A, j, j, 0.0, 0.0, 0.0)
                if x != x or (x < v if kind == 3 else x > v):
                    v = x
        for i in range(n):
            S[i, out] = v
    return step


def _check_step(slot, slots, kind_col, check: Check, before):
    """`before`, then one invariant of every agent of its kind (once for a swarm one):
    agent-ticks checked into `counts[0, slot]`, premise held into `counts[0, slots +
    slot]`; True when some agent failed it. Only when `active[slot]` (a property
    the run checks), the premise when `active[slots + slot]`."""
    test = node(check.test)
    premise = node(check.premise) if check.premise is not None else _never
    kind = float(check.kind)
    swarm = check.kind < 0

    @njit(**_FLAT)
    def step(A, S, n, active, counts):
        bad = before(A, S, n, active, counts)
        if active[slot] == 0:
            return bad
        held = active[slots + slot] != 0
        if swarm:
            counts[0, slot] += 1
            if not test(S, A, 0, 0, 0.0, 0.0, 0.0):
                bad = True
            if held and premise(S, A, 0, 0, 0.0, 0.0, 0.0):
                counts[0, slots + slot] += 1
            return bad
        for i in range(n):
            if A[i, kind_col] != kind:
                continue
            counts[0, slot] += 1
            if not test(S, A, i, i, 0.0, 0.0, 0.0):
                bad = True
            if held and premise(S, A, i, i, 0.0, 0.0, 0.0):
                counts[0, slots + slot] += 1
        return bad
    return step


@njit(**_JIT)
def no_observer(A, S, n, tick, names, active, counts, tick_cols):
    return False


def observer(plan: CheckPlan | None, status_col: int, name_col: int, kind_col: int):
    """The jitted checks of `plan`, called by the kernel after each tick commits:
    `observe(A, S, n, tick, names, active, counts, tick_cols) -> failed`. `counts` is
    (2, 2P + 1) int64: row 0 the tick's counts, row 1 the call's (a failing tick's are
    not added: the monitor counts that tick itself), `counts[1, 2P]` set to 1 when the
    call stops at a failing tick."""
    if plan is None or not plan.checks:
        return no_observer
    swarm = _no_swarm
    for name, tree, out in plan.swarm:
        swarm = _swarm_step(name, tree, out, swarm)
    slots = len(plan.checks)
    checks = _no_check
    for slot, c in enumerate(plan.checks):
        checks = _check_step(slot, slots, kind_col, c, checks)
    width = 2 * slots

    @njit(**_JIT)
    def observe(A, S, n, tick, names, active, counts, tick_cols):
        for i in range(n):      # the tick's status names, as the next tick's start sets
            A[i, name_col] = names[int(A[i, status_col])]
        for c in tick_cols:
            for i in range(n):
                A[i, c] = float(tick)
        swarm(A, S, n)
        for k in range(width):
            counts[0, k] = 0
        if checks(A, S, n, active, counts):
            counts[1, width] = 1
            return True
        for k in range(width):
            counts[1, k] += counts[0, k]
        return False
    return observe


def watched_arrays(plan: CheckPlan | None, properties, premises) -> tuple:
    """(active flags, counts) for a call checking `properties` (qualified names) and
    counting the premises of `premises`; None when one of them has no compiled check
    (`reason` says why): (None, reason)."""
    slots = len(plan.checks) if plan is not None else 0
    active = np.zeros(max(2 * slots, 1), np.uint8)
    for name in properties:
        slot = plan.slot(name) if plan is not None else None
        if slot is None:
            why = plan.refused.get(name, "it has no compiled check") if plan else \
                "the program has no compiled check"
            return None, f"the property `{name}`: {why}"
        active[slot] = 1
    for name in premises:
        slot = plan.slot(name) if plan is not None else None
        if slot is None or not active[slot]:
            continue
        if plan.checks[slot].premise is None:
            return None, f"the premise of `{name}` has no compiled form"
        active[slots + slot] = 1
    return (active, np.zeros((2, 2 * slots + 1), np.int64)), None


def tick_columns(plan: TickPlan, checks: CheckPlan | None) -> np.ndarray:
    """The state table's columns holding the tick being checked."""
    if checks is None:
        return np.zeros(0, np.int64)
    first = plan.layout.width + len(plan.consts)
    return np.array([first + c for c, v in enumerate(checks.consts) if v == CHECKED_TICK],
                    np.int64)
