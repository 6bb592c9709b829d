"""The counterexample hunt behind `swarmdsl test`: hypothesis draws swarm sizes, ticks,
seeds and params; a failing draw is shrunk toward the fewest agents and ticks.

Draw order sets what shrinking favours (hypothesis shrinks earlier draws first): size
params, then the number of ticks, then the seed, then the other params (toward their
defaults). Results are cached per draw, so a time budget that stops new runs never
makes a replay disagree with the original run.
"""

from __future__ import annotations

import shlex
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from hypothesis import HealthCheck, Phase, Verbosity, given, settings
from hypothesis import seed as hypothesis_seed
from hypothesis import strategies as st

from swarmdsl.compiler.errors import SwarmError
from swarmdsl.compiler.lang_properties import properties_of
from swarmdsl.testing.runner import RunResult, _text, load, run_program
from swarmdsl.testing.strategies import param_axes, seeds

DEFAULT_STEPS = 100


@dataclass(frozen=True)
class Example:
    """One drawn run: param values, seed and number of ticks."""

    params: tuple[tuple[str, object], ...]
    seed: int
    steps: int

    def overrides(self) -> dict[str, object]:
        return dict(self.params)

    def command(self, filename: str, steps: int | None = None) -> str:
        """The `swarmdsl run` command that replays this example with checks on."""
        parts = ["swarmdsl", "run", filename, "--headless", "--check",
                 "--steps", str(self.steps if steps is None else steps),
                 "--seed", str(self.seed)]
        for name, value in self.params:
            parts += ["--set", f"{name}={_text(value)}"]
        return shlex.join(parts)


@dataclass
class Counterexample:
    example: Example
    result: RunResult

    @property
    def tick(self) -> int:
        return self.result.first_tick() or 0

    @property
    def agents(self) -> int:
        """How many agents the run started with."""
        return sum(k.count for k in self.result.program.kinds)

    def command(self, filename: str) -> str:
        return self.example.command(filename, max(self.tick, 1))

    def describe(self, filename: str) -> str:
        r = self.result
        lines = []
        if r.violations:
            first = [v for v in r.violations if v.tick == self.tick]
            for v in first:
                lines.append(f"{v.span}: {v.message()}")
        if r.fault is not None and isinstance(r.sim, _NoRun):
            lines.append(f"the program rejects these params: {r.fault}")
        elif r.fault is not None:
            lines.append(f"runtime fault at tick {r.fault_tick}: {r.fault}")
        params = ", ".join(f"{k}={_text(v)}" for k, v in self.example.params) or "defaults"
        lines.append(f"  swarm: {self.agents} agent{'s' * (self.agents != 1)}, "
                     f"{self.tick} tick{'s' * (self.tick != 1)}, seed {self.example.seed}, "
                     f"params: {params}")
        lines.append(f"  reproduce: {self.command(filename)}")
        return "\n".join(lines)


@dataclass
class SearchReport:
    counterexample: Counterexample | None
    examples: int                   # distinct runs made
    seconds: float
    properties: list[str] = field(default_factory=list)
    steps: int = 0


class _Found(Exception):
    def __init__(self, ce: Counterexample):
        super().__init__("counterexample")
        self.ce = ce


def example_strategy(program, steps: int, fixed: dict | None = None) -> st.SearchStrategy:
    """Examples for `program`: size params, ticks, seed, other params (that order)."""
    fixed = fixed or {}
    axes = [a for a in param_axes(program) if a.drawn and a.name not in fixed]
    sizes = [a for a in axes if a.size]
    others = [a for a in axes if not a.size]
    ticks = st.one_of(st.integers(1, max(steps, 1)), st.just(max(steps, 1)))

    def build(s, n, seed, o):
        return Example(tuple(zip([a.name for a in sizes], s, strict=True))
                       + tuple(zip([a.name for a in others], o, strict=True)), seed, n)
    return st.builds(build, st.tuples(*[a.strategy() for a in sizes]), ticks, seeds(),
                     st.tuples(*[a.strategy() for a in others]))


def search(program, *, max_examples: int = 100, time_budget: float = 60.0,
           steps: int | None = None, fixed: dict | None = None,
           properties: list[str] | None = None, hypothesis_seed_value: int | None = None,
           progress: Callable[[int, float, bool], None] | None = None) -> SearchReport:
    """Hunt for a counterexample to `program`'s properties (path, text or Program).

    `time_budget` bounds the search for new examples, and again the shrinking; `fixed`
    params are not drawn. Raises SwarmError when the program does not compile.
    """
    fixed = fixed or {}
    base = load(program, fixed)
    names = [p.info.qualified for p in properties_of(base)]
    from swarmdsl.testing.monitor import Monitor

    monitor = Monitor(base, properties)
    if properties is not None:
        names = [p.info.qualified for p in monitor.properties]
    steps = steps if steps is not None else max(DEFAULT_STEPS, monitor.horizon)
    report = SearchReport(None, 0, 0.0, names, steps)
    if not names:
        return report
    cache: dict[Example, RunResult] = {}
    started = time.perf_counter()
    found_at: list[float] = []

    def attempt(ex: Example) -> RunResult | None:
        if ex in cache:
            return cache[ex]
        now = time.perf_counter()
        limit = found_at[0] + time_budget if found_at else started + time_budget
        if now > limit:
            return None
        try:
            result = run_program(base, ex.steps, seed=ex.seed,
                                 params={**fixed, **ex.overrides()}, properties=properties)
        except SwarmError as err:      # the program rejects a drawn param value
            result = RunResult(base, _NoRun(), fault=err, fault_tick=0)
        cache[ex] = result
        report.examples = len(cache)
        if progress is not None:
            progress(len(cache), time.perf_counter() - started, bool(found_at))
        return result

    @settings(max_examples=max_examples, deadline=None, database=None,
              phases=(Phase.generate, Phase.shrink), report_multiple_bugs=False,
              suppress_health_check=list(HealthCheck), verbosity=Verbosity.quiet,
              print_blob=False)
    @given(example_strategy(base, steps, fixed))
    def hunt(ex):
        result = attempt(ex)
        if result is not None and not result.ok:
            if not found_at:
                found_at.append(time.perf_counter())
            raise _Found(Counterexample(ex, result))

    if hypothesis_seed_value is not None:
        hunt = hypothesis_seed(hypothesis_seed_value)(hunt)
    try:
        hunt()
    except _Found as exc:
        report.counterexample = exc.ce
    report.seconds = time.perf_counter() - started
    return report


class _NoRun:
    """Stands in for a Simulation when the drawn params did not compile."""

    tick = 0
