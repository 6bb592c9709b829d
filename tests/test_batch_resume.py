"""A batched sweep stopped midway (SIGTERM, SIGKILL) and started again ends with the
uninterrupted sweep's table and run folders: it loses at most the batches in flight,
which run again. A batch itself keeps no checkpoint: asking for one is an option error
naming the option."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from conftest import assert_same_outputs

from swarmdsl import load_program
from swarmdsl.cli import main
from swarmdsl.errors import SwarmOptionError
from swarmdsl.runtime.batch_runner import Batch

ROOT = Path(__file__).resolve().parent.parent
PROGRAM = ROOT / "programs" / "spring1d.swarm"
SEEDS = 8


def _args(out: Path) -> list[str]:
    """4 batches of 2 runs, run folders too (`--runs`), one process. 60 ticks a run:
    the three batches after the first take long enough for the kill to land first."""
    return ["sweep", str(PROGRAM), "--set", "turn_noise=0.1", "--seeds", str(SEEDS),
            "--steps", "60", "--every", "10", "--out", str(out), "--workers", "1",
            "--batch", "2", "--runs"]


def _sweep(args: list[str], capsys) -> tuple[int, str, str]:
    """The sweep run in this process (on the numpy backend): its code, stdout, stderr."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("SWARMDSL_BACKEND", "numpy")
        capsys.readouterr()
        code = main(args)
    said = capsys.readouterr()
    return code, said.out, said.err


ENV = {**os.environ, "SWARMDSL_BACKEND": "numpy", "PYTHONPATH": str(ROOT)}


def _finished(log: Path) -> int:
    if not log.exists():
        return 0
    return sum(1 for line in log.read_text().splitlines() if line.endswith("}"))


@pytest.fixture
def uninterrupted(tmp_path, capsys) -> Path:
    out = tmp_path / "whole"
    assert _sweep(_args(out), capsys)[0] == 0
    return out


def _table(out: Path):
    return pq.read_table(out / "sweep.parquet").drop(["wall_seconds"])


# SIGKILL: nothing closes, the batches in flight are lost; SIGTERM, SIGINT (a clean stop)
# and the solo table are test_sweep.py's killed sweeps, which batch by default.
@pytest.mark.parametrize("sig", [signal.SIGKILL])
def test_a_stopped_batched_sweep_resumes_to_the_uninterrupted_sweep(sig, uninterrupted,
                                                                     tmp_path, capsys):
    """The stopped sweep is a process of its own (a signal to it); the uninterrupted
    one and the restart run in this one."""
    out = tmp_path / "s"
    proc = subprocess.Popen([sys.executable, "-m", "swarmdsl", *_args(out)], env=ENV,
                            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    log = out / "runs.jsonl"
    try:
        deadline = time.monotonic() + 600
        while _finished(log) < 2 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.005)
        proc.send_signal(sig)
        _stdout, stderr = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode in (130, 128 + sig, -sig), stderr   # stopped, not finished
    done = _finished(log)
    assert 2 <= done < SEEDS   # the runs of finished batches (a kill may cut between rows)
    code, stdout, stderr = _sweep([*_args(out), "-v"], capsys)
    assert code == 0, stderr
    assert f"({done} already done, 0 failed)" in stdout
    assert f"{SEEDS - done} runs to run" in stderr
    assert len(log.read_text().splitlines()) == SEEDS      # nothing ran twice
    assert _table(out).equals(_table(uninterrupted))
    theirs = sorted(p.name for p in (uninterrupted / "runs").iterdir())
    assert sorted(p.name for p in (out / "runs").iterdir()) == theirs
    for name in theirs:
        assert_same_outputs(out / "runs" / name, uninterrupted / "runs" / name)


def test_a_batch_refuses_checkpoints_naming_the_option(tmp_path):
    program = load_program(PROGRAM)
    with pytest.raises(SwarmOptionError, match="checkpoint_every"):
        Batch(program, [1, 2], steps=5, out=tmp_path, checkpoint_every=2)
    batch = Batch(program, [1, 2], steps=5, out=tmp_path)
    batch.checkpoint_every = 2          # set by hand, as on a Run
    with pytest.raises(SwarmOptionError, match="checkpoint_every"):
        batch.execute()
    assert not any(tmp_path.iterdir())  # refused before any run started
    Batch(program, [1, 2], steps=5, out=tmp_path, checkpoint_every=0).execute()


def test_checkpointing_a_batched_simulation_says_why_not(tmp_path):
    from swarmdsl.runtime import checkpoint
    from swarmdsl.runtime.batch import BatchedSimulation

    batch = BatchedSimulation(load_program(PROGRAM), [1, 2], backend="numpy")
    batch.step()
    with pytest.raises(SwarmOptionError, match="keeps no checkpoint"):
        checkpoint.save(batch, tmp_path / "checkpoint")
    assert not (tmp_path / "checkpoint").exists()
