"""Every shipped program is a test: it compiles and runs, and the boids program flocks."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from swarmdsl.cli import main
from swarmdsl.compiler import compile_file
from swarmdsl.runtime.simulation import Simulation

PROGRAMS = Path(__file__).resolve().parent.parent / "programs"
SHIPPED = sorted(p.name for p in PROGRAMS.glob("*.swarm"))
DOCUMENTED = ["aco.swarm", "aco_bt.swarm", "boids.swarm", "boids_leader.swarm",
              "mas_environment.swarm", "matrix2d.swarm", "matrix2d_nn.swarm", "patrol.swarm",
              "spring1d.swarm", "spring1d_nn.swarm", "vicsek.swarm"]


def test_shipped_programs_are_the_documented_ones():
    assert set(SHIPPED) <= set(DOCUMENTED)
    assert "boids.swarm" in SHIPPED


@pytest.mark.parametrize("name", SHIPPED)
def test_program_compiles_without_warnings_and_runs(name, backend):
    program = compile_file(PROGRAMS / name)
    assert [str(w) for w in program.info.warnings] == []
    sim = Simulation(program, seed=0, backend=backend)
    sim.run(20)
    assert np.isfinite(sim.agents.cols["pos"]).all()


def polarisation(vx, vy) -> float:
    v = np.stack([vx, vy], axis=1)
    unit = v / np.maximum(np.linalg.norm(v, axis=1), 1e-12)[:, None]
    return float(np.linalg.norm(unit.mean(axis=0)))


def clusters(x, y, radius) -> int:
    pos = np.stack([x, y], axis=1)
    tree = cKDTree(pos)
    links = tree.sparse_distance_matrix(tree, radius)
    return connected_components(links, directed=False)[0]


def test_boids_flock_forms_over_several_seeds(tmp_path, backend):
    """Scattered agents end as one flock: one cluster and polarisation above 0.9 in
    most seeds (the recorded final tick, read back from agents.parquet).

    600 ticks: over seeds 0-11 the flock had formed by tick 400 in all but seeds 2, 6,
    7 and 8 (two flocks at tick 600), so at tick 600 8 of 12 are one flock above 0.9
    (three of the four kept here). A formed flock dips below 0.9 for a while as it turns
    at an edge."""
    flocked = []
    for seed in range(4):
        out = tmp_path / f"s{seed}"
        assert main(["run", str(PROGRAMS / "boids.swarm"), "--headless", "--steps", "600",
                     "--seed", str(seed), "--every", "600", "--out", str(out),
                     "--backend", backend]) == 0
        table = pq.read_table(out / "agents.parquet").to_pydict()
        radius = json.loads((out / "run.json").read_text())["params"]["radius"]
        ticks = np.array(table["tick"])
        last = ticks == ticks.max()
        first = ticks == 0
        col = {k: np.array(v) for k, v in table.items() if k in ("x", "y", "vx", "vy")}
        start_clusters = clusters(col["x"][first], col["y"][first], radius)
        end_clusters = clusters(col["x"][last], col["y"][last], radius)
        pol = polarisation(col["vx"][last], col["vy"][last])
        assert start_clusters > 1            # they did start scattered
        flocked.append(end_clusters == 1 and pol > 0.9)
    assert sum(flocked) >= 3, flocked
