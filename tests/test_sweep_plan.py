"""How runs of one param combination are split into batches: a sweep's (`sweep/plan.py`)
and a `Batch`'s (`batch_runner.even_chunks`)."""

from __future__ import annotations

import json

import pytest

from swarmdsl.cli import main
from swarmdsl.compiler import compile_source
from swarmdsl.runtime.batch_runner import Batch

PROGRAM = """
world { size 40 x 40; edges wrap }
agent a {
  count 6
  velocity random_direction() * 0.5
  status go { velocity = unit(angle(vel) + uniform(-0.3, 0.3)) * 0.5 }
}
"""


@pytest.mark.parametrize("seeds, batch, replicas", [
    (7, 3, [3, 3, 3, 2, 2, 2, 2]),      # 3 + 2 + 2, no run left over
    (5, 2, [2, 2, 2, 2, 1]),            # no even split avoids the single run
    (6, 4, [3, 3, 3, 3, 3, 3]),
])
def test_batch_r_splits_a_combinations_runs_as_evenly_as_it_can(backend, tmp_path, seeds,
                                                                  batch, replicas):
    path = tmp_path / "p.swarm"
    path.write_text(PROGRAM)
    out = tmp_path / "s"
    assert main(["sweep", str(path), "--seeds", str(seeds), "--steps", "3", "--out",
                 str(out), "--workers", "1", "--batch", str(batch)]) == 0
    logged = [json.loads(line) for line in (out / "runs.jsonl").read_text().splitlines()]
    assert sorted(r["seed"] for r in logged) == list(range(seeds))
    assert sorted((r.get("replicas", 1) for r in logged), reverse=True) == replicas


def test_a_batch_of_size_r_splits_its_seeds_as_evenly_as_it_can(backend):
    program = compile_source(PROGRAM, "p.swarm")
    results = Batch(program, list(range(7)), steps=3, size=3, backend=backend).execute()
    assert [r.seed for r in results] == list(range(7))
    assert [r.replicas for r in results] == [3, 3, 3, 2, 2, 2, 2]


def test_runs_that_would_take_whole_ticks_run_solo_not_batched(monkeypatch):
    """A batch never takes whole ticks; a small run whose whole-tick kernel is kept
    here does, by default, when it is long enough to repay loading it."""
    from swarmdsl.runtime.compiled import warm
    from swarmdsl.sweep.plan import plan_tasks

    program = compile_source(PROGRAM, "p.swarm")

    def calls(steps):
        return [("p.swarm", PROGRAM, (), seed, steps, 1, None, ".") for seed in range(6)]
    monkeypatch.setattr(warm, "whole_here", lambda p: True)
    monkeypatch.setattr(warm, "compiled_here", lambda p: True)
    long = plan_tasks(calls(20_000), None, 2, program)
    assert [kind for kind, _ in long.tasks] == ["one"] * 6
    assert long.notes == ["the runs: 6 runs solo: each takes whole ticks from kernels "
                          "kept on disk, faster than a batch of replicas"]
    assert [kind for kind, _ in plan_tasks(calls(50), None, 2, program).tasks] == \
        ["batch"] * 2   # too short to repay loading them: batched
    assert [kind for kind, _ in plan_tasks(calls(20_000), 3, 2, program).tasks] == \
        ["batch"] * 2   # --batch R asked for batches
    monkeypatch.setattr(warm, "whole_here", lambda p: False)
    assert [kind for kind, _ in plan_tasks(calls(20_000), None, 2, program).tasks] == \
        ["batch"] * 2
