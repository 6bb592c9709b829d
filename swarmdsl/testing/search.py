"""The counterexample hunt behind `swarmdsl test`: hypothesis draws whole runs (the
initial swarm agent by agent, params, ticks, seed; see `swarms.py`), and a failing run
is shrunk toward the fewest agents and ticks.

Results are cached per draw, so a time budget that stops new runs never makes a replay
disagree with the original run. A seeded hunt is a function of its inputs: what ran
before it in the process changes none of its draws (`draws.py`). Hypothesis keeps no
example database and writes nothing in the current folder. An internal error (a bug in swarmdsl, not in the program) ends
the hunt at once and is raised, never reported as a counterexample.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, Phase, Verbosity, given, settings
from hypothesis import seed as hypothesis_seed

from swarmdsl.compiler import ast
from swarmdsl.compiler.lang_properties import PropertyInfo, properties_of
from swarmdsl.errors import SwarmError, SwarmOptionError, did_you_mean
from swarmdsl.internal import InternalError, internal_error
from swarmdsl.testing.draws import inputs_only
from swarmdsl.testing.example import Example, example_command, param_text
from swarmdsl.testing.runner import RunResult, load, run_program
from swarmdsl.testing.swarms import example_strategy

DEFAULT_STEPS = 100
SHOWN_AGENTS = 12           # initial states printed with a counterexample


@dataclass
class Counterexample:
    example: Example
    result: RunResult
    properties: list[str] | None = None     # the `--property` selection, if any

    @property
    def tick(self) -> int:
        return self.result.first_tick() or 0

    @property
    def agents(self) -> int:
        """How many agents the run started with."""
        return self.example.agent_count(self.result.program)

    @property
    def violations(self) -> list:
        """The violations at the failing tick (the ones a replay stops at)."""
        return [v for v in self.result.violations if v.tick == self.tick]

    def failure(self) -> dict:
        """What failed, as the saved example records it."""
        v = self.violations
        if v:
            return {"property": v[0].name, "keyword": v[0].keyword, "tick": v[0].tick,
                    "agents": list(v[0].agent_ids), "message": v[0].message()}
        return {"fault": str(self.result.fault), "tick": self.tick}

    def replay(self) -> Example:
        """The example cut to the failing tick (a shorter run fails the same way)."""
        ex = self.example
        return Example(ex.params, ex.seed, self.tick, ex.layout)

    def save(self, path: Path, option: str | None = "--save-example") -> None:
        self.replay().save(path, self.result.program, self.properties, self.failure(),
                           option)

    def command(self, filename: str, saved: Path | str) -> str:
        return example_command(filename, saved, self.properties)

    def describe(self, filename: str, saved: Path | str | None = None) -> str:
        r = self.result
        lines = []
        for v in self.violations:
            lines.append(f"{v.span}: {v.message()}")
        if r.fault is not None and isinstance(r.sim, _NoRun):
            lines.append(f"the program rejects these params: {r.fault}")
        elif r.fault is not None:
            lines.append(f"runtime fault: {r.fault}")
        ex = self.example
        params = ", ".join(f"{k}={param_text(v)}" for k, v in ex.params) or "defaults"
        lines.append(f"  swarm: {self.agents} agent{'s' * (self.agents != 1)}, "
                     f"{self.tick} tick{'s' * (self.tick != 1)}, seed {ex.seed}, "
                     f"params: {params}")
        lines += self._subsets()
        lines += self._initial_states()
        if saved is not None:
            lines.append(f"  reproduce: {self.command(filename, saved)}")
        return "\n".join(lines)

    def _subsets(self) -> list[str]:
        """A line naming the kinds that started with fewer agents than their `count`,
        so a property that needs the whole count is seen for what it is."""
        layout, r = self.example.layout, self.result
        if layout is None or isinstance(r.sim, _NoRun):
            return []
        have = layout.counts()
        fewer = [f"`{k.name}` {have[k.name]} of {k.count}" for k in r.program.kinds
                 if k.name in have and have[k.name] < k.count]
        if not fewer:
            return []
        return [f"  fewer agents than the program's count: {', '.join(fewer)} "
                "(--fixed-counts keeps every kind's count)"]

    def _initial_states(self) -> list[str]:
        """One line per agent (the first few): id, kind, status, position, variables."""
        r = self.result
        if isinstance(r.sim, _NoRun):
            return []
        start = r.initial
        n = len(start["id"])
        lines = []
        skip = {"id", "kind", "status", "pos", "vel", "heading", "index", "sense",
                "max_speed", "status_name", "kind_name"}
        for row in range(min(n, SHOWN_AGENTS)):
            x, y = start["pos"][row]
            vx, vy = start["vel"][row]
            extra = "".join(f", {name}={_value(col[row])}" for name, col in start.items()
                            if name not in skip and not name.startswith("_")
                            and r.sim.agents.declared.get(name) is not None
                            and start["_declared"][name][row])
            kind = start["kind_name"][row]
            status = str(start["status_name"][row]).removeprefix(f"{kind}.")
            lines.append(f"    agent {int(start['id'][row])} ({kind}, {status}): "
                         f"pos=({number_text(x)}, {number_text(y)}), "
                         f"vel=({number_text(vx, 3)}, {number_text(vy, 3)}){extra}")
        if n > SHOWN_AGENTS:
            lines.append(f"    ... and {n - SHOWN_AGENTS} more")
        return lines


def _value(v) -> str:
    v = np.asarray(v)
    if v.dtype == bool:
        return "true" if bool(v) else "false"
    if v.ndim:
        return "(" + ", ".join(number_text(x) for x in v.reshape(-1)) + ")"
    return number_text(v)


def number_text(x, digits: int = 6) -> str:
    """A value as a reader wants it in a counterexample: a whole number as one
    (`5263440`, never `5.26344e+06`, which hides the last digits), other numbers with
    `digits` significant digits, in plain decimals unless tiny or huge (below 1e-4 or
    from 1e16 on); `nan`, `inf`, `-inf` as such."""
    x = float(x)
    if not math.isfinite(x):
        return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")
    if x == int(x) and abs(x) < 2**53:
        return str(int(x))
    if not 1e-4 <= abs(x) < 1e16:
        return f"{x:.{digits}g}"
    whole = math.floor(math.log10(abs(x))) + 1          # digits before the point
    text = f"{x:.{max(digits - whole, 1)}f}"
    return text.rstrip("0").rstrip(".") if "." in text else text


@dataclass
class SearchReport:
    counterexample: Counterexample | None
    examples: int                   # distinct runs made, searching and shrinking
    seconds: float                  # the whole hunt
    properties: list[str] = field(default_factory=list)
    steps: int = 0
    found_after: int = 0            # runs until the first failure
    found_seconds: float = 0.0      # time until the first failure
    shrink_runs: int = 0            # runs made while shrinking
    horizon: str = ""               # why `steps` is what it is (`horizon`)
    exercised: dict[str, int] = field(default_factory=dict)  # runs that could break each
    infos: dict[str, PropertyInfo] = field(default_factory=dict)   # by qualified name

    def unexercised(self) -> list[str]:
        """The properties no run exercised: they passed without being put to the test."""
        return [name for name in self.properties if not self.exercised.get(name)]


class _Found(Exception):
    def __init__(self, ce: Counterexample):
        super().__init__("counterexample")
        self.ce = ce


class _OutOfTime(BaseException):
    """Ends the search for new runs when the time budget is spent before any failure:
    hypothesis would otherwise go on drawing (not running) up to `max_examples`
    swarms, which for a large count takes far longer than the budget."""


class _Internal(BaseException):
    """Ends the hunt at once: hypothesis lets a BaseException through (as it does
    Ctrl-C) instead of shrinking it as a failure."""

    def __init__(self, err: InternalError):
        super().__init__(str(err))
        self.err = err


def search(program, *, max_examples: int = 100, time_budget: float = 60.0,
           steps: int | None = None, fixed: dict | None = None,
           properties: list[str] | None = None, hypothesis_seed_value: int | None = None,
           progress: Callable[[int, float, bool], None] | None = None,
           fixed_counts: bool | Iterable[str] = False) -> SearchReport:
    """Hunt for a counterexample to `program`'s properties (path, text or Program).

    `time_budget` bounds the search for new examples, and again the shrinking; `fixed`
    params are not drawn; `fixed_counts` (True, or kind names) keeps those kinds at their
    program count instead of drawing a smaller swarm. Raises SwarmError when the program
    does not compile, SwarmOptionError for a `fixed_counts` name that is not a kind,
    `swarmdsl.internal.InternalError` when swarmdsl itself fails during a drawn run.
    """
    _check_search_arguments(max_examples, time_budget, steps)
    fixed = fixed or {}
    base = load(program, fixed)
    if fixed_counts is not True:
        fixed_counts = kind_names(base, fixed_counts or (), "--fixed-count")
    from swarmdsl.testing.monitor import Monitor

    monitor = Monitor(base, properties)
    infos = {p.info.qualified: p.info for p in (monitor.properties if properties
                                                is not None else properties_of(base))}
    steps, why = horizon(base, steps, monitor.horizon)
    report = SearchReport(None, 0, 0.0, list(infos), steps, horizon=why, infos=infos)
    names = report.properties
    if not names:
        return report
    cache: dict[Example, RunResult] = {}
    compiled: dict[tuple, object] = {}
    started = time.perf_counter()
    found_at: list[float] = []

    def compile_with(params: dict):
        key = tuple(sorted((k, param_text(v)) for k, v in params.items()))
        if key not in compiled:
            try:
                compiled[key] = load(base, params)
            except SwarmError as err:
                compiled[key] = err
            except Exception as exc:
                raise _Internal(internal_error(exc)) from exc
        got = compiled[key]
        if isinstance(got, SwarmError):
            raise got
        return got

    def attempt(ex: Example) -> RunResult | None:
        if ex in cache:
            return cache[ex]
        now = time.perf_counter()
        limit = found_at[0] + time_budget if found_at else started + time_budget
        # at least one run, however small the budget: a hunt of none reported "no
        # counterexample" (exit 0) for a program it never ran
        if now > limit and (cache or found_at):
            if not found_at:
                raise _OutOfTime
            return None     # shrinking: the smallest failure so far is the answer
        params = {**fixed, **ex.overrides()}
        try:
            prog = compile_with(params)
            result = run_program(prog, ex.steps, seed=ex.seed, properties=properties,
                                 layout=ex.layout)
        except InternalError as err:   # a bug in swarmdsl, not a counterexample
            raise _Internal(err) from None
        except SwarmError as err:      # the program rejects a drawn param value
            result = RunResult(base, _NoRun(), fault=err, fault_tick=0)
        cache[ex] = result
        report.examples = len(cache)
        for name in result.exercised:
            report.exercised[name] = report.exercised.get(name, 0) + 1
        if found_at:
            report.shrink_runs += 1
        if progress is not None:
            progress(len(cache), time.perf_counter() - started, bool(found_at))
        return result

    @settings(max_examples=max_examples, deadline=None, database=None,
              phases=(Phase.generate, Phase.shrink), report_multiple_bugs=False,
              suppress_health_check=list(HealthCheck), verbosity=Verbosity.quiet,
              print_blob=False)
    @given(example_strategy(base, steps, fixed, compile_with, fixed_counts))
    def hunt(ex):
        result = attempt(ex)
        if result is not None and not result.ok:
            if not found_at:
                found_at.append(time.perf_counter())
                report.found_after = len(cache)
                report.found_seconds = found_at[0] - started
            every = Example(tuple(fixed.items()) + ex.params, ex.seed, ex.steps, ex.layout)
            raise _Found(Counterexample(every, result, properties))

    if hypothesis_seed_value is not None:
        hunt = hypothesis_seed(hypothesis_seed_value)(hunt)
    try:
        with inputs_only():     # the same seed, the same hunt, whatever ran before
            hunt()
    except _Found as exc:
        report.counterexample = exc.ce
    except _OutOfTime:
        pass
    except _Internal as stop:
        raise stop.err  # its __cause__ is the exception itself
    report.seconds = time.perf_counter() - started
    return report


def horizon(program, steps: int | None, within: int) -> tuple[int, str]:
    """The ticks per run of a hunt, and why: `steps` when given, else the program's own
    `world { steps N }` (what its runs are), else the default 100 or the largest
    `within` when larger (an `eventually` needs its N ticks to be put to the test)."""
    if steps is not None:
        return steps, "--steps"
    for w in program.info.tree.decls_of(ast.WorldDecl)[:1]:
        if any(opt.name == "steps" for opt in w.options) and program.world.steps >= 1:
            return program.world.steps, f"the program's `world {{ steps " \
                f"{program.world.steps} }}`"
    if within > DEFAULT_STEPS:
        return within, "the largest `within`; the program's world sets no `steps`"
    return DEFAULT_STEPS, "the default; the program's world sets no `steps`"


def _check_search_arguments(max_examples, time_budget, steps) -> None:
    """What `swarmdsl test` checks of its options, for callers of `search`."""
    import math
    import numbers

    from swarmdsl.limits import upper
    from swarmdsl.runtime.arguments import whole

    whole("max_examples", max_examples, 1, 2**62)
    if steps is not None:
        whole("steps", steps, 1, upper("steps"))
    if isinstance(time_budget, bool) or not isinstance(time_budget, numbers.Real) \
            or not math.isfinite(time_budget) or time_budget <= 0:
        raise SwarmOptionError(f"time_budget must be a positive number of seconds, got "
                               f"{time_budget!r}")


def kind_names(program, names: Iterable[str], option: str) -> tuple[str, ...]:
    """`names` checked against the program's kinds (an option error names the kinds)."""
    kinds = [k.name for k in program.kinds]
    for name in names:
        if name not in kinds:
            hint = did_you_mean(name, kinds)
            raise SwarmOptionError(f"{option} {name}: no such kind (the program has: "
                                   f"{', '.join(kinds)}){'; ' + hint if hint else ''}")
    return tuple(names)


class _NoRun:
    """Stands in for a Simulation when the drawn params did not compile."""

    tick = 0
