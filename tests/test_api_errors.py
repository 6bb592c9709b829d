"""Every failure of the Python API on bad input is a documented SwarmError subclass."""

from __future__ import annotations

import importlib
import pkgutil
from pathlib import Path

import numpy as np
import pytest
from conftest import PROGRAMS, shipped

import swarmdsl
from swarmdsl import SwarmError, SwarmOptionError, load_program, viz
from swarmdsl.runtime.nn import ModelError, load_model, read_model_info, resolve_model_path
from swarmdsl.runtime.runner import Run
from swarmdsl.runtime.simulation import Simulation

DOC = Path(__file__).parent.parent / "docs" / "api.md"


@pytest.fixture
def program(tmp_path):
    path = tmp_path / "ok.swarm"
    path.write_text("param n = 3 in 1 .. 10\nagent a { count n; status s { } }\n")
    return load_program(path)


def test_a_good_program_still_runs(backend, program):
    run = Run(program, seed=np.int64(3), steps=np.int32(2))
    assert run.execute(headless=True) == "completed"


@pytest.mark.parametrize("call", [
    lambda p, d: load_program(None),
    lambda p, d: load_program(7),
    lambda p, d: load_program("a\0b.swarm"),
    lambda p, d: load_program(d),
    lambda p, d: load_program(d / "missing.swarm"),
    lambda p, d: load_program(d / "ok.swarm", [("n", 3)]),
    lambda p, d: load_program(d / "ok.swarm", {"n": [3]}),
    lambda p, d: load_program(d / "ok.swarm", {"n": 99}),
    lambda p, d: load_program(d / "ok.swarm", {"n": float("nan")}),
    lambda p, d: load_program(d / "ok.swarm", {"zz": 1}),
    lambda p, d: Run(None),
    lambda p, d: Run(p, seed=-1),
    lambda p, d: Run(p, seed=1.5),
    lambda p, d: Run(p, seed="1"),
    lambda p, d: Run(p, steps=-1),
    lambda p, d: Run(p, steps="100"),
    lambda p, d: Run(p, every=0),
    lambda p, d: Run(p, out=d / "ok.swarm" / "x"),
    lambda p, d: Run(p, out=3),
    lambda p, d: Run(p, record=d / "x.txt"),
    lambda p, d: Run(p, video_px=10**9),
    lambda p, d: resolve_model_path(None, d),
    lambda p, d: resolve_model_path("a\0.pt", d),
    lambda p, d: resolve_model_path("m.pt", None),
    lambda p, d: resolve_model_path("/etc/passwd", d),
    lambda p, d: read_model_info(None),
    lambda p, d: load_model(d / "missing.pt"),
    lambda p, d: load_model(3.5),
], ids=lambda c: str(c.__code__.co_firstlineno))
def test_bad_input_raises_a_swarm_error(program, tmp_path, call):
    with pytest.raises(SwarmError) as err:
        call(program, tmp_path)
    assert type(err.value).__name__ in DOC.read_text()


def test_overrides_take_numpy_scalars(tmp_path):
    # A notebook's `for n in np.arange(...)` gave np.int64, refused as "expected a
    # number ... got int64"; np.float32 and np.bool_ were refused likewise.
    path = tmp_path / "p.swarm"
    path.write_text("param n = 3 in 1 .. 10\nparam r = 1.5\nparam flag = true\n"
                    "agent a { count n; status s { } }\n")
    prog = load_program(path, {"n": np.int64(4), "r": np.float32(2.5), "flag": np.bool_(False)})
    assert (prog.params["n"], prog.params["r"], prog.params["flag"]) == (4, 2.5, False)


@pytest.mark.parametrize("overrides, message", [
    ({"r": float("nan")}, "overrides['r'] = nan: `nan` is not a number"),
    ({"n": 11}, "overrides['n'] = 11: outside the declared range 1..10"),
    ({"flag": 2}, "overrides['flag'] = 2: `flag` is a boolean; use true or false"),
    ({"nosuch": 1}, "overrides['nosuch'] = 1: the program has no param `nosuch`"),
])
def test_a_bad_override_names_overrides_not_the_command_line(tmp_path, overrides,
                                                              message):
    """`load_program`'s caller gave no `--set`: the message names what they wrote."""
    path = tmp_path / "p.swarm"
    path.write_text("param n = 3 in 1 .. 10\nparam r = 1.5\nparam flag = true\n"
                    "agent a { count n; status s { } }\n")
    with pytest.raises(SwarmOptionError) as err:
        load_program(path, overrides)
    assert str(err.value).startswith(f"error: {message}"), str(err.value)
    assert "--set" not in str(err.value)


def test_a_second_execute_is_refused_and_keeps_the_first_runs_outputs(backend, program, tmp_path):
    # Calling execute() again (a notebook cell run twice) cleared the finished run's
    # agents.parquet and left run.json saying "running", and returned "completed".
    import json

    import pyarrow.parquet as pq

    run = Run(program, seed=1, steps=3, out=tmp_path / "out")
    assert run.execute(headless=True) == "completed"
    with pytest.raises(SwarmOptionError, match="already run"):
        run.execute(headless=True)
    assert json.loads((tmp_path / "out" / "run.json").read_text())["finished"] == "completed"
    assert pq.read_table(tmp_path / "out" / "agents.parquet").num_rows == 4 * 3


@pytest.mark.parametrize(("call", "named"), [
    (lambda p: Simulation(p, None), "seed"),
    (lambda p: Simulation(p, -1), "seed"),
    (lambda p: Simulation(p, 2**64), "seed"),
    (lambda p: Simulation(p, 1.5), "seed"),
    (lambda p: Simulation(p, "3"), "seed"),
    (lambda p: Simulation(None, 1), "compiled program"),
    (lambda p: Simulation("programs/boids.swarm", 1), "compiled program"),
    (lambda p: Simulation(p, 1).run(None), "steps"),
    (lambda p: Simulation(p, 1).run(2.5), "steps"),
    (lambda p: Simulation(p, 1).run(-1), "steps"),
])
def test_simulation_checks_its_arguments_as_run_does(backend, program, call, named):
    # Simulation(program, None) was a TypeError, Simulation(None, 1) an AttributeError,
    # and a seed of -1, 1.5 or "3" was taken silently (Run refuses each).
    with pytest.raises(SwarmOptionError, match=named):
        call(program)


def test_simulation_takes_numpy_whole_numbers(backend, program):
    sim = Simulation(program, np.uint32(4))
    sim.run(np.int64(2))
    assert sim.seed == 4 and sim.tick == 2


@pytest.mark.parametrize("call, cls", [
    (lambda: __import__("swarmdsl.train.fit", fromlist=["x"]).TrainConfig.for_task("nope"),
     SwarmOptionError),
    (lambda: __import__("swarmdsl.train.fit", fromlist=["x"]).TrainConfig.for_task(
        "spring1d", zz=1), SwarmOptionError),
    (lambda: __import__("swarmdsl.train.fit", fromlist=["x"]).TrainConfig.for_task(
        "spring1d", epochs="10"), SwarmOptionError),
    (lambda: __import__("swarmdsl.train.fit", fromlist=["x"]).TrainConfig.for_task(
        "spring1d", hidden=[10**7]), SwarmOptionError),
    (lambda: __import__("swarmdsl.train.fit", fromlist=["x"]).TrainConfig.for_task(
        "spring1d", sampling=3), SwarmOptionError),
    (lambda: __import__("swarmdsl.train.fit", fromlist=["x"]).TrainConfig.for_task(
        "spring1d", lr=float("inf")), SwarmOptionError),
])
def test_training_settings_are_checked(call, cls):
    with pytest.raises(cls):
        call()


def test_model_errors_are_swarm_errors():
    assert issubclass(ModelError, SwarmError)


def test_every_swarm_error_class_is_documented():
    """A new error class must be listed in docs/api.md with what raises it."""
    for mod in pkgutil.walk_packages(swarmdsl.__path__, "swarmdsl."):
        if mod.name.split(".")[1] in ("viz", "testing", "__main__"):
            continue  # optional extras, loaded lazily; their errors derive from these
        importlib.import_module(mod.name)
    doc = DOC.read_text()
    seen, todo = set(), [SwarmError]
    while todo:
        cls = todo.pop()
        for sub in cls.__subclasses__():
            if sub not in seen and sub.__module__.startswith("swarmdsl"):
                seen.add(sub)
                todo.append(sub)
    assert len(seen) >= 6  # syntax, check, runtime, option, model, containment
    missing = sorted(c.__name__ for c in seen if f"`{c.__name__}`" not in doc and
                     f".{c.__name__}`" not in doc)
    assert not missing, f"undocumented SwarmError subclasses: {missing}"


def test_train_checks_a_config_built_by_hand():
    pytest.importorskip("torch")
    from swarmdsl.train.fit import TrainConfig, train

    config = TrainConfig.for_task("spring1d")
    config.epochs = -3
    with pytest.raises(SwarmOptionError, match="epochs"):
        train(config)
    config.task = "nope"
    with pytest.raises(SwarmOptionError, match="known task"):
        train(config)


@pytest.mark.parametrize("call, named", [
    (lambda sim: sim.rng.set_state({}), "state must be what rng.state"),
    (lambda sim: sim.rng.set_state(None), "state must be what rng.state"),
    (lambda sim: sim.run(2, on_tick=5), "on_tick"),
    (lambda sim: Simulation(sim.program, 0, work="lots"), "work"),
])
def test_a_bad_simulation_argument_is_an_option_error_and_changes_nothing(call, named):
    """`rng.set_state({})` was a KeyError, `run(2, on_tick=5)` a TypeError after the
    first tick had run, `work="lots"` a TypeError from the backend choice."""
    sim = shipped("boids.swarm")
    before = sim.rng.state()
    with pytest.raises(SwarmOptionError, match=named):
        call(sim)
    assert sim.tick == 0 and sim.rng.state() == before


def test_pickling_a_simulation_says_what_to_send_and_a_deep_copy_still_forks_it(backend):
    """Sending a Simulation or Run to a process pool failed inside pickle with
    "Can't pickle local object 'CodeGen.status_body.<locals>.run'"; the error now says
    to send the path and overrides. `copy.deepcopy` and `copy.copy` fork it: a fork
    runs on as the original would, sharing no state with it."""
    import copy
    import pickle

    sim = shipped("boids.swarm")
    for obj in (sim, Run(sim.program, steps=1)):
        with pytest.raises(SwarmOptionError, match="load_program"):
            pickle.dumps(obj)
    sim.run(2)
    forks = [copy.deepcopy(sim), copy.copy(sim)]
    for fork in forks:
        fork.run(2)
    sim.run(2)
    assert all(np.array_equal(f.snapshot().pos, sim.snapshot().pos) for f in forks)


@pytest.mark.parametrize("drive", [
    lambda run: run.step(),
    lambda run: viz.run_viewer(run, fps=1000),
])
def test_stepping_a_run_outside_execute_is_refused(tmp_path, drive):
    """`run_viewer(run)` (a Run has the driver's step/snapshot/tick/done) or `run.step()`
    ran the ticks with the outputs never opened: the folder got a stray fields.npy/ and
    no run.json or rows. Now it is refused, pointing to execute(headless=False)."""
    program = swarmdsl.load_program(PROGRAMS / "boids.swarm", {"n": 3})
    run = Run(program, steps=3, out=tmp_path / "run")
    with pytest.raises(SwarmOptionError, match="execute"):
        drive(run)
    assert run.tick == 0 and not (tmp_path / "run").exists()


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
