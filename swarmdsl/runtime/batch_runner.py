"""Many seeds of one program as batches: R replicas ticking as one vectorised simulation.

`Batch(program, runs=[seeds])` is to `BatchedSimulation` (`runtime/batch.py`) what `Run`
is to `Simulation`: it drives the ticks and gives every replica the outputs a solo run
of the same seed would have, one `MetricLog` and (with `out`) one `Recorder` each, fed
from the replica's read-only view and the batch's metric rows. A replica's agent rows,
metrics and fields are bit-identical to `Run(program, seed=S, backend=B)` on the backend
B the batch ran on (its run.json names it); run.json's timing differs and says the run
was batched.

Whatever cannot be batched runs solo, never differently: a program `batch_refusal`
refuses runs each seed as `Run` does; a runtime fault in any replica (`ReplicaFault`)
makes the batch unusable, so its seeds run again solo and each gets its own outcome
(the faulting seed its fault, the others their completed runs). `RunResult.solo` says
why a run did not run batched. Ctrl-C (and, under the command, SIGTERM and SIGHUP:
`stopping.install`) stops between ticks: every output is
closed holding its recorded ticks, the runs of finished batches are kept, and the runs
of the batch in flight are `interrupted`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from swarmdsl import stopping
from swarmdsl.errors import SwarmError, SwarmOptionError, SwarmRuntimeError
from swarmdsl.runtime.driver import Driver
from swarmdsl.runtime.metrics import MetricLog

# The default rule for how many runs share one batch (`replicas_per_batch`): a batch holds
# at most BATCH_AGENTS agents (beyond that a tick's arrays are large enough that the
# per-tick overhead batching saves is already small, and the batch only costs memory),
# and runs of more than SMALL_RUN_AGENTS agents run solo (one run already keeps the
# arrays busy). docs/scaling.md gives the measurements behind the numbers.
BATCH_AGENTS = 50_000
SMALL_RUN_AGENTS = 5_000
# A batch's metric rows are handed to its runs' logs this many ticks at a time (fewer
# calls than one a tick, and the copy held meanwhile stays small).
HAND_OVER_TICKS = 1024


def agents_of(program) -> int:
    """Agents a run of `program` starts with (its kinds' counts, params applied)."""
    return int(sum(k.count for k in program.kinds))


def replicas_per_batch(agents: int, runs: int, workers: int = 1) -> int:
    """The default batch size for `runs` runs of `agents` agents on `workers` workers:
    as many replicas as fit in BATCH_AGENTS agents, but no more than keep every worker
    busy (runs / workers, rounded up); 1 (solo runs) for runs above SMALL_RUN_AGENTS
    agents or when fewer than two runs would share a batch."""
    if runs < 2 or agents > SMALL_RUN_AGENTS:
        return 1
    size = min(BATCH_AGENTS // max(agents, 1), -(-runs // max(workers, 1)))
    return size if size >= 2 else 1


def even_chunks(group: list, size: int) -> list[list]:
    """`group` in as few batches as hold at most `size` runs each, their sizes differing
    by at most one: 7 runs at `--batch 3` are 3+2+2, not 3+3 and a run left over to
    run solo (a batch of two costs less than two solo runs)."""
    count = -(-len(group) // size)
    base, more = divmod(len(group), count)
    chunks, start = [], 0
    for c in range(count):
        end = start + base + (c < more)
        chunks.append(group[start:end])
        start = end
    return chunks


def batch_refusal_of(program) -> str | None:
    """Why `program` cannot run batched (`batch.batch_refusal`), in the user's words."""
    from swarmdsl.runtime.batch import batch_refusal

    return batch_refusal(program)


@dataclass
class RunResult:
    """One run of a `Batch`: what a solo `Run` of its seed would leave, and how it ran."""

    seed: int
    outcome: str                    # "completed", "fault", "interrupted"; "error": it
    #                                 could not start (placing its agents failed)
    ticks: int                      # the tick it ended at
    metrics: MetricLog              # its metric samples (`.summary()`: last, mean, ...)
    out: Path | None = None         # its folder (agents.parquet, metrics.parquet, ...)
    error: SwarmError | None = None     # the fault, when it faulted
    replicas: int = 1               # runs in the batch it ran in; 1 when it ran solo
    solo: str | None = None         # why it ran solo (refused, a replica's fault, size)
    backend: str = ""               # the backend it ran on ("numpy" or "numba")
    wall_seconds: float = 0.0       # its ticks' time (a batched run: its share)
    extra: dict = field(default_factory=dict)

    def summary(self) -> dict[str, dict[str, float | None]]:
        """{metric: {last, mean, min, max}} of the run, as `swarmdsl run` puts in run.json."""
        return self.metrics.summary()


class Batch:
    """Runs of one program, one per seed in `runs`, ticking up to `size` replicas at a
    time (batches as even as that allows: `even_chunks`).

    `program` from `load_program` (params are compiled into it: runs with other param
    values are another program, hence another Batch); `runs` distinct seeds; `steps`,
    `every`, `backend` as for `Run`; `out` a folder that gets one run folder per seed,
    `out/seed-S`, in `swarmdsl run --out`'s format; `size` the replicas per batch
    (default `replicas_per_batch`; 1 runs every seed solo); `folders` maps seeds to
    their own run folders instead of `out/seed-S` (a sweep's `--runs`).

    A batch keeps no checkpoint (`checkpoint_every` other than 0 is refused): its runs
    are short, and resuming is per run, as a sweep does (`runs.jsonl`: a stopped sweep
    runs again only the runs it did not finish, batched again). A long run that needs
    checkpoints is a `Run`.
    """

    checkpoint_every = 0    # as on a Run; only 0 (`_check_no_checkpoints`)

    def __init__(self, program, runs, *, steps: int | None = None, every: int = 1,
                 out: Path | str | None = None, backend: str | None = None,
                 size: int | None = None, folders: dict | None = None,
                 checkpoint_every: int = 0):
        from swarmdsl.runtime.arguments import check_program, check_run_arguments, whole

        check_program(program, "Batch")     # named as the user called it, not as Run
        self.checkpoint_every = checkpoint_every
        self._check_no_checkpoints()
        seeds = _seeds(runs)
        _seed, steps, every, out, _rec, _px = check_run_arguments(
            program, seeds[0], steps, every, out, None, 640)
        if backend is not None:
            from swarmdsl.runtime import backends

            if backends.plugin(backend) is None:
                raise SwarmOptionError(f"backend {backend!r}: the backends are "
                                       f"{', '.join(backends.names())}")
        self.program, self.seeds, self.steps, self.every = program, seeds, steps, every
        self.out = None if out is None else out.absolute()
        self.folders = {int(k): Path(v).absolute() for k, v in (folders or {}).items()}
        self.backend = backend
        self.agents = agents_of(program)
        self.size = (replicas_per_batch(self.agents, len(seeds)) if size is None
                     else whole("size", size, 1, 2**31))
        self.refusal = batch_refusal_of(program) if len(seeds) > 1 else None
        self.results: list[RunResult] | None = None

    def _check_no_checkpoints(self) -> None:
        every = self.checkpoint_every
        if isinstance(every, int | float) and not isinstance(every, bool) and every == 0:
            return
        raise SwarmOptionError(
            f"checkpoint_every={every!r}: a Batch keeps no checkpoints; its runs resume "
            "per run (a sweep runs again only the runs it did not finish); for a long "
            "run with checkpoints use Run(..., out=DIR) with run.checkpoint_every = K")

    def folder(self, seed: int) -> Path | None:
        """Where the run of `seed` writes its outputs (None without `out`)."""
        if seed in self.folders:
            return self.folders[seed]
        return None if self.out is None else self.out / f"seed-{seed}"

    def execute(self) -> list[RunResult]:
        """Run every seed; one result per seed, in `runs`' order. A stop signal ends it
        with the finished runs' results and the stopped ones `interrupted`; the runs
        not started yet have no result."""
        if self.results is not None:
            raise SwarmOptionError("this Batch has already run; build a new Batch to run "
                                   "it again")
        self._check_no_checkpoints()    # also when set by hand, as on a Run
        self.results = []
        chunks = even_chunks(self.seeds, self.size)
        with stopping.plain_ctrl_c():   # a Ctrl-C while a batch closes keeps it whole
            for chunk in chunks:
                got = self._chunk(chunk)
                self.results.extend(got)
                if any(r.outcome == "interrupted" for r in got) or stopping.pending():
                    break   # a stop noted while the batch closed: start no other
        return self.results

    def _chunk(self, seeds: list[int]) -> list[RunResult]:
        if len(seeds) == 1:
            why = "its batch holds one run" if self.size > 1 else "batches of 1 run (size)"
            return [self._solo(seeds[0], why, self.backend)]
        if self.refusal is not None:
            return self._solos(seeds, self.refusal, self.backend)
        try:
            return _Batched(self, seeds).execute()
        except _Fallback as fb:
            return self._solos(seeds, fb.why, fb.backend)

    def _solos(self, seeds, why, backend) -> list[RunResult]:
        results = []
        for seed in seeds:
            results.append(self._solo(seed, why, backend))
            if results[-1].outcome == "interrupted":
                break
        return results

    def _solo(self, seed: int, why: str, backend: str | None) -> RunResult:
        from swarmdsl.runtime.runner import Run

        try:
            run = Run(self.program, seed=seed, steps=self.steps, out=self.folder(seed),
                      every=self.every, backend=backend)
        except SwarmError as err:   # placing its agents ran program code and failed
            return RunResult(seed, "error", 0, MetricLog(self.program), self.folder(seed),
                             err.with_source(self.program.source), 1, why, backend or "")
        run.show_progress = False
        outcome = run.execute(headless=True)
        return RunResult(seed, outcome, int(run.sim.tick), run.metrics,
                         self.folder(seed), run.fault, 1, why, run.sim.backend.name,
                         run.tick_seconds)


class _Fallback(Exception):
    """The batch cannot give its runs their own outcomes: run them solo, saying why."""

    def __init__(self, why: str, backend: str | None):
        super().__init__(why)
        self.why, self.backend = why, backend


class _Batched:
    """One batch in flight: the simulation stepped by a `Driver`, and as its observer
    a metric log and a recorder per replica."""

    def __init__(self, batch: Batch, seeds: list[int]):
        self.batch, self.seeds = batch, seeds
        self.driver = None
        self.logs = [MetricLog(batch.program) for _ in seeds]
        self.recorders: list = []
        # each tick's (R, k) metric rows, handed to the logs when the batch ends
        # (`_hand_over`) unless recorders read the logs as they go
        self.ticks: list[int] = []
        self.rows: list[np.ndarray] = []

    @property
    def sim(self):
        return self.driver.sim

    def execute(self) -> list[RunResult]:
        from swarmdsl.runtime.batch import BatchedSimulation

        b = self.batch
        work = float(b.steps) * b.agents * len(self.seeds)
        try:
            sim = BatchedSimulation(b.program, self.seeds, backend=b.backend, work=work)
        except SwarmRuntimeError as err:    # placing ran program code and failed
            raise _Fallback(f"placing the batch's agents failed ({err.message}); each "
                            "run placed its own", b.backend) from None
        backend = sim.backend.name
        self.driver = driver = Driver(sim, b.steps, every=b.every, subject=self)
        driver.observers.append(self)
        outcome = driver.drive()
        self._hand_over()
        if outcome not in ("completed", "interrupted"):
            # ReplicaFault, a metric failing in one replica, or a bug in the batch:
            # the solo runs still run right
            fault = driver.error if isinstance(driver.error, SwarmError) else driver.fault
            seed = self._fault_seed(fault)
            raise _Fallback(f"{seed}faulted in a batch of {len(self.seeds)} "
                            f"({fault.message}); its runs ran again solo, each to its own "
                            "outcome", backend)
        share = driver.tick_seconds / len(self.seeds)
        return [RunResult(seed, outcome, int(self.sim.tick), self.logs[r], b.folder(seed),
                          None, len(self.seeds), None, backend, share)
                for r, seed in enumerate(self.seeds)]

    def _fault_seed(self, fault) -> str:
        replica = getattr(fault, "replica", None)
        if isinstance(replica, int) and 0 <= replica < len(self.seeds):
            return f"seed {self.seeds[replica]} "
        return ""

    # ---- the batch's observing (`observers.Observer`) ----
    def start(self, _batched) -> None:
        """Each replica's outputs begun (tick 0 is recorded next, by the driver)."""
        from swarmdsl.runtime.record import Recorder

        b = self.batch
        if all(b.folder(seed) is not None for seed in self.seeds):
            for r, seed in enumerate(self.seeds):
                rec = Recorder(b.folder(seed), self.sim.replica(r), b.every, self.logs[r])
                # the batch's rows in memory stay within one solo run's budget
                rec.flush_bytes = max(Recorder.flush_bytes // len(self.seeds), 2**16)
                self.recorders.append(rec)
            for rec in self.recorders:
                rec.begin()

    def tick(self, _batched) -> None:
        """The current tick into every replica's metric log and recorder."""
        tick = self.sim.tick
        if self.logs and self.logs[0]:
            if self.recorders:
                MetricLog.add_rows(self.logs, tick, self.sim.metric_rows())
            elif not self.ticks or self.ticks[-1] != tick:   # a tick once, as add_row
                self.ticks.append(int(tick))
                self.rows.append(self.sim.metric_rows())
                if len(self.ticks) >= HAND_OVER_TICKS:
                    self._hand_over()
        for r, rec in enumerate(self.recorders):
            rec.sim = self.sim.replica(r)
            rec.record()

    def _hand_over(self) -> None:
        """The metric rows held since the start into every replica's log."""
        if self.ticks:
            MetricLog.add_block(self.logs, np.array(self.ticks), np.stack(self.rows))
            self.ticks, self.rows = [], []

    def close(self, _batched, outcome: str) -> None:
        """Close every replica's outputs (a faulted batch's are rewritten by the solo
        runs that follow; closed first, so a stop in between leaves whole files)."""
        discard = outcome not in ("completed", "interrupted")
        if outcome == "interrupted" and self.driver.observed_tick != self.sim.tick:
            self.tick(self)     # any stop, not only a signal's: its last tick recorded
        self._hand_over()
        n = len(self.seeds)
        seconds = self.driver.tick_seconds
        for r, rec in enumerate(self.recorders):
            if rec.closed:
                continue
            rec.sim = self.sim.replica(r)
            log = self.logs[r]
            if log and not discard:
                rec.extra_json["metrics"] = log.summary()
            rec.wall_seconds = seconds / n
            rec.ticks_timed = None
            if outcome == "interrupted":
                rec.extra_json["signal"] = self.driver.stop_signal
            rec.extra_json["backend"] = self.sim.backend.name
            rec.extra_json["compile_seconds"] = round(self.sim.backend.compile_seconds, 6)
            rec.extra_json["batch"] = {"replicas": n, "replica": r,
                                       "seeds": [int(s) for s in self.seeds],
                                       "wall_seconds": round(seconds, 6)}
            rec.close(self.sim.tick, "fault" if discard else outcome)
        if not discard:
            self.sim.backend.finished(self.batch.program, self.sim.tick)


def _seeds(runs) -> list[int]:
    from swarmdsl.runtime.arguments import whole

    if isinstance(runs, str | bytes) or not hasattr(runs, "__iter__"):
        raise SwarmOptionError("runs must be a list of seeds, e.g. range(100)")
    seeds = [whole(f"runs[{i}]", s, 0, 2**63 - 1) for i, s in enumerate(runs)]
    if not seeds:
        raise SwarmOptionError("runs is empty: give at least one seed")
    seen: dict[int, int] = {}
    for i, s in enumerate(seeds):
        if s in seen:
            raise SwarmOptionError(f"runs[{i}]: seed {s} is also runs[{seen[s]}]; each "
                                   "seed runs once")
        seen[s] = i
    return seeds


__all__ = ["BATCH_AGENTS", "SMALL_RUN_AGENTS", "Batch", "RunResult", "agents_of",
           "batch_refusal_of", "replicas_per_batch"]
