"""What a researcher trying the Python API and the viewer from a notebook or script runs
into: arguments of the wrong type, objects shared or mutated, runs side by side."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

import swarmdsl
from swarmdsl import SwarmOptionError, viz
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


def test_resuming_without_the_runs_tree_columns_names_the_option(tmp_path):
    """A checkpoint of a `tree_leaf=True` run resumed by a Run without it was refused
    as "the checkpoint's agent columns differ from this program's", though the program
    was the same; now the message names tree_leaf and the value to give."""
    program = swarmdsl.load_program(PROGRAMS / "patrol.swarm")
    out = tmp_path / "run"
    run = _quiet(Run(program, seed=1, steps=4, out=out, backend="numpy", tree_leaf=True))
    run.checkpoint_every = 2
    run.execute()
    with pytest.raises(SwarmOptionError, match="build the Run with tree_leaf=True"):
        Run(program, seed=1, steps=8, out=out, backend="numpy").resume(out)


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


def _tiny_snapshot():
    return _sim("boids.swarm").snapshot()


def _render(options):
    return viz.FrameRenderer(64, 64).render(_tiny_snapshot(), options)


def _options(**settings):
    return viz.RenderOptions(**settings)


def _record(path, frame=None, fps=30):
    with viz.VideoWriter(path, fps=fps) as video:
        video.add(np.zeros((32, 32, 3), np.uint8) if frame is None else frame)
    return video


def _add_after_close(path):
    _record(path).add(np.zeros((32, 32, 3), np.uint8))


class _Driver:
    """The viewer's driver protocol over a simulation, done after two ticks."""

    def __init__(self):
        self.sim = _sim("boids.swarm")
        self.step, self.snapshot = self.sim.step, self.sim.snapshot

    tick = property(lambda self: self.sim.tick)
    done = property(lambda self: self.sim.tick >= 2)


def _viewer(**settings):
    return viz.run_viewer(_Driver(), **settings)


@pytest.mark.parametrize("call, named", [
    (lambda tmp: _render({"show_links": True}), "options must be a RenderOptions"),
    (lambda tmp: _render(_options(colormap=None)), "RenderOptions.colormap"),
    (lambda tmp: _render(_options(field=3)), "RenderOptions.field"),
    (lambda tmp: _render(_options(field_alpha=float("nan"))), "RenderOptions.field_alpha"),
    (lambda tmp: _render(_options(splat_above="10")), "RenderOptions.splat_above"),
    (lambda tmp: _render(_options(marker_px=-4)), "RenderOptions.marker_px"),
    (lambda tmp: _render(_options(hud_text=5)), "RenderOptions.hud_text"),
    (lambda tmp: viz.FrameRenderer(64, 64).render({}),
     "draws a Snapshot"),
    (lambda tmp: viz.FrameRenderer(64, 64, font_px="big"),
     "font_px"),
    (lambda tmp: viz.fit_size((600, 600), "640"), "max_px"),
    (lambda tmp: viz.fit_size("600x600", 640), "world size"),
    (lambda tmp: viz.fit_size((600, 600), 640, multiple=0), "multiple"),
    (lambda tmp: _record(None), "--record"),
    (lambda tmp: _record(tmp / "a.gif", fps="30"), "frames per second"),
    (lambda tmp: _record(tmp / "a.gif", frame=np.zeros((32, 32, 3))), "uint8"),
    (lambda tmp: _record(tmp / "a.gif", frame=np.zeros((0, 5, 3), np.uint8)), "uint8"),
    (lambda tmp: _add_after_close(tmp / "a.gif"), "closed"),
    (lambda tmp: _viewer(fps="30"), "--fps"),
    (lambda tmp: _viewer(options={"show_links": True}), "options"),
    (lambda tmp: _viewer(ticks_per_frame=float("nan")), "ticks_per_frame"),
    (lambda tmp: _viewer(title=None), "title"),
    (lambda tmp: _viewer(recorder=object()), "recorder"),
    (lambda tmp: viz.run_viewer(_sim("boids.swarm")), "driver needs"),
])
def test_a_bad_viz_argument_is_an_option_error_naming_it(tmp_path, call, named):
    """Each of these was a TypeError, ValueError, AttributeError or pygame error from
    inside a layer, a NaN field_alpha a garbage heatmap, and a closed or refused frame a
    bare ValueError; now a SwarmOptionError names the argument."""
    with pytest.raises(SwarmOptionError, match=named):
        call(tmp_path)


def test_a_video_under_a_file_is_refused_before_the_first_frame(tmp_path):
    """`VideoWriter("notes.txt/run.gif")` was accepted, and every frame was then lost
    with only `complete` False to say so; it is refused when the writer is made."""
    (tmp_path / "notes.txt").write_text("")
    with pytest.raises(SwarmOptionError, match="a file, not a folder"):
        viz.VideoWriter(tmp_path / "notes.txt" / "run.gif")


def test_outputs_go_where_they_were_named_when_the_run_was_made(tmp_path, monkeypatch):
    """A notebook's `%cd` between `Run(out="runs/a", record="a.gif")` and `execute()`
    left an empty runs/a in the first folder and wrote the run and its video in the
    second; both now go where the Run was made, as they were checked there."""
    first, second = tmp_path / "first", tmp_path / "second"
    first.mkdir()
    second.mkdir()
    monkeypatch.chdir(first)
    program = swarmdsl.load_program(PROGRAMS / "boids.swarm", {"n": 3})
    run = _quiet(Run(program, steps=2, out="runs/a", record="a.gif", video_px=32,
                     backend="numpy"))
    monkeypatch.chdir(second)
    assert run.execute() == "completed"
    assert (first / "runs" / "a" / "run.json").is_file()
    assert (first / "a.gif").is_file()
    assert not any(second.iterdir())


def test_a_layout_of_numpy_ids_saves_as_json():
    """A layout built from numpy arrays (ids from `np.arange`, accepted as documented)
    gave a `to_json()` that `json.dumps` refused: "int64 is not JSON serializable"."""
    import json

    from swarmdsl.runtime.layout import AgentSpec, Layout

    agents = tuple(AgentSpec("boid", i, pos=(np.float64(5), 5.0), index=np.int32(i))
                   for i in np.arange(2, dtype=np.int64))
    layout = Layout(agents, ("boid",))
    assert Layout.from_json(json.loads(json.dumps(layout.to_json()))) == layout


@pytest.mark.parametrize("folder", [None, 3, "missing"])
def test_open_fields_of_no_run_folder_is_an_option_error(tmp_path, folder):
    """`open_fields(None)` was a TypeError and a folder without a run a bare
    FileNotFoundError; both are option errors naming run_dir."""
    from swarmdsl.runtime.spool import open_fields

    with pytest.raises(SwarmOptionError, match="run_dir"):
        open_fields(tmp_path / folder if isinstance(folder, str) else folder)


@pytest.mark.parametrize("call, named", [
    (lambda sim: sim.rng.set_state({}), "state must be what rng.state"),
    (lambda sim: sim.rng.set_state(None), "state must be what rng.state"),
    (lambda sim: sim.run(2, on_tick=5), "on_tick"),
    (lambda sim: Simulation(sim.program, 0, work="lots"), "work"),
])
def test_a_bad_simulation_argument_is_an_option_error_and_changes_nothing(call, named):
    """`rng.set_state({})` was a KeyError, `run(2, on_tick=5)` a TypeError after the
    first tick had run, `work="lots"` a TypeError from the backend choice."""
    sim = _sim("boids.swarm")
    before = sim.rng.state()
    with pytest.raises(SwarmOptionError, match=named):
        call(sim)
    assert sim.tick == 0 and sim.rng.state() == before


def test_pickling_a_simulation_says_what_to_send_and_a_deep_copy_still_forks_it():
    """Sending a Simulation or Run to a process pool failed inside pickle with
    "Can't pickle local object 'CodeGen.status_body.<locals>.run'"; the error now says
    to send the path and overrides. `copy.deepcopy` and `copy.copy` fork it: a fork
    runs on as the original would, sharing no state with it."""
    import copy
    import pickle

    sim = _sim("boids.swarm")
    for obj in (sim, Run(sim.program, steps=1)):
        with pytest.raises(SwarmOptionError, match="load_program"):
            pickle.dumps(obj)
    sim.run(2)
    forks = [copy.deepcopy(sim), copy.copy(sim)]
    for fork in forks:
        fork.run(2)
    sim.run(2)
    assert all(np.array_equal(f.snapshot().pos, sim.snapshot().pos) for f in forks)


def test_making_a_run_creates_no_folder_until_it_executes(tmp_path):
    """`Run(program, out="runs/a")` made runs/a at once, so a Run built only to look
    at (or refused later) left an empty folder; it is made when the run begins, as
    the outputs doc says ("created when the output is written")."""
    program = swarmdsl.load_program(PROGRAMS / "boids.swarm", {"n": 3})
    run = _quiet(Run(program, steps=1, out=tmp_path / "runs" / "a", backend="numpy"))
    assert not (tmp_path / "runs").exists()
    assert run.execute() == "completed"
    assert (tmp_path / "runs" / "a" / "run.json").is_file()


@pytest.mark.parametrize("drive", [
    lambda run: run.step(),
    lambda run: viz.run_viewer(run, fps=1000),
])
def test_stepping_a_run_outside_execute_is_refused(tmp_path, drive):
    """`run_viewer(run)` (a Run has the driver's step/snapshot/tick/done) or `run.step()`
    ran the ticks with the outputs never opened: the folder got a stray fields.npy/ and
    no run.json or rows. Now it is refused, pointing to execute(headless=False)."""
    program = swarmdsl.load_program(PROGRAMS / "boids.swarm", {"n": 3})
    run = Run(program, steps=3, out=tmp_path / "run", backend="numpy")
    with pytest.raises(SwarmOptionError, match="execute"):
        drive(run)
    assert run.tick == 0 and not (tmp_path / "run").exists()


@pytest.mark.parametrize("bad", [
    dict(regions=[{"shape": "circle", "name": "nest"}]),
    dict(regions={"nest": 1}),
    dict(vectors={"wind": np.ones((11, 11))}),
    dict(grid_points=np.ones(5)),
])
def test_a_hand_built_snapshot_the_layers_cannot_draw_is_a_swarm_error(bad):
    """A snapshot built by hand (from a recorded run, say) with a circle without its
    centre, regions not a list, a vector field without its components or grid points
    not (P, 2) failed with a KeyError, AttributeError or numpy ValueError."""
    from dataclasses import replace

    snap = replace(_sim("aco.swarm").snapshot(), **bad)
    options = viz.RenderOptions(show_grid_points=True)
    with pytest.raises(swarmdsl.SwarmError, match="snapshot|run.json"):
        viz.FrameRenderer(64, 64).render(snap, options)


@pytest.mark.parametrize("overrides, said", [
    ({"n=3": 5}, "overrides['n=3'] = 5: the program has no param `n=3`"),
    ({" n": 5}, "overrides[' n'] = 5: the program has no param ` n`"),
    ({"n": "5: x"}, "overrides['n'] = '5: x': `5: x` is not a number"),
])
def test_an_odd_override_is_named_as_given(overrides, said):
    """An override whose name or value holds `=`, `:` or a space was reported as the
    command line's `--set n=3: ...`, or with its value cut at the colon."""
    with pytest.raises(SwarmOptionError) as err:
        swarmdsl.load_program(PROGRAMS / "boids.swarm", overrides)
    assert str(err.value).startswith(f"error: {said}")


def test_a_run_without_steps_runs_the_programs_own_length():
    """`Run(program)` ran 100 ticks whatever the program's `world { steps N }` said,
    while `swarmdsl run` of the same file ran N."""
    program = swarmdsl.load_program(PROGRAMS / "aco.swarm")
    assert Run(program).steps == program.world.steps == 6000
    assert Run(program, steps=7).steps == 7
