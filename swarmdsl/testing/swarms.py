"""Drawing whole runs as hypothesis data, so that hypothesis can shrink the swarm itself.

A kind whose `count` is one size param (`count n`, no other kind counting by `n`) is
*free*: its agents are a hypothesis list, each agent a stable slot (its id), an optional
start position (when the kind has no `place` option, anywhere in the world) and optional
values for variables whose initialiser is a random draw with constant bounds
(`uniform(a, b)`, `random()`, `chance(p)`). `n` is set to the list's length, so
a property that reads `n` sees the real swarm. Hypothesis shrinks a list by deleting
elements and each element toward "the program's own choice" (no position, no value),
so a failing swarm shrinks agent by agent; because draws are keyed by agent id, deleting
one agent leaves the others' draws unchanged. Other kinds keep their program count.

Draw order sets what shrinking favours (earlier draws shrink first): the agents of free
kinds, other size params, the number of ticks, the seed, then the other params.
"""

from __future__ import annotations

import math

from hypothesis import strategies as st

from swarmdsl.compiler import ast
from swarmdsl.compiler.consteval import NotConstant, const_value
from swarmdsl.compiler.errors import SwarmError
from swarmdsl.runtime.layout import AgentSpec, Layout
from swarmdsl.testing.example import Example
from swarmdsl.testing.strategies import ParamAxis, param_axes, seeds


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


def _agent(program, kind, slots: int) -> st.SearchStrategy:
    """(slot, position, values) for one agent of a free kind. A position is None (the
    program places it), ("near", j, dx, dy): within neighbour range of an earlier placed
    agent (so crowds, the usual trigger of interaction bugs, are common), or ("at", x, y)."""
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
    return st.tuples(st.integers(0, max(slots - 1, 0)), pos, vals)


def example_strategy(program, steps: int, fixed: dict | None = None,
                     compile_with=None) -> st.SearchStrategy:
    """Examples for `program` (compiled with the `fixed` params). `compile_with(params)`
    compiles it with drawn params (for the counts of kinds that are not free)."""
    fixed = fixed or {}
    axes = [a for a in param_axes(program) if a.drawn and a.name not in fixed]
    free = free_kinds(program, axes)
    free_params = {a.name for a in free.values()}
    sizes = [a for a in axes if a.size and a.name not in free_params]
    others = [a for a in axes if not a.size]
    kinds = program.info.kinds
    agent_lists = []
    for k in kinds:
        if k.name in free:
            lo, hi = _bounds(free[k.name])
            agent_lists.append(st.lists(_agent(program, k, hi), min_size=lo, max_size=hi,
                                        unique_by=lambda a: a[0]))
        else:
            agent_lists.append(st.none())
    ticks = st.one_of(st.integers(1, max(steps, 1)), st.just(max(steps, 1)))

    @st.composite
    def draw(d):
        drawn = [d(s) for s in agent_lists]
        size_values = [d(a.strategy()) for a in sizes]
        n = d(ticks)
        seed = d(seeds())
        other_values = [d(a.strategy()) for a in others]
        params = {free[k.name].name: len(drawn[i]) for i, k in enumerate(kinds)
                  if k.name in free}
        params.update(zip([a.name for a in sizes], size_values, strict=True))
        params.update(zip([a.name for a in others], other_values, strict=True))
        layout = _layout(program, kinds, free, drawn, params, fixed, compile_with)
        order = [a.name for a in axes]
        return Example(tuple((p, params[p]) for p in order if p in params), seed, n, layout)
    return draw()


def _layout(program, kinds, free, drawn, params, fixed, compile_with) -> Layout | None:
    if not free:
        return None
    counts = {}
    if compile_with is not None and len(free) < len(kinds):
        try:
            compiled = compile_with({**fixed, **params})
        except SwarmError:
            return None           # the run reports that the program rejects these params
        counts = {k.name: k.count for k in compiled.kinds}
    agents = []
    base = 0
    placed: list[tuple[float, float]] = []
    for k, records in zip(kinds, drawn, strict=True):
        if k.name in free:
            for slot, pos, values in sorted(records, key=lambda r: r[0]):
                pos = _resolve(program.world, pos, placed)
                agents.append(AgentSpec(k.name, base + slot, pos, values))
            base += _bounds(free[k.name])[1]
        else:
            count = counts.get(k.name, k.count)
            agents += [AgentSpec(k.name, base + i) for i in range(count)]
            base += count
    return Layout(tuple(agents), tuple(k.name for k in kinds))


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
