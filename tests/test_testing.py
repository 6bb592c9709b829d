"""The Python testing API: strategies, perturbations and the SwarmMachine state machine."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st
from hypothesis.stateful import run_state_machine_as_test

from swarmdsl.testing import (
    MoveAgents,
    RemoveAgents,
    SetVariable,
    SwarmMachine,
    load,
    param_axes,
    params,
    perturbations,
    placements,
    load_example,
    run_program,
    search,
)

FLOCK = """
param n = 8 in 2..12
param gap = 1.5 in 0.5..3
param cruise = 1
world { size 40 x 40; edges wrap }
agent bot {
  count n
  velocity random_direction() * cruise
  max_speed cruise
  var energy = 10
  status moving { energy -= 0.01 }
  invariant charged: energy > 0
}
invariant enough: count() >= 2
"""

# CI: find, do not shrink (shrinking a state machine takes hundreds of runs; the slow
# test below does it).
QUICK = settings(max_examples=15, deadline=None, suppress_health_check=list(HealthCheck),
                 stateful_step_count=8, phases=(Phase.generate,), database=None)


def test_param_axes_know_sizes_ranges_and_defaults():
    axes = {a.name: a for a in param_axes(load(FLOCK))}
    assert axes["n"].size and axes["n"].integer and (axes["n"].lo, axes["n"].hi) == (2, 12)
    assert not axes["gap"].size and not axes["gap"].integer
    assert not axes["cruise"].drawn


@settings(max_examples=30, deadline=None)
@given(st.data())
def test_params_draw_inside_their_ranges(data):
    drawn = data.draw(params(load(FLOCK)))
    assert list(drawn) == ["n", "gap"]          # size params first
    assert 2 <= drawn["n"] <= 12 and isinstance(drawn["n"], int)
    assert 0.5 <= drawn["gap"] <= 3
    prog = load(FLOCK, drawn)
    assert prog.kinds[0].count == drawn["n"]


@settings(max_examples=10, deadline=None)
@given(st.data())
def test_placements_replace_initial_positions(backend, data):
    prog = load(FLOCK)
    pos = data.draw(placements(prog))
    assert pos.shape == (8, 2) and (pos >= 0).all() and (pos < 40).all()
    res = run_program(prog, 0, positions=pos)
    assert np.array_equal(res.state["pos"], pos)


def test_perturbations_apply_to_a_simulation(backend):
    from swarmdsl.runtime.simulation import Simulation

    sim = Simulation(load(FLOCK), 0)
    assert list(RemoveAgents((1, 9)).apply(sim)) == [1]     # 9 % 8 == 1: one agent
    assert sim.agents.n == 7 and 1 not in sim.agents.cols["id"]
    before = sim.agents.cols["pos"][0].copy()
    MoveAgents((0,), ((1.0, -2.0),)).apply(sim)
    assert np.allclose(sim.agents.cols["pos"][0], before + (1.0, -2.0))
    SetVariable("energy", (2, 3), -1.0).apply(sim)
    assert list(sim.agents.cols["energy"][[2, 3]]) == [-1.0, -1.0]


@settings(max_examples=20, deadline=None)
@given(st.data())
def test_perturbation_kinds_can_be_chosen(data):
    p = data.draw(perturbations(load(FLOCK), kinds=("move",)))
    assert isinstance(p, MoveAgents)
    with pytest.raises(ValueError):
        perturbations(load(FLOCK), kinds=())


class FlockLosingRobots(SwarmMachine):
    program = FLOCK
    params = {"n": 4}
    perturb = ("remove",)


class FlockMovedAround(SwarmMachine):
    program = FLOCK
    perturb = ("move",)


class FlockDrained(SwarmMachine):
    program = FLOCK
    perturb = ("set",)


def test_machine_finds_that_losing_robots_breaks_the_swarm_invariant(backend):
    with pytest.raises(AssertionError, match="invariant `enough` violated"):
        run_state_machine_as_test(FlockLosingRobots, settings=QUICK)


class CountingFlockMovedAround(FlockMovedAround):
    """Counts the property checks and perturbations, so a pass means they happened."""

    checks = 0
    moved = 0

    def _check(self):
        cls = type(self)
        cls.checks += 1
        cls.moved = max(cls.moved, len(self.perturbed_ids))
        super()._check()


def test_machine_passes_when_perturbations_cannot_break_a_property(backend):
    run_state_machine_as_test(CountingFlockMovedAround, settings=QUICK)
    # moving agents never breaks the flock's properties, and they were really checked
    assert CountingFlockMovedAround.checks > 0
    assert CountingFlockMovedAround.moved > 0


def test_machine_finds_a_variable_change_that_breaks_a_per_agent_invariant(backend):
    with pytest.raises(AssertionError, match="invariant `bot.charged` violated"):
        run_state_machine_as_test(FlockDrained, settings=QUICK)


@pytest.mark.slow
def test_machine_shrinks_robot_loss_to_a_short_story():
    with pytest.raises(AssertionError) as info:
        run_state_machine_as_test(FlockLosingRobots, settings=settings(
            QUICK, phases=tuple(Phase), max_examples=50))
    assert "invariant `enough` violated" in str(info.value)


def test_machine_needs_a_program():
    from swarmdsl.compiler.errors import SwarmError

    class Empty(SwarmMachine):
        pass

    with pytest.raises(SwarmError, match="set `program`"):
        Empty()


@pytest.mark.parametrize(("call", "named"), [
    (lambda: run_program(FLOCK, 3, seed=None), "seed"),
    (lambda: run_program(FLOCK, 3, seed=-1), "seed"),
    (lambda: run_program(FLOCK, None), "steps"),
    (lambda: run_program(FLOCK, 2.5), "steps"),
    (lambda: run_program(FLOCK, 3, params=["n", 3]), "params"),
    (lambda: run_program(FLOCK, 3, positions="abc"), "positions"),
    (lambda: run_program(FLOCK, 3, properties=5), "properties"),
    (lambda: search(FLOCK, max_examples=0), "max_examples"),
    (lambda: search(FLOCK, max_examples="5"), "max_examples"),
    (lambda: search(FLOCK, max_examples=2, time_budget=None), "time_budget"),
    (lambda: search(FLOCK, max_examples=2, time_budget=-1), "time_budget"),
    (lambda: search(FLOCK, max_examples=2, steps=0), "steps"),
    (lambda: search(FLOCK, max_examples=2, seeds=-1), "seeds"),
    (lambda: search(FLOCK, max_examples=2, seeds=1.5), "seeds"),
    (lambda: search(FLOCK, max_examples=2, shrink_budget=0), "shrink_budget"),
    (lambda: search(FLOCK, max_examples=2, shrink_budget=float("nan")), "shrink_budget"),
    (lambda: load_example(None), "path"),
])
def test_the_testing_api_names_a_bad_argument(call, named):
    # These were TypeErrors, AttributeErrors, hypothesis' InvalidArgument, or an
    # "internal error ... please report this" for a seed of None; a negative time
    # budget or steps ran a hunt that checked nothing.
    from swarmdsl.compiler.errors import SwarmOptionError

    with pytest.raises(SwarmOptionError, match=named):
        call()


def test_one_property_name_is_one_name_not_its_letters():
    from swarmdsl.testing.monitor import Monitor

    assert [p.info.qualified for p in Monitor(load(FLOCK), "enough").properties] == \
        ["enough"]
    assert run_program(FLOCK, 2, properties="bot.charged").ok


def test_param_values_may_be_numpy_scalars(backend):
    # np.float64(2.0) became the text "np.float64(2.0)" (its repr), refused as not a
    # number; np.bool_ became "True".
    result = run_program(FLOCK, 1, params={"gap": np.float64(2.0), "n": np.int64(3),
                                           "cruise": np.float32(0.5)})
    assert (result.program.params["gap"], result.sim.agents.n) == (2.0, 3)
    assert load("param flag = true\nagent a { count 1; status s { } }\n",
                {"flag": np.bool_(False)}).params["flag"] is False
