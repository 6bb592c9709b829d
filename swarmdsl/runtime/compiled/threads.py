"""How the compiled kernels share the machine's cores.

A kernel over agents is split into runs of agents, one per chunk, on numba's thread
pool, when the swarm is big enough that the split repays starting and joining the
threads. Every agent's result is computed by the same code on the same inputs whichever
thread runs it, so results are bit-identical for any thread count.

The thread count is numba's own setting, `NUMBA_NUM_THREADS` (default: every core);
`NUMBA_NUM_THREADS=1` keeps every kernel serial. A sweep sets it to 1 in its workers,
which share the cores as processes instead.
"""

from __future__ import annotations

# Below this many agents a kernel stays serial: joining the pool costs ~10-50 us per
# call. From 2,000 agents two threads already save 15-35 % of a tick on a quiet
# 2-core machine (docs/backends.md#threads); at 1,000 they save less than 10 %.
MIN_PARALLEL = 2_000
# Chunks per thread: agents differ in their neighbour counts (a dense flock beside an
# empty corner), so a few chunks per thread keep the threads evenly loaded.
CHUNKS_PER_THREAD = 4


def count() -> int:
    """The number of threads the kernels may use (numba's NUMBA_NUM_THREADS)."""
    from numba import config

    return max(1, int(config.NUMBA_NUM_THREADS))


def chunks(n: int) -> int:
    """How many chunks a kernel over `n` agents runs in: 1 means serial."""
    t = count()
    if t <= 1 or n < MIN_PARALLEL:
        return 1
    return t * CHUNKS_PER_THREAD
