"""`swarmdsl sweep`: grids, replicates, failures recorded, resume, workers, Dask."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from conftest import cli_error

from swarmdsl.cli import main
from swarmdsl.compiler.errors import SwarmOptionError
from swarmdsl.sweep.grid import parse_axis, tasks_of

ROOT = Path(__file__).resolve().parent.parent
PROGRAM = """
param n = 12
param noise = 0.1
world { size 40 x 40; edges wrap }
agent a {
  count n
  sense 8
  velocity random_direction()
  status s {
    let heading_sum = sum(neighbors(8) : normalize(other.vel)) + normalize(vel)
    velocity = unit(angle(heading_sum) + uniform(-noise / 2, noise / 2))
  }
}
metric order = length(mean(normalize(vel)))
"""


@pytest.fixture
def program(tmp_path):
    path = tmp_path / "flock.swarm"
    path.write_text(PROGRAM)
    return path


def _table(out: Path):
    return pq.read_table(out / "sweep.parquet").to_pandas()


def test_grid_of_two_by_three_with_two_seeds_gives_twelve_rows(backend, program, tmp_path):
    out = tmp_path / "s"
    code = main(["sweep", str(program), "--set", "n=5,9", "--set", "noise=0:1:0.5",
                 "--seeds", "2", "--steps", "4", "--out", str(out), "--workers", "1"])
    assert code == 0
    t = _table(out)
    assert len(t) == 12
    assert sorted(zip(t.n, t.noise, t.seed, strict=True)) == sorted(
        (n, e, s) for n in (5.0, 9.0) for e in (0.0, 0.5, 1.0) for s in (0, 1))
    assert (t.outcome == "completed").all() and (t.ticks == 4).all()
    assert t["order.mean"].between(0, 1 + 1e-9).all()
    assert set(t.columns) >= {"order.last", "order.min", "order.max", "wall_seconds",
                              "sha256", "version", "error"}


def test_ranges_keep_the_values_as_typed():
    assert parse_axis("eta=0:1:0.1")[1] == ["0", "0.1", "0.2", "0.3", "0.4", "0.5", "0.6",
                                            "0.7", "0.8", "0.9", "1"]
    assert parse_axis("n=100, 400")[1] == ["100", "400"]
    tasks = tasks_of(["a=1,2", "b=x"], [3, 4])
    assert [(t.params, t.seed) for t in tasks] == [
        ((("a", "1"), ("b", "x")), 3), ((("a", "1"), ("b", "x")), 4),
        ((("a", "2"), ("b", "x")), 3), ((("a", "2"), ("b", "x")), 4)]


@pytest.mark.parametrize("bad", ["eta", "eta=1:0:0.5", "eta=0:1:0", "eta=0:1", "eta=a:b:c",
                                 "eta=1,,2"])
def test_bad_axes_are_option_errors(bad):
    with pytest.raises(SwarmOptionError):
        parse_axis(bad)


@pytest.mark.parametrize("bad, message", [
    ("eta=1:0.5:1", "STOP is below START"),       # less than one STEP below: not [1]
    ("eta=1:0.9:0.5", "STOP is below START"),
    ("eta=nan:1:1", "START, STOP and STEP must be finite numbers"),
    ("eta=0:inf:1", "START, STOP and STEP must be finite numbers"),
])
def test_a_range_running_backwards_is_refused_not_run_at_start(bad, message):
    with pytest.raises(SwarmOptionError, match=f"--set {bad}: {message}"):
        parse_axis(bad)


@pytest.mark.parametrize("args, message", [
    (["--seed-list", f"1,{2**63}"], f"--seed-list 1,{2**63}: seeds are from 0 to"),
    (["--steps", str(10**20)], f"--steps {10**20}: must be from 0 to"),
    (["--every", str(2**63)], f"--every {2**63}: must be from 1 to"),
])
def test_out_of_range_run_options_are_refused_before_any_run(program, tmp_path, capsys,
                                                             args, message):
    """Refused up front naming the option, not as a table of failed runs (a seed past
    int64 even made the table unwritable, on every later start of the same sweep)."""
    out = tmp_path / "s"
    assert main(["sweep", str(program), "--workers", "1", "--out", str(out), *args]) == 2
    err = capsys.readouterr().err
    assert message in err and "internal error" not in err
    assert not out.exists()


def test_the_output_folder_is_checked_before_the_program(tmp_path, capsys):
    bad = tmp_path / "bad.swarm"
    bad.write_text("agent a {\n  count 2\n  status s { velocity = foo }\n}\n")
    (tmp_path / "afile").write_text("")
    assert main(["sweep", str(bad), "--out", str(tmp_path / "afile")]) == 2
    assert f"error: --out {tmp_path / 'afile'}: is a file, not a folder" in \
        capsys.readouterr().err


def test_rerun_with_other_params_says_the_table_holds_only_this_sweep(backend, program, tmp_path,
                                                                      capsys):
    out = tmp_path / "s"
    base = ["sweep", str(program), "--steps", "2", "--workers", "1", "--out", str(out)]
    assert main([*base, "--set", "noise=0,1", "--seeds", "2"]) == 0
    assert "other sweeps" not in capsys.readouterr().err
    assert main([*base, "--set", "noise=1,2"]) == 0
    err = capsys.readouterr().err
    assert f"{out}: 3 earlier runs of other sweeps stay in runs.jsonl" in err
    t = _table(out)
    assert list(zip(t.noise, t.seed, strict=True)) == [(1.0, 0), (2.0, 0)]
    assert len((out / "runs.jsonl").read_text().splitlines()) == 5


def test_a_text_param_column_keeps_the_values_as_typed(backend, tmp_path):
    """A boolean param's column is text, the values as typed. (A value that is not a
    number for a number param is refused before the sweep starts, below.)"""
    path = tmp_path / "loud.swarm"
    path.write_text(PROGRAM.replace("param noise = 0.1", "param noise = 0.1\nparam loud = true")
                    .replace("count n", "count if loud then n else 2"))
    out = tmp_path / "s"
    assert main(["sweep", str(path), "--set", "loud=true,false", "--steps", "2",
                 "--workers", "1", "--out", str(out)]) == 0
    t = _table(out)
    assert list(t.loud) == ["true", "false"]
    assert list(t.outcome) == ["completed", "completed"]


def test_unknown_param_is_refused_with_a_hint(program, tmp_path, capsys):
    code = main(["sweep", str(program), "--set", "nosie=0,1", "--out", str(tmp_path / "x")])
    assert code == 2
    err = capsys.readouterr().err
    assert "no param `nosie`" in err and "noise" in err


@pytest.mark.parametrize(("axis", "message"), [
    ("noise=0:2:0.5", "error: --set noise=1.5: outside the declared range 0..1"),
    ("n=4,many", "error: --set n=many: `many` is not a number"),
    ("noise=0.1,1e400", "error: --set noise=1e400: the value must be finite"),
])
def test_a_value_run_would_refuse_as_an_option_stops_the_sweep_before_any_run(
        tmp_path, capsys, axis, message):
    """Not one failed row per such value after the others have run: `run --set` refuses
    it before compiling, and so does the sweep, before it makes its folder."""
    path = tmp_path / "ranged.swarm"
    path.write_text(PROGRAM.replace("param noise = 0.1", "param noise = 0.1 in 0..1"))
    out = tmp_path / "s"
    assert main(["sweep", str(path), "--set", axis, "--steps", "2", "--out", str(out),
                 "--workers", "1"]) == 2
    assert capsys.readouterr().err.startswith(message)
    assert not out.exists()


def test_failing_value_is_recorded_and_the_others_complete(backend, program, tmp_path):
    out = tmp_path / "s"
    code = main(["sweep", str(program), "--set", "n=4,-3,6", "--steps", "3",
                 "--out", str(out), "--workers", "1"])
    assert code == 1
    t = _table(out).set_index("n")
    assert t.loc[-3.0, "outcome"] == "error"
    assert "flock.swarm:6:9: error: the count of `a` must be at least 0" in t.loc[-3.0, "error"]
    assert (t.loc[[4.0, 6.0], "outcome"] == "completed").all()
    assert t.loc[[4.0, 6.0], "error"].isna().all()


def test_table_is_identical_with_one_and_two_workers(backend, program, tmp_path):
    tables = []
    for workers in ("1", "2"):
        out = tmp_path / f"w{workers}"
        assert main(["sweep", str(program), "--set", "noise=0,2,4", "--seeds", "2",
                     "--steps", "6", "--out", str(out), "--workers", workers]) == 0
        tables.append(_table(out).drop(columns=["wall_seconds"]))
    assert tables[0].equals(tables[1])


def test_a_sweep_leaves_its_callers_thread_settings_alone(backend, program, tmp_path, monkeypatch):
    """Workers run with one thread per library; the calling process keeps its own
    settings (numba refuses to compile once they differ from its running pool), so a
    simulation after a sweep still compiles its kernels."""
    pytest.importorskip("numba")
    from swarmdsl.sweep.worker import THREAD_VARIABLES

    monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    before = {v: os.environ.get(v) for v in THREAD_VARIABLES}
    for workers in ("1", "2"):
        assert main(["sweep", str(program), "--set", "noise=0,2", "--steps", "3",
                     "--out", str(tmp_path / workers), "--workers", workers]) == 0
        assert {v: os.environ.get(v) for v in THREAD_VARIABLES} == before
    from swarmdsl.compiler import compile_source
    from swarmdsl.runtime.simulation import Simulation

    sim = Simulation(compile_source(PROGRAM, "flock.swarm", {"n": "40"}), 0,
                     backend="numba")
    sim.run(2)
    assert "10:23 sum: compiled" in "\n".join(sim.backend.summary(sim.program))


def _cli(*args, **kw):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.Popen([sys.executable, "-m", "swarmdsl", *args], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def _finished_rows(log: Path) -> int:
    """Whole lines of the run log (a line is appended whole, newline last)."""
    return log.read_text().count("\n") if log.exists() else 0


def _wait_until(condition, proc, what: str, timeout: float = 600) -> None:
    """Poll something on disk rather than sleep a fixed time: a loaded machine (load 8
    on 2 cores) makes every run ten times slower, which must change how long the test
    takes, never its verdict. The timeout only ends a sweep that truly hangs."""
    deadline = time.monotonic() + timeout
    while not condition():
        if proc.poll() is not None:
            out, err = proc.communicate()
            pytest.fail(f"the sweep exited ({proc.returncode}) before {what}:\n{err}")
        if time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"no {what} after {timeout:.0f} s")
        time.sleep(0.01)


@pytest.mark.parametrize("how, workers", [(signal.SIGKILL, "1"), (signal.SIGTERM, "1"),
                                          (signal.SIGINT, "2")])
def test_killed_sweep_restarts_and_skips_finished_runs(backend, program, tmp_path, capsys,
                                                       how, workers):
    """The killed sweep is a process of its own (a signal to it); the restart runs in
    this one. 100 ticks a run: the runs after the first batch take long enough for the
    signal to land before they all finish, on a loaded machine too (the signal goes as
    soon as the log has two lines)."""
    out = tmp_path / "s"
    args = ["sweep", str(program), "--set", "noise=0:1:0.25", "--seeds", "4", "--steps",
            "100", "--set", "n=30", "--out", str(out), "--workers", workers]
    proc = _cli(*args)
    log = out / "runs.jsonl"
    try:
        _wait_until(lambda: _finished_rows(log) >= 2, proc, "two finished runs in the log")
        proc.send_signal(how)
        proc.communicate(timeout=600)
    finally:
        proc.kill()
    if how != signal.SIGKILL:
        assert proc.returncode == 130
        assert len(_table(out)) >= 2          # finished rows kept in the table
    done_before = _finished_rows(log)
    assert 2 <= done_before < 20
    capsys.readouterr()
    assert main(args) == 0
    assert f"({done_before} already done, 0 failed)" in capsys.readouterr().out
    lines = log.read_text().splitlines()
    assert len(lines) == 20                    # nothing ran twice
    assert len(_table(out)) == 20


@contextlib.contextmanager
def _port_held(port: int):
    """`port` of 127.0.0.1 taken while the block runs (by this socket, or already by
    something else)."""
    with socket.socket() as sock:
        try:
            sock.bind(("127.0.0.1", port))
            sock.listen()
        except OSError:
            pass        # in use already: held all the same
        yield


def test_sweep_on_a_dask_local_cluster(backend, program, tmp_path):
    pytest.importorskip("dask.distributed")
    out = tmp_path / "d"
    # another cluster on the machine holds Dask's default HTTP port: this one starts
    # without a word about it
    with _port_held(8787):
        proc = _cli("sweep", str(program), "--set", "noise=0,3", "--steps", "3",
                    "--out", str(out), "--scheduler", "local", "--workers", "1")
        stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr
    assert "already in use" not in stderr
    t = _table(out)
    assert list(t.noise) == [0.0, 3.0] and (t.outcome == "completed").all()
    serial = tmp_path / "s"
    assert main(["sweep", str(program), "--set", "noise=0,3", "--steps", "3",
                 "--out", str(serial), "--workers", "1"]) == 0
    assert t.drop(columns=["wall_seconds"]).equals(
        _table(serial).drop(columns=["wall_seconds"]))


def test_a_local_dask_cluster_starts_no_more_workers_than_runs(program, tmp_path,
                                                              monkeypatch):
    # `--scheduler local --workers 8` started 8 worker processes for one run (the
    # process pool starts at most one per run); a large --workers could exhaust memory.
    from swarmdsl.sweep import execute

    asked = []

    class Cluster:
        def __init__(self, scheduler, workers):
            asked.append(workers)
            raise SwarmOptionError("stop here")

    monkeypatch.setattr(execute, "DaskCluster", Cluster)
    assert main(["sweep", str(program), "--set", "noise=0,3", "--steps", "1", "--out",
                 str(tmp_path / "d"), "--scheduler", "local", "--workers", "64"]) == 2
    assert asked == [2]


@pytest.mark.parametrize("empty", ["", " "])
def test_an_empty_scheduler_is_refused_not_run_on_this_machine(program, tmp_path, capsys,
                                                                empty):
    # `--scheduler ""` (an unset shell variable) ran the sweep on the local process
    # pool with a worker per core, as if no cluster had been asked for.
    out = tmp_path / "d"
    assert main(["sweep", str(program), "--steps", "1", "--out", str(out),
                 "--scheduler", empty]) == 2
    assert f'--scheduler "{empty}": the address is empty' in capsys.readouterr().err
    assert not out.exists()


def test_an_unreachable_scheduler_leaves_no_folder_behind(program, tmp_path, capsys,
                                                          monkeypatch):
    """A bad --scheduler address is an option error before anything is written (an
    empty sweep.parquet used to be left, which looked like a finished sweep of 0 runs)."""
    pytest.importorskip("dask.distributed")
    from swarmdsl.sweep import execute

    monkeypatch.setattr(execute, "CONNECT_TIMEOUT", 0.5, raising=False)   # port 9: no one
    out = tmp_path / "d"
    assert main(["sweep", str(program), "--steps", "1", "--out", str(out),
                 "--scheduler", "tcp://127.0.0.1:9", "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert "--scheduler tcp://127.0.0.1:9: cannot reach the Dask scheduler" in err
    assert not out.exists()


def test_seed_list_and_per_run_folders_when_asked(backend, program, tmp_path):
    out = tmp_path / "s"
    assert main(["sweep", str(program), "--set", "noise=0.5", "--seed-list", "7,3",
                 "--steps", "5", "--keep", "last", "--runs", "--out", str(out),
                 "--workers", "1"]) == 0
    t = _table(out)
    assert list(t.seed) == [7, 3]
    assert [c for c in t.columns if c.startswith("order.")] == ["order.last"]
    for seed in t.seed:
        run = out / "runs" / f"noise=0.5_seed={seed}"     # named by params and seed
        meta = __import__("json").loads((run / "run.json").read_text())
        assert meta["seed"] == seed and meta["params"]["noise"] == 0.5
        metrics = pq.read_table(run / "metrics.parquet").to_pandas()
        assert metrics[metrics.name == "order"].value.iloc[-1] == t.loc[
            t.seed == seed, "order.last"].item()
    plain = tmp_path / "plain"
    assert main(["sweep", str(program), "--seed-list", "1", "--steps", "2", "--out",
                 str(plain), "--workers", "1"]) == 0
    assert not (plain / "runs").exists()


FAULTING = """
param n = 6
param stop = 100
world { size 40 x 40; edges wrap }
agent a {
  count n
  velocity random_direction()
  status s {
    let r = sqrt(stop - tick)
    velocity = unit(angle(vel) + r * 0)
  }
}
metric order = length(mean(normalize(vel)))
"""


def test_a_faulted_run_has_null_summaries_and_its_error_names_the_file_as_typed(
        backend, tmp_path, monkeypatch):
    # the summaries of a run that faulted at tick 4 covered ticks 0-3 only and looked
    # like a finished run's; the error named the program by its resolved path
    (tmp_path / "fault.swarm").write_text(FAULTING)
    monkeypatch.chdir(tmp_path)
    assert main(["sweep", "fault.swarm", "--set", "stop=3,100", "--steps", "6",
                 "--out", "s", "--workers", "1"]) == 1
    t = _table(tmp_path / "s").set_index("stop")
    assert t.loc[3.0, "outcome"] == "fault"
    assert t.loc[3.0, "error"].startswith("fault.swarm:9:5: error: `r` is NaN")
    summaries = ["order.last", "order.mean", "order.min", "order.max"]
    assert t.loc[3.0, summaries].isna().all()
    assert t.loc[100.0, summaries].notna().all()


def test_retry_failed_runs_again_only_the_failed_runs(backend, tmp_path, capsys):
    program = tmp_path / "fault.swarm"
    program.write_text(FAULTING)
    out = tmp_path / "s"
    args = ["sweep", str(program), "--set", "stop=3,100", "--seeds", "2", "--steps", "6",
            "--out", str(out), "--workers", "1"]
    assert main(args) == 1
    assert main(args) == 1
    assert "(4 already done, 2 failed)" in capsys.readouterr().out
    assert main([*args, "--retry-failed"]) == 1
    assert "(2 already done, 2 failed)" in capsys.readouterr().out
    import pandas as pd

    log = pd.read_json(out / "runs.jsonl", lines=True)
    runs = log.groupby("key").size()
    assert sorted(runs) == [1, 1, 2, 2]          # the failed runs ran twice, no other
    assert set(log[log.key.isin(runs[runs == 2].index)].outcome) == {"fault"}
    assert len(_table(out)) == 4


def test_a_torn_last_line_of_the_log_is_dropped_when_the_sweep_starts_again(backend, program,
                                                                            tmp_path):
    # a SIGKILL inside a write leaves half a line; it stayed in the log (and the next
    # row was written after it), so `pandas.read_json(lines=True)` failed on the log
    import pandas as pd

    out = tmp_path / "s"
    args = ["sweep", str(program), "--set", "noise=0,1", "--steps", "3", "--out",
            str(out), "--workers", "1"]
    assert main([*args, "--seed-list", "0"]) == 0
    log = out / "runs.jsonl"
    whole = log.read_text()
    log.write_text(whole + '{"key": "0123", "params": [["noi')
    assert main([*args, "--seeds", "2"]) == 0
    assert log.read_text().startswith(whole)
    rows = pd.read_json(log, lines=True)
    assert len(rows) == 4 and "0123" not in set(rows.key)


def _children(pid: int) -> set[int]:
    """The processes whose parent is `pid` (Linux /proc)."""
    found = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.add(int(stat.parent.name))
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_killed_sweeps_pool_workers_and_resource_tracker_end_with_it(backend, program,
                                                                       tmp_path):
    # after SIGKILL of `sweep --workers 2` its workers and the pool's resource tracker
    # were still running two minutes later
    out = tmp_path / "s"
    proc = _cli("sweep", str(program), "--set", "noise=0:1:0.25", "--seeds", "4",
                "--steps", "100", "--set", "n=30", "--out", str(out), "--workers", "2")
    children: set[int] = set()
    try:
        _wait_until(lambda: _finished_rows(out / "runs.jsonl") >= 1, proc,
                    "a finished run in the log")
        children = _children(proc.pid)
        assert len(children) >= 3                  # two workers and the tracker
        proc.kill()
        proc.communicate(timeout=60)
        deadline = time.monotonic() + 60
        while any(_alive(c) for c in children) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not [c for c in children if _alive(c)]
    finally:
        proc.kill()
        for c in children:
            if _alive(c):
                os.kill(c, signal.SIGKILL)


def test_a_scheduler_without_workers_is_said_and_given_up_when_asked(program, tmp_path,
                                                                     capsys, monkeypatch):
    # the sweep waited in silence for workers that never came
    distributed = pytest.importorskip("dask.distributed")
    from swarmdsl.sweep import execute

    monkeypatch.setattr(execute, "POLL_SECONDS", 0.2)
    out = tmp_path / "d"
    with distributed.LocalCluster(n_workers=0, processes=False, dashboard_address=None,
                                  scheduler_kwargs=execute.HTTP_ON_A_FREE_PORT) as cluster:
        code = main(["sweep", str(program), "--set", "noise=0,3", "--steps", "3",
                     "--out", str(out), "--scheduler", cluster.scheduler_address,
                     "--wait-workers", "1"])
    assert code == 2
    err = capsys.readouterr().err
    assert f"waiting for workers: the Dask scheduler at {cluster.scheduler_address} " \
           "has none" in err
    assert "--wait-workers 1: the Dask scheduler at" in err and "no worker for 1 s" in err
    assert len(_table(out)) == 0


def test_wait_workers_needs_a_scheduler(program, tmp_path, capsys):
    assert main(["sweep", str(program), "--steps", "1", "--out", str(tmp_path / "d"),
                 "--wait-workers", "5"]) == 2
    assert "--wait-workers: only with --scheduler" in capsys.readouterr().err


def test_a_lost_scheduler_is_one_error_naming_it_and_keeps_the_finished_runs(backend, program,
                                                                             tmp_path):
    # a scheduler killed mid-sweep ended in exit 3 after ~37 lines of Dask's tracebacks
    pytest.importorskip("dask.distributed")
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    out = tmp_path / "d"
    args = ["sweep", str(program), "--set", "noise=0,3", "--steps", "3", "--out", str(out)]
    assert main([*args, "--seed-list", "0", "--workers", "1"]) == 0   # two runs done
    scheduler = subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
         "--port", str(port), "--no-dashboard", "--dashboard-address", "127.0.0.1:0"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL)
    sweep = None
    try:
        deadline = time.monotonic() + 120
        while True:                              # until the scheduler listens
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                assert time.monotonic() < deadline and scheduler.poll() is None
                time.sleep(0.2)
        sweep = _cli(*args, "--seeds", "2", "--scheduler", address)
        import selectors

        with selectors.DefaultSelector() as sel:  # no workers: it says so, then waits
            sel.register(sweep.stderr, selectors.EVENT_READ)
            assert sel.select(timeout=300), "the sweep said nothing of the missing workers"
        line = sweep.stderr.readline()
        assert line.startswith(f"waiting for workers: the Dask scheduler at {address}")
        scheduler.kill()
        stdout, stderr = sweep.communicate(timeout=300)
    finally:
        scheduler.kill()
        scheduler.wait()
        if sweep is not None:
            sweep.kill()
    assert sweep.returncode == 2, stderr
    assert "Traceback" not in stderr
    assert f"error: --scheduler {address}: lost the Dask scheduler" in stderr
    assert "sweep stopped: 2/4 runs in the table" in stdout
    assert len(_table(out)) == 2


@pytest.mark.parametrize("axis, said", [("pace=1,2,1", "1 is the same value as 1"),
                                        ("pace=1,1.0", "1.0 is the same value as 1"),
                                        ("home=true,True", "True is the same value as true")])
def test_sweep_refuses_a_value_listed_twice(walk, tmp_path, capsys, axis, said):
    """`--set pace=1,1` ran one run twice under the same key, two rows that `plot sweep`
    averaged as two replicates."""
    out = tmp_path / "sweep"
    err = cli_error(capsys, ["sweep", str(walk), "--set", axis, "--steps", "2",
                          "--workers", "1", "--out", str(out)])
    assert f"--set {axis}: {said}" in err
    assert not out.exists()


def test_a_sweep_with_failed_runs_says_why(backend, walk, tmp_path, capsys):
    """It exited 1 saying only `1 failed`; the reason sat in sweep.parquet's `error`."""
    out = tmp_path / "sweep"
    assert main(["sweep", str(walk), "--set", "n=2,2.5", "--steps", "2",
                 "--workers", "1", "--out", str(out)]) == 1
    captured = capsys.readouterr()
    assert "(0 already done, 1 failed)" in captured.out
    assert "the first failed run (n=2.5, seed 0):" in captured.err
    assert "walk.swarm:8:9: error: the count of `walker` must be a whole number" in (
        captured.err)


def _sweep(walk: Path, out: Path, capsys) -> str:
    assert main(["sweep", str(walk), "--set", "n=2,3,4", "--steps", "2",
                 "--workers", "1", "--out", str(out)]) == 0
    return capsys.readouterr().out


def test_a_sweep_killed_mid_line_keeps_every_later_run(backend, walk, tmp_path, capsys):
    """The restart appended its first run to the killed sweep's torn last line, so that
    run was lost from runs.jsonl and ran again on the next start."""
    out = tmp_path / "sweep"
    _sweep(walk, out, capsys)
    log = out / "runs.jsonl"
    lines = log.read_text().splitlines(keepends=True)
    log.write_text(lines[0] + lines[1][:40])        # SIGKILL while writing the second
    assert "(1 already done, 0 failed)" in _sweep(walk, out, capsys)
    assert "(3 already done, 0 failed)" in _sweep(walk, out, capsys)


def test_a_sweep_folder_whose_log_is_unreadable_is_refused(walk, tmp_path, capsys):
    out = tmp_path / "sweep"
    (out / "runs.jsonl").mkdir(parents=True)
    err = cli_error(capsys, ["sweep", str(walk), "--steps", "2", "--workers", "1",
                          "--out", str(out)])
    assert f"error: --out {out}: its runs.jsonl is unreadable (Is a directory)" in err


@pytest.mark.parametrize("inside, extra, said", [
    ("sweep.parquet", [], "--out {out}: sweep.parquet there is a folder"),
    ("runs", ["--runs"], "--runs {out}/runs: is a file, not a folder"),
])
def test_a_sweep_folder_that_cannot_take_its_outputs_is_refused_first(
        walk, tmp_path, capsys, inside, extra, said):
    """A folder named sweep.parquet was an internal error after every run had run; a
    file named runs failed every run of --runs."""
    out = tmp_path / "sweep"
    out.mkdir()
    (out / inside).mkdir() if inside == "sweep.parquet" else (out / inside).write_text("")
    err = cli_error(capsys, ["sweep", str(walk), "--steps", "2", "--workers", "1",
                          "--out", str(out), *extra])
    assert said.format(out=out) in err
    assert not (out / "runs.jsonl").exists()        # no run was made
