"""Hypothesis strategies over a compiled program: params, seeds, placements, perturbations.

Params that set a kind's `count` are *size* params: they draw whole numbers (the
range's end as often as the rest of it) and shrink toward the smallest swarm (the low
end of their range, or 1 without a range). Other params with a `LO..HI` range draw
inside it, their ends as often as their inside, and shrink toward their default;
params without a range keep their default. A param whose default and bounds are whole
numbers draws whole numbers. `placements()` draws explicit positions for the Python
API; `swarmdsl test` draws whole initial swarms agent by agent (`swarms.py`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from swarmdsl.compiler import ast
from swarmdsl.compiler.consteval import NotConstant, const_value

MAX_SEED = 2**32 - 1


@dataclass(frozen=True)
class ParamAxis:
    """One param as the tester sees it."""

    name: str
    default: object
    lo: float | None
    hi: float | None
    integer: bool
    size: bool                  # appears in some kind's `count`

    @property
    def drawn(self) -> bool:
        return self.lo is not None or (self.size and self.integer and self.default >= 1)

    def strategy(self) -> st.SearchStrategy:
        if self.size:
            lo = int(self.lo) if self.lo is not None else min(1, int(self.default))
            hi = int(self.hi) if self.hi is not None else int(self.default)
            lo, hi = max(lo, 0), max(hi, 0)
            # both ends: the range, and its largest (the swarm at its declared scale)
            return st.one_of(st.integers(lo, hi), st.just(hi))
        if self.integer:
            rng = st.integers(int(self.lo), int(self.hi))
        else:
            rng = st.floats(float(self.lo), float(self.hi), allow_nan=False,
                            allow_infinity=False)
        # shrinks toward the default; the range's ends come up as often as its inside
        cast = int if self.integer else float
        ends = st.sampled_from([cast(self.lo), cast(self.hi)])
        return st.one_of(st.just(self.default), ends, rng)


def param_axes(program) -> list[ParamAxis]:
    """Every param of a compiled program (compiled without overrides), in order."""
    info = program.info
    size_names = set()
    for k in info.kinds:
        opt = k.options.get("count")
        if opt is not None:
            size_names |= {n.id for a in opt.args for n in _walk(a)
                           if isinstance(n, ast.Name) and n.id in info.params}
    axes = []
    for name, decl in info.param_decls.items():
        default = info.params[name]
        if isinstance(default, bool):
            continue
        lo = hi = None
        if decl.lo is not None:
            try:
                lo, hi = const_value(decl.lo, info.params), const_value(decl.hi, info.params)
            except (NotConstant, ArithmeticError, ValueError, TypeError):
                lo = hi = None
            if not (_number(lo) and _number(hi) and lo <= hi):
                lo = hi = None
        integer = all(isinstance(v, int) for v in (default, lo, hi) if v is not None)
        axes.append(ParamAxis(name, default, lo, hi, integer, name in size_names))
    return axes


def _number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and np.isfinite(v)


def _walk(node):
    yield node
    for c in node.children():
        yield from _walk(c)


def params(program, fixed: dict | None = None) -> st.SearchStrategy:
    """Dicts {param: value} for the drawn params (size params first), minus `fixed`."""
    fixed = fixed or {}
    axes = [a for a in param_axes(program) if a.drawn and a.name not in fixed]
    axes.sort(key=lambda a: not a.size)
    names = [a.name for a in axes]
    return st.tuples(*[a.strategy() for a in axes]).map(
        lambda values: dict(zip(names, values, strict=True)))


def seeds() -> st.SearchStrategy:
    """Run seeds; shrink toward 0."""
    return st.integers(0, MAX_SEED)


def placements(program, n: int | None = None) -> st.SearchStrategy:
    """(N, 2) float arrays of positions inside the world (N: the program's agent count)."""
    w = program.world
    n = sum(k.count for k in program.kinds) if n is None else n
    xs = st.floats(0.0, float(w.width), allow_nan=False, allow_infinity=False,
                   exclude_max=True)
    ys = st.floats(0.0, float(w.height), allow_nan=False, allow_infinity=False,
                   exclude_max=True)
    return st.tuples(hnp.arrays(np.float64, n, elements=xs),
                     hnp.arrays(np.float64, n, elements=ys)).map(
        lambda xy: np.stack(xy, axis=1))


# ---- perturbations ----

@dataclass(frozen=True)
class RemoveAgents:
    """Remove the agents at these rows (taken modulo the swarm size)."""

    picks: tuple[int, ...]

    def apply(self, sim) -> np.ndarray:
        n = sim.agents.n
        if n == 0:
            return np.zeros(0, np.int64)
        mask = np.zeros(n, bool)
        mask[np.asarray(self.picks, np.int64) % n] = True
        ids = sim.agents.cols["id"][mask].copy()
        sim.agents.remove(mask)
        return ids


@dataclass(frozen=True)
class MoveAgents:
    """Displace agents (rows modulo the swarm size) by offsets, kept inside the world."""

    picks: tuple[int, ...]
    offsets: tuple[tuple[float, float], ...]

    def apply(self, sim) -> np.ndarray:
        n = sim.agents.n
        if n == 0:
            return np.zeros(0, np.int64)
        rows = np.asarray(self.picks, np.int64) % n
        pos = sim.agents.cols["pos"].copy()
        pos[rows] += np.asarray(self.offsets, float).reshape(-1, 2)
        w = sim.world
        pos[:, 0] = np.clip(pos[:, 0], 0.0, np.nextafter(w.width, 0))
        pos[:, 1] = np.clip(pos[:, 1], 0.0, np.nextafter(w.height, 0))
        sim.agents.cols["pos"] = pos
        return sim.agents.cols["id"][rows].copy()


@dataclass(frozen=True)
class SetVariable:
    """Set a declared variable of some agents (rows modulo the swarm size) to a value."""

    name: str
    picks: tuple[int, ...]
    value: object

    def apply(self, sim) -> np.ndarray:
        n = sim.agents.n
        if n == 0:
            return np.zeros(0, np.int64)
        rows = np.asarray(self.picks, np.int64) % n
        rows = rows[sim.agents.declared[self.name][rows]]
        col = sim.agents.cols[self.name].copy()
        col[rows] = self.value
        sim.agents.cols[self.name] = col
        return sim.agents.cols["id"][rows].copy()


def perturbations(program, max_agents: int = 3, max_offset: float | None = None,
                  values: st.SearchStrategy | None = None,
                  kinds: tuple[str, ...] = ("remove", "move", "set")) -> st.SearchStrategy:
    """One perturbation of `kinds`: "remove" agents, "move" agents, or "set" a variable
    of some agents (`values` draws the new numbers)."""
    picks = st.lists(st.integers(0, 10_000), min_size=1, max_size=max_agents).map(tuple)
    w = program.world
    reach = max_offset if max_offset is not None else 0.25 * max(w.width, w.height)
    offset = st.tuples(*[st.floats(-reach, reach, allow_nan=False)] * 2)
    options = []
    if "remove" in kinds:
        options.append(st.builds(RemoveAgents, picks))
    if "move" in kinds:
        options.append(picks.flatmap(lambda p: st.lists(
            offset, min_size=len(p), max_size=len(p)).map(
            lambda off, p=p: MoveAgents(p, tuple(off)))))
    for name, t in program.var_types.items() if "set" in kinds else ():
        if t == "num":
            v = values or st.floats(-1e3, 1e3, allow_nan=False)
        elif t == "bool":
            v = st.booleans()
        else:
            v = st.tuples(*[st.floats(-1e3, 1e3, allow_nan=False)] * 2)
        options.append(st.builds(SetVariable, st.just(name), picks, v))
    if not options:
        raise ValueError(f"no perturbation of kinds {kinds!r} applies to this program")
    return st.one_of(options)
