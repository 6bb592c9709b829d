"""The tiered start's other process: compile a program's numba kernels onto disk.

`python -m swarmdsl.runtime.compiled.warmup` reads one JSON object on stdin (what
`tiered.request` writes: the program's text, file name, folder and every param's value),
compiles the text with those params for the numba backend, and steps its swarm a few
ticks on numba. Every kernel those ticks run is compiled and kept on disk
(`disk_cache.py`, numba's own cache for the cell list, motion and draws), where the run
that started this process loads them when it switches (`tiered.py`). The swarm is the
run's own up to `AGENTS` agents (the kernels a tick runs depend on its size: threaded
from `threads.MIN_PARALLEL` agents, the portable math's compiled loops from 4,096
values), larger ones scaled down to it, so a tick costs milliseconds. Nothing it
computes is kept but the kernels: a fault of the program is the run's to report, and
ends the warm-up with what compiled so far.

Where an earlier warm-up kept numba's shared kernels on disk (the cell list, motion,
draws, fields: the same for every program; `warm.py` marks them), it first says `SHARED`
on its own line (the run takes them from its next tick, loading them itself:
`tiered.SharedFirst`). Then the ticks that compile the program's own kernels, and it
says `READY` (the run switches to numba whole at that word, not at the process's end);
where no earlier warm-up kept the shared kernels, it steps the swarm with those alone
after `READY`, for the next run. Then it goes on to compile the program's whole-tick kernel
(`tick_kernel.py`: tens of seconds, for the ticks a run hands over between records),
which the run picks up from disk while it goes on, if it is still running by then.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

# The warm-up's swarm at most (a bigger run's kinds scaled to it), and its ticks: the
# first searches the cells in the sums, the second reads the pairs a tick wrote when
# something else wanted them (`NumbaBackend.search_directly`), the third both settled.
AGENTS = 20_000
TICKS = 3


READY = "READY"
SHARED = "SHARED"


def warm_up(req: dict, ticks: int = TICKS) -> float:
    """Compile and step the program `req` describes (saying `SHARED` and `READY` as the
    run may take its kernels), then compile its whole-tick kernel; the seconds numba
    spent compiling."""
    from swarmdsl.compiler import compile_source
    from swarmdsl.errors import SwarmError
    from swarmdsl.runtime.compiled import threads, warm
    from swarmdsl.runtime.compiled.lowering import NUMBA
    from swarmdsl.runtime.simulation import Simulation

    program = compile_source(req["source"], req["filename"], req["params"],
                             Path(req["program_dir"]), lowering=NUMBA)
    total = sum(k.count for k in program.kinds)
    if total > AGENTS:
        for kind in program.kinds:
            kind.count = max(1, kind.count * AGENTS // total) if kind.count else 0
    threaded = sum(k.count for k in program.kinds) >= threads.MIN_PARALLEL
    # numba's shared kernels (the program's parts on the reference closures, as
    # `tiered.SharedFirst` runs them) are on disk where an earlier warm-up kept them:
    # the run may take them at once and load them itself. Where none did, compiling
    # them before the program's own would hold back `READY` by their compile (9 s for
    # boids at 10^4 agents, loaded machine): they are compiled after it, for next time.
    shared_first = warm.shared_here(threaded)
    if shared_first:
        print(SHARED, flush=True)
    sim = Simulation(program, 0, backend="numba")
    try:
        for _ in range(ticks):
            sim.step()
    except SwarmError as err:   # the run itself reports it: what compiled is kept
        print(f"warm-up stopped at tick {sim.tick}: {err}", file=sys.stderr)
        return sim.backend.compile_seconds
    print(READY, flush=True)
    warm.note_compiled(program)   # its kernels are on disk: later runs may load them
    seconds = sim.backend.compile_seconds
    try:
        if not shared_first:
            seconds += _steps(program, ticks, fused=False)
            warm.note_shared(threaded)
        before = sim.backend.compile_seconds
        sim.advance(2)          # compiles the whole-tick kernel where the program has one
        seconds += sim.backend.compile_seconds - before
    except SwarmError:
        pass
    return seconds


def _steps(program, ticks: int, fused: bool) -> float:
    """Step a fresh swarm of `program` `ticks` ticks on numba, with the program's own
    kernels or (not `fused`) only the shared ones: the seconds spent compiling."""
    from swarmdsl.runtime.simulation import Simulation

    sim = Simulation(program, 0, backend="numba")
    sim.backend.fused = fused
    for _ in range(ticks):
        sim.step()
    return sim.backend.compile_seconds


def main() -> int:
    req = json.loads(sys.stdin.read())
    seconds = warm_up(req)
    print(f"compiled in {seconds:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
