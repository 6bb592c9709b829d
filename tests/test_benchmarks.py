"""The benchmark suite's references compute the same model as the programs they time.

Without this a faster reference could simply be doing less work. Each reference starts
from the compiled program's agents with the noise switched off; after a few ticks every
position agrees to rounding. (The timings themselves are not tests.) And `--neighbours K`
runs every model, in every column and memory probe, at the density it states.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from benchmarks.cases import CASES, SWARMDSL_BACKENDS, SwarmdslRun, statistics
from benchmarks.suite import memory, same_work


@pytest.mark.parametrize("model", sorted(CASES))
def test_references_follow_the_programs_rules(model):
    gaps = same_work(CASES[model], dict(SWARMDSL_BACKENDS), seed=3, n=300, ticks=5)
    assert "numpy" in gaps
    if importlib.util.find_spec("numba") is not None:
        assert "numba" in gaps
    assert max(gaps.values()) < 1e-9, gaps


@pytest.mark.parametrize("width, height", [(100.0, 80.0), (95.0, 87.0), (100.0, 87.0)])
def test_the_numba_reference_pushes_from_each_edge_node_once(width, height):
    """Agents in every corner (a corner node counts once; a side of a length that is not
    a whole number of spacings ends short of the far corner): the hand-written numba
    edge push is the runtime's, which the same-work check rarely reaches."""
    pytest.importorskip("numba")
    import numpy as np

    from benchmarks.numba_refs import edge_push
    from swarmdsl.runtime.world import World

    near = np.linspace(0.0, 18.0, 13)
    xs = np.concatenate([near, width - near])
    ys = np.concatenate([near, height - near])
    pos = np.array([(x, y) for x in xs for y in ys])
    want = World(width, height, 10.0, "repel", 1.0, 20.0).edge_push(pos)
    got = edge_push(pos, width, height, 10.0, 1.0, 20.0)
    assert np.allclose(got, want, rtol=1e-12, atol=1e-12, equal_nan=True)


def test_a_reference_with_other_rules_is_caught(monkeypatch):
    """The check is sharp: the numpy boids with a different cohesion weight fails it."""
    from benchmarks import reference_boids

    steer = reference_boids.ReferenceBoids.steer
    monkeypatch.setattr(reference_boids.ReferenceBoids, "steer",
                        lambda self: steer(self) * 1.01)
    gaps = same_work(CASES["boids"], dict(SWARMDSL_BACKENDS), seed=3, n=300, ticks=5)
    assert gaps["numpy"] > 1e-6


@pytest.mark.parametrize("neighbours", [3.0, 20.0])
@pytest.mark.parametrize("model", sorted(CASES))
def test_the_world_is_sized_for_the_mean_neighbours_asked(model, neighbours):
    """The program's own uniform placement on the sized world, counted by the suite's
    statistics, has K neighbours on average (walls cost boids ~2 % at this size); 3 and
    20 between them differ from every model's own density by more than the tolerance."""
    case = CASES[model]
    run = SwarmdslRun(case, 10_000, 0, "numpy", neighbours=neighbours)
    got = statistics(case, run.params, run.state())["neighbours"]
    assert got == pytest.approx(neighbours, rel=0.04)


def test_the_chemotaxis_grid_keeps_its_nodes_per_agent():
    """Sizing the world for a density keeps the field work per agent the model's own."""
    own = SwarmdslRun(CASES["chemotaxis"], 1000, 0, "numpy")
    dense = SwarmdslRun(CASES["chemotaxis"], 1000, 0, "numpy", neighbours=20)
    grid = (lambda run: run.sim.environment.fields["chem"].grid.shape)
    assert grid(dense) == grid(own) == (64, 64)
    assert dense.params["size"] < own.params["size"] / 2


def test_the_same_work_check_runs_at_the_density_asked():
    """At K = 3 the references still follow the program (on its sized world)."""
    gaps = same_work(CASES["vicsek"], dict(SWARMDSL_BACKENDS), seed=3, n=300, ticks=5,
                     neighbours=3.0)
    assert max(gaps.values()) < 1e-9, gaps


@pytest.mark.skipif(not Path("/proc/self/clear_refs").exists(),
                    reason="the memory probes measure Linux resident sets")
def test_the_memory_probe_measures_the_timed_world():
    """The fresh-process probe gets the option: it reports a swarmdsl column built at
    K = 3, and one that ran at the model's own density is refused, not reported."""
    case = CASES["vicsek"]
    timed = SwarmdslRun(case, 500, 0, "numpy", neighbours=3.0)
    args = ("vicsek", "swarmdsl-numpy", 500, 0, [], timed.state(), timed.params)
    assert memory(*args, neighbours=3.0)["peak_mb"] > 0
    assert memory(*args) == {}
