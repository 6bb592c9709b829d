"""A hypothesis state machine that drives a program tick by tick and perturbs it.

Subclass `SwarmMachine`, set `program` (a path or program text) and optionally
`params`; `TestX = MyMachine.TestCase` makes it a pytest test. Each step is a rule:
advance a few ticks, remove agents (robot loss), move agents, or change a variable
of some agents. The program's invariants are checked at every tick and after every
rule, so a shrunk failure is the shortest story of ticks and perturbations that breaks
one.
"""

from __future__ import annotations

from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, rule

from swarmdsl.errors import SwarmOptionError
from swarmdsl.runtime.driver import Driver
from swarmdsl.runtime.simulation import Simulation
from swarmdsl.testing.monitor import Monitor
from swarmdsl.testing.runner import load, state_arrays
from swarmdsl.testing.strategies import perturbations, seeds

_COMPILED: dict = {}


class SwarmMachine(RuleBasedStateMachine):
    """Base machine: set `program`; tune `params`, `perturb` (which perturbations:
    any of "remove", "move", "set") and `max_agents_per_perturbation`."""

    program: str | None = None
    params: dict = {}
    perturb: tuple[str, ...] = ("remove", "move", "set")
    max_agents_per_perturbation: int = 3

    def __init__(self):
        super().__init__()
        if self.program is None:
            raise SwarmOptionError(f"{type(self).__name__}: set `program` to a .swarm path "
                                   "or program text")
        key = (self.program, tuple(sorted(self.params.items())), self.perturb,
               self.max_agents_per_perturbation)
        if key not in _COMPILED:
            prog = load(self.program, self.params)
            _COMPILED[key] = (prog, perturbations(prog, self.max_agents_per_perturbation,
                                                  kinds=self.perturb))
        self.compiled, self._perturbations = _COMPILED[key]
        self.monitor = Monitor(self.compiled)
        self.driver: Driver | None = None
        self.violations: list = []
        self.perturbed_ids: list[int] = []

    @property
    def sim(self) -> Simulation | None:
        """The simulation the machine drives (None before `place`)."""
        return None if self.driver is None else self.driver.sim

    @property
    def state(self):
        """Every agent column ordered by id (see `state_arrays`)."""
        return state_arrays(self.sim)

    @initialize(seed=seeds())
    def place(self, seed):
        self.monitor.reset()
        self.driver = Driver(Simulation(self.compiled, seed), every=1)
        self.driver.observers.append(_Checks(self))
        self.driver.start()     # tick 0 checked

    @rule(ticks=st.integers(1, 5))
    def advance(self, ticks):
        self.driver.run(ticks)  # every tick checked

    @rule(data=st.data())
    def perturb_swarm(self, data):
        p = data.draw(self._perturbations, label="perturbation")
        self.perturbed_ids.extend(int(i) for i in p.apply(self.sim))

    @invariant()
    def properties_hold(self):
        if self.sim is not None:
            self._check()

    def _check(self):
        found = self.monitor.check(self.sim)
        if found:
            lines = [f"{v.span}: {v.message()}" for v in found]
            raise AssertionError("\n".join(lines))


class _Checks:
    """The machine's property checks as an observer of every tick it drives (its own
    object: a machine's rules may be called `tick` or `close`)."""

    def __init__(self, machine: SwarmMachine):
        self.machine = machine

    def start(self, driver) -> None:
        """Nothing opens."""

    def tick(self, driver) -> None:
        self.machine._check()

    def close(self, driver, outcome: str) -> None:
        """Nothing to close."""
