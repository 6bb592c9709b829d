"""The one tick loop (`runtime/driver.py`): every caller that advances a simulation (a
`Run`, a `Batch`, `swarmdsl test`'s runs, the studio, `Simulation.run`) faults, stops
and closes the same way, at the same tick; work between ticks (the tiered start's
backend switch) and the studio's mid-run param change carry the run's state as a
checkpoint does."""

from __future__ import annotations

import json
import signal

import numpy as np
import pyarrow.parquet as pq
import pytest
from conftest import assert_same_outputs

from swarmdsl import stopping
from swarmdsl.compiler import compile_file, compile_source
from swarmdsl.runtime import checkpoint
from swarmdsl.runtime.batch_runner import Batch
from swarmdsl.runtime.driver import Driver
from swarmdsl.runtime.runner import Run
from swarmdsl.runtime.simulation import Simulation
from swarmdsl.studio.session import Session
from swarmdsl.testing.runner import run_program

# `velocity` becomes infinite while the 5th tick is computed: the run stops at tick 4
FAULTS = """agent a {
  count 3
  var t = 0
  status s {
    t += 1
    velocity = (1 / (5 - t), 0)
  }
}
"""


def _recorded(out) -> list[int]:
    return sorted(set(pq.read_table(out / "agents.parquet")["tick"].to_pylist()))


def test_every_caller_stops_at_a_fault_at_the_same_tick_with_the_same_message(backend,
                                                                             tmp_path):
    path = tmp_path / "fault.swarm"
    path.write_text(FAULTS)
    program = compile_file(path)
    with pytest.raises(Exception) as raised:
        Simulation(program, 0, backend=backend).run(10)
    message = str(raised.value)
    assert "`velocity` became infinite" in message

    run = Run(program, steps=10, out=tmp_path / "run", backend=backend)
    run.show_progress = False
    assert run.execute() == "fault"
    assert str(run.fault) == message and run.sim.tick == 4
    assert _recorded(tmp_path / "run") == [0, 1, 2, 3, 4]
    assert json.loads((tmp_path / "run" / "run.json").read_text())["finished"] == "fault"

    checked = run_program(program, 10)
    assert str(checked.fault) == message
    assert checked.ticks == 4 and checked.fault_tick == 5    # the tick being computed

    results = Batch(program, [0, 1], steps=10, out=tmp_path / "batch",
                    backend=backend).execute()
    assert [(r.outcome, r.ticks, str(r.error)) for r in results] == [
        ("fault", 4, message)] * 2
    assert _recorded(tmp_path / "batch" / "seed-1") == [0, 1, 2, 3, 4]

    session = Session(path, backend=backend)
    session.step(10)
    assert session.sim.tick == 4 and session.fault.startswith(message)
    assert not session.playing


def _stop_at(monkeypatch, tick: int) -> None:
    """SIGTERM arrives as tick `tick` is about to start (as `stopping` raises it)."""
    real = Simulation.step

    def step(sim):
        if sim.tick == tick:
            raise stopping.Stopped(signal.SIGTERM)
        real(sim)
    monkeypatch.setattr(Simulation, "step", step)


def test_every_caller_stops_at_a_signal_with_its_outputs_whole(backend, walk, tmp_path,
                                                               monkeypatch):
    program = compile_file(walk)
    _stop_at(monkeypatch, 5)
    run = Run(program, steps=12, every=2, out=tmp_path / "run", backend=backend)
    run.show_progress = False
    assert run.execute() == "interrupted"
    info = json.loads((tmp_path / "run" / "run.json").read_text())
    assert info["finished"] == "interrupted" and info["signal"] == "SIGTERM"
    assert _recorded(tmp_path / "run") == [0, 2, 4, 5]     # the stop tick, off the grid

    results = Batch(program, [0, 1], steps=12, every=2, out=tmp_path / "batch",
                    backend=backend).execute()
    assert [(r.outcome, r.ticks) for r in results] == [("interrupted", 5)] * 2
    for seed in (0, 1):
        folder = tmp_path / "batch" / f"seed-{seed}"
        assert json.loads((folder / "run.json").read_text())["signal"] == "SIGTERM"
        assert _recorded(folder) == [0, 2, 4, 5]

    with pytest.raises(stopping.Stopped):
        run_program(program, 12)
    with pytest.raises(stopping.Stopped):
        Simulation(program, 0, backend=backend).run(12)


class Watcher:
    """An observer noting what it was told."""

    def __init__(self):
        self.events = []

    def start(self, run):
        self.events.append("start")

    def tick(self, run):
        self.events.append(run.sim.tick)

    def close(self, run, outcome):
        self.events.append(outcome)


@pytest.mark.parametrize("ending", ["completed", "fault", "interrupted"])
def test_a_run_closes_its_observers_once_whatever_ends_it(backend, tmp_path, monkeypatch,
                                                          ending):
    path = tmp_path / "fault.swarm"
    path.write_text(FAULTS if ending == "fault" else FAULTS.replace("5 - t", "50 - t"))
    if ending == "interrupted":
        _stop_at(monkeypatch, 3)
    run = Run(compile_file(path), steps=6, every=2, backend=backend)
    run.show_progress = False
    watcher = Watcher()
    run.attach(watcher)
    assert run.execute() == ending
    ticks = {"completed": [0, 2, 4, 6], "fault": [0, 2, 4], "interrupted": [0, 2, 3]}
    assert watcher.events == ["start", *ticks[ending], ending]


def test_between_ticks_hooks_run_at_every_tick_boundary(walk):
    sim = Simulation(compile_file(walk), 0, backend="numpy")
    driver = Driver(sim, 4)
    seen = []
    driver.between_ticks.append(lambda d: seen.append(d.tick))
    driver.run()
    assert seen == [0, 1, 2, 3] and sim.tick == 4


def test_a_switch_between_ticks_continues_the_run_bit_for_bit(backend, walk, tmp_path):
    """What the tiered start does at a tick boundary: a new simulation (here on the
    same backend, built fresh) given the run's state by `checkpoint.carry`, then
    `Driver.switch`; the recorded run is the run never switched."""
    program = compile_file(walk)
    whole = Run(program, seed=2, steps=12, out=tmp_path / "whole", backend=backend)
    whole.show_progress = False
    assert whole.execute() == "completed"

    switched = Run(program, seed=2, steps=12, out=tmp_path / "switched", backend=backend)
    switched.show_progress = False

    def switch_at_7(driver):
        if driver.tick == 7:
            fresh = Simulation(program, 2, backend=backend)
            driver.switch(checkpoint.carry(driver.sim, fresh))
    switched.driver.between_ticks.append(switch_at_7)
    old = switched.sim
    assert switched.execute() == "completed"
    assert switched.sim is not old
    assert_same_outputs(tmp_path / "whole", tmp_path / "switched")


def test_a_switch_to_a_simulation_at_another_tick_is_refused(walk):
    program = compile_file(walk)
    driver = Driver(Simulation(program, 0, backend="numpy"))
    driver.run(3)
    with pytest.raises(ValueError, match="tick 3"):
        driver.switch(Simulation(program, 0, backend="numpy"))


def test_a_studio_param_change_mid_run_equals_a_checkpoint_resume_with_that_param(
        backend, walk, tmp_path):
    """The studio carries the run into the new program as a checkpoint saved at the
    change and loaded into a run with the new value does (`checkpoint.carry`)."""
    session = Session(walk, seed=1, backend=backend)
    session.step(7)
    assert session.set_param("pace", 2) == {"reset": False}
    session.step(5)

    text = walk.read_text()
    before = Simulation(compile_source(text, str(walk)), 1, backend=backend)
    before.run(7)
    folder = checkpoint.save(before, tmp_path / "checkpoint")
    after = Simulation(compile_source(text, str(walk), {"pace": "2"}), 1, backend=backend)
    meta = json.loads((folder / "meta.json").read_text())
    with np.load(folder / "state.npz") as data:
        checkpoint.put(after, {k: data[k] for k in data.files}, meta, "test")
    after.run(5)

    assert session.sim.tick == after.tick == 12
    assert session.sim.agents.cols.keys() == after.agents.cols.keys()
    for name, col in after.agents.cols.items():
        np.testing.assert_array_equal(session.sim.agents.cols[name], col, err_msg=name)
    assert session.sim.rng.state() == after.rng.state()
    np.testing.assert_array_equal(session.sim.environment.fields["scent"].values,
                                  after.environment.fields["scent"].values)


def test_a_switch_to_another_backend_between_ticks_changes_no_bit(other_backend, walk,
                                                                   tmp_path):
    """The tiered start's move: a run begun on the reference backend goes on, from a
    tick boundary, on another; its outputs are the run's on either backend alone."""
    program = compile_file(walk)
    whole = Run(program, seed=3, steps=12, out=tmp_path / "whole", backend="numpy")
    whole.show_progress = False
    assert whole.execute() == "completed"
    tiered = Run(program, seed=3, steps=12, out=tmp_path / "tiered", backend="numpy")
    tiered.show_progress = False

    def switch_at_4(driver):
        if driver.tick == 4:
            fresh = Simulation(program, 3, backend=other_backend)
            driver.switch(checkpoint.carry(driver.sim, fresh))
    tiered.driver.between_ticks.append(switch_at_4)
    assert tiered.execute() == "completed"
    assert tiered.sim.backend.name == other_backend
    assert json.loads((tmp_path / "tiered" / "run.json").read_text())["backend"] == \
        other_backend
    assert_same_outputs(tmp_path / "whole", tmp_path / "tiered")


class _Clock:
    now = 0.0

    def __call__(self):
        return self.now


class _PacedSim:
    """A simulation whose ticks take `step_s` one by one and `whole_s` each when run
    whole, on a clock the test owns: what the driver chooses is then certain."""

    def __init__(self, clock, step_s, whole_s):
        self.clock, self.step_s, self.whole_s = clock, step_s, whole_s
        self.tick, self.calls = 0, []
        self.backend = type("B", (), {"compile_seconds": 0.0,
                                      "whole_ticks_ready": lambda _s, _sim, _left: True})()
        self.program = None

    def step(self):
        self.clock.now += self.step_s
        self.tick += 1
        self.calls.append(1)

    def advance(self, k):
        self.clock.now += self.whole_s * k
        self.tick += k
        self.calls.append(k)
        return k


@pytest.mark.parametrize("whole_s, keeps_whole", [(0.001, True), (0.02, False)])
def test_ticks_run_whole_only_after_a_stepped_tick_and_while_they_are_faster(
        monkeypatch, whole_s, keeps_whole):
    """A large swarm's per-tick kernels use threads and beat the one serial whole-tick
    loop (Vicsek at 10^6 agents: 0.6 s a tick stepped, 3.6 s whole): the driver times a
    stepped tick before it hands over any chunk, sizes chunks by it, and goes back to
    stepping for good once whole ticks proved slower."""
    from swarmdsl.runtime import driver as driver_module

    clock = _Clock()
    monkeypatch.setattr(driver_module.time, "perf_counter", clock)
    sim = _PacedSim(clock, step_s=0.01, whole_s=whole_s)
    d = Driver(sim, steps=200, every=None, stops=False)
    d.run()
    assert sim.tick == 200
    assert sim.calls[0] == 1                 # timed one by one first
    assert sim.calls[1] == 5                 # chunks of CHUNK_SECONDS at the stepped pace
    if keeps_whole:
        assert all(k > 1 for k in sim.calls[1:-1])
    else:
        assert set(sim.calls[2:]) == {1}     # one slower chunk, then stepped to the end


def test_a_checkpoint_every_k_ticks_cuts_whole_ticks_at_its_own_ticks_only(monkeypatch):
    """A checkpoint every K ticks needs the state at multiples of K (and the last
    tick): whole ticks run up to each, where any other after-tick callback makes every
    tick its own."""
    from swarmdsl.runtime import driver as driver_module
    from swarmdsl.runtime.driver import Scheduled

    clock = _Clock()
    monkeypatch.setattr(driver_module.time, "perf_counter", clock)
    seen = []
    sim = _PacedSim(clock, step_s=0.01, whole_s=0.001)
    d = Driver(sim, steps=23, every=None, stops=False)
    d.after_tick.append(Scheduled(lambda drv: seen.append(drv.sim.tick), lambda: 10))
    d.run()
    assert sim.tick == 23 and sim.calls == [1, 5, 4, 10, 3]   # ends at 10, 20, 23
    assert {10, 20, 23} <= set(seen)
    sim = _PacedSim(clock, step_s=0.01, whole_s=0.001)
    d = Driver(sim, steps=6, every=None, stops=False)
    d.after_tick.append(lambda drv: None)
    d.run()
    assert sim.calls == [1] * 6
