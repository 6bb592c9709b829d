"""One run of a sweep, as a plain function a process pool or a Dask worker can call.

It takes and returns only plain data (paths, strings, numbers), so any executor can
ship it, and it never raises for a mistake in the program or its params: the row says
what went wrong, located, and the sweep goes on.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import os
import time
from pathlib import Path

from swarmdsl.runtime.metrics import SUMMARIES
from swarmdsl.version import __version__, libraries

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                    "NUMBA_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")


@contextlib.contextmanager
def one_thread_environment():
    """Worker processes started inside this block inherit one thread per library: runs
    share the machine's cores as processes, and threads inside them would fight. The
    calling process gets its own settings back afterwards: numba refuses to compile
    anything once its thread count differs from the pool it has started."""
    saved = {var: os.environ.get(var) for var in THREAD_VARIABLES}
    os.environ.update(dict.fromkeys(THREAD_VARIABLES, "1"))
    try:
        yield
    finally:
        for var, value in saved.items():
            if value is None:
                os.environ.pop(var, None)
            else:
                os.environ[var] = value


def limit_threads() -> None:
    """Inside a worker process: one thread per library, for good (libraries already
    imported get one thread too). Never in the sweep's own process (a serial sweep's
    runs run there, and the caller may go on using numba's threads)."""
    import multiprocessing
    import sys

    if multiprocessing.parent_process() is None:
        return
    os.environ.update(dict.fromkeys(THREAD_VARIABLES, "1"))
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.set_num_threads(1)


def run_key(source_sha: str, params: tuple, seed: int, steps: int, every: int = 1) -> str:
    """What makes a run the same run: program text, params, seed, length, how often
    its metrics are sampled (the summaries depend on it) and the random generator (a
    sweep resumed by a swarmdsl whose draws differ runs its runs again rather than mix
    the two in one table)."""
    from swarmdsl.runtime.randomness import RNG_NAME

    text = json.dumps([source_sha, [list(p) for p in params], int(seed), int(steps),
                       int(every), RNG_NAME])
    return hashlib.sha256(text.encode()).hexdigest()[:24]


@functools.lru_cache(maxsize=64)
def _compiled(path: str, source: str, params: tuple, program_dir: str | None):
    from swarmdsl.compiler import compile_source

    return compile_source(source, path, dict(params),
                          Path(program_dir) if program_dir else None)


def run_one(path: str, source: str, params: tuple, seed: int, steps: int | None,
            every: int = 1, folder: str | None = None,
            program_dir: str | None = None) -> dict:
    """Run once and return the table row (metric summaries, outcome, timing); with
    `folder` (`--runs`: `runs/eta=0.5_seed=3`, `sweep/folders.py`) the run's outputs
    are written there and the row names it.

    The program's text travels with the task, so a cluster's workers need no copy of
    the file (only of its `models/` folder, at the same path, when it calls `nn()`).
    `path` is the file as the user typed it (errors name it so); `program_dir` is its
    folder as an absolute path, where `nn()` finds its models.
    """
    from swarmdsl.errors import SwarmError
    from swarmdsl.runtime.runner import Run

    limit_threads()
    row = _row(source, params, seed, steps, every)
    if folder:
        row["folder"] = Path(folder).name
    started = time.perf_counter()
    try:
        program = _compiled(path, source, params, program_dir)
        n_steps = steps if steps is not None else program.world.steps
        out = Path(folder) if folder else None
        run = Run(program, seed=seed, steps=n_steps, out=out, every=every)
        run.show_progress = False
        outcome = run.execute(headless=True)
    except SwarmError as err:
        row["error"] = err.with_source(source).render()
        row["wall_seconds"] = time.perf_counter() - started
        return row
    if outcome == "interrupted":        # a stopped sweep: this run is not finished
        raise KeyboardInterrupt
    row["outcome"] = outcome
    if outcome == "fault":
        row["error"] = run.fault.render()
    row["ticks"] = int(run.sim.tick)
    row["wall_seconds"] = time.perf_counter() - started
    if outcome == "completed":  # a faulted run's summaries cover only the ticks before
        row["metrics"] = run.metrics.summary()     # its fault: no value for the run
    return row


def _row(source: str, params: tuple, seed: int, steps: int | None, every: int) -> dict:
    """A run's table row before it runs: an `error` outcome until it says otherwise."""
    source_sha = hashlib.sha256(source.encode()).hexdigest()
    return {"key": run_key(source_sha, params, seed, steps if steps is not None else -1,
                           every),
            "params": [list(p) for p in params], "seed": int(seed), "outcome": "error",
            "error": None, "ticks": 0, "wall_seconds": 0.0, "sha256": source_sha,
            "version": __version__, "libraries": _libraries(), "metrics": {}}


@functools.cache
def _libraries() -> str:
    """`version.libraries()` once per process: reading the packages' metadata costs
    ~3 ms, a quarter of a 300-tick 100-agent run's own time in a batch, and it cannot change
    while the process runs."""
    return libraries()


def run_batch(path: str, source: str, params: tuple, seeds: list[int], steps: int | None,
              every: int = 1, folders: dict | None = None,
              program_dir: str | None = None) -> list[dict]:
    """Run `seeds` of one param combination as one batch (`runtime.batch_runner.Batch`)
    and return their rows, each the row `run_one` gives the same run (same key, same
    summaries, its `--runs` folder, `folders[seed]`, under the same name), plus
    `replicas` (the runs its
    batch held, 1 when it ran solo) and `solo` (why it ran solo, if it did: a program
    that cannot be batched, a replica's fault). `wall_seconds` is the run's share of its
    batch's time. A stop loses the whole batch: none of its runs is in the log."""
    from swarmdsl.errors import SwarmError
    from swarmdsl.runtime.batch_runner import Batch

    limit_threads()
    rows = [_row(source, params, seed, steps, every) for seed in seeds]
    if folders:
        for seed, row in zip(seeds, rows, strict=True):
            row["folder"] = Path(folders[seed]).name
    started = time.perf_counter()
    try:
        program = _compiled(path, source, params, program_dir)
        n_steps = steps if steps is not None else program.world.steps
        outs = {seed: Path(f) for seed, f in folders.items()} if folders else None
        results = Batch(program, seeds, steps=n_steps, every=every, size=len(seeds),
                        folders=outs).execute()
    except SwarmError as err:
        share = (time.perf_counter() - started) / len(seeds)
        for row in rows:
            row.update(error=err.with_source(source).render(), wall_seconds=share)
        return rows
    if len(results) < len(seeds) or any(r.outcome == "interrupted" for r in results):
        raise KeyboardInterrupt         # a stopped sweep: this batch is not finished
    share = (time.perf_counter() - started) / len(seeds)
    for row, result in zip(rows, results, strict=True):
        row.update(outcome=result.outcome, ticks=result.ticks, replicas=result.replicas,
                   solo=result.solo, wall_seconds=share)
        if result.error is not None:
            row["error"] = result.error.render()
        if result.outcome == "completed":
            row["metrics"] = result.summary()
    return rows


def run_task(kind: str, args: tuple) -> list[dict]:
    """One task of a sweep's executor: a solo run (`one`) or a batch of runs (`batch`);
    the rows of the runs it finished."""
    if kind == "batch":
        return run_batch(*args)
    return [run_one(*args)]


__all__ = ["SUMMARIES", "run_batch", "run_key", "run_one", "run_task"]
