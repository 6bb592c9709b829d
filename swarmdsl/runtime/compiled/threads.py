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

import contextlib
import os

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
    t = count_limited()
    if t <= 1 or n < MIN_PARALLEL:
        return 1
    return t * CHUNKS_PER_THREAD


# The thread count a batch asked for (`limited`), None: numba's own.
_limit: int | None = None


def count_limited() -> int:
    """`count()` capped by the batch in progress (`limited`)."""
    got = count()
    return got if _limit is None else max(1, min(got, _limit))


@contextlib.contextmanager
def limited(n: int):
    """Kernels run inside the block use at most `n` threads (1: every kernel serial,
    no thread pool joined)."""
    global _limit
    saved, _limit = _limit, n
    pool = None
    if 1 < n < count():   # the threaded kernels' pool too (this thread's setting)
        import numba

        pool = numba.get_num_threads()
        numba.set_num_threads(n)
    try:
        yield
    finally:
        _limit = saved
        if pool is not None:
            import numba

            numba.set_num_threads(pool)


def for_batch(agents: int) -> tuple[int, str]:
    """How many threads a batch of `agents` agents ticks on, and why, in words `-v`
    prints. `NUMBA_NUM_THREADS` set by the user (a sweep's workers: 1) decides. Else
    numba's pool only on cores nobody else is using: a batch calls a dozen threaded
    kernels a tick, each waiting for its slowest thread, and a thread that waits for a
    busy core stalls the whole tick (measured: a 10^4-agent vicsek batch on 2 threads
    ran 5x slower than on one, at a load average of 6 on 2 cores). The load average
    counts this process itself, hence the one added back."""
    t = count()
    if "NUMBA_NUM_THREADS" in os.environ or t <= 1:
        return t, f"{t} thread{'s' * (t != 1)} (NUMBA_NUM_THREADS)"
    if agents < MIN_PARALLEL:
        return 1, f"1 thread ({agents:,} agents: fewer than {MIN_PARALLEL:,})"
    try:
        load = os.getloadavg()[0]
    except OSError:   # no load average on this system: numba's own count
        return t, f"{t} threads"
    free = max(1, min(t, int(t - load + 1.0)))
    return free, (f"{free} of {t} threads (load average {load:.1f} on {t} cores: "
                  "threads only on idle cores)")
