"""Shared fixtures: compile program text, run it, and hypothesis profiles."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

# The grammar cache goes to a folder of the test session's own, not the user's cache.
_CACHE = tempfile.mkdtemp(prefix="swarmdsl-test-cache-")
atexit.register(shutil.rmtree, _CACHE, ignore_errors=True)
os.environ["SWARMDSL_CACHE_DIR"] = _CACHE
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
# The suite runs the reference (numpy) backend unless a test picks numba: compiling
# kernels for every program the suite builds would cost minutes. tests/test_compiled.py
# and the shipped-program tests run both.
os.environ.setdefault("SWARMDSL_BACKEND", "numpy")

settings.register_profile("ci", max_examples=60, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("dev", max_examples=200, deadline=None)
settings.register_profile("long", max_examples=2000, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


@pytest.fixture
def compile_src():
    """Compile program text (default name `test.swarm`) into a Program."""
    from swarmdsl.compiler import compile_source

    def _compile(text: str, overrides=None, filename="test.swarm"):
        return compile_source(text, filename, overrides)
    return _compile


@pytest.fixture
def run_src(compile_src):
    """Compile and run program text for `steps` ticks; return the Simulation."""
    from swarmdsl.runtime.simulation import Simulation

    def _run(text: str, steps: int = 1, seed: int = 0, overrides=None):
        sim = Simulation(compile_src(text, overrides), seed)
        sim.run(steps)
        return sim
    return _run


def by_id(sim, col: str) -> np.ndarray:
    """A column ordered by agent id."""
    order = np.argsort(sim.agents.cols["id"])
    return sim.agents.cols[col][order]
