"""`swarmdsl sweep` with batches: the same table and run folders as solo runs, refusals
said, the options' errors named, a killed batched sweep resumed per run."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from conftest import assert_same_outputs, cli_error
from test_sweep import program  # noqa: F401  (the flock program's file)

from swarmdsl.cli import main
from swarmdsl.compiler import compile_file
from swarmdsl.runtime import batch_runner

ROOT = Path(__file__).resolve().parent.parent


def _sweep(program: Path, out: Path, *more: str) -> int:
    return main(["sweep", str(program), "--set", "noise=0.2,2", "--seeds", "3", "--steps",
                 "10", "--every", "2", "--out", str(out), "--workers", "1", "--runs",
                 *more])


def _rows(out: Path):
    return pq.read_table(out / "sweep.parquet").drop(["wall_seconds"])


def _batched(path: Path) -> bool:
    return batch_runner.batch_refusal_of(compile_file(path)) is None


def test_a_batched_sweep_gives_the_solo_sweeps_table_and_run_folders(backend, program,
                                                                     tmp_path, capsys):
    assert _sweep(program, tmp_path / "batched", "-v") == 0
    said = capsys.readouterr().err
    assert _sweep(program, tmp_path / "solo", "--no-batch") == 0
    batched, solo = _rows(tmp_path / "batched"), _rows(tmp_path / "solo")
    assert batched.num_rows == 6 and batched.equals(solo)   # summaries bit for bit
    if _batched(program):
        assert "6 runs to run: 6 in 2 batches, 0 solo" in said
        assert "noise=0.2: 3 runs in 1 batch of 3 replicas (12 agents a run)" in said
    logged = [json.loads(line) for line in
              (tmp_path / "batched" / "runs.jsonl").read_text().splitlines()]
    for row in logged:
        noise = dict(row["params"])["noise"]
        assert row["folder"] == f"noise={noise}_seed={row['seed']}"
        folder = tmp_path / "batched" / "runs" / row["folder"]
        assert_same_outputs(folder, tmp_path / "solo" / "runs" / row["folder"])
        info = json.loads((folder / "run.json").read_text())
        assert info["backend"] == backend and info["seed"] == row["seed"]
        if _batched(program):
            assert row["replicas"] == 3 and info["batch"]["replicas"] == 3


def test_batch_r_splits_a_combination_into_batches_of_r(backend, program, tmp_path,
                                                         capsys):
    if not _batched(program):
        pytest.skip("the flock program is not batched yet")
    out = tmp_path / "s"
    assert main(["sweep", str(program), "--seeds", "5", "--steps", "4", "--out", str(out),
                 "--workers", "1", "--batch", "2", "-v"]) == 0
    said = capsys.readouterr().err
    assert "5 runs to run: 4 in 2 batches, 1 solo" in said
    assert "the runs: 4 runs in 2 batches of 2 replicas (12 agents a run), 1 run " \
        "solo (left over)" in said
    logged = [json.loads(line) for line in (out / "runs.jsonl").read_text().splitlines()]
    assert sorted((r["seed"], r.get("replicas", 1)) for r in logged) == [
        (0, 2), (1, 2), (2, 2), (3, 2), (4, 1)]


def test_a_refused_program_runs_solo_and_says_why(backend, program, tmp_path, capsys,
                                                  monkeypatch):
    why = "messaging is not batched yet (`broadcast`, line 9)"
    monkeypatch.setattr(batch_runner, "batch_refusal_of", lambda program: why)
    assert _sweep(program, tmp_path / "s", "-v") == 0
    said = capsys.readouterr().err
    assert "6 runs to run: 0 in 0 batches, 6 solo" in said
    assert f"  6 runs solo: {why}" in said
    assert len(_rows(tmp_path / "s")) == 6


def test_a_replica_fault_runs_its_batch_solo_and_v_says_so(backend, tmp_path, capsys):
    path = tmp_path / "faulty.swarm"
    from test_batch_run import FAULTY

    path.write_text(FAULTY)
    if not _batched(path):
        pytest.skip("the program is not batched yet")
    out = tmp_path / "s"
    assert main(["sweep", str(path), "--seed-list", "0,11,1", "--steps", "20", "--out",
                 str(out), "--workers", "1", "-v"]) == 1
    said = capsys.readouterr().err
    assert "\nseed 11 faulted in a batch of 3 (" in said and "seed 0" not in said
    t = pq.read_table(out / "sweep.parquet").to_pandas()
    assert t.outcome.tolist() == ["completed", "fault", "completed"]
    assert "`luck` became NaN" in t.error[1]


@pytest.mark.parametrize("argv, said", [
    (["--batch", "0"], "--batch 0: must be 1 or more"),
    (["--batch", "two"], "--batch: invalid int value: 'two'"),
    (["--batch", "4", "--no-batch"], "--no-batch: not allowed with argument --batch")])
def test_batch_option_errors_name_the_option(program, tmp_path, capsys, argv, said):
    out = tmp_path / "s"
    argv = ["sweep", str(program), "--steps", "2", "--out", str(out), *argv]
    if argv[-1] == "0":
        err = cli_error(capsys, argv)
    else:   # argparse's own: the usage, then the option, exit 2
        with pytest.raises(SystemExit) as exit_:
            main(argv)
        assert exit_.value.code == 2
        err = capsys.readouterr().err
        assert "Traceback" not in err
    assert said in err
    assert not out.exists()


def test_the_sweep_benchmark_runs_quick(monkeypatch, capsys):
    """`python -m benchmarks.sweeps --quick`: the batched and the solo sweep, back to back,
    give the same table; the batch's memory and single runs' ticks/s are reported."""
    monkeypatch.setenv("SWARMDSL_BACKEND", "numpy")
    monkeypatch.syspath_prepend(str(ROOT))
    from benchmarks import sweeps

    monkeypatch.setattr(sweeps, "BACKENDS", ("numpy",))
    monkeypatch.setattr(sweeps, "SINGLE", sweeps.SINGLE[-2:])
    assert sweeps.main(["--quick", "--only", "vicsek100,rss,ticks"]) == 0
    table = capsys.readouterr().out
    assert "| vicsek n=100: 10 eta x 100 seeds, 300 ticks |" in table
    assert "x | 10x | yes |" in table
    assert "Batch of 20 vicsek runs (n = 100, 10 ticks, 20 replicas a batch)" in table
    assert "20 completed" in table
    assert "| vicsek n=400 | 400 |" in table


def test_dask_workers_run_batches_and_give_the_solo_table(backend, program, tmp_path):
    """A cluster gets batches as tasks: each noise value's three seeds as one task, the
    rows those of the solo sweep."""
    pytest.importorskip("dask.distributed")
    out = tmp_path / "d"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-m", "swarmdsl", "sweep", str(program),
                           "--set", "noise=0,3", "--seeds", "3", "--steps", "4", "--out",
                           str(out), "--scheduler", "local", "--workers", "1", "-v"],
                          env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    logged = [json.loads(line) for line in (out / "runs.jsonl").read_text().splitlines()]
    if _batched(program):
        assert "6 runs to run: 6 in 2 batches, 0 solo" in done.stderr
        assert [r["replicas"] for r in logged] == [3] * 6
    solo = tmp_path / "s"
    assert main(["sweep", str(program), "--set", "noise=0,3", "--seeds", "3", "--steps",
                 "4", "--out", str(solo), "--workers", "1", "--no-batch"]) == 0
    assert _rows(out).equals(_rows(solo))
