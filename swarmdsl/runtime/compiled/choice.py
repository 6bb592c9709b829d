"""Which backend a run gets by default: numba when the time its kernels save over the
run is more than compiling them costs, else numpy; and the one line that says so.

A run's numpy time is estimated from its work, agents x ticks, at a cost per
agent-step that grows with the neighbours each agent has (a uniform swarm's count
within the pair radius: a flock tightens later, which only makes numpy slower than
estimated). The numba backend ticks about ten times faster per agent; the fixed Python
cost of a tick, which numba cuts a little too, is left out, so the estimate errs
towards numpy. Compiling costs a start (importing numba, its cell list, motion and
draws) and a share per fused kernel, or almost nothing once a numba run of the program
has left its kernels on disk (`warm.py`). Kernels a process compiled for an earlier run
are not counted as free: a sweep run's backend would then depend on which runs its
worker happened to run before it. The constants are measured on a quiet 2-core machine
(docs/backends.md#how-the-default-is-chosen); a loaded machine slows compiling and
ticking alike, so the choice holds. Nothing here imports numba or numpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from swarmdsl.runtime.compiled import warm
from swarmdsl.runtime.compiled.threads import MIN_PARALLEL

# seconds per agent-step on the numpy backend: the agent's own work, and per neighbour
# (boids at 10^4 agents, ~25 neighbours: 5.8 us; Vicsek at 10^4, ~13: 3.7 us)
NUMPY_AGENT = 1.5e-6
NUMPY_NEIGHBOUR = 0.17e-6
# the share of that per-agent time left on the numba backend (boids 0.3 us of 5.8,
# Vicsek 0.34 of 3.7 at 10^4 agents)
NUMBA_SHARE = 0.1
# A first numba run of a program: importing numba and compiling the kernels programs
# share (cell list, motion, draws, fields), then one loop per fused aggregate (sums
# sharing a loop count once) and one per fused statement. Fitted to one-tick runs from
# empty cache folders, the extra wall time over numpy's (quiet machine; aggregate loops
# and statements: boids 1 and 2, Vicsek 1 and 2, patrol 1 and 1, aco 0 and 1,
# boids_leader 2 and 2): 9.8, 8.3, 6.6, 5.8 and 11.8 s; and to the program's own
# kernels alone, the shared ones kept (`benchmarks.compile_time`): 3.7, 2.9, 1.4, 0.7
# and 6.4 s. From threads.MIN_PARALLEL agents each aggregate is compiled again as its
# threaded form (Vicsek at 10^4 agents: 11.5 s in all). A program that uses none of
# the shared kernels (matrix2d: no pair search, its robots' own motion) costs less.
COMPILE_START = 5.0
COMPILE_START_KEPT = 0.4   # the shared kernels on disk (a warm-up kept them: `warm.py`)
COMPILE_AGGREGATE = 1.8
COMPILE_AGGREGATE_THREADED = 3.0
COMPILE_STATEMENT = 0.7
# importing numba and loading kernels a numba run left on disk
LOAD = 0.4
# Whole ticks (`tick_kernel.py`) only up to this many agents. Its one loop walks the
# agents serially in row order; the per-tick kernels walk them in cell order, on threads
# from `threads.MIN_PARALLEL`. Vicsek at one agent per unit area, median ms a tick,
# `advance` / `step()` with one thread: 1.3-2.3 / 0.6-1.4 at 1,000 agents, 8 / 3 at
# 10^4, 155-170 / 36-54 at 10^5, and at 10^6 2,400-3,200 / 520-800 (two threads),
# with the kernel's (N, C) tables pushing the peak past 1 GB (docs/benchmarks.md).
# At 100-400 agents the whole tick is level or ahead (its Python cost is less).
WHOLE_TICKS_MAX = 500
# A small swarm's tick is mostly Python's fixed cost, which the figures per agent-step
# above leave out: a numpy tick of 40 bees (BEECLUST) takes 0.75 ms, of patrol's 8
# robots 0.45 ms, of 100 chemotaxis cells 0.52 ms; a whole tick (`tick_kernel.py`)
# 0.024, 0.015 and 0.042 ms (docs/benchmarks.md#fields-in-whole-ticks). Counted only
# where a run gets whole ticks: at most WHOLE_TICKS_MAX agents, and the program's
# whole-tick kernel kept on disk here (`warm.whole_here`): its compile (tens of
# seconds) is never worth a short run's while.
NUMPY_TICK = 0.4e-3
WHOLE_TICK = 0.05e-3
# A run numpy would take at least this long (estimated) starts on numpy at once and
# takes numba once another process has compiled its kernels (`tiered.py`); shorter ones
# stay on numpy (the compile would outlast them).
TIERED_FROM = 1.0
# ...unless one numpy tick would take this long (estimated): a swarm that dense (boids
# with a 160-unit sight at 10^4 agents in 600 x 600: ~2,000 neighbours each, a numpy
# tick of 10-40 s holding GBs of pairs) gets its first tick sooner from the compile.
TIERED_TICK_MAX = 1.0


@dataclass(frozen=True)
class Choice:
    name: str          # "numba" or "numpy"
    why: str           # what the line says in brackets
    seconds_saved: float
    compile_seconds: float
    worth_saying: bool = True   # False: numba is missing and would not have paid
    tiered: bool = False        # numpy at once, numba once its kernels are compiled

    @property
    def line(self) -> str:
        if self.tiered:
            return f"backend: numpy now, numba from the tick its kernels are ready ({self.why})"
        return f"backend: {self.name} ({self.why})"


def neighbours(program) -> float:
    """Each agent's neighbours within the pair radius for a uniform swarm."""
    n = agents(program)
    radius = float(getattr(program, "pair_radius", 0.0) or 0.0)
    world = program.world
    area = float(world.width) * float(world.height)
    if n < 2 or radius <= 0 or not area > 0:
        return 0.0
    return (n - 1) * min(1.0, math.pi * radius * radius / area)


def agents(program) -> int:
    """The agents a tick of `program` moves, as it starts."""
    return sum(k.count for k in program.kinds)


def kernels(program) -> tuple[int, int]:
    """The loops a first numba run of `program` compiles: (aggregates, statements). One
    per fused aggregate (sums that share a loop, `siblings.py`, count once; a filter an
    aggregate takes is compiled into its loop) and one per fused statement. A program not
    lowered for numba yet is lowered on a copy, which plans without importing numba."""
    lowered = _lowered(program)
    loops = set()
    for part in getattr(lowered, "fused_parts", ()):
        if part.name != "where" and getattr(part, "plan", None) is not None:
            group = getattr(part, "siblings", None)
            loops.add(id(part) if group is None else id(group))
    statements = getattr(lowered, "fused_statements", ())
    return len(loops), sum(getattr(p, "plan", None) is not None for p in statements)


def _lowered(program):
    """`program` with the numba lowering's parts: itself once a numba run lowered it,
    else a copy (memoised on it: the count is asked once a run, a sweep's many times)."""
    lowering = getattr(program, "lowering", None)
    if getattr(lowering, "name", None) == "numba" or not hasattr(program, "info"):
        return program
    copy = getattr(program, "_numba_copy", None)
    if copy is None:
        from swarmdsl.compiler.program import build_program
        from swarmdsl.runtime.compiled.lowering import NUMBA

        try:
            copy = build_program(program.info, program.source, program.program_dir, NUMBA)
        except Exception:   # noqa: BLE001 - an estimate must not stop a numpy run; a
            copy = program  # numba run lowers it again and says what failed
        program._numba_copy = copy
    return copy


def whole_saving(program, work: float) -> float | None:
    """Seconds numba saves over `work` agent-steps of `program` with whole ticks, each
    tick's fixed cost counted, when the run gets them from kernels kept here (the
    program's own and its whole-tick kernel); None when it would not."""
    n = agents(program)
    if not 2 <= n <= WHOLE_TICKS_MAX or not (warm.whole_here(program)
                                             and warm.compiled_here(program)):
        return None
    return work / n * (NUMPY_TICK - WHOLE_TICK) + saved(program, work)


def compile_estimate(program) -> tuple[float, str]:
    """Seconds numba costs this run before it saves any, and what they are."""
    if warm.compiled_here(program) or _compiled_in_process(program):
        return LOAD, "kernels kept from an earlier run"
    kept = ", kept for later runs" if warm.keeps_kernels() else ""
    threaded = agents(program) >= MIN_PARALLEL
    start = COMPILE_START_KEPT if warm.shared_here(threaded) else COMPILE_START
    aggregate = COMPILE_AGGREGATE_THREADED if threaded else COMPILE_AGGREGATE
    aggregates, statements = kernels(program)
    seconds = start + aggregate * aggregates + COMPILE_STATEMENT * statements
    return seconds, f"compiling kernels, ~{_seconds(seconds)}{kept}"


def saved(program, work: float) -> float:
    """Seconds the numba backend saves over `work` agent-steps of `program`."""
    per_step = NUMPY_AGENT + NUMPY_NEIGHBOUR * neighbours(program)
    return work * per_step * (1 - NUMBA_SHARE)


def numpy_seconds(program, work: float) -> float:
    """What `work` agent-steps of `program` take on numpy (estimated)."""
    return work * (NUMPY_AGENT + NUMPY_NEIGHBOUR * neighbours(program))


def choose(program, work: float | None, installed: bool, tiered: bool = False) -> Choice:
    """numba when installed and it repays its compile time over `work` agent-steps
    (unknown work: numba when installed, a `Simulation` stepped by hand), else numpy.
    With `tiered` (a solo run that can change backend between ticks), a first run whose
    kernels are not on disk yet, if numpy would take a second or more, starts on numpy
    and takes numba when another process has compiled them (`tiered.py`)."""
    if (tiered and installed and work is not None and program is not None
            and numpy_seconds(program, work) >= TIERED_FROM
            and not warm.compiled_here(program) and _can_tier(program)):
        tick = numpy_seconds(program, agents(program))
        if tick < TIERED_TICK_MAX:
            return Choice("numba", "compiling them in another process, kept for later "
                          "runs", saved(program, work), 0.0, tiered=True)
        cost, how = compile_estimate(program)
        how = how.replace("compiling kernels", "compiling kernels before the first tick")
        return Choice("numba", f"{how}: one numpy tick of ~{neighbours(program):,.0f} "
                      f"neighbours each would take ~{_seconds(tick)}", saved(program, work),
                      cost)
    if work is None or program is None:
        if installed:
            return Choice("numba", "the run's length is not known", math.inf, 0.0)
        return Choice("numpy", "numba is not installed", 0.0, 0.0, False)
    gain = saved(program, work)
    cost, how = compile_estimate(program)
    whole = whole_saving(program, work)
    if whole is not None:
        gain, how = whole, "kernels kept from an earlier run, its whole-tick kernel too"
    steps = f"{work:,.0f} agent-steps"
    if not installed:
        if gain <= cost + 1:
            return Choice("numpy", "numba is not installed", gain, cost, False)
        return Choice("numpy", f"numba is not installed: it would save ~"
                      f"{_seconds(gain - cost)} of {steps} (pip install swarmdsl[numba])",
                      gain, cost)
    if gain > cost:
        return Choice("numba", f"{how}; saves ~{_seconds(gain)} over {steps}", gain, cost)
    what = "compiling" if how.startswith("compiling") else "loading its kept kernels"
    return Choice("numpy", f"short run: {steps}; numba would save ~{_seconds(gain)} "
                  f"for ~{_seconds(cost)} of {what}", gain, cost)


def _can_tier(program) -> bool:
    """Whether another process can compile the kernels for this one: the kernel cache
    is on, and this process has not compiled them already."""
    from swarmdsl.runtime.compiled import tiered

    return tiered.environment_ready() and not tiered.compiled_in_process(program)


def _compiled_in_process(program) -> bool:
    """Whether a tiered start of this process compiled `program`'s kernels onto disk."""
    import sys

    tiered = sys.modules.get("swarmdsl.runtime.compiled.tiered")   # none: no such start
    return tiered is not None and tiered.compiled_in_process(program)


def _seconds(seconds: float) -> str:
    if seconds < 10:
        return f"{seconds:.1f} s"
    if seconds < 120:
        return f"{seconds:.0f} s"
    return f"{seconds / 60:.0f} min"
