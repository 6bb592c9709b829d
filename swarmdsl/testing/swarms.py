"""Drawing whole runs as hypothesis data, so that hypothesis can shrink the swarm itself.

Every kind's agents are drawn as a size (`sizes`: over the whole range up to the
declared count, weighted to both ends; hypothesis' own list sizes stay small), then a
hypothesis list of that many agents: each an optional start position (when the kind
has no `place` option, anywhere in the world) and optional values for variables whose
initialiser is a random draw with constant bounds (`uniform(a, b)`, `random()`,
`chance(p)`), each shrinking toward "the program's own choice" (no position, no
value). A kind the program places over the world may also be drawn dense (`_Dense`): a
smaller swarm in a window of the world at the program's own density, so a bug that
needs a crowd stays reachable. Because draws are keyed by agent id, deleting one agent
leaves the others' draws unchanged. A kind's list is one of:

- *size*: the kind is counted by one size param of its own (`count n`); `n` is set to
  the list's length and the agents are ids 0..n-1, so the run is a whole swarm of that
  size (a property reading `n` sees the real swarm, `index` counts 0..n-1);
- *subset*: any other count (`count 12`, `count 2 * n`, a param shared by kinds); the
  list holds 1 up to the count (evaluated with the drawn params) of the agents of the
  whole swarm, drawn slots of it, each keeping the id and `index` it has there, so a shrunk swarm names
  and places its agents as the whole run would;
- *fixed*: the program's count, not drawn: with `fixed_counts`, and for a *formation*,
  a kind whose `place` reads `index` or `id` (a line, a ring, a lattice: a formation
  with holes would be another experiment).

Ids are given per kind from the most agents it can have over the params' ranges, so
shrinking a param never renames another kind's agents. Draw order sets what shrinking
favours (earlier draws shrink first): the agents, other size params, the number of
ticks, the seed, then the other params.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

from hypothesis import strategies as st

from swarmdsl.compiler import ast
from swarmdsl.compiler.consteval import NotConstant, const_value
from swarmdsl.errors import SwarmError
from swarmdsl.runtime.layout import AgentSpec, Layout
from swarmdsl.testing.example import Example
from swarmdsl.testing.strategies import ParamAxis, param_axes, seeds

SIZE, SUBSET, FIXED = "size", "subset", "fixed"
CORNERS = 64          # most param corners tried for the largest count of a kind


@dataclass(frozen=True)
class KindDraw:
    """How `swarmdsl test` draws one kind's agents (see the module docstring)."""

    name: str
    mode: str                   # SIZE, SUBSET or FIXED
    lo: int                     # fewest agents drawn
    hi: int                     # most agents it can have: its ids are base..base+hi-1
    axis: ParamAxis | None = None       # SIZE: the param set to the list's length
    params: tuple[str, ...] = ()        # drawn params its count depends on


def kind_draws(program, axes: list[ParamAxis], fixed_counts=False) -> list[KindDraw]:
    """How each kind of `program` (compiled with the fixed params) is drawn. `axes`: the
    drawn params; `fixed_counts`: True (every kind keeps its program count) or the names
    of kinds that do."""
    free = free_kinds(program, axes)
    drawn = {a.name: a for a in axes}
    out = []
    for k, compiled in zip(program.info.kinds, program.kinds, strict=True):
        opt = k.options.get("count")
        names = tuple(sorted({n for n in _names(opt.args if opt is not None else ())
                              if n in drawn}))
        if k.name in free:
            lo, hi = _bounds(free[k.name])
            out.append(KindDraw(k.name, SIZE, lo, hi, free[k.name], names))
            continue
        hi = _largest_count(opt, compiled.count, program.info.params,
                            [drawn[n] for n in names])
        keep = fixed_counts is True or k.name in (fixed_counts or ()) or formation(k)
        out.append(KindDraw(k.name, FIXED if keep else SUBSET, min(1, hi), hi, None, names))
    return out


def formation(kind) -> bool:
    """A kind placed by a formula of its `index` or `id`: a line, ring or lattice."""
    opt = kind.options.get("place")
    return opt is not None and any(n in ("index", "id") for n in _names(opt.args))


def _largest_count(opt, count: int, params: dict, axes: list[ParamAxis]) -> int:
    """The most agents a kind counted by `opt` can have when `axes` take any value in
    their ranges (tried at the ranges' ends; `count`: with the params' defaults)."""
    best = count
    if opt is None or not axes:
        return best
    ends = [sorted({*_bounds(a)}) for a in axes]
    for corner in itertools.islice(itertools.product(*ends), CORNERS):
        values = {**params, **{a.name: v for a, v in zip(axes, corner, strict=True)}}
        try:
            n = const_value(opt.args[0], values)
        except (NotConstant, ArithmeticError, ValueError, TypeError):
            continue
        if isinstance(n, int | float) and not isinstance(n, bool) and math.isfinite(n):
            best = max(best, int(n))
    return best


def free_kinds(program, axes: list[ParamAxis]) -> dict[str, ParamAxis]:
    """{kind name: its size axis} for kinds counted by exactly one drawn size param."""
    by_name = {a.name: a for a in axes if a.size}
    counted: dict[str, list[str]] = {}
    for k in program.info.kinds:
        opt = k.options.get("count")
        if opt is not None and len(opt.args) == 1 and isinstance(opt.args[0], ast.Name):
            counted.setdefault(opt.args[0].id, []).append(k.name)
    uses = {name: 0 for name in by_name}
    for k in program.info.kinds:
        opt = k.options.get("count")
        for n in _names(opt.args if opt is not None else ()):
            if n in uses:
                uses[n] += 1
    return {kinds[0]: by_name[p] for p, kinds in counted.items()
            if p in by_name and len(kinds) == 1 and uses[p] == 1}


def _names(exprs):
    for e in exprs:
        stack = [e]
        while stack:
            node = stack.pop()
            if isinstance(node, ast.Name):
                yield node.id
            stack.extend(node.children())


def _bounds(axis: ParamAxis) -> tuple[int, int]:
    lo = int(axis.lo) if axis.lo is not None else min(1, int(axis.default))
    hi = int(axis.hi) if axis.hi is not None else int(axis.default)
    return max(lo, 0), max(hi, 0)


def value_strategies(program, kind) -> dict[str, st.SearchStrategy]:
    """{var: values it can start with} for variables initialised by a bounded random draw."""
    params = program.info.params
    out = {}
    for name, v in kind.vars.items():
        e = v.decl.value
        if not isinstance(v.decl, ast.VarDecl) or not isinstance(e, ast.Call) \
                or e.each is not None:
            continue
        try:
            args = [float(const_value(a, params)) for a in e.args]
        except (NotConstant, ArithmeticError, ValueError, TypeError):
            continue
        if e.name == "random" and not args:
            args = [0.0, 1.0]
        if e.name in ("random", "uniform") and len(args) == 2 and args[0] < args[1]:
            out[name] = st.floats(args[0], args[1], exclude_max=True, allow_nan=False)
        elif e.name == "chance" and len(args) == 1 and v.type == "bool":
            out[name] = st.booleans()
    return out


def _agent(program, kind) -> st.SearchStrategy:
    """(position, values) for one agent of a drawn kind. A position is None (the
    program places it, or the kind's dense window does: `_dense`), ("near", j, dx, dy):
    within neighbour range of an earlier placed agent (so crowds, the usual trigger of
    interaction bugs, are common), or ("at", x, y)."""
    w = program.world
    if "place" in kind.options:
        pos = st.none()
    else:
        reach = float(program.pair_radius) or 0.05 * max(w.width, w.height)
        offset = st.floats(-reach, reach, allow_nan=False)
        pos = st.one_of(
            st.none(),
            st.tuples(st.just("near"), st.integers(0, 7), offset, offset),
            st.tuples(st.just("at"),
                      st.floats(0.0, float(w.width), exclude_max=True, allow_nan=False),
                      st.floats(0.0, float(w.height), exclude_max=True, allow_nan=False)))
    values = value_strategies(program, kind)
    names = sorted(values)
    vals = st.tuples(*[st.one_of(st.none(), values[n]) for n in names]).map(
        lambda vs: tuple((n, v) for n, v in zip(names, vs, strict=True) if v is not None))
    return st.tuples(pos, vals)


def sizes(lo: int, hi: int) -> st.SearchStrategy:
    """How many agents a drawn kind starts with: over the whole range `lo..hi`, weighted
    to both ends (a few agents, the declared count and just under it), shrinking toward
    the fewest. Hypothesis' own list sizes stay small (a median of 3 of 80 declared)."""
    if hi <= lo:
        return st.just(lo)
    top = st.one_of(st.just(hi), st.integers(max(lo, hi - max(hi // 8, 1)), hi))
    return st.one_of(st.integers(lo, min(hi, lo + 4)), st.integers(lo, hi), top)


MANY_SLOTS = 256     # past this, a kind's slots are a keyed sample, not drawn one by one


def _slots(hi: int, k: int) -> st.SearchStrategy:
    """`k` distinct slots of `0..hi-1`, sorted (toward the first `k`). Of a large count,
    a sample keyed by one drawn number: drawing a thousand distinct slots one by one
    overruns hypothesis' budget for a test case, and such sizes were then never tried."""
    if k >= hi:
        return st.just(tuple(range(hi)))
    if hi > MANY_SLOTS:
        import numpy as np

        return st.integers(0, 2**31 - 1).map(lambda key: tuple(sorted(
            int(i) for i in np.random.default_rng([key, hi, k]).choice(hi, k,
                                                                       replace=False))))
    if k <= hi // 2:
        return st.lists(st.integers(0, hi - 1), unique=True, min_size=k,
                        max_size=k).map(lambda xs: tuple(sorted(xs)))
    gone = st.lists(st.integers(0, hi - 1), unique=True, min_size=hi - k, max_size=hi - k)
    return gone.map(lambda xs: tuple(i for i in range(hi) if i not in set(xs)))


PER_AGENT = 64      # agents drawn one by one; more agents take the kind's placement


@dataclass(frozen=True)
class _Dense:
    """A window of the world holding a shrunk kind at its declared density: the
    program places `declared` agents over the world, so `k` agents go in a window of
    `k / declared` of its area (`sizes` keeps the full count reachable too)."""

    x0: float
    y0: float
    width: float
    height: float
    key: int

    def place(self, slot: int) -> tuple[str, float, float]:
        import numpy as np

        u, v = np.random.default_rng([self.key, slot]).random(2)
        return ("at", self.x0 + float(u) * self.width, self.y0 + float(v) * self.height)


def _dense(program, kind, size: int, declared: int, d) -> _Dense | None:
    """Drawn per kind: whether its agents that the program would place go in a window
    at the program's own density (None: the program places them over the world)."""
    if "place" in kind.options or declared <= 0 or size >= declared \
            or not d(st.booleans()):
        return None
    w = program.world
    scale = math.sqrt(size / declared)
    width, height = float(w.width) * scale, float(w.height) * scale
    cu = d(st.floats(0.0, 1.0, allow_nan=False))
    cv = d(st.floats(0.0, 1.0, allow_nan=False))
    key = d(st.integers(0, 2**31 - 1))
    return _Dense(cu * (float(w.width) - width), cv * (float(w.height) - height),
                  width, height, key)


def _records(program, kind, plan_entry, declared: int, body, d) -> list:
    """One drawn kind's agents as (slot, position, values) records."""
    size = d(sizes(plan_entry.lo, plan_entry.hi))
    bodies = d(st.lists(body, min_size=min(size, PER_AGENT), max_size=min(size, PER_AGENT)))
    bodies += [(None, ())] * (size - len(bodies))
    slots = range(size) if plan_entry.mode == SIZE else d(_slots(plan_entry.hi, size))
    dense = _dense(program, kind, size, declared, d)
    out = []
    for slot, (pos, values) in zip(slots, bodies, strict=True):
        if pos is None and dense is not None:
            pos = dense.place(slot)
        out.append((slot, pos, values))
    return out


def example_strategy(program, steps: int, fixed: dict | None = None,
                     compile_with=None, fixed_counts=False) -> st.SearchStrategy:
    """Examples for `program` (compiled with the `fixed` params). `compile_with(params)`
    compiles it with drawn params (for counts that depend on them); `fixed_counts`: True,
    or the names of kinds that keep their program count (`kind_draws`)."""
    fixed = fixed or {}
    axes = [a for a in param_axes(program) if a.drawn and a.name not in fixed]
    plan = kind_draws(program, axes, fixed_counts)
    free_params = {d.axis.name for d in plan if d.mode == SIZE}
    sizes_ = [a for a in axes if a.size and a.name not in free_params]
    others = [a for a in axes if not a.size]
    kinds = program.info.kinds
    bodies = [None if d.mode == FIXED else _agent(program, k)
              for k, d in zip(kinds, plan, strict=True)]
    declared = [k.count for k in program.kinds]
    ticks = st.one_of(st.integers(1, max(steps, 1)), st.just(max(steps, 1)))
    counted = any(d.params for d in plan if d.mode != SIZE)

    @st.composite
    def draw(d):
        drawn = [None if p.mode == FIXED else _records(program, k, p, n, body, d)
                 for k, p, n, body in zip(kinds, plan, declared, bodies, strict=True)]
        size_values = [d(a.strategy()) for a in sizes_]
        n = d(ticks)
        seed = d(seeds())
        other_values = [d(a.strategy()) for a in others]
        params = {p.axis.name: len(drawn[i]) for i, p in enumerate(plan) if p.mode == SIZE}
        params.update(zip([a.name for a in sizes_], size_values, strict=True))
        params.update(zip([a.name for a in others], other_values, strict=True))
        layout = _layout(program, plan, drawn, {**fixed, **params},
                         compile_with if counted else None)
        order = [a.name for a in axes]
        return Example(tuple((p, params[p]) for p in order if p in params), seed, n, layout)
    return draw()


def _layout(program, plan, drawn, params, compile_with) -> Layout | None:
    """The drawn swarm; None when every kind keeps its program placement."""
    if all(d.mode == FIXED for d in plan):
        return None
    counts = {k.name: k.count for k in program.kinds}
    if compile_with is not None:
        try:
            counts = {k.name: k.count for k in compile_with(params).kinds}
        except SwarmError:
            return None           # the run reports that the program rejects these params
    agents = []
    base = 0
    placed: list[tuple[float, float]] = []
    for d, records in zip(plan, drawn, strict=True):
        count = counts[d.name]
        if d.mode == FIXED:
            agents += [AgentSpec(d.name, base + i) for i in range(count)]
        else:
            records = sorted(records, key=lambda r: r[0])
            if d.mode == SUBSET:
                records = _within(records, count)
            for slot, pos, values in records:
                pos = _resolve(program.world, pos, placed)
                agents.append(AgentSpec(d.name, base + slot, pos, values,
                                        slot if d.mode == SUBSET else None))
        base += d.hi if d.mode == SIZE else max(d.hi, count)
    return Layout(tuple(agents), tuple(d.name for d in plan))


def _within(records: list, count: int) -> list:
    """The drawn agents of a subset kind whose slots exist with `count` agents (drawn
    params can make the count smaller than the largest); never none of them if some
    were drawn and the count allows one."""
    kept = [r for r in records if r[0] < count]
    if not kept and records and count > 0:
        slot, pos, values = records[0]
        kept = [(slot % count, pos, values)]
    return kept


def _resolve(world, pos, placed: list) -> tuple[float, float] | None:
    """A drawn position as a point in the world (`placed`: the points so far)."""
    if pos is None:
        return None
    if pos[0] == "at":
        x, y = pos[1], pos[2]
    else:
        cx, cy = placed[pos[1] % len(placed)] if placed else (world.width / 2,
                                                              world.height / 2)
        x, y = cx + pos[2], cy + pos[3]
    x = min(max(x, 0.0), math.nextafter(float(world.width), 0.0))
    y = min(max(y, 0.0), math.nextafter(float(world.height), 0.0))
    placed.append((x, y))
    return (x, y)
