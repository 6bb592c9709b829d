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
