"""Shrinking one failure to a 1-minimal counterexample, or saying honestly that it is not.

Hypothesis shrinks a drawn run well but stops where its own moves stop, and a failure
of the program as written (declared counts, its own placement) was never drawn at all.
So every failure, whoever found it, is shrunk here for one property at a time:

1. the run is cut to the tick of the property's first failure;
2. the swarm is made explicit: every agent with the id, index and start position it
   had in the failing run, so removing agents leaves the others where they were (the
   crowd that broke a density property stays as dense);
3. agents are removed by delta debugging (halves, then quarters, ... then one by one),
   keeping a removal when the property still fails within the current ticks, and the
   run is cut again to the new first failure;
4. once no agent can go, a drawn param is made smaller (a count param toward the low
   end of its range, another param toward its default) if the run still fails, and
   agents are tried again;
5. the last round, one agent at a time with nothing removable, *is* the check of
   1-minimality: each of those runs passed. One more run, a tick shorter, passes.

A kind that is counted by a size param of its own (`count n`) keeps `n` equal to its
agents; a kind that keeps its count (a formation, `--fixed-count`, a `--set` count)
and the last agents a kind must keep (its fewest: 1 for a constant count) are not
removed, and the result says so. When the time budget ends first, the result says the
case may not be minimal and how large it is.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

from swarmdsl.runtime.layout import AgentSpec, Layout
from swarmdsl.testing.example import Example
from swarmdsl.testing.swarms import FIXED, SIZE


@dataclass
class Shrunk:
    """A shrunk failure: the example, its run, and what is known of its minimality."""

    example: Example
    result: object                  # RunResult, failing
    minimal: bool                   # checked: no one agent can go, nor one tick
    runs: int = 0                   # runs made while shrinking
    seconds: float = 0.0
    removal_checks: int = 0         # single-agent removals checked in the last round
    kept: list[str] = field(default_factory=list)   # why some agents cannot go


def first_failure(result, prop: str | None) -> int | None:
    """The tick at which `prop` first failed in `result` (None: a runtime fault while
    running, not a refusal of the params or the swarm), or None when it did not fail."""
    if prop is None:
        ran = getattr(result.sim, "agents", None) is not None
        return result.fault_tick if ran and result.fault is not None and \
            result.fault_tick is not None else None
    ticks = [v.tick for v in result.violations if v.name == prop]
    return min(ticks) if ticks else None


def shrink(example: Example, prop: str | None, plan, base_program,
           run: Callable[[Example], object | None], deadline: float,
           axes=()) -> Shrunk | None:
    """Shrink a failure of `prop` (a qualified property name; None: a runtime fault).

    `run(example)` runs an example checking only `prop` (None when past the time
    budget); `plan`: the hunt's `KindDraw`s (which kinds may lose agents, and their
    size params); `axes`: the drawn params (`ParamAxis`), made smaller once no agent
    can go, toward the low end of a count's range or a param's default. Returns None when the example no longer fails (it always should: runs
    are deterministic)."""
    started = time.perf_counter()
    runs = 0

    def attempt(ex: Example):
        nonlocal runs
        if time.perf_counter() > deadline:
            return None
        runs += 1
        return run(ex)

    runs = 1
    result = run(example)
    tick = first_failure(result, prop)
    if tick is None:
        return None
    layout, params = _explicit(example, result, plan)
    empty = layout is None      # no agents at all: none to remove
    current = Example(params, example.seed, tick, layout)
    runs += 1
    got = run(current)          # the explicit swarm is the same run: check it
    draws = {d.name: d for d in plan}
    kept: list[str] = []
    if first_failure(got, prop) is not None:
        result = got
        current = _cut(current, first_failure(got, prop))
    else:                       # not the same run: shrink nothing, claim nothing
        current, layout = _cut(example, tick), None
        kept = ["its swarm could not be made explicit, so no agent was removed"]
    minimal = empty and first_failure(got, prop) is not None
    checks = 0
    if layout is not None:
        agents = list(layout.agents)
        while True:
            agents, current, result, minimal, checks = _remove_agents(
                agents, current, result, prop, draws, layout.kinds, attempt)
            if not minimal:
                break
            smaller = _smaller_params(current, prop, axes, draws, attempt)
            if smaller is None:
                break
            current, result = smaller       # fewer agents may go now: check again
    if minimal and current.steps >= 1:
        shorter = attempt(_cut(current, current.steps - 1))
        minimal = shorter is not None and first_failure(shorter, prop) is None
    if layout is not None:
        kept = _kept(plan, current.layout)
    return Shrunk(current, result, minimal, runs, time.perf_counter() - started, checks,
                  kept)


def _remove_agents(agents, current, result, prop, draws, kinds, attempt):
    """Delta debugging over the removable agents: (agents, example, run, minimal,
    single-agent removals checked in the last round). `minimal`: the last round
    removed each agent in turn and every run passed (False: out of time)."""
    chunk = max(len(_removable(agents, draws)) // 2, 1)
    while True:
        accepted = False
        checks = 0
        for block in _blocks(_removable(agents, draws), chunk):
            trial = [a for i, a in enumerate(agents) if i not in block]
            if not _allowed(trial, draws):
                continue
            ex = _with_agents(current, trial, draws, kinds)
            got = attempt(ex)
            if got is None:
                return agents, current, result, False, checks
            checks += 1
            t = first_failure(got, prop)
            if t is not None:
                agents, current, result = trial, _cut(ex, t), got
                accepted = True
                break
        if accepted:
            chunk = min(chunk, max(len(_removable(agents, draws)) // 2, 1))
            continue
        if chunk == 1:
            return agents, current, result, True, checks
        chunk = max(chunk // 2, 1)


SMALLER_TRIES = 8       # values tried per param, from its smallest up


def _smaller_params(current: Example, prop, axes, draws, attempt):
    """(example, run) with one drawn param made smaller (a count param toward the low
    end of its range, another toward its default) that still fails, or None. Agent
    removal leaves a drawn `count 2 * n` at the `n` it was drawn with; a smaller count
    may need the agents of a subset kind renumbered to its first slots (`_compacted`),
    tried when the swarm as it is does not fail."""
    values = dict(current.params)
    for axis in axes:
        if axis.name not in values:
            continue
        now = values[axis.name]
        if axis.size and axis.integer and axis.lo is not None:
            tries = list(range(int(axis.lo), int(now)))[:SMALLER_TRIES]
        elif not axis.size and now != axis.default:
            tries = [axis.default]
        else:
            continue
        layouts = [current.layout]
        if axis.size and current.layout is not None:
            compact = _compacted(current.layout, draws)
            if compact != current.layout:
                layouts.append(compact)
        for value in tries:
            params = tuple((k, value if k == axis.name else v) for k, v in current.params)
            for layout in layouts:
                ex = Example(params, current.seed, current.steps, layout)
                got = attempt(ex)
                if got is None:
                    return None
                t = first_failure(got, prop)
                if t is not None:
                    return _cut(ex, t), got
    return None


def _compacted(layout: Layout, draws) -> Layout:
    """The layout with each subset kind's agents on its first slots (index 0..k-1 and
    the ids that go with them), in the order of their slots."""
    agents = list(layout.agents)
    for name, d in draws.items():
        if d.mode == FIXED or d.mode == SIZE:
            continue
        rows = sorted((i for i, a in enumerate(agents) if a.kind == name
                       and a.index is not None), key=lambda i: agents[i].index)
        for slot, i in enumerate(rows):
            a = agents[i]
            agents[i] = AgentSpec(a.kind, a.id - a.index + slot, a.pos, a.values, slot)
    return Layout(tuple(agents), layout.kinds)


def _cut(ex: Example, steps: int) -> Example:
    return Example(ex.params, ex.seed, steps, ex.layout)


def _explicit(example: Example, result, plan) -> tuple[Layout | None, tuple]:
    """The failing run's swarm as a layout of every agent, each at the start position it
    had (and keeping its id, its index in a subset kind, its drawn values); the params
    with each size param set to its kind's agents."""
    start = result.initial
    if start is None or not len(start.get("id", ())):
        return None, example.params
    drawn = {}
    if example.layout is not None:
        drawn = {(a.kind, int(a.id)): a for a in example.layout.agents}
    agents = []
    kinds = [d.name for d in plan]
    for row in range(len(start["id"])):
        kind = str(start["kind_name"][row])
        ident = int(start["id"][row])
        old = drawn.get((kind, ident))
        pos = (float(start["pos"][row][0]), float(start["pos"][row][1]))
        d = next((d for d in plan if d.name == kind), None)
        index = int(start["index"][row]) if d is not None and d.mode != SIZE else None
        values = old.values if old is not None else ()
        agents.append(AgentSpec(kind, ident, pos, values, index))
    order = {k: i for i, k in enumerate(kinds)}
    agents.sort(key=lambda a: (order.get(a.kind, len(order)), a.id))
    return Layout(tuple(agents), tuple(kinds)), example.params


def _kept(plan, layout: Layout) -> list[str]:
    """Why some of the agents left were not tried for removal, one phrase per kind."""
    have = layout.counts()
    out = []
    for d in plan:
        if d.mode == FIXED and have.get(d.name):
            out.append(f"`{d.name}` keeps its count")
        elif d.mode != FIXED and d.lo > 0 and have.get(d.name, 0) <= d.lo:
            out.append(f"`{d.name}` keeps at least {d.lo}")
    return out


def _removable(agents: list[AgentSpec], draws) -> list[int]:
    return [i for i, a in enumerate(agents)
            if a.kind in draws and draws[a.kind].mode != FIXED]


def _blocks(rows: list[int], size: int):
    for start in range(0, len(rows), size):
        yield set(rows[start:start + size])


def _allowed(agents: list[AgentSpec], draws) -> bool:
    """Every kind keeps at least its fewest agents."""
    have: dict[str, int] = {}
    for a in agents:
        have[a.kind] = have.get(a.kind, 0) + 1
    return all(have.get(name, 0) >= d.lo for name, d in draws.items() if d.mode != FIXED)


def _with_agents(ex: Example, agents: list[AgentSpec], draws, kinds) -> Example:
    """`ex` with these agents; each size param set to its kind's number of agents."""
    params = dict(ex.params)
    have: dict[str, int] = {}
    for a in agents:
        have[a.kind] = have.get(a.kind, 0) + 1
    for name, d in draws.items():
        if d.mode == SIZE and d.axis is not None:
            params[d.axis.name] = have.get(name, 0)
    order = [k for k, _ in ex.params] + [k for k in params if k not in dict(ex.params)]
    return Example(tuple((k, params[k]) for k in order), ex.seed, ex.steps,
                   Layout(tuple(agents), tuple(kinds)))
