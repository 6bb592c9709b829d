"""What a researcher trying the Python API and the viewer from a notebook or script runs
into: arguments of the wrong type, objects shared or mutated, runs side by side."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import swarmdsl
from swarmdsl.runtime.simulation import Simulation

PROGRAMS = Path(__file__).parent.parent / "programs"


def _sim(name: str, seed: int = 3) -> Simulation:
    return Simulation(swarmdsl.load_program(PROGRAMS / name), seed, backend="numpy")


def test_editing_a_snapshots_grid_leaves_the_simulation_alone():
    """A snapshot's arrays are the caller's: zeroing its grid coordinates (a plot that
    shifts them in place) once moved the grid the simulation samples its fields on."""
    edited, untouched = _sim("mas_environment.swarm"), _sim("mas_environment.swarm")
    edited.step()
    untouched.step()
    snap = edited.snapshot()
    for arr in (snap.grid_x, snap.grid_y, snap.grid_points):
        arr[...] = 0.0
    edited.step()
    untouched.step()
    a, b = edited.snapshot(), untouched.snapshot()
    assert np.array_equal(a.grid_x, b.grid_x) and np.array_equal(a.grid_points, b.grid_points)
    assert np.array_equal(a.pos, b.pos)
    assert all(np.array_equal(a.fields[k], b.fields[k]) for k in b.fields)
