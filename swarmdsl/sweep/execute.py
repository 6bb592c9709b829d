"""Where a sweep's runs execute: this process, a process pool, or a Dask cluster.

Each executor yields rows as runs finish, in whatever order they finish; the table is
sorted by the sweep's own order afterwards, so it does not depend on the executor or
the number of workers. Stopping (Ctrl-C, SIGTERM) cancels what has not started and
ends the workers; the rows already yielded are kept by the caller.
"""

from __future__ import annotations

import signal
from collections.abc import Iterator

from swarmdsl.errors import SwarmOptionError
from swarmdsl.sweep.worker import limit_threads, one_thread_environment, run_one


def _ignore_interrupts() -> None:
    """Workers leave Ctrl-C to the sweep, which stops them itself."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    limit_threads()


def serial(calls: list[tuple]) -> Iterator[dict]:
    for args in calls:
        yield run_one(*args)


def processes(calls: list[tuple], workers: int) -> Iterator[dict]:
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    pool = ProcessPoolExecutor(max_workers=workers, initializer=_ignore_interrupts,
                               mp_context=multiprocessing.get_context("spawn"))
    pending = set()
    todo = iter(calls)
    try:
        with one_thread_environment():   # the pool spawns its workers on submit
            for args in todo:                 # keep a short queue: stopping drops the rest
                pending.add(pool.submit(run_one, *args))
                if len(pending) >= 2 * workers:
                    break
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                yield fut.result()
                nxt = next(todo, None)
                if nxt is not None:
                    with one_thread_environment():   # the pool may start a worker here
                        pending.add(pool.submit(run_one, *nxt))
    finally:
        procs = list(getattr(pool, "_processes", {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        if pending:
            for p in procs:
                p.terminate()
        for p in procs:
            p.join(timeout=5)


# How long to wait for a remote scheduler to answer before giving up on it.
CONNECT_TIMEOUT = 10.0


class DaskCluster:
    """A Dask client, connected (or the error raised) before the sweep creates its
    folder, so a scheduler that cannot be reached leaves no empty table behind; for
    ``local`` also the LocalCluster it started."""

    def __init__(self, scheduler: str, workers: int):
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError:
            raise SwarmOptionError("sweeps on Dask need dask.distributed: "
                                   "pip install 'swarmdsl[sweep]'") from None
        self.cluster = None
        if scheduler == "local":
            with one_thread_environment():
                self.cluster = LocalCluster(n_workers=workers, threads_per_worker=1,
                                            processes=True, dashboard_address=None)
            self.client = Client(self.cluster)
            return
        try:
            self.client = Client(scheduler, timeout=CONNECT_TIMEOUT)
        except (OSError, TimeoutError, ValueError) as exc:
            raise SwarmOptionError(f"--scheduler {scheduler}: cannot reach the Dask "
                                   f"scheduler ({exc})") from None

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def dask(calls: list[tuple], cluster: DaskCluster) -> Iterator[dict]:
    """Rows from the runs on a connected cluster; the caller closes it."""
    from dask.distributed import as_completed

    client = cluster.client
    futures = []
    try:
        client.run(limit_threads)
        futures = [client.submit(run_one, *args, pure=False) for args in calls]
        for fut in as_completed(futures):
            yield fut.result()
    finally:
        for fut in futures:
            fut.cancel()
