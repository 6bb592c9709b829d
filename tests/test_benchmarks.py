"""The benchmark suite's references compute the same model as the programs they time.

Without this a faster reference could simply be doing less work. Each reference starts
from the compiled program's agents with the noise switched off; after a few ticks every
position agrees to rounding. (The timings themselves are not tests.)
"""

from __future__ import annotations

import importlib.util

import pytest

from benchmarks.cases import CASES, SWARMDSL_BACKENDS
from benchmarks.suite import same_work


@pytest.mark.parametrize("model", sorted(CASES))
def test_references_follow_the_programs_rules(model):
    gaps = same_work(CASES[model], dict(SWARMDSL_BACKENDS), seed=3, n=300, ticks=5)
    assert "numpy" in gaps
    if importlib.util.find_spec("numba") is not None:
        assert "numba" in gaps
    assert max(gaps.values()) < 1e-9, gaps


def test_a_reference_with_other_rules_is_caught(monkeypatch):
    """The check is sharp: the numpy boids with a different cohesion weight fails it."""
    from benchmarks import reference_boids

    steer = reference_boids.ReferenceBoids.steer
    monkeypatch.setattr(reference_boids.ReferenceBoids, "steer",
                        lambda self: steer(self) * 1.01)
    gaps = same_work(CASES["boids"], dict(SWARMDSL_BACKENDS), seed=3, n=300, ticks=5)
    assert gaps["numpy"] > 1e-6
