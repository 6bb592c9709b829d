"""The ant-colony experiment (EXPERIMENTS.md §4): pheromone trails link the nest to the
food sources, near ones first. Measured on the recorded fields.npz, as a reader would."""

from __future__ import annotations

from pathlib import Path

import pytest

from swarmdsl.analysis.trails import first_linked
from swarmdsl.compiler import compile_file
from swarmdsl.runtime.runner import Run

ACO = Path(__file__).parents[1] / "programs" / "aco.swarm"
SOURCES = ["alpha", "beta", "gamma", "delta", "epsilon"]


def _first_links(tmp_path, seed: int, steps: int) -> dict[str, int | None]:
    out = tmp_path / f"seed{seed}"
    Run(compile_file(ACO), seed=seed, steps=steps, out=out, every=10).execute()
    return {b: t for (_a, b), t in first_linked(out).items()}


def test_near_sources_are_linked_first(tmp_path):
    links = [_first_links(tmp_path, seed, 600) for seed in range(3)]
    assert all(r["alpha"] is not None for r in links)
    assert sum(r["beta"] is not None for r in links) >= 2
    for r in links:
        if r["beta"] is not None:
            assert r["alpha"] <= r["beta"]


@pytest.mark.slow
def test_trails_link_the_nest_to_every_source_in_most_seeds(tmp_path):
    links = [_first_links(tmp_path, seed, 6000) for seed in range(10)]
    all_five = [all(r[s] is not None for s in SOURCES) for r in links]
    assert sum(all_five) >= 6, links
