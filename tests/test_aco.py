"""The ant-colony experiment (EXPERIMENTS.md §4): pheromone trails link the nest to the
food sources, near ones first. Measured on the recorded fields.npz, as a reader would."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from swarmdsl.analysis.trails import first_linked, trail_steps
from swarmdsl.compiler import compile_file
from swarmdsl.runtime.runner import Run

ACO = Path(__file__).parents[1] / "programs" / "aco.swarm"
SOURCES = ["alpha", "beta", "gamma", "delta", "epsilon"]


def _first_links(tmp_path, seed: int, steps: int) -> dict[str, int | None]:
    out = tmp_path / f"seed{seed}"
    Run(compile_file(ACO), seed=seed, steps=steps, out=out, every=10).execute()
    return {b: t for (_a, b), t in first_linked(out).items()}


def test_trail_steps_follow_the_trail_and_stop_at_gaps():
    values = np.zeros((5, 9))
    values[2, 1:8] = 1.0
    a = np.zeros((5, 9), bool)
    b = np.zeros((5, 9), bool)
    a[2, 0], b[2, 8] = True, True
    assert trail_steps(values, 0.5, a, b) == 8
    values[2, 4] = 0.0
    assert trail_steps(values, 0.5, a, b) is None


def test_near_sources_are_linked_first(tmp_path):
    links = [_first_links(tmp_path, seed, 1000) for seed in range(3)]
    assert all(r["alpha"] is not None and r["beta"] is not None for r in links), links
    assert sum(r["gamma"] is not None for r in links) >= 2, links
    for r in links:
        assert r["alpha"] <= r["beta"]
        if r["gamma"] is not None:
            assert r["beta"] <= r["gamma"]


@pytest.mark.slow
def test_trails_link_the_nest_to_every_source_in_most_seeds(tmp_path):
    links = [_first_links(tmp_path, seed, 3000) for seed in range(10)]
    all_five = [all(r[s] is not None for s in SOURCES) for r in links]
    assert sum(all_five) >= 6, links
    done = [r for r, ok in zip(links, all_five, strict=True) if ok]
    near = np.mean([max(r["alpha"], r["beta"]) for r in done])
    far = np.mean([min(r["delta"], r["epsilon"]) for r in done])
    assert near < far
