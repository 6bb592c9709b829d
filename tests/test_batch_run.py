"""`swarmdsl.Batch`: many seeds of one program as batched replicas, each run's outputs
those of its solo run (`swarmdsl run --seed S --out`), refusals and faults run solo."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import assert_same_outputs

import swarmdsl
from swarmdsl.cli import main
from swarmdsl.errors import SwarmOptionError
from swarmdsl.runtime import batch_runner
from swarmdsl.runtime.batch_runner import Batch, replicas_per_batch
from swarmdsl.runtime.runner import Run

FLOCK = """
param n = 8
world { size 30 x 30; edges wrap }
agent a {
  count n
  sense 6
  velocity random_direction()
  var turned = 0.0
  status s {
    let heading_sum = sum(neighbors(6) : normalize(other.vel)) + normalize(vel)
    velocity = unit(angle(heading_sum) + uniform(-0.4, 0.4))
    turned = turned + abs(angle(heading_sum) - angle(vel))
  }
}
metric order = length(mean(normalize(vel)))
metric turning = mean(turned)
"""

# `luck` becomes NaN when a draw falls below 0.002: seeds 0 and 1 run 20 ticks, seed 11
# faults at tick 11 (on both backends; over seeds 0-39, 8 fault within 20 ticks, seed 11
# the latest)
FAULTY = """
param n = 6
world { size 20 x 20; edges wrap }
agent a {
  count n
  sense 5
  velocity random_direction()
  var luck = 0.0
  status s {
    luck = luck + log(uniform(0, 1) - 0.002)
    velocity = unit(angle(sum(neighbors(5) : normalize(other.vel)) + normalize(vel)))
  }
}
metric luckiest = max(luck)
"""


def _file(tmp_path: Path, text: str, name: str = "flock.swarm") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _solo(path: Path, seed: int, out: Path, backend: str, steps: int = 12,
          every: int = 3) -> Path:
    code = main(["run", str(path), "--headless", "--seed", str(seed), "--steps",
                 str(steps), "--every", str(every), "--out", str(out), "--backend", backend])
    assert code in (0, 2)
    return out


def _batched(program) -> bool:
    return batch_runner.batch_refusal_of(program) is None


def test_each_run_of_a_batch_is_its_solo_run_bit_for_bit(backend, tmp_path):
    path = _file(tmp_path, FLOCK)
    program = swarmdsl.load_program(path)
    results = swarmdsl.Batch(program, runs=[4, 0, 9], steps=12, every=3,
                             out=tmp_path / "batch", backend=backend).execute()
    assert [r.seed for r in results] == [4, 0, 9]
    assert all(r.outcome == "completed" and r.ticks == 12 for r in results)
    if _batched(program):
        assert all(r.replicas == 3 and r.solo is None for r in results)
    for r in results:
        assert r.out == (tmp_path / "batch" / f"seed-{r.seed}").absolute()
        solo = _solo(path, r.seed, tmp_path / f"solo{r.seed}", backend)
        assert_same_outputs(r.out, solo)
        mine, theirs = (json.loads((d / "run.json").read_text()) for d in (r.out, solo))
        assert mine["metrics"] == theirs["metrics"] == r.summary()
        assert mine["backend"] == theirs["backend"] == backend
        assert (mine["finished"], mine["last_tick"], mine["recorded_ticks"]) == (
            "completed", 12, 5)
        if r.replicas > 1:
            assert mine["batch"]["replicas"] == 3 and mine["batch"]["seeds"] == [4, 0, 9]


@pytest.mark.parametrize("hand_over", [3, 1024])
def test_a_batch_without_out_keeps_each_runs_metric_log(backend, tmp_path, monkeypatch,
                                                        hand_over):
    """Without folders a batch hands its metric rows to the runs' logs a block of ticks
    at a time (every 3 ticks here, or once at the end): each log is the solo run's."""
    monkeypatch.setattr(batch_runner, "HAND_OVER_TICKS", hand_over)
    program = swarmdsl.load_program(_file(tmp_path, FLOCK), {"n": 5})
    results = Batch(program, range(3), steps=7, backend=backend).execute()
    for r in results:
        run = Run(program, seed=r.seed, steps=7, backend=backend)
        run.show_progress = False
        assert run.execute() == "completed"
        assert r.out is None
        ticks, values = r.metrics.pending()
        solo_ticks, solo_values = run.metrics.pending()
        assert np.array_equal(ticks, solo_ticks) and ticks.tolist() == list(range(8))
        assert values.tobytes() == solo_values.tobytes()
        assert r.metrics.count == run.metrics.count == 8
        assert r.metrics.last_tick == 7 and r.summary() == run.metrics.summary()


def test_a_refused_program_runs_solo_and_says_why(backend, tmp_path, monkeypatch):
    path = _file(tmp_path, FLOCK)
    program = swarmdsl.load_program(path)
    monkeypatch.setattr(batch_runner, "batch_refusal_of",
                        lambda program: "fields are not batched yet (`field f`, line 3)")
    batch = Batch(program, [1, 2], steps=12, every=3, out=tmp_path / "b", backend=backend)
    assert batch.refusal == "fields are not batched yet (`field f`, line 3)"
    results = batch.execute()
    assert [(r.replicas, r.solo) for r in results] == [(1, batch.refusal)] * 2
    for r in results:
        assert "batch" not in json.loads((r.out / "run.json").read_text())
        assert_same_outputs(r.out, _solo(path, r.seed, tmp_path / f"solo{r.seed}", backend))


def test_a_replica_fault_reruns_its_batch_solo_each_to_its_own_outcome(backend, tmp_path):
    path = _file(tmp_path, FAULTY, "faulty.swarm")
    program = swarmdsl.load_program(path)
    results = Batch(program, [0, 11, 1], steps=20, every=3, out=tmp_path / "b",
                    backend=backend).execute()
    assert [r.outcome for r in results] == ["completed", "fault", "completed"]
    if _batched(program):
        assert all(r.replicas == 1 for r in results)
        assert all(r.solo.startswith("seed 11 faulted in a batch of 3 (") for r in results)
        assert "at tick 11" in results[0].solo
        assert "ran again solo" in results[0].solo
    assert "`luck` became NaN" in results[1].error.message
    for r in results:
        solo = _solo(path, r.seed, tmp_path / f"solo{r.seed}", backend, steps=20)
        assert_same_outputs(r.out, solo)
        assert json.loads((r.out / "run.json").read_text())["finished"] == r.outcome


def test_a_stop_closes_the_batch_in_flight_and_keeps_the_finished_one(tmp_path,
                                                                       monkeypatch):
    program = swarmdsl.load_program(_file(tmp_path, FLOCK))
    if not _batched(program):
        pytest.skip("the flock program is not batched yet")
    from swarmdsl.runtime import batch

    step = batch.BatchedSimulation.step

    def stopping_step(self):    # Ctrl-C in the second batch's fourth tick
        if self.seeds[0] == 2 and self.tick == 3:
            raise KeyboardInterrupt
        step(self)

    monkeypatch.setattr(batch.BatchedSimulation, "step", stopping_step)
    results = Batch(program, [0, 1, 2, 3, 4, 5], steps=12, every=2, size=2,
                    out=tmp_path / "b", backend="numpy").execute()
    assert [(r.seed, r.outcome, r.ticks) for r in results] == [
        (0, "completed", 12), (1, "completed", 12), (2, "interrupted", 3),
        (3, "interrupted", 3)]
    import pyarrow.parquet as pq

    for seed, ticks in ((1, [0, 2, 4, 6, 8, 10, 12]), (3, [0, 2, 3])):
        folder = tmp_path / "b" / f"seed-{seed}"
        info = json.loads((folder / "run.json").read_text())
        assert info["recorded_ticks"] == len(ticks)
        assert sorted(set(pq.read_table(folder / "agents.parquet")["tick"].to_pylist())) == ticks
    assert not (tmp_path / "b" / "seed-4").exists()


def test_a_ctrl_c_while_a_batch_closes_keeps_its_runs_whole(tmp_path, monkeypatch):
    """In a plain Python process (Python's own SIGINT handler), a Ctrl-C landing while a
    batch's outputs close used to escape from the middle of it and leave run.json
    saying `running`: the batch closes whole, no other batch starts, and then the
    KeyboardInterrupt is raised."""
    import os
    import signal

    from swarmdsl.runtime import record

    program = swarmdsl.load_program(_file(tmp_path, FLOCK), {"n": 3})
    close = record.Recorder.close

    def ctrl_c_while_closing(self, *args, **kwargs):
        if self.out.name == "seed-0":
            os.kill(os.getpid(), signal.SIGINT)
        return close(self, *args, **kwargs)

    monkeypatch.setattr(record.Recorder, "close", ctrl_c_while_closing)
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    batch = Batch(program, [0, 1, 2, 3, 4, 5], steps=3, size=2, out=tmp_path / "b",
                  backend="numpy")
    try:
        with pytest.raises(KeyboardInterrupt):
            batch.execute()
        # Python's own handler is back (this process's own may be SIG_IGN: a job started
        # in the background ignores SIGINT, so it is set above and put back below)
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, old)
    assert [(r.seed, r.outcome) for r in batch.results] == [(0, "completed"),
                                                             (1, "completed")]
    for seed in (0, 1):
        info = json.loads((tmp_path / "b" / f"seed-{seed}" / "run.json").read_text())
        assert (info["finished"], info["last_tick"]) == ("completed", 3)
    assert not (tmp_path / "b" / "seed-2").exists()


@pytest.mark.parametrize("runs, said", [([], "runs is empty"),
                                        ([1, 2, 1], "runs[2]: seed 1 is also runs[0]"),
                                        ("12", "runs must be a list of seeds"),
                                        ([1, -2], "runs[1]")])
def test_bad_runs_are_refused_naming_them(tmp_path, runs, said):
    program = swarmdsl.load_program(_file(tmp_path, FLOCK))
    with pytest.raises(SwarmOptionError, match=said.replace("[", r"\[")):
        Batch(program, runs)


def test_bad_size_and_backend_are_refused(tmp_path):
    program = swarmdsl.load_program(_file(tmp_path, FLOCK))
    with pytest.raises(SwarmOptionError, match="size"):
        Batch(program, [1, 2], size=0)
    with pytest.raises(SwarmOptionError, match="backend 'cuda'"):
        Batch(program, [1, 2], backend="cuda")


def test_a_path_instead_of_a_program_is_refused_naming_batch(tmp_path):
    with pytest.raises(SwarmOptionError, match=r"Batch needs a compiled program: "
                       r"Batch\(swarmdsl.load_program\(path\), ...\), got str"):
        Batch(str(_file(tmp_path, FLOCK)), [1, 2])


def test_a_batch_runs_once(tmp_path):
    program = swarmdsl.load_program(_file(tmp_path, FLOCK), {"n": 3})
    batch = Batch(program, [1, 2], steps=2, backend="numpy")
    batch.execute()
    with pytest.raises(SwarmOptionError, match="already run"):
        batch.execute()


def test_the_default_batch_size_rule():
    assert replicas_per_batch(100, 1000, workers=2) == 500
    assert replicas_per_batch(400, 240, workers=2) == 120
    assert replicas_per_batch(30, 100_000, workers=1) == batch_runner.BATCH_AGENTS // 30
    assert replicas_per_batch(batch_runner.SMALL_RUN_AGENTS + 1, 100, workers=1) == 1
    assert replicas_per_batch(100, 1) == 1
    assert replicas_per_batch(100, 2, workers=2) == 1     # one run a worker
