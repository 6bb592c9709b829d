"""Checking a running simulation against its program's properties, tick by tick.

Tick t means the state after t ticks (tick 0: just placed). An invariant must hold at
every tick checked; `eventually NAME within N` must hold at some tick 0..N (a swarm
property once, a per-agent property for each agent of its kind; agents removed before
tick N are excused).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmdsl.compiler.codegen import broadcast
from swarmdsl.compiler.errors import Span, SwarmError, SwarmOptionError, SwarmRuntimeError
from swarmdsl.compiler.lang_properties import CompiledProperty, properties_of
from swarmdsl.runtime.frame import AgentFrame


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

    def message(self) -> str:
        what = f"{self.keyword} `{self.name}`"
        if self.keyword == "eventually":
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
        return err


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
        if names is not None:
            unknown = set(names) - {p.info.qualified for p in props} \
                - {p.info.name for p in props}
            if unknown:
                known = ", ".join(p.info.qualified for p in props) or "none"
                raise SwarmOptionError(f"--property {', '.join(sorted(unknown))}: no such "
                                       f"property (the program has: {known})")
            props = [p for p in props if p.info.qualified in names or p.info.name in names]
        self.properties: list[CompiledProperty] = props
        self.reset()

    def reset(self) -> None:
        """Forget `eventually` progress (for a new run)."""
        self._done: dict[str, object] = {}

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

    def _check_one(self, p: CompiledProperty, sim, tick: int) -> Violation | None:
        info = p.info
        if info.within is not None and (tick > info.within or
                                        self._done.get(info.qualified) is True):
            return None
        try:
            ok, ids = self._evaluate(p, sim, tick)
        except SwarmError:
            raise
        except Exception as exc:
            raise SwarmRuntimeError(f"{info.keyword} `{info.qualified}` failed to evaluate "
                                    f"at tick {tick}: {exc}", info.decl.span) from exc
        span = info.decl.name_span
        if info.within is None:
            if ok.all():
                return None
            bad = () if p.kind_index is None else tuple(int(i) for i in ids[~ok])
            return Violation(info.qualified, info.keyword, tick, bad, span)
        return self._eventually(p, ok, ids, tick, span)

    def _eventually(self, p, ok, ids, tick, span) -> Violation | None:
        info = p.info
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

    @staticmethod
    def _evaluate(p: CompiledProperty, sim, tick: int):
        """(ok (M,) bool, ids (M,) int) for a per-agent property; ((1,), ()) for a swarm one."""
        if p.kind_index is None:
            value = p.test(_SwarmFrame(sim, tick))
            return np.atleast_1d(np.asarray(value, dtype=bool)), np.zeros(0, np.int64)
        kind = sim.program.kinds[p.kind_index]
        rows = np.flatnonzero(sim.agents.cols["kind"] == p.kind_index)
        f = AgentFrame(sim, rows, kind, None)
        f.tick = tick
        ok = np.asarray(broadcast(p.test(f), rows.size, "bool"), dtype=bool)
        return ok, sim.agents.cols["id"][rows]


class _CheckExtension:
    """Runtime plug-in for `swarmdsl run --check`: stop at the first violation."""

    names: list[str] | None = None     # only these properties (`run --property`)

    def __init__(self, sim):
        self.monitor = Monitor(sim.program, self.names)
        self.pending: list[Violation] = []

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

    def state_dict(self, sim) -> dict:
        """`eventually` progress: met (true) or the ids that met it so far."""
        done = self.monitor._done
        return {"done": {k: v if v is True else sorted(int(i) for i in v)
                         for k, v in done.items()}}

    def load_state(self, sim, state: dict) -> None:
        self.monitor._done = {k: v if v is True else set(v)
                              for k, v in state.get("done", {}).items()}
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
