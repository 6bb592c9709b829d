"""`swarmdsl sweep FILE`: a parameter grid x replicate seeds, resumable, in parallel."""

from __future__ import annotations

import os
import signal
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from swarmdsl.command_args import path_arg
from swarmdsl.errors import SwarmOptionError, did_you_mean
from swarmdsl.runtime.metrics import SUMMARIES


def register(sub) -> None:
    p = sub.add_parser(
        "sweep", help="run a program over a parameter grid and replicate seeds",
        description="Run FILE for every combination of the --set values and every seed, "
        "in parallel, into one Parquet table (DIR/sweep.parquet). Finished runs are "
        "skipped when the same sweep is started again.")
    p.add_argument("file", type=path_arg("file", "a .swarm program file", text=True),
                   help="the .swarm program")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUES",
                   help="a param axis: START:STOP:STEP (inclusive) or V1,V2,...; repeatable")
    p.add_argument("--seeds", type=int, metavar="N", help="replicates: seeds 0..N-1 "
                   "(default 1)")
    p.add_argument("--seed-list", metavar="A,B,...", help="replicates: these seeds")
    p.add_argument("--steps", type=int, help="ticks per run (default: the world's `steps`)")
    p.add_argument("--every", type=int, default=1, metavar="K",
                   help="sample metrics every K ticks (tick 0 and the last always)")
    p.add_argument("--keep", default=",".join(SUMMARIES), metavar="S,...",
                   help="metric summaries to keep: last, mean (second half), min, max")
    p.add_argument("--out", type=path_arg("--out", "a folder name, e.g. sweep"),
                   metavar="DIR",
                   help="where the table goes (default: FILE's name + '-sweep')")
    p.add_argument("--runs", action="store_true",
                   help="also keep each run's folder (agents.parquet, metrics, run.json) "
                   "under DIR/runs/")
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1, metavar="N",
                   help="parallel runs on this machine (default: the number of cores)")
    p.add_argument("--retry-failed", action="store_true",
                   help="run again the runs DIR's log records as failed (a fault or an "
                   "error); without it a started-again sweep skips them as done")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on a Dask cluster: tcp://HOST:8786, or `local` to start a "
                   "Dask LocalCluster of --workers processes")
    batching = p.add_mutually_exclusive_group()
    batching.add_argument("--batch", type=int, metavar="R",
                          help="tick up to R runs of the same params (seeds) together as one "
                          "batched simulation (default: batch small runs, docs/scaling.md)")
    batching.add_argument("--no-batch", action="store_true",
                          help="run every run on its own")
    p.add_argument("-v", "--verbose", action="store_true",
                   help="say which runs are batched, how, and why the others run solo")
    p.add_argument("--wait-workers", type=float, metavar="SECONDS",
                   help="with --scheduler: stop (exit 2, finished runs kept) when the "
                   "scheduler has had no worker for this long (default: wait, saying so "
                   "every minute)")
    p.set_defaults(func=cmd_sweep)


def cmd_sweep(args) -> int:
    from swarmdsl.compiler import compile_file
    from swarmdsl.sweep.grid import seeds_of, tasks_of

    if args.workers < 1:
        raise SwarmOptionError(f"--workers {args.workers}: must be 1 or more")
    if args.scheduler is not None and not args.scheduler.strip():
        # `--scheduler $SCHEDULER` with the variable unset: not a reason to run here
        raise SwarmOptionError(f'--scheduler "{args.scheduler}": the address is empty; '
                               "give tcp://HOST:PORT, or `local`")
    if args.wait_workers is not None:
        if args.scheduler is None:
            raise SwarmOptionError("--wait-workers: only with --scheduler (the process "
                                   "pool always has its workers)")
        if not args.wait_workers > 0 or args.wait_workers == float("inf"):
            raise SwarmOptionError(f"--wait-workers {args.wait_workers:g}: must be a "
                                   "number of seconds above 0")
    if args.steps is not None and args.steps < 0:
        raise SwarmOptionError(f"--steps {args.steps}: must be 0 or more")
    if args.every < 1:
        raise SwarmOptionError(f"--every {args.every}: must be 1 or more")
    if args.batch is not None and args.batch < 1:
        raise SwarmOptionError(f"--batch {args.batch}: must be 1 or more replicas a batch "
                               "(--no-batch runs every run on its own)")
    from swarmdsl.cli import check_run_ranges
    from swarmdsl.runtime.backends import environment_backend

    check_run_ranges(None, args.steps, args.every)   # else every run would fail alike
    environment_backend()
    keep = [s.strip() for s in args.keep.split(",") if s.strip()]
    bad = [s for s in keep if s not in SUMMARIES]
    if bad or not keep:
        raise SwarmOptionError(f"--keep {args.keep}: summaries are {', '.join(SUMMARIES)}")
    out = args.out or Path(Path(args.file).stem + "-sweep")
    from swarmdsl.runtime.outputs import check_folder

    check_folder(out, "--out")      # before compiling, as every command's output path
    _check_inside(out, args.runs)
    program = compile_file(args.file)
    tasks = tasks_of(args.set, seeds_of(args.seeds, args.seed_list))
    names = [n for n, _ in tasks[0].params] if tasks else []
    for n in names:
        if n not in program.info.param_decls:
            raise SwarmOptionError(
                f"--set {n}: the program has no param `{n}` (params: "
                f"{', '.join(program.info.param_decls) or 'none'})",
                hint=did_you_mean(n, program.info.param_decls))
    from swarmdsl.compiler.checker import check_override

    for n, raw in sorted({p for t in tasks for p in t.params}):
        check_override(program.info, n, raw)   # before any run: else each such run fails
    from swarmdsl.compiler.lang_metrics import metrics_of

    metric_names = [m.info.name for m in metrics_of(program)]
    if not metric_names:
        print(f"{args.file}: declares no `metric`; the table holds outcomes only",
              file=sys.stderr)
    cluster = None
    if args.scheduler:   # before the folder: an unreachable address leaves nothing behind
        from swarmdsl.sweep.execute import DaskCluster

        # a local cluster starts every worker at once, each importing numpy and scipy:
        # no more than there are runs, as the process pool does
        cluster = DaskCluster(args.scheduler, min(args.workers, len(tasks)))
    try:
        return _sweep(args, program, out, tasks, names, keep, metric_names, cluster)
    finally:
        if cluster is not None:
            cluster.close()


def _check_inside(out: Path, runs: bool) -> None:
    """What the sweep writes inside DIR, checked with DIR before any run: a file named
    `runs` failed every run of `--runs`, and a folder named `sweep.parquet` was an
    internal error once all the runs had finished."""
    from swarmdsl.runtime.outputs import check_folder
    from swarmdsl.sweep.table import TABLE

    if (out / TABLE).is_dir():
        raise SwarmOptionError(f"--out {out}: {TABLE} there is a folder, not a sweep's "
                               "table; give the sweep another folder")
    if runs:
        check_folder(out / "runs", "--runs")


def _sweep(args, program, out, tasks, names, keep, metric_names, cluster) -> int:
    from swarmdsl.runtime.metrics import bounds_of
    from swarmdsl.sweep.table import ResultLog, write_table
    from swarmdsl.sweep.worker import run_key

    log = ResultLog(out)
    sha = program.sha256
    steps = args.steps
    keys = [run_key(sha, t.params, t.seed, steps if steps is not None else -1, args.every)
            for t in tasks]
    program_dir = str(Path(args.file).resolve().parent)
    todo = [(t, k) for t, k in zip(tasks, keys, strict=True)
            if k not in log or (args.retry_failed and log.failed(k))]
    folders = _run_folders(out, todo, log) if args.runs else {}
    calls = [(str(args.file), program.source, t.params, t.seed, steps, args.every,
              folders.get(k), program_dir) for t, k in todo]
    skipped = len(tasks) - len(calls)
    _note_other_runs(out, len(log.rows) - skipped)
    from swarmdsl.sweep.plan import plan_tasks

    plan = plan_tasks(calls, 0 if args.no_batch else args.batch, args.workers, program)
    if args.verbose:
        _say_plan(plan, len(calls), args.workers == 1 and cluster is None)
    progress = _Progress(len(tasks), skipped)
    from swarmdsl.sweep.execute import ClusterError

    stopped, lost = False, None
    said: set[str] = set()
    try:
        with _sigterm_as_interrupt():
            for task_rows in _rows(plan.tasks, args, cluster):
                log.add_all(task_rows)
                for row in task_rows:
                    progress.advance(row)
                    if args.verbose and row.get("solo") and row["solo"] not in said:
                        # a batch that fell back to solo runs: the reason names the
                        # seed that made it, the row is whichever of its runs came first
                        said.add(row["solo"])
                        print(f"{_params_label(row)}{row['solo']}", file=sys.stderr)
    except KeyboardInterrupt:
        stopped = True
    except ClusterError as exc:   # the table is still written from the finished runs
        lost = exc
    finally:
        progress.close()
        log.close()
        rows = [log.rows[k] for k in keys if k in log.rows]
        table = write_table(out, rows, names, keep, metric_names,
                            bounds_of(program.metrics))
    failed = [r for r in rows if r["outcome"] != "completed"]
    word = "stopped" if stopped or lost else "finished"
    print(f"{Path(args.file).name}: sweep {word}: {len(rows)}/{len(tasks)} runs in the "
          f"table ({skipped} already done, {len(failed)} failed) -> {table}")
    if lost is not None:
        raise lost
    if failed:
        _show_failure(failed[0], len(failed), table)
    if stopped:
        print("run the same command again to continue", file=sys.stderr)
        return 130
    return 1 if failed else 0


def _run_folders(out: Path, todo, log) -> dict[str, str]:
    """{key: absolute folder} of the runs to run, named by params and seed
    (`sweep/folders.py`), unique in DIR/runs/ (a retried run keeps its folder)."""
    from swarmdsl.sweep.folders import assign

    # the folders of finished runs (older sweeps' `runs/KEY/` are not named in the
    # log and cannot clash: a key has no `=`); a folder on disk the log does not name
    # is a run stopped before it finished, written again by whichever run it names
    earlier = {row["folder"]: key for key, row in log.rows.items()
               if isinstance(row.get("folder"), str)}
    names = assign([(k, t.params, t.seed) for t, k in todo], earlier)
    root = (out / "runs").resolve()
    return {k: str(root / names[k]) for _t, k in todo}


def _say_plan(plan, runs: int, here: bool) -> None:
    """`-v`: how the runs are batched, one line per param combination, and the threads
    a batch ticks on (`here`: in this process, else in single-threaded workers)."""
    print(f"{runs} run{'s' * (runs != 1)} to run: {plan.batched_runs} in {plan.batches} "
          f"batch{'es' * (plan.batches != 1)}, {runs - plan.batched_runs} solo",
          file=sys.stderr)
    for note in plan.notes:
        print(f"  {note}", file=sys.stderr)
    if plan.batches and not here:
        print("  threads: 1 in each worker process (the workers share the cores)",
              file=sys.stderr)
    elif plan.batches:
        from swarmdsl.runtime.backends import notes

        for line in notes():   # each installed backend's (numba: its threads)
            print(f"  {line}", file=sys.stderr)


def _params_label(row: dict) -> str:
    """`noise=0.2: `, the run's param combination, or nothing without axes."""
    return ", ".join(f"{name}={value}" for name, value in row["params"]) + \
        (": " if row["params"] else "")


def _show_failure(row: dict, failed: int, table) -> None:
    """Why the first failed run failed, as `swarmdsl run` would have said it: a sweep
    that exits 1 with only a count of failures leaves the user to dig the reason out of
    the table's `error` column."""
    params = "".join(f"{name}={value}, " for name, value in row["params"])
    print(f"the first failed run ({params}seed {row['seed']}):\n"
          f"{row['error'] or row['outcome']}", file=sys.stderr)
    if failed > 1:
        print(f"({failed} failed runs: each one's error is in the `error` column of "
              f"{table})", file=sys.stderr)


def _note_other_runs(out: Path, others: int) -> None:
    """Say so when DIR's log holds runs this sweep does not ask for (another program,
    other params, seeds, --steps or --every): the log keeps them, but sweep.parquet is
    rewritten with this sweep's runs only, so the table they were in is replaced."""
    if others > 0:
        print(f"{out}: {others} earlier run{'s' * (others != 1)} of other sweeps stay in "
              f"runs.jsonl, not in the new sweep.parquet (their command rebuilds their "
              f"table without running them again)", file=sys.stderr)


def _rows(calls, args, cluster):
    from swarmdsl.sweep import execute

    if not calls:
        return iter(())
    if cluster is not None:
        return execute.dask(calls, cluster, args.wait_workers)
    if args.workers == 1 or len(calls) == 1:
        return execute.serial(calls)
    return execute.processes(calls, min(args.workers, len(calls)))


@contextmanager
def _sigterm_as_interrupt():
    """SIGTERM (a cluster's job manager stopping us) stops as cleanly as Ctrl-C."""
    from swarmdsl import stopping

    def handler(signum, frame):
        raise KeyboardInterrupt

    if stopping.installed():    # the command's own handler: it also waits for whole rows
        yield
        return
    try:
        old = signal.signal(signal.SIGTERM, handler)
    except ValueError:          # not the main thread: leave signals alone
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


class _Progress:
    """A rich bar with an ETA on a terminal; plain lines on stderr otherwise."""

    def __init__(self, total: int, skipped: int):
        self.total, self.done, self.failed = total, skipped, 0
        self.start = time.perf_counter()
        self.first = skipped
        self.next_line = 0.1
        self.bar = None
        if sys.stderr.isatty() and total > skipped:
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )

            self.bar = Progress(TextColumn("runs"), BarColumn(), MofNCompleteColumn(),
                                TextColumn("{task.fields[failed]} failed"),
                                TimeElapsedColumn(), TextColumn("ETA"),
                                TimeRemainingColumn(), console=Console(stderr=True))
            self.task = self.bar.add_task("runs", total=total, completed=skipped, failed=0)
            self.bar.start()

    def advance(self, row: dict) -> None:
        self.done += 1
        self.failed += row["outcome"] != "completed"
        if self.bar is not None:
            self.bar.update(self.task, completed=self.done, failed=self.failed)
            return
        frac = self.done / max(self.total, 1)
        if frac >= self.next_line or self.done == self.total:
            elapsed = time.perf_counter() - self.start
            fresh = self.done - self.first
            eta = elapsed / fresh * (self.total - self.done) if fresh else 0.0
            print(f"runs {self.done}/{self.total} ({frac:.0%}), {self.failed} failed, "
                  f"ETA {eta:.0f} s", file=sys.stderr)
            while self.next_line <= frac:
                self.next_line += 0.1

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()
