"""What a researcher trying the Python API and the viewer from a notebook or script runs
into: arguments of the wrong type, objects shared or mutated, runs side by side."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

import swarmdsl
from swarmdsl import SwarmOptionError
from swarmdsl.runtime.runner import Run
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


def _checkpointed(tmp_path, steps: int = 6) -> tuple[object, Path]:
    """A program and the folder of its finished run, checkpointed at its last tick."""
    program = swarmdsl.load_program(PROGRAMS / "vicsek.swarm", {"n": 20})
    out = tmp_path / "run"
    run = _quiet(Run(program, seed=2, steps=steps, out=out, backend="numpy"))
    run.checkpoint_every = 3
    assert run.execute() == "completed"
    return program, out


def _quiet(run: Run) -> Run:
    run.show_progress = False
    return run


def _recorded(out: Path):
    return pq.read_table(out / "agents.parquet")


@pytest.mark.parametrize("change, named", [
    (dict(seed=3), "seed 3: the checkpoint"),
    (dict(steps=2), "steps 2: the checkpoint"),
    (dict(out="other"), "build the Run with out="),
])
def test_a_resume_the_checkpoint_cannot_continue_is_refused_and_keeps_the_files(
        tmp_path, change, named):
    """`Run(seed=3).resume(DIR)` of a seed-2 checkpoint drew seed 2's numbers and wrote
    `"seed": 3` into run.json; fewer steps than the checkpoint's tick, or another out
    folder, were taken too, the folder's files cut back to the checkpoint before any
    check. Now each is refused naming the argument, the finished run left whole."""
    program, out = _checkpointed(tmp_path)
    before = _recorded(out)
    settings = dict(seed=2, steps=10, out=out, backend="numpy")
    settings.update({k: tmp_path / v if k == "out" else v for k, v in change.items()})
    with pytest.raises(SwarmOptionError, match=named):
        Run(program, **settings).resume(out)
    assert _recorded(out).equals(before)


def test_resume_refuses_a_run_that_already_ran_and_a_folder_that_is_not_a_path(tmp_path):
    """`run.resume(DIR)` after `run.execute()` cut the finished run's files back to the
    checkpoint; `resume(None)` was a TypeError from pathlib."""
    program, out = _checkpointed(tmp_path)
    run = _quiet(Run(program, seed=2, steps=6, out=out, backend="numpy"))
    run.execute()
    before = _recorded(out)
    with pytest.raises(SwarmOptionError, match="already run"):
        run.resume(out)
    assert _recorded(out).equals(before)
    for folder in (None, 3):
        with pytest.raises(SwarmOptionError, match="folder"):
            Run(program, seed=2, steps=10, out=out).resume(folder)


@pytest.mark.parametrize("every, out, named", [
    ("2", "run", "checkpoint_every must be a whole number"),
    (-1, "run", "checkpoint_every must be from 0"),
    (2, None, "checkpoint_every needs a Run with out"),
])
def test_a_bad_checkpoint_every_is_refused_before_the_run(tmp_path, every, out, named):
    """`run.checkpoint_every = "2"` ran a tick and stopped with an internal error; with
    no `out` the run went on and wrote no checkpoint. Both are refused before a tick."""
    program = swarmdsl.load_program(PROGRAMS / "vicsek.swarm", {"n": 20})
    run = Run(program, steps=4, out=out and tmp_path / out, backend="numpy")
    run.checkpoint_every = every
    with pytest.raises(SwarmOptionError, match=named):
        run.execute()
    assert run.sim.tick == 0
