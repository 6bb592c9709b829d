"""Where a sweep's runs execute: this process, a process pool, or a Dask cluster.

A task is a solo run or a batch of runs of one param combination (`worker.run_task`).
Each executor yields a task's rows (one list per task: a batch's runs finish together,
and the log writes them with one flush to disk) as tasks finish, in whatever order
they finish; the table is
sorted by the sweep's own order afterwards, so it does not depend on the executor or
the number of workers. Stopping (Ctrl-C, SIGTERM) cancels what has not started and
ends the workers; the rows already yielded are kept by the caller.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Iterator

from swarmdsl.errors import SwarmOptionError
from swarmdsl.sweep.worker import limit_threads, one_thread_environment, run_task


def _start_worker() -> None:
    """Workers leave Ctrl-C to the sweep, which stops them itself, and end with it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent()
    limit_threads()


# How often a pool worker looks whether the sweep that started it is still there.
PARENT_POLL_SECONDS = 1.0


def die_with_parent() -> None:
    """End this pool worker as soon as the sweep that started it ends, however it ends.

    A sweep stopped by a signal it can catch ends its workers itself; after a SIGKILL
    (or an out-of-memory kill) its workers ran on, each finishing its run and then
    waiting for work forever, and kept the pool's resource tracker alive with them. On
    Linux the kernel sends the worker SIGKILL when the sweep dies (PR_SET_PDEATHSIG);
    everywhere a daemon thread notices that the worker's parent changed (it is
    re-parented) within a second and exits the process.
    """
    import multiprocessing

    parent = multiprocessing.parent_process()
    if parent is None:
        return
    ppid = parent.pid
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            pr_set_pdeathsig = 1
            ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, int(signal.SIGKILL))
        except (OSError, AttributeError):   # no prctl: the thread below does it
            pass
    if os.getppid() != ppid:    # the sweep died while this worker was starting
        os._exit(1)

    def watch() -> None:
        while os.getppid() == ppid:
            time.sleep(PARENT_POLL_SECONDS)
        os._exit(1)

    threading.Thread(target=watch, name="swarmdsl-parent-watch", daemon=True).start()


def serial(calls: list[tuple]) -> Iterator[list[dict]]:
    for kind, args in calls:
        yield run_task(kind, args)


def processes(calls: list[tuple], workers: int) -> Iterator[list[dict]]:
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    pool = ProcessPoolExecutor(max_workers=workers, initializer=_start_worker,
                               mp_context=multiprocessing.get_context("spawn"))
    pending = set()
    todo = iter(calls)
    try:
        with one_thread_environment():   # the pool spawns its workers on submit
            for kind, args in todo:           # keep a short queue: stopping drops the rest
                pending.add(pool.submit(run_task, kind, args))
                if len(pending) >= 2 * workers:
                    break
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                yield fut.result()
                nxt = next(todo, None)
                if nxt is not None:
                    with one_thread_environment():   # the pool may start a worker here
                        pending.add(pool.submit(run_task, *nxt))
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
# How often the sweep looks at the cluster while no run finishes, and how often it says
# again that the scheduler has no workers.
POLL_SECONDS = 2.0
NO_WORKERS_REMINDER = 60.0


class ClusterError(SwarmOptionError):
    """The Dask cluster went away (or never had a worker): the sweep stops with the
    runs already finished kept, exit 2, as for a scheduler that never answered."""


HTTP_ON_A_FREE_PORT = {"dashboard_address": "127.0.0.1:0"}


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
        self.address = scheduler
        self.cluster = None
        if scheduler == "local":
            with one_thread_environment():
                # no dashboard; the scheduler's HTTP server (health, metrics) on a
                # free port of 127.0.0.1: its default, 8787, is taken by any other
                # cluster on the machine, and Dask then warns on every start
                self.cluster = LocalCluster(
                    n_workers=workers, threads_per_worker=1, processes=True,
                    dashboard_address=None, scheduler_kwargs=HTTP_ON_A_FREE_PORT)
            self.client = Client(self.cluster)
            return
        try:
            self.client = Client(scheduler, timeout=CONNECT_TIMEOUT)
        except (OSError, TimeoutError, ValueError) as exc:
            raise SwarmOptionError(f"--scheduler {scheduler}: cannot reach the Dask "
                                   f"scheduler ({exc})") from None

    def workers(self) -> int:
        """How many workers the scheduler has now (a scheduler that no longer answers
        is a lost one)."""
        from concurrent.futures import CancelledError

        try:
            info = self.client.scheduler_info(n_workers=-1)
        except (OSError, TimeoutError, CancelledError) as exc:
            raise self.lost(_reason(exc)) from None
        return len(info.get("workers", {}))

    def lost(self, why: str) -> ClusterError:
        return ClusterError(f"--scheduler {self.address}: lost the Dask scheduler "
                            f"({why}); the finished runs are kept",
                            hint="run the same command again to continue")

    def close(self) -> None:
        """Close the client (and a local cluster); a scheduler already gone is no
        reason for a traceback here. Dask stays silent afterwards: the client's attempts
        to reconnect to a lost scheduler go on in its own thread and would log their
        tracebacks while the command exits."""
        _quiet_distributed().__enter__()
        try:
            self.client.close(timeout=CONNECT_TIMEOUT)
        except Exception:  # noqa: BLE001  (the connection is gone: nothing to close)
            pass
        if self.cluster is not None:
            self.cluster.close()


def dask(calls: list[tuple], cluster: DaskCluster,
         wait_workers: float | None = None) -> Iterator[list[dict]]:
    """Each task's rows from the runs on a connected cluster; the caller closes it.

    A scheduler without workers is said at once, then again every minute (and given up
    after `wait_workers` seconds when set); a scheduler lost midway stops the sweep
    with a `ClusterError` naming it, not Dask's own tracebacks.
    """
    from concurrent.futures import CancelledError

    from dask.distributed import wait

    client = cluster.client
    futures = []
    idle = _NoWorkers(cluster, wait_workers)
    with _quiet_distributed():
        try:
            client.run(limit_threads)
            futures = [client.submit(run_task, kind, args, pure=False)
                       for kind, args in calls]
            pending = set(futures)
            while pending:
                try:
                    done, pending = wait(pending, timeout=POLL_SECONDS,
                                         return_when="FIRST_COMPLETED")
                    tasks = [fut.result() for fut in done]
                except TimeoutError:
                    idle.check()
                    continue
                except (CancelledError, OSError) as exc:
                    if client.status == "running":
                        raise
                    raise cluster.lost(_reason(exc)) from None
                idle.reset()
                yield from tasks
        finally:
            for fut in futures:
                fut.cancel()


def _reason(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    if "connection-lost" in str(exc) or not text:
        return "the connection to it closed"
    return text[0]


class _NoWorkers:
    """Says when the scheduler has no workers to run on (else a sweep waits in silence)."""

    def __init__(self, cluster: DaskCluster, give_up: float | None):
        self.cluster, self.give_up = cluster, give_up
        self.since = None       # when the scheduler was first seen without workers
        self.said = 0.0

    def reset(self) -> None:
        self.since = None

    def check(self) -> None:
        if self.cluster.client.status != "running":
            raise self.cluster.lost("the connection to it closed")
        if self.cluster.workers():
            self.since = None
            return
        now = time.monotonic()
        address = self.cluster.address
        if self.since is None:
            self.since, self.said = now, now
            print(f"waiting for workers: the Dask scheduler at {address} has none "
                  f"(start some with `dask worker {address}`)", file=sys.stderr)
        elif now - self.said >= NO_WORKERS_REMINDER:
            self.said = now
            print(f"still no workers on the Dask scheduler at {address} after "
                  f"{now - self.since:.0f} s", file=sys.stderr)
        if self.give_up is not None and now - self.since >= self.give_up:
            raise ClusterError(f"--wait-workers {self.give_up:g}: the Dask scheduler at "
                               f"{address} had no worker for {self.give_up:g} s",
                               hint="start workers, then run the same command again")


class _quiet_distributed:
    """Dask's own loggers silenced while the sweep talks to the cluster: a lost
    scheduler logged ~37 lines of tracebacks from inside Dask before the sweep could
    say in one line what happened."""

    def __enter__(self):
        import logging

        self.saved = {}
        names = ["distributed"] + [n for n in logging.root.manager.loggerDict
                                   if n.startswith("distributed.")]
        for name in names:
            logger = logging.getLogger(name)
            self.saved[name] = logger.level
            logger.setLevel(logging.CRITICAL + 1)
        return self

    def __exit__(self, *exc):
        import logging

        for name, level in self.saved.items():
            logging.getLogger(name).setLevel(level)
        return False
