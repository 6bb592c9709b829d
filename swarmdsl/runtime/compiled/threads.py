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


# Solo runs from this many agents choose, tick by tick, between threads and one thread
# (`Pace`); smaller ones keep `chunks`' rule. Not `MIN_PARALLEL`, which tests lower to
# thread every kernel of a small swarm on every tick.
PACE_FROM = 2_000
# Ticks between tries of the choice that lost, at first; doubled each time it loses
# again, up to `PACE_LONGEST`.
PACE_RETRY = 16
PACE_LONGEST = 512


class Pace:
    """One run's choice, tick by tick, between splitting its kernels over numba's
    threads and running them on one: whichever ticked faster lately.

    Why measure rather than trust the core count: a threaded kernel waits at its end for
    its slowest thread, and a tick calls several. Beside other busy processes a thread
    often waits for a core, and the whole tick with it: on 2 shared cores at a load
    average of 5, Vicsek ticked 10-15x slower on two threads than on one at 10^4 agents
    (33-48 ms against 3) and 2.4x slower at 10^6, while on an idle machine two threads
    save a third (docs/benchmarks.md). A tick's result has the same bits either way
    (`chunks`), so only its time depends on the choice. Each choice's first tick is not
    timed (it may load its kernels); then every tick takes the choice whose recent
    ticks (a running mean) were faster, so a choice that slows down gives way, and the
    other is tried again after `PACE_RETRY` ticks, twice as long after each loss.
    `NUMBA_NUM_THREADS` set by the user, a batch's limit (`limited`), one core, or a
    swarm under `PACE_FROM` agents: no choice, `chunks` decides as it always has."""

    def __init__(self):
        self.seconds: dict[int, float] = {}   # threads -> smoothed seconds a tick
        self.runs: dict[int, int] = {}        # threads -> ticks run on it
        self.best = 0            # the choice in use once both are timed
        self.ticks = 0           # ticks since the last try of the other
        self.gap = PACE_RETRY    # ticks until the next try
        self.agents = 0          # the swarm's size when last timed

    def pick(self, n: int) -> int | None:
        """How many threads this tick may use, or None: no choice to make."""
        t = count()
        if (t <= 1 or n < PACE_FROM or _limit is not None
                or "NUMBA_NUM_THREADS" in os.environ):
            return None
        if not (n // 2 <= self.agents <= 2 * n):   # a new swarm, or it changed size
            self.seconds.clear()
            self.best, self.ticks, self.gap, self.agents = 0, 0, PACE_RETRY, n
        for choice in (t, 1):
            if choice not in self.seconds:
                return choice
        self.best = min((t, 1), key=self.seconds.__getitem__)
        self.ticks += 1
        if self.ticks >= self.gap:   # try the other: its time may be stale
            return 1 if self.best == t else t
        return self.best

    def took(self, choice: int, seconds: float) -> None:
        """This tick ran on `choice` threads in `seconds` (nothing compiled during it)."""
        runs = self.runs[choice] = self.runs.get(choice, 0) + 1
        if runs == 1:
            return   # its first tick: kernels loaded
        old = self.seconds.get(choice)
        if self.best and choice != self.best:   # a try of the other: its old time is stale
            self.ticks = 0
            self.seconds[choice] = seconds
            lost = seconds >= self.seconds[self.best]
            self.gap = min(2 * self.gap, PACE_LONGEST) if lost else PACE_RETRY
            return
        self.seconds[choice] = seconds if old is None else 0.5 * (old + seconds)

    @contextlib.contextmanager
    def ticking(self, n: int, compiling):
        """Around one tick of n agents: on the chosen threads, timed unless
        `compiling()` (seconds spent compiling so far) moved during it."""
        import time

        choice = self.pick(n)
        if choice is None:
            yield
            return
        c0, t0 = compiling(), time.perf_counter()
        with limited(choice):
            yield
        if compiling() == c0:
            self.took(choice, time.perf_counter() - t0)
