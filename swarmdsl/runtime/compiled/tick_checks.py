"""What observers read of a tick, computed inside the whole-tick kernel: a program's
invariants checked after the ticks they are checked at, its metrics sampled.

`swarmdsl test` and `swarmdsl run --check` check properties after every tick
(`testing/monitor.py`), so their runs never had two ticks nobody observes, and never
ran whole. The checks that can be compiled are here instead: `plan_checks(program,
tick_plan)` lowers every `invariant` (its test, and its premise when it is
implication-shaped: `compiler/implication.py`) into the scalar trees of the tick's
own planner (`tick_plan._TickPlanner`), and `observer(plan, ...)` composes them into
one jitted function that the kernel calls after each tick commits
(`tick_kernel._loop`). It counts what the monitor counts (per property: agent-ticks
checked, agent-ticks its premise held) and, at the first tick where a checked
property fails, stops the call with that tick committed: the monitor then checks
that tick itself, in Python, and builds the violation with its agents, as it always
did. So the counts, the violations and the run's state are the same whether ticks
ran whole or one by one (`tests/test_tick_checks.py`).

The program's metrics (`metric NAME = EXPR`, `runtime/metrics.py`) are lowered the
same way and sampled at the ticks the run records (`every`, and its last tick) into
an output array, which the run's metric log takes (`driver.Watch`): so a run that
records only metrics (a sweep's solo run, `swarmdsl run` without `--out`) takes whole
ticks too, with the same samples.

What compiles: expressions over the agent's state and variables, params, `tick`, and
the swarm aggregates `count`, `all`, `any`, `min`, `max` (exact whatever the order),
`sum` and `mean` (numpy's own order: a number's terms added pairwise as
`np.add.reduce` adds a contiguous array, a vector's x and y one after another, as it
reduces the rows of an (N, 2) array; `_pairwise`), over every agent or, in a metric
of a kind, over its agents. Refused, with the reason (the observer then sees every
tick itself, and the run stays per tick): `previous(X)` (the monitor's memory), a
neighbour query (an observer's exact neighbours, not the program's pair table), the
swarm's geometry (`clusters`, ...), and anything the tick's planner refuses.
`eventually` and `always` are not compiled: an `eventually` decided or past its tick
N checks nothing more, so the monitor asks for none (`Monitor.watchable`); an
`always` keeps its run per tick.

The observations belong to the program, not to a run: every run of the program
compiles the same kernel (a run passes what it watches; one that watches nothing pays
nothing for them), so the tester, a plain run and the tiered start's warm-up share one
machine code on disk.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import BOOL, KIND, NUM
from swarmdsl.compiler.implication import premise_nodes, reads_previous
from swarmdsl.ops.operators import COMPARISONS
from swarmdsl.runtime.compiled.jit import njit
from swarmdsl.runtime.compiled.kernels import FALSE, ZERO, node
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
SWARM = ("count", "all", "any", "min", "max", "sum", "mean")


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
    # swarm aggregates, in the order they are worked out: (aggregate, its trees (none,
    # one, or two for a vector), first S column of its value, kind (-1: every agent),
    # default trees, S column of its terms (a sum of numbers))
    swarm: list = field(default_factory=list)
    metrics: list = field(default_factory=list)   # each metric's value tree
    unmeasured: str | None = None   # why the metrics are not compiled (any one is not)
    consts: list = field(default_factory=list)  # after the tick plan's: float or tick
    s_width: int = 0                            # S columns, the tick plan's included

    @property
    def key(self) -> tuple:
        """The shape (no numbers): equal keys compile to the same machine code."""
        return (tuple((c.kind, c.test, c.premise) for c in self.checks),
                tuple(self.swarm), tuple(self.metrics))

    @property
    def empty(self) -> bool:
        return not self.checks and not self.metrics

    def slot(self, name: str) -> int | None:
        for k, c in enumerate(self.checks):
            if c.name == name:
                return k
        return None


class _CheckPlanner(_TickPlanner):
    """The tick's planner over the committed state of a checked tick: `tick` is the
    tick checked, swarm aggregates loops over every agent, and what an observer reads
    differently from a status (neighbours, `previous`) is refused."""

    def __init__(self, tick: _TickBuilder, body: _Body, out: CheckPlan, over: int = -1):
        super().__init__(tick, body)
        self.out = out
        self.over = over      # swarm aggregates over this kind only (a kind's metric)

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
            raise Unsupported(f"the swarm `{name}(...)`{_line(e)}")
        trees = ()
        if e.args:
            kind = self.body.kind if self.over >= 0 else None
            inner = _CheckPlanner(self.tick, _Body(self.tick, kind, ""), self.out,
                                  self.over)
            trees = inner.value(e.args[0])
            if any(_s_reads(t) for t in trees):
                raise Unsupported(f"`{name}(...)`{_line(e)}: its argument is not a value "
                                  "of each agent's own")
        width = len(trees) if name in ("sum", "mean") else 1
        default = None
        if e.default is not None:
            default = self.value(e.default)
        elif name in ("mean", "min", "max"):
            default = self._const(0.0, NUM) * width
        terms = self.tick.column() if name in ("sum", "mean") and width == 1 else -1
        out = self.tick.column(width)
        self.out.swarm.append((name, tuple(trees), out, self.over, default, terms))
        if width == 2:
            return (("s", out), ("s", out + 1))
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
    _plan_metrics(program, tick, out)
    out.consts = tick.consts[len(plan.consts):]
    out.s_width = tick.s_width
    return out


def _plan_metrics(program, tick: _TickBuilder, out: CheckPlan) -> None:
    """Every metric's value tree, or none (the log takes whole rows) and why not."""
    saved = (len(tick.consts), tick.s_width, len(out.swarm))
    trees = []
    try:
        for m in program.metrics:
            kind = program.info.kind(m.info.kind) if m.info.kind else None
            over = m.kind_index if m.kind_index is not None else -1
            trees.append(_lower(tick, kind, m.info.decl.expr, out, over))
    except Unsupported as exc:
        del tick.consts[saved[0]:], out.swarm[saved[2]:]
        tick.s_width = saved[1]
        out.unmeasured = f"the metric `{m.info.name}`: {exc}"
        return
    out.metrics = trees


def _lower(tick: _TickBuilder, kind, expr, out: CheckPlan, over: int = -1) -> tuple:
    body = _Body(tick, kind, "")
    planner = _CheckPlanner(tick, body, out, over)
    trees = planner.value(expr)
    if body.steps:      # the planner stored a value: nothing a property needs
        raise Unsupported(f"this expression{_line(expr)}")
    return trees[0]


# ---- the jitted observer ----
@njit(**_FLAT)
def _no_swarm(A, S, n, kind_col):
    return None


@njit(**_FLAT)
def _no_check(A, S, n, active, counts):
    return False


@njit(**_JIT)
def _block(S, col, lo, n):
    """numpy's `pairwise_sum` of at most 128 terms `S[lo:lo + n, col]`: one after
    another below 8, else eight running sums, joined as a tree, then the rest."""
    if n < 8:
        r = 0.0
        for i in range(lo, lo + n):
            r += S[i, col]
        return r
    r0, r1, r2, r3 = S[lo, col], S[lo + 1, col], S[lo + 2, col], S[lo + 3, col]
    r4, r5, r6, r7 = S[lo + 4, col], S[lo + 5, col], S[lo + 6, col], S[lo + 7, col]
    i = 8
    while i < n - n % 8:
        a = lo + i
        r0 += S[a, col]
        r1 += S[a + 1, col]
        r2 += S[a + 2, col]
        r3 += S[a + 3, col]
        r4 += S[a + 4, col]
        r5 += S[a + 5, col]
        r6 += S[a + 6, col]
        r7 += S[a + 7, col]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += S[lo + i, col]
        i += 1
    return res


@njit(**_JIT)
def _pairwise(S, col, lo, n):
    """The sum of `S[lo:lo + n, col]` as numpy adds a contiguous float64 array
    (`pairwise_sum` of its `add.reduce`: blocks of up to 128 terms, `_block`; above
    that the two halves, split at a multiple of eight, each summed so and then
    added); the caller adds it to 0.0, the reduction's start. numpy recurses; this
    walks the same tree with a stack of its own (a recursive function cannot be
    kept in the kernel cache on disk)."""
    if n <= 128:
        return _block(S, col, lo, n)
    los = np.empty(128, np.int64)
    ns = np.empty(128, np.int64)
    stage = np.empty(128, np.int64)
    vals = np.empty(128)
    top, nv = 0, 0
    los[0], ns[0], stage[0] = lo, n, 0
    while top >= 0:
        m = ns[top]
        if m <= 128:
            vals[nv] = _block(S, col, los[top], m)
            nv += 1
            top -= 1
            continue
        half = m // 2
        half -= half % 8
        if stage[top] == 0:         # its first half next
            stage[top] = 1
            los[top + 1], ns[top + 1], stage[top + 1] = los[top], half, 0
            top += 1
        elif stage[top] == 1:       # then its second half
            stage[top] = 2
            los[top + 1], ns[top + 1], stage[top + 1] = los[top] + half, m - half, 0
            top += 1
        else:                       # both summed: first + second
            vals[nv - 2] = vals[nv - 2] + vals[nv - 1]
            nv -= 1
            top -= 1
    return vals[0]


def _swarm_step(step, before):
    """`before`, then one swarm aggregate (a `CheckPlan.swarm` entry) over every agent
    (or every agent of its kind) into its columns of every row of `S`, with the values
    of the reference's numpy reductions: `np.count_nonzero`, `np.all`, `np.any`,
    `np.min` and `np.max` (a NaN wins), `np.sum` and `np.mean` in numpy's order (a
    number's terms gathered into column `terms`, `_pairwise`); of no agents, the
    default (`mean`, `min`, `max`), 0 (`count`, `sum`), true (`all`), false (`any`)."""
    name, trees, out, over, default, terms = step
    kind = SWARM.index(name)
    fx = node(trees[0]) if trees else FALSE
    fy = node(trees[1]) if len(trees) == 2 else ZERO
    two = len(trees) == 2
    counted = bool(trees)
    gx = node(default[0]) if default else ZERO
    gy = node(default[1]) if default and len(default) == 2 else ZERO
    over_kind = float(over)
    every_kind = over < 0

    @njit(**_FLAT)
    def step(A, S, n, kind_col):
        before(A, S, n, kind_col)
        m = 0
        vx = 0.0
        vy = 0.0
        if kind == 1:
            vx = 1.0
        for j in range(n):
            if not every_kind and A[j, kind_col] != over_kind:
                continue
            if kind == 0:       # count
                if not counted or fx(S, A, j, j, 0.0, 0.0, 0.0):
                    vx += 1.0
            elif kind == 1:     # all
                if not fx(S, A, j, j, 0.0, 0.0, 0.0):
                    vx = 0.0
            elif kind == 2:     # any
                if fx(S, A, j, j, 0.0, 0.0, 0.0):
                    vx = 1.0
            elif kind <= 4:     # min, max: the first NaN, else the least / the most
                x = fx(S, A, j, j, 0.0, 0.0, 0.0)
                if m == 0 or (vx == vx and (x != x or (x < vx if kind == 3 else x > vx))):
                    vx = x
            elif two:           # sum, mean of vectors: row after row
                vx += fx(S, A, j, j, 0.0, 0.0, 0.0)
                vy += fy(S, A, j, j, 0.0, 0.0, 0.0)
            else:               # of numbers: gathered, then added pairwise
                S[m, terms] = fx(S, A, j, j, 0.0, 0.0, 0.0)
            m += 1
        if kind >= 5 and not two:
            vx = 0.0 + _pairwise(S, terms, 0, m)
        if m == 0 and (kind == 3 or kind == 4 or kind == 6):
            vx = gx(S, A, 0, 0, 0.0, 0.0, 0.0)
            vy = gy(S, A, 0, 0, 0.0, 0.0, 0.0)
        elif kind == 6:
            vx = vx / float(m)
            vy = vy / float(m)
        for i in range(n):
            S[i, out] = vx
            if two:
                S[i, out + 1] = vy
    return step


def _check_step(slot, slots, kind_col, check: Check, before):
    """`before`, then one invariant of every agent of its kind (once for a swarm one):
    agent-ticks checked into `counts[0, slot]`, premise held into `counts[0, slots +
    slot]`; True when some agent failed it. Only when `active[slot]` (a property
    the run checks), the premise when `active[slots + slot]`."""
    test = node(check.test)
    premise = node(check.premise) if check.premise is not None else FALSE
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


@njit(**_FLAT)
def _no_metric(A, S, rows, r):
    return None


def _metric_step(k, tree, before):
    """`before`, then metric `k`'s value into `rows[r, k]` (a condition as 1 or 0)."""
    fn = node(tree)

    @njit(**_FLAT)
    def step(A, S, rows, r):
        before(A, S, rows, r)
        rows[r, k] = float(fn(S, A, 0, 0, 0.0, 0.0, 0.0))
    return step


@njit(**_JIT)
def no_observer(A, S, n, tick, names, watch):
    return False


def observer(plan: CheckPlan | None, status_col: int, name_col: int, kind_col: int):
    """The jitted observations of `plan`, called by the kernel after each tick commits:
    `observe(A, S, n, tick, names, watch) -> failed`. `watch` (`tick_run.advance`):
    (on, every, last, checking, check_every, active, counts, tick_cols, measuring,
    rows, row_ticks, taken). With `checking`, at a tick on the `check_every` grid (1:
    every tick, as `run --check` checks; else the `every` grid the observers see) or
    the run's `last`, the active properties checked and counted into `counts` (2, 2P
    + 1) int64, row 0 the tick's, row 1 the call's (a failing tick's are not added:
    the monitor counts that tick itself; `counts[1, 2P]` set to 1 and True returned);
    with `measuring`, at a tick on the `every` grid or the `last`, the metrics into
    row `taken[0]` of `rows`, the tick into `row_ticks`."""
    if plan is None or plan.empty:
        return no_observer
    swarm = _no_swarm
    for step in plan.swarm:
        swarm = _swarm_step(step, swarm)
    slots = len(plan.checks)
    checks = _no_check
    for slot, c in enumerate(plan.checks):
        checks = _check_step(slot, slots, kind_col, c, checks)
    measure = _no_metric
    for k, tree in enumerate(plan.metrics):
        measure = _metric_step(k, tree, measure)
    width = 2 * slots

    @njit(**_JIT)
    def observe(A, S, n, tick, names, watch):
        (_on, every, last, checking, check_every, active, counts, tick_cols, measuring,
         rows, row_ticks, taken) = watch
        due = tick % every == 0 or tick == last
        check = checking and (due or tick % check_every == 0)
        if not (check or (measuring and due)):
            return False
        for i in range(n):      # the tick's status names, as the next tick's start sets
            A[i, name_col] = names[int(A[i, status_col])]
        for c in tick_cols:
            for i in range(n):
                A[i, c] = float(tick)
        swarm(A, S, n, kind_col)
        if check:
            for k in range(width):
                counts[0, k] = 0
            if checks(A, S, n, active, counts):
                counts[1, width] = 1
                return True
            for k in range(width):
                counts[1, k] += counts[0, k]
        if measuring and due:
            r = taken[0]
            measure(A, S, rows, r)
            row_ticks[r] = tick
            taken[0] = r + 1
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
