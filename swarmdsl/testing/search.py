"""The counterexample hunt behind `swarmdsl test`.

First the program runs as written, as a user's `swarmdsl run --check` would: its
declared counts, its params at their values (or `--set`), several seeds, its horizon;
a property one of those runs breaks is never reported as holding. Then hypothesis
draws whole runs (the initial swarm agent by agent, params, ticks, seed; see
`swarms.py`) for the properties still standing, round after round: a failure takes
its properties out of the hunt and the hunt goes on for the others, so every failing
property gets its own counterexample. Each is shrunk (`shrink.py`) to a 1-minimal
case, checked, or said to be possibly not minimal.

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

from hypothesis import HealthCheck, Phase, Verbosity, given, settings
from hypothesis import seed as hypothesis_seed

from swarmdsl.compiler import ast
from swarmdsl.compiler.lang_properties import PropertyInfo, properties_of
from swarmdsl.errors import SwarmError, SwarmOptionError, did_you_mean
from swarmdsl.internal import InternalError, internal_error
from swarmdsl.testing.counterexample import (Counterexample, _NoRun,  # noqa: F401
                                             number_text)
from swarmdsl.testing.coverage import Coverage
from swarmdsl.testing.draws import inputs_only
from swarmdsl.testing.example import Example, param_text
from swarmdsl.testing.runner import RunResult, load, run_program
from swarmdsl.testing.shrink import first_failure, shrink
from swarmdsl.testing.strategies import param_axes
from swarmdsl.testing.swarms import SIZE, example_strategy, kind_draws

DEFAULT_STEPS = 100
DEFAULT_SEEDS = 3           # runs of the program as written


@dataclass
class SearchReport:
    counterexamples: list[Counterexample]   # one per failing property (or fault)
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
    coverage: Coverage | None = None    # what the hunting runs tried (`coverage.py`)
    shrink_budget: float = 0.0
    program: object = None              # compiled with the fixed params
    as_written_steps: int = 0           # the ticks of the runs of the program as written
    # with `verbose`: how the runs ticked (the backend's whole-tick line, its counts
    # left out) -> how many runs said it
    ticking: dict[str, int] = field(default_factory=dict)

    @property
    def counterexample(self) -> Counterexample | None:
        """The first counterexample found, or None."""
        return self.counterexamples[0] if self.counterexamples else None

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
           fixed_counts: bool | Iterable[str] = False, seeds: int = DEFAULT_SEEDS,
           shrink_budget: float | None = None, verbose: bool = False) -> SearchReport:
    """Hunt for counterexamples to `program`'s properties (path, text or Program).

    The program first runs as written at seeds `0..seeds-1` (its declared counts, the
    `fixed` params, the horizon); then hypothesis draws runs (up to `max_examples`)
    for the properties still standing. `time_budget` bounds the hunt (the runs as
    written are always made); each counterexample is shrunk for up to `shrink_budget`
    seconds (default: `time_budget`). `fixed` params are not drawn, and a kind counted
    by one keeps that count; `fixed_counts` (True, or kind names) keeps those kinds at
    their program count. Raises SwarmError when the program does not compile,
    SwarmOptionError for a bad option, `swarmdsl.internal.InternalError` when
    swarmdsl itself fails during a run.
    """
    _check_search_arguments(max_examples, time_budget, steps)
    _check_more_arguments(seeds, shrink_budget)
    fixed = fixed or {}
    base = load(program, fixed)
    if fixed_counts is not True:
        fixed_counts = kind_names(base, fixed_counts or (), "--fixed-count") \
            + pinned_kinds(base, fixed)
    from swarmdsl.testing.monitor import Monitor

    monitor = Monitor(base, properties)
    infos = {p.info.qualified: p.info for p in (monitor.properties if properties
                                                is not None else properties_of(base))}
    given = steps
    steps, why = horizon(base, steps, monitor.horizon)
    # the program as written runs what `swarmdsl run FILE --check` runs: the world's
    # `steps`, 1000 when it sets none (drawn runs default to fewer: `horizon`)
    own = int(base.world.steps)
    as_written = given if given is not None else own
    shrink_budget = time_budget if shrink_budget is None else float(shrink_budget)
    report = SearchReport([], 0, 0.0, list(infos), steps, horizon=why, infos=infos,
                          shrink_budget=shrink_budget, program=base,
                          as_written_steps=as_written if seeds else 0)
    if not report.properties:
        return report
    report.coverage = Coverage({k.name: k.count for k in base.kinds}, own)
    axes = [a for a in param_axes(base) if a.drawn and a.name not in fixed]
    plan = kind_draws(base, axes, fixed_counts)
    free = {d.axis.name for d in plan if d.mode == SIZE and d.axis is not None}
    shrink_axes = [a for a in axes if a.name not in free]   # a kind's size: its agents
    hunt = _Hunt(base, fixed, report, progress, time_budget)
    hunt.verbose = verbose
    remaining = list(report.properties)
    faulted = False

    def settle(example: Example, failing: list[str | None], origin: str,
               deadline: float | None = None, since: tuple | None = None) -> None:
        """Shrink each failure of `example` (a property, or None: a fault) on its own."""
        nonlocal faulted
        for prop in failing:
            if prop is None:
                faulted = True
            elif prop in remaining:
                remaining.remove(prop)
            else:
                continue
            checked = properties if prop is None else [prop]
            end = deadline if deadline is not None else time.perf_counter() + shrink_budget
            deadline = None
            hunt.shrinking = True
            before, t0 = since if since is not None else (hunt.shrink_runs,
                                                          time.perf_counter())
            since = None
            got = shrink(example, prop, plan, base,
                         lambda ex, checked=checked: hunt.run(ex, checked), end,
                         shrink_axes)
            hunt.shrinking = False
            if got is None:     # cannot happen with deterministic runs; keep it unshrunk
                result = hunt.run(example, checked)
                ce = Counterexample(example, result, checked, origin)
            else:
                ce = Counterexample(got.example, got.result, checked, origin,
                                    minimal=got.minimal,
                                    shrink_runs=hunt.shrink_runs - before,
                                    shrink_seconds=time.perf_counter() - t0,
                                    removal_checks=got.removal_checks, kept=got.kept,
                                    shrink_budget=shrink_budget)
            ce.found_after, ce.found_seconds = hunt.found
            report.counterexamples.append(ce)

    try:
        # 1. the program as written: what `swarmdsl run FILE --check` runs
        for seed in range(seeds):
            if not remaining or faulted:
                break
            ex = Example(tuple(fixed.items()), seed, as_written, None)
            result = hunt.run(ex, list(remaining), stop=False, drawn=False)
            failing = [name for name in list(remaining)
                       if first_failure(result, name) is not None]
            if result.fault is not None:
                failing.append(None)
            if failing:
                hunt.mark_found()
                failing.sort(key=lambda n: (_tick_of(result, n), str(n)))
                settle(ex, failing, f"the program as written, seed {seed}")
        # 2. drawn runs, for the properties still standing
        while remaining and not faulted and hunt.drawn < max_examples \
                and (time.perf_counter() < hunt.started + time_budget or hunt.runs == 0):
            found = _draw_round(base, steps, fixed, plan, fixed_counts, hunt, remaining,
                                max_examples, hypothesis_seed_value, shrink_budget)
            if found is None:
                break
            example, result, found_time, runs_then = found
            tick = result.first_tick()
            failing = sorted({v.name for v in result.violations if v.tick == tick
                              and v.name in remaining})
            if result.fault is not None and result.fault_tick == tick:
                failing.append(None)
            if not failing:
                break
            settle(example, failing, "a drawn run", found_time + shrink_budget,
                   (runs_then, found_time))
    except _Internal as stop:
        raise stop.err  # its __cause__ is the exception itself
    report.examples = hunt.runs
    report.shrink_runs = hunt.shrink_runs
    if report.counterexamples:
        report.found_after = report.counterexamples[0].found_after
        report.found_seconds = report.counterexamples[0].found_seconds
    report.seconds = time.perf_counter() - hunt.started
    return report


def _tick_of(result, name) -> int:
    t = first_failure(result, name)
    return t if t is not None else 1 << 62


class _Hunt:
    """The runs of one hunt: compiled params and results cached, coverage counted,
    internal errors turned into `_Internal`."""

    def __init__(self, base, fixed: dict, report: SearchReport, progress, budget: float):
        self.base, self.fixed, self.report, self.progress = base, fixed, report, progress
        self.budget = budget
        self.cache: dict[tuple, RunResult] = {}
        self.passed: dict[Example, tuple] = {}   # (properties, run) that broke none
        self.compiled: dict[tuple, object] = {}
        self.started = time.perf_counter()
        self.runs = 0           # distinct runs made
        self.hunting = 0        # of them, runs of the hunt (not shrinking)
        self.drawn = 0          # of them, drawn runs
        self.shrink_runs = 0
        self.shrinking = False
        self.found = (0, 0.0)   # hunting runs and seconds until the last failure found
        self.verbose = False    # tally how each run ticked (`SearchReport.ticking`)

    def mark_found(self) -> None:
        self.found = (self.hunting, time.perf_counter() - self.started)

    def compile_with(self, params: dict):
        key = tuple(sorted((k, param_text(v)) for k, v in params.items()))
        if key not in self.compiled:
            try:
                self.compiled[key] = load(self.base, params)
            except SwarmError as err:
                self.compiled[key] = err
            except Exception as exc:
                raise _Internal(internal_error(exc)) from exc
        got = self.compiled[key]
        if isinstance(got, SwarmError):
            raise got
        return got

    def cached(self, ex: Example, properties, stop: bool = True) -> RunResult | None:
        """The run of `ex` made before, checking `properties` (or more, for a pass)."""
        key = (ex, None if properties is None else tuple(properties), stop)
        if key in self.cache:
            return self.cache[key]
        if stop and ex in self.passed:
            checked, result = self.passed[ex]
            if checked is None or (properties is not None and set(properties) <= checked):
                return result
        return None

    def run(self, ex: Example, properties, stop: bool = True,
            drawn: bool = False) -> RunResult:
        """One checked run of `ex` (cached): `properties` checked (None: all)."""
        known = self.cached(ex, properties, stop)
        if known is not None:
            return known
        key = (ex, None if properties is None else tuple(properties), stop)
        params = {**self.fixed, **ex.overrides()}
        try:
            prog = self.compile_with(params)
            left = self.started + self.budget - time.perf_counter()
            result = run_program(prog, ex.steps, seed=ex.seed, properties=properties,
                                 layout=ex.layout, stop_at_first=stop,
                                 coverage=not self.shrinking, more_seconds=max(left, 0.0))
        except InternalError as err:   # a bug in swarmdsl, not a counterexample
            raise _Internal(err) from None
        except SwarmError as err:      # the program rejects a drawn param value
            result = RunResult(self.base, _NoRun(), fault=err, fault_tick=0)
        self.cache[key] = result
        if self.verbose and hasattr(result.sim, "backend"):
            self._tally(result)
        if result.ok and stop:
            self.passed[ex] = (None if properties is None else set(properties), result)
        self.runs += 1
        if self.shrinking:
            self.shrink_runs += 1
        else:
            self.hunting += 1
            self.drawn += drawn
            cov = self.report.coverage
            cov.add(result, drawn)
            if not drawn:
                cov.as_written += 1
                cov.as_written_seeds.append(ex.seed)
            for name in result.exercised:
                self.report.exercised[name] = self.report.exercised.get(name, 0) + 1
        self.report.examples = self.runs
        if self.progress is not None:
            self.progress(self.runs, time.perf_counter() - self.started, self.shrinking)
        return result


    def _tally(self, result: RunResult) -> None:
        """Count the run's whole-tick line (`-v`), so that runs that ticked alike count
        together (`ticked_alike`)."""
        lines = [line for line in result.sim.backend.summary(result.program)
                 if line.startswith(("whole-tick kernel", "properties checked"))]
        whole = getattr(result.sim.backend, "whole_ticks_ready", None) is not None
        if whole and result.stepped:   # the monitor saw ticks itself, the backend could not
            lines.append(f"ticks checked one by one in Python while {result.stepped}"
                         if lines else f"whole-tick kernel: no ({result.stepped})")
        for line in lines or ["whole-tick kernel: not asked (a run of one tick, or a "
                              "backend without whole ticks)"]:
            line = ticked_alike(line)
            self.report.ticking[line] = self.report.ticking.get(line, 0) + 1


def ticked_alike(line: str) -> str:
    """A run's whole-tick line with its numbers left out: "whole-tick kernel: yes (1,500
    ticks in 1 call)" is "whole-tick kernel: yes"; "yes (60 ticks in 3 calls;
    properties checked in the kernel at 60 ticks)" is "yes (properties checked in the
    kernel at N ticks)"."""
    import re

    line = re.sub(r" \(\d[\d,]* ticks? in [\d,]+ calls?(; |\))",
                  lambda m: " (" if m[1] == "; " else "", line)
    return re.sub(r"[\d,]+ (ticks|stopped)", r"N \1", line)


def _draw_round(base, steps, fixed, plan, fixed_counts, hunt: _Hunt, remaining: list[str],
                max_examples: int, seed_value, shrink_budget: float):
    """One hypothesis hunt for the `remaining` properties: (example with the fixed
    params, its failing run, when it was found) after hypothesis' own shrinking (for
    up to half the shrink budget), or None when the hunt found nothing."""
    checked = list(remaining)
    found_at: list[float] = []
    best: list = []

    def attempt(ex: Example) -> RunResult | None:
        every = Example(tuple(fixed.items()) + ex.params, ex.seed, ex.steps, ex.layout)
        known = hunt.cached(every, checked)
        if known is not None:   # a replay agrees with its run, whatever the clock says
            return known
        now = time.perf_counter()
        if found_at:
            if now > found_at[0] + shrink_budget / 2:
                return None     # shrinking: the smallest failure so far is the answer
        elif (now > hunt.started + hunt.budget and hunt.runs) or hunt.drawn >= max_examples:
            raise _OutOfTime
        hunt.shrinking = bool(found_at)
        try:
            return hunt.run(every, checked, drawn=True)
        finally:
            hunt.shrinking = False

    @settings(max_examples=max(max_examples, 1) * 4, deadline=None, database=None,
              phases=(Phase.generate, Phase.shrink), report_multiple_bugs=False,
              suppress_health_check=list(HealthCheck), verbosity=Verbosity.quiet,
              print_blob=False)
    @given(example_strategy(base, steps, fixed, hunt.compile_with, fixed_counts))
    def round_(ex):
        result = attempt(ex)
        if result is not None and not result.ok and result.first_tick() is not None:
            if not found_at:
                found_at.append(time.perf_counter())
                found_at.append(hunt.shrink_runs)
                hunt.mark_found()
            every = Example(tuple(fixed.items()) + ex.params, ex.seed, ex.steps, ex.layout)
            best[:] = [every, result]
            raise _Found(None)

    if seed_value is not None:
        round_ = hypothesis_seed(seed_value)(round_)
    try:
        with inputs_only():     # the same seed, the same hunt, whatever ran before
            round_()
    except _Found:
        pass
    except _OutOfTime:
        pass
    except Exception:       # hypothesis' own complaint about a failure it replayed
        if not best:
            raise
    if not best:
        return None
    return best[0], best[1], found_at[0], found_at[1]


def pinned_kinds(program, fixed: dict) -> tuple[str, ...]:
    """The kinds whose `count` reads a `--set` param: they keep that count in every run."""
    from swarmdsl.testing.swarms import _names

    out = []
    for k in program.info.kinds:
        opt = k.options.get("count")
        if opt is not None and any(n in fixed for n in _names(opt.args)):
            out.append(k.name)
    return tuple(out)


def _check_more_arguments(seeds, shrink_budget) -> None:
    import numbers

    from swarmdsl.runtime.arguments import whole

    whole("seeds", seeds, 0, 10_000)
    if shrink_budget is not None and (
            isinstance(shrink_budget, bool) or not isinstance(shrink_budget, numbers.Real)
            or not math.isfinite(shrink_budget) or shrink_budget <= 0):
        raise SwarmOptionError(f"shrink_budget must be a positive number of seconds, got "
                               f"{shrink_budget!r}")


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
