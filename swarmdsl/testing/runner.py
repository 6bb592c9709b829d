"""Run a program for N ticks under its properties and get its state back as arrays."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from swarmdsl.compiler import compile_file, compile_source
from swarmdsl.errors import SwarmError, SwarmOptionError
from swarmdsl.internal import internal_error
from swarmdsl.runtime.driver import Driver, Watch
from swarmdsl.runtime.simulation import Simulation
from swarmdsl.testing.example import param_text
from swarmdsl.testing.monitor import Monitor, Violation


def load(program, params: dict | None = None):
    """A compiled Program from a path, program text (containing a newline or `{`), or a
    Program (recompiled when `params` are given). Param values may be numbers."""
    if params is not None and not isinstance(params, dict):
        raise SwarmOptionError(f"params must map param names to values, e.g. {{\"n\": 20}}, "
                               f"got {type(params).__name__}")
    overrides = {k: param_text(v) for k, v in (params or {}).items()}
    if hasattr(program, "info"):
        if not overrides:
            return program
        return compile_source(program.source, program.filename, overrides,
                              program.program_dir)
    text = str(program)
    if "\n" in text or "{" in text:
        return compile_source(text, "<test>.swarm", overrides)
    return compile_file(Path(text), overrides)


@dataclass
class RunResult:
    """What one checked run did: the simulation at its end, and what failed."""

    program: object
    sim: Simulation
    violations: list[Violation] = field(default_factory=list)
    fault: SwarmError | None = None
    fault_tick: int | None = None
    initial: dict | None = None     # `state_arrays` at tick 0, plus `_declared` masks
    exercised: frozenset[str] = frozenset()   # the properties the run could have broken
    agent_ticks: dict = field(default_factory=dict)     # by property: agent-ticks checked
    premise_ticks: dict = field(default_factory=dict)   # by property: premise held
    premised: frozenset[str] = frozenset()    # the properties whose premise was counted
    # why the monitor checked ticks one by one in Python (an `always`, an `eventually`
    # still open), where a backend could have run them whole: what `test -v` says
    stepped: str | None = None

    @property
    def ok(self) -> bool:
        return not self.violations and self.fault is None

    @property
    def ticks(self) -> int:
        return self.sim.tick

    @property
    def state(self) -> dict[str, np.ndarray]:
        return state_arrays(self.sim)

    def first_tick(self) -> int | None:
        """The tick of the first failure (violation or fault), or None."""
        ticks = [v.tick for v in self.violations]
        if self.fault_tick is not None:
            ticks.append(self.fault_tick)
        return min(ticks) if ticks else None


def run_program(program, steps: int, *, seed: int = 0, params: dict | None = None,
                positions=None, check: bool = True, stop_at_first: bool = True,
                properties: list[str] | None = None, layout=None,
                coverage: bool = False, more_seconds: float = 0.0) -> RunResult:
    """Run `program` (path, text or Program) for `steps` ticks from `seed`.

    `positions` ((N, 2)) replaces the initial placement; `layout` (a
    `swarmdsl.runtime.layout.Layout`) gives the initial swarm agent by agent. With
    `check`, the program's properties are checked at tick 0 and after every tick; with
    `stop_at_first` the run stops at the first tick with a violation; with `coverage`,
    implication-shaped invariants also count the agent-ticks their premise held. A
    runtime fault (a SwarmError while ticking) is kept in `fault`, not raised. Any other
    exception is a bug in swarmdsl, raised as a `swarmdsl.internal.InternalError` naming
    the tick (the original as its `__cause__`), never mistaken for a failure of the
    program. The ticks are a `Driver`'s, the monitor its observer: on a backend that
    runs whole ticks with the properties checked inside (`driver.Watch`), the run
    takes them once the kernel is at hand, with the same results. `more_seconds`: the
    seconds of like runs the caller has left after this one (a hunt), so that a long
    hunt has the kernel compiled in another process (`Driver.more_seconds`).
    """
    from swarmdsl.limits import upper
    from swarmdsl.runtime.arguments import whole

    prog = load(program, params)
    steps = whole("steps", steps, 0, upper("steps"))
    sim = None
    try:
        sim = Simulation(prog, seed, layout)
        return _checked_run(prog, sim, steps, positions, check, stop_at_first, properties,
                            coverage, more_seconds)
    except SwarmError:
        raise
    except Exception as exc:
        raise internal_error(exc, sim.tick if sim is not None else 0) from exc


def _checked_run(prog, sim, steps, positions, check, stop_at_first,
                 properties, coverage=False, more_seconds=0.0) -> RunResult:
    """The run itself: placement replaced, tick 0 checked, then ticks to `steps`."""
    if positions is not None:
        try:
            pos = np.asarray(positions, dtype=float)
        except (TypeError, ValueError):
            raise SwarmOptionError(f"positions must be an (N, 2) array of numbers, got "
                                   f"{type(positions).__name__}") from None
        if pos.shape != (sim.agents.n, 2):
            raise SwarmOptionError(f"positions: got {pos.shape}, expected ({sim.agents.n}, 2)")
        sim.agents.cols["pos"] = pos.copy()
    result = RunResult(prog, sim, initial=state_arrays(sim))
    order = np.argsort(sim.agents.cols["id"], kind="stable")
    result.initial["_declared"] = {k: v[order] for k, v in sim.agents.declared.items()}
    monitor = Monitor(prog, properties) if check else None
    if monitor is not None and coverage:
        monitor.count_premises()
    driver = Driver(sim, steps, every=1)
    driver.more_seconds = float(more_seconds)
    observer = None
    if monitor is not None:
        observer = MonitorObserver(monitor, result.violations, stop_at_first)
        driver.observers.append(observer)
    driver.start()      # tick 0 checked
    driver.attempt(driver.run)
    if driver.error is not None:
        if not (driver.fault_in_tick and isinstance(driver.error, SwarmError)):
            raise driver.error      # a stop, a property that failed to evaluate, a bug
        result.fault, result.fault_tick = driver.fault, driver.fault_tick
    if monitor is not None:
        result.exercised = frozenset(monitor.exercised)
        result.agent_ticks = dict(monitor.agent_ticks)
        result.premise_ticks = dict(monitor.premise_ticks)
        result.premised = frozenset(monitor.premises)
        result.stepped = observer.stepped
    return result


class MonitorObserver:
    """A `Monitor` as an observer of a driven run: the violations of every tick into
    `found`; with `stop_at_first`, the run halts at the first tick that has any."""

    def __init__(self, monitor: Monitor, found: list, stop_at_first: bool = False):
        self.monitor, self.found, self.stop_at_first = monitor, found, stop_at_first
        self._watching: tuple[str, ...] = ()     # the properties of the last `watch`
        self.stepped: str | None = None   # why it first had to see a tick itself

    def start(self, driver) -> None:
        """Nothing opens: the monitor's state is the properties' own."""

    def tick(self, driver) -> None:
        self.found += self.monitor.check(driver.sim)
        if self.stop_at_first and self.found:
            driver.halt()

    def watch(self, driver):
        """The properties a backend may check after each tick instead (`Watch`), or
        None while the monitor must see every tick (`Monitor.watchable`)."""
        names = self.monitor.watchable(driver.sim.tick)
        if names is None:
            self.stepped = self.stepped or self.monitor.unwatchable(driver.sim.tick)
            return None
        self._watching = names
        return Watch(names, tuple(n for n in self.monitor.premises if n in names))

    def watched(self, driver, watch) -> None:
        """The counts of the ticks the backend checked for this monitor."""
        self.monitor.add_watched({n: watch.agent_ticks[n] for n in self._watching},
                                 watch.premise_ticks)

    def close(self, driver, outcome: str) -> None:
        """Nothing to close."""


def state_arrays(sim) -> dict[str, np.ndarray]:
    """Every agent column ordered by id, plus `status_name` and `kind_name` (str arrays)."""
    cols = sim.agents.cols
    order = np.argsort(cols["id"], kind="stable")
    out = {name: np.array(values[order]) for name, values in cols.items()}
    prog = sim.program
    out["status_name"] = np.asarray(prog.status_display, dtype=object)[out["status"]] \
        if len(order) else np.zeros(0, dtype=object)
    kinds = np.asarray([k.name for k in prog.kinds], dtype=object)
    out["kind_name"] = kinds[out["kind"]] if len(order) else np.zeros(0, dtype=object)
    return out
