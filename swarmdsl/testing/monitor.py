"""Checking a running simulation against its program's properties, tick by tick.

Tick t means the state after t ticks (tick 0: just placed). An invariant must hold at
every tick checked; `eventually NAME within N` must hold at some tick 0..N (a swarm
property once, a per-agent property for each agent of its kind; agents removed before
tick N are excused). `always NAME: P -> eventually Q within N`: whenever P holds at tick
t, Q must hold at some tick t..t+N (for the swarm, or for that agent); a violation is
reported at tick t+N. Only the oldest unanswered trigger matters (a Q answers every
trigger before it), so the state is one start tick per agent, kept in an array indexed
by agent id. A run that ends before t+N cannot break it.

A property is *exercised* by a run that could have broken it (`Monitor.exercised`):
an invariant checked on at least one agent (a swarm invariant always is), an
`eventually` that held or whose tick N the run reached, an `always` whose trigger held
and whose window then closed (answered, or N ticks passed). A property no run
exercised passed vacuously, and `swarmdsl test` and `run --check` say so.

`previous(X)` in a property reads X at the previous checked tick: the monitor keeps
what each call site saw last (`previous.py`) and hands it to the frames it builds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmdsl.compiler.codegen import broadcast
from swarmdsl.compiler.lang_properties import CompiledProperty, properties_of
from swarmdsl.errors import Span, SwarmError, SwarmOptionError, SwarmRuntimeError
from swarmdsl.runtime.driver import Watch
from swarmdsl.runtime.frame import AgentFrame, NeighborSet
from swarmdsl.runtime.spatial import build_pairs
from swarmdsl.testing.previous import PreviousValues


class PropertyViolation(SwarmRuntimeError):
    """A property failed during `swarmdsl run --check`: exit code 1, not 2."""

    exit_code = 1
    outcome = "violation"     # how `Run` reports the stop ("stopped by a property violation")
    details: dict = {}        # the violation for run.json: property, keyword, tick, agents


@dataclass(frozen=True)
class Violation:
    """One property failing at one tick; `agent_ids` is empty for a swarm property."""

    name: str             # qualified: `kind.name` for per-agent properties
    keyword: str          # "invariant" or "eventually"
    tick: int
    agent_ids: tuple[int, ...]
    span: Span
    since: int | None = None    # `always`: the tick of the unanswered trigger

    def message(self) -> str:
        what = f"{self.keyword} `{self.name}`"
        if self.keyword == "always":
            verb = f"triggered at tick {self.since} with no response by tick {self.tick}"
        elif self.keyword == "eventually":
            verb = f"did not hold by tick {self.tick}"
        else:
            verb = f"violated at tick {self.tick}"
        if not self.agent_ids:
            return f"{what} {verb}"
        ids = ", ".join(str(i) for i in self.agent_ids[:12])
        more = f" and {len(self.agent_ids) - 12} more" if len(self.agent_ids) > 12 else ""
        plural = "s" if len(self.agent_ids) > 1 else ""
        return f"{what} {verb} for agent{plural} {ids}{more}"

    def error(self, source: str | None = None) -> PropertyViolation:
        err = PropertyViolation(self.message(), self.span)
        err = err.with_source(source) if source is not None else err
        err.details = {"property": self.name, "keyword": self.keyword, "tick": self.tick,
                       "agents": list(self.agent_ids), "message": self.message()}
        if self.since is not None:
            err.details["since"] = self.since
        return err


def never_exercised(info, ticks: int, one_run: bool = False) -> str:
    """Why a property was not exercised (`info` a `PropertyInfo`), for its warning;
    `ticks`: how long the run (`one_run`) or the hunt's longest runs were."""
    if info.keyword == "always":
        window = f"{info.within} tick{'s' * (info.within != 1)}"
        return f"its trigger never held with {window} left to watch the response"
    if info.keyword == "eventually":
        runs, long = ("the run never", f"it ran {ticks} ticks") if one_run else \
            ("no run", f"runs of up to {ticks} ticks")
        return f"it never held, and {runs} reached its tick {info.within} ({long})"
    return f"there was no agent of kind `{info.kind}` to check"


class _SwarmFrame:
    """The frame a swarm property evaluates in: one row, no agent of its own."""

    def __init__(self, sim, tick: int):
        self.sim, self.tick, self.rng = sim, tick, sim.rng
        self.n = 1
        self.kind = None
        self.status_name = None
        self.locals: dict = {}
        self.overlay: dict = {}

    def state(self, col: str):  # pragma: no cover - the checker forbids it
        raise SwarmRuntimeError(f"internal: a swarm property read per-agent `{col}`")


class Monitor:
    """Evaluates a program's properties on a Simulation; remembers `eventually` progress."""

    def __init__(self, program, names: list[str] | None = None):
        self.program = program
        props = properties_of(program)
        if isinstance(names, str):      # one name, not its letters
            names = [names]
        if names is not None and (not isinstance(names, list | tuple | set | frozenset)
                                  or not all(isinstance(n, str) for n in names)):
            raise SwarmOptionError(f"properties must be a list of property names, got "
                                   f"{names!r:.60}")
        if names is not None:
            unknown = set(names) - {p.info.qualified for p in props} \
                - {p.info.name for p in props}
            if unknown:
                known = ", ".join(p.info.qualified for p in props) or "none"
                raise SwarmOptionError(f"--property {', '.join(sorted(unknown))}: no such "
                                       f"property (the program has: {known})")
            props = [p for p in props if p.info.qualified in names or p.info.name in names]
        self.properties: list[CompiledProperty] = props
        self.premises = {}          # qualified name -> Premise (implication-shaped)
        self.reset()

    def count_premises(self) -> None:
        """Also count, per implication-shaped invariant, the agent-ticks its premise
        held (`premise_ticks`; `premises.py`). Off by default: `run --check` needs no
        coverage, and a premise costs one more evaluation per tick."""
        from swarmdsl.testing.premises import compile_premise

        for p in self.properties:
            premise = compile_premise(self.program, p.info)
            if premise is not None:
                self.premises[p.info.qualified] = premise

    def reset(self) -> None:
        """Forget `eventually` progress and `always` triggers (for a new run)."""
        self._done: dict[str, object] = {}
        self._oldest: dict[str, np.ndarray] = {}    # per `always`: start tick by id, -1
        self._tables: dict = {}                      # neighbour tables of this tick
        self.exercised: set[str] = set()             # qualified names (module docstring)
        self.agent_ticks: dict[str, int] = {}        # agent-ticks checked, by property
        self.premise_ticks: dict[str, int] = {}      # agent-ticks a premise held
        self.previous = PreviousValues()             # what `previous(X)` saw last

    @property
    def horizon(self) -> int:
        """The largest `within` bound (0 when there is no `eventually`)."""
        return max((p.info.within or 0 for p in self.properties), default=0)

    def check(self, sim, tick: int | None = None) -> list[Violation]:
        """Every violation at this tick (`tick` defaults to `sim.tick`)."""
        tick = sim.tick if tick is None else tick
        out = []
        # An extension call may draw random numbers; put the generator back so that
        # checking a run never changes it.
        rng_state = sim.rng.state()
        try:
            with np.errstate(all="ignore"):
                for p in self.properties:
                    v = self._check_one(p, sim, tick)
                    if v is not None:
                        out.append(v)
        finally:
            sim.rng.set_state(rng_state)
        return out

    def watchable(self, tick: int) -> tuple[str, ...] | None:
        """The properties to check after each tick from `tick` on, for a backend that
        checks them inside a run of whole ticks (`driver.Watch`); None when one needs
        this monitor every tick: an `always`, an `eventually` still open. An
        `eventually` decided or past its tick N checks nothing more, so it is left
        out. (The backend refuses what it cannot compile, `previous(X)` among them:
        the run then stays per tick, and `-v` says which property and why.)"""
        if self.unwatchable(tick) is not None:
            return None
        return tuple(p.info.qualified for p in self.properties
                     if p.info.keyword == "invariant")

    def unwatchable(self, tick: int) -> str | None:
        """Why this monitor must see each tick from `tick` on itself (`watchable`), or
        None: an `always` (every tick, so named first), an `eventually` still open."""
        for p in self.properties:
            if p.info.keyword == "always":
                return f"`always {p.info.qualified}` is watched in Python every tick"
        for p in self.properties:
            info = p.info
            if info.keyword == "eventually" and not (
                    tick >= info.within or self._done.get(info.qualified) is True):
                return (f"`eventually {info.qualified}` is watched in Python until it "
                        f"holds or its tick {info.within} passes")
        return None

    def add_watched(self, agent_ticks: dict, premise_ticks: dict) -> None:
        """Counts of ticks a backend checked for this monitor (`watchable`), as
        `check` would have counted them: agent-ticks checked, premise held (for the
        premises it counts), exercised when any agent was checked."""
        for name, checked in agent_ticks.items():
            premise = premise_ticks.get(name) if name in self.premises else None
            self._count(name, checked, premise)
            if checked:
                self.exercised.add(name)

    def _check_one(self, p: CompiledProperty, sim, tick: int) -> Violation | None:
        info = p.info
        if info.keyword == "eventually" and (tick > info.within or
                                             self._done.get(info.qualified) is True):
            return None
        self._tables = {k: v for k, v in self._tables.items() if k[0] == tick}
        try:
            ok, ids = self._evaluate(p.test, p, sim, tick)
            if p.trigger is not None:
                triggered, _ = self._evaluate(p.trigger, p, sim, tick)
        except SwarmError:
            raise
        except Exception as exc:
            raise SwarmRuntimeError(f"{info.keyword} `{info.qualified}` failed to evaluate "
                                    f"at tick {tick}: {exc}", info.decl.span) from exc
        span = info.decl.name_span
        if p.trigger is not None:
            self._count(info.qualified, ok.size, int(np.count_nonzero(triggered)))
            return self._respond(p, triggered, ok, ids, tick, span)
        if info.within is None:
            premise = self.premises.get(info.qualified)
            held = None
            if premise is not None:
                try:
                    held = self._premise(premise, p, sim, tick)
                except Exception:   # counted no further; the property itself evaluated
                    del self.premises[info.qualified]
            if held is not None:
                self._count(info.qualified, ok.size, held)
            else:
                self._count(info.qualified, ok.size)
            if ok.size:
                self.exercised.add(info.qualified)
            if ok.all():
                return None
            bad = () if p.kind_index is None else tuple(int(i) for i in ids[~ok])
            return Violation(info.qualified, info.keyword, tick, bad, span)
        self._count(info.qualified, ok.size)
        return self._eventually(p, ok, ids, tick, span)

    def _count(self, name: str, checked: int, premise: int | None = None) -> None:
        self.agent_ticks[name] = self.agent_ticks.get(name, 0) + int(checked)
        if premise is not None:
            self.premise_ticks[name] = self.premise_ticks.get(name, 0) + premise

    def _premise(self, premise, p, sim, tick) -> int:
        """How many of the checked agents (1 for a swarm property) the premise held for."""
        held = None
        for part in premise.parts:
            value, _ = self._evaluate(part, p, sim, tick)
            value = ~value if premise.negate else value
            held = value if held is None else held & value
        return int(np.count_nonzero(held))

    def _eventually(self, p, ok, ids, tick, span) -> Violation | None:
        info = p.info
        if bool(ok.any()) or (tick >= info.within and ok.size):
            self.exercised.add(info.qualified)
        if p.kind_index is None:
            if bool(ok.all()):
                self._done[info.qualified] = True
                return None
            if tick >= info.within:
                self._done[info.qualified] = True
                return Violation(info.qualified, info.keyword, tick, (), span)
            return None
        seen = self._done.setdefault(info.qualified, set())
        seen.update(int(i) for i in ids[ok])
        if tick < info.within:
            return None
        self._done[info.qualified] = True
        late = tuple(int(i) for i in ids if int(i) not in seen)
        return Violation(info.qualified, info.keyword, tick, late, span) if late else None

    def _respond(self, p, triggered, answered, ids, tick, span) -> Violation | None:
        """Advance `always P -> eventually Q within N`; the agents whose oldest trigger
        is N ticks old with no Q since (one row for a swarm property)."""
        info = p.info
        swarm = p.kind_index is None
        keys = np.zeros(1, np.int64) if swarm else np.asarray(ids, np.int64)
        oldest = self._oldest.get(info.qualified, np.full(0, -1, np.int64))
        if keys.size and keys.max() >= oldest.size:
            grown = np.full(max(int(keys.max()) + 1, 2 * oldest.size), -1, np.int64)
            grown[:oldest.size] = oldest
            oldest = grown
        start = oldest[keys]
        expired = (start >= 0) & (tick - start >= info.within)
        if (((start >= 0) | triggered) & (answered | expired)).any():   # a window closed
            self.exercised.add(info.qualified)
        start = np.where(answered, -1, start)
        start = np.where((start < 0) & triggered & ~answered, tick, start)
        late = (start >= 0) & (tick - start >= info.within)
        oldest[keys] = np.where(late, -1, start)
        self._oldest[info.qualified] = oldest
        if not late.any():
            return None
        bad = () if swarm else tuple(int(i) for i in keys[late])
        return Violation(info.qualified, info.keyword, tick, bad, span,
                         since=tick - info.within)

    def _evaluate(self, test, p: CompiledProperty, sim, tick: int):
        """(ok (M,) bool, ids (M,) int) for a per-agent property; ((1,), ()) for a swarm one."""
        if p.kind_index is None:
            frame = _SwarmFrame(sim, tick)
            frame.previous_values = self.previous
            value = test(frame)
            return np.atleast_1d(np.asarray(value, dtype=bool)), np.zeros(0, np.int64)
        kind = sim.program.kinds[p.kind_index]
        rows = np.flatnonzero(sim.agents.cols["kind"] == p.kind_index)
        f = _ObserverFrame(sim, rows, kind, self._tables)
        f.tick = tick
        f.previous_values = self.previous
        ok = np.asarray(broadcast(test(f), rows.size, "bool"), dtype=bool)
        return ok, sim.agents.cols["id"][rows]


class _ObserverFrame(AgentFrame):
    """A per-agent property's frame: neighbours are every agent within the radius in the
    checked state, exactly (no sensing model, no sense limit), from a pair table built
    for the check and shared by the properties of the tick."""

    def __init__(self, sim, rows, kind, tables: dict):
        super().__init__(sim, rows, kind, None)
        self.tables = tables

    def neighbors(self, radius) -> NeighborSet:
        limit = np.broadcast_to(np.asarray(radius, dtype=np.float64), (self.n,))
        finite = limit[np.isfinite(limit)]
        widest = float(finite.max()) if finite.size else 0.0
        key = (self.tick, widest)
        if key not in self.tables:
            self.tables[key] = build_pairs(self.sim.agents.cols["pos"], widest,
                                           self.sim.world.box)
        table = self.tables[key]
        seg, rows = table.select(self.idx)
        pairs = NeighborSet(self, seg, base=table, rows=rows)
        keep = pairs.dist <= limit[seg]
        return pairs if keep.all() else pairs.subset(keep)


class _CheckExtension:
    """Runtime plug-in for `swarmdsl run --check`: stop at the first violation.

    It checks each tick at its end (`end_tick`), or, on a backend that runs whole
    ticks with the properties checked inside (`driver.Watch`, as `swarmdsl test`'s
    runs do), offers the driver a watch of them (`watch`) and takes the counts
    (`watched`); after a tick where the kernel found one failing, the monitor checks
    that tick itself and builds the violation, so the violation, its tick and
    message, the counts, what a checkpoint keeps and the run's outputs are those of
    the run checked tick by tick. Whatever the kernel cannot check (an `always`, an
    `eventually` still open, `previous(X)`, a neighbour query) keeps the run per
    tick, and `-v` says why (`stepped`)."""

    names: list[str] | None = None     # only these properties (`run --property`)

    def __init__(self, sim):
        self.monitor = Monitor(sim.program, self.names)
        self.pending: list[Violation] = []
        self._watching: tuple[str, ...] = ()     # the properties of the last `watch`
        self.stepped: str | None = None     # why the monitor asked to see a tick

    def watch(self, sim):
        """The properties a backend may check after each tick in whole ticks (a
        `driver.Watch`, `each_tick`: every tick, whatever the run records), or None
        while the monitor must see each tick itself (`Monitor.watchable`)."""
        if self.pending:    # a violation not raised yet: `begin_tick` raises it
            return None
        why = self.monitor.unwatchable(sim.tick)
        if why is not None:
            self.stepped = self.stepped or why
            return None
        self._watching = self.monitor.watchable(sim.tick)
        return Watch(self._watching, each_tick=True)

    def watched(self, sim, watch) -> None:
        """The counts of the ticks the backend checked; at a tick where a property
        failed (the last), the monitor checks it as `end_tick` would have."""
        self.monitor.add_watched({n: watch.agent_ticks[n] for n in self._watching}, {})
        if watch.failed:
            self.pending = self.monitor.check(sim, sim.tick)

    def after_placement(self, sim) -> None:
        self.pending = self.monitor.check(sim, 0)

    def begin_tick(self, sim) -> None:
        self._raise(sim)     # a driver that did not ask `violation()` stops here

    def end_tick(self, sim) -> None:
        self.pending = self.monitor.check(sim, sim.tick + 1)

    def violation(self, sim) -> PropertyViolation | None:
        """The first violation at the tick just finished (the driver raises it once the
        tick is recorded), or None."""
        if not self.pending:
            return None
        err = self.pending[0].error(sim.program.source)
        self.pending = []
        return err

    def unexercised(self) -> list:
        """The `PropertyInfo`s of the properties this run has not exercised (so far)."""
        return [p.info for p in self.monitor.properties
                if p.info.qualified not in self.monitor.exercised]

    def checked(self) -> str | list[str]:
        """Which properties this run checks, as a checkpoint records it: "all"
        (`--check`) or the `--property` names; a resumed run must check the same."""
        return "all" if self.names is None else list(self.names)

    def state_dict(self, sim) -> dict:
        """`eventually` progress (met, or the ids that met it so far), the oldest
        unanswered `always` trigger per agent id, what each `previous(X)` saw last."""
        done = self.monitor._done
        return {"done": {k: v if v is True else sorted(int(i) for i in v)
                         for k, v in done.items()},
                "oldest": {k: v.tolist() for k, v in self.monitor._oldest.items()},
                "previous": self.monitor.previous.state(),
                "exercised": sorted(self.monitor.exercised)}

    def load_state(self, sim, state: dict) -> None:
        self.monitor._done = {k: v if v is True else set(v)
                              for k, v in state.get("done", {}).items()}
        self.monitor._oldest = {k: np.asarray(v, np.int64)
                                for k, v in state.get("oldest", {}).items()}
        self.monitor.previous.load(state.get("previous", {}))
        self.monitor.exercised = set(state.get("exercised", ()))
        self.pending = []

    def _raise(self, sim) -> None:
        if self.pending:
            raise self.pending[0].error(sim.program.source)


def enable_checks(program, names: list[str] | None = None) -> None:
    """Make every Simulation of `program` check its properties (or only `names`) each
    tick and raise PropertyViolation at the first one that fails."""
    program.extensions[:] = [e for e in program.extensions
                             if not (isinstance(e, type) and issubclass(e, _CheckExtension))]
    if names is None:
        program.extensions.append(_CheckExtension)
        return
    Monitor(program, names)            # unknown names fail here, before the run
    program.extensions.append(type("_CheckSome", (_CheckExtension,), {"names": list(names)}))
