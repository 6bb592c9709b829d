"""A new user's pass over the shipped experiments and the robot/MAS features: the
programs keep working when their params change, and odd inputs give sensible results
or located errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from swarmdsl.compiler import compile_file
from swarmdsl.runtime.simulation import Simulation

PROGRAMS = Path(__file__).resolve().parent.parent / "programs"


def _run_program(name: str, steps: int, seed: int = 0, **overrides) -> Simulation:
    """A shipped program run `steps` ticks with `--set`-style overrides."""
    prog = compile_file(PROGRAMS / name, {k: str(v) for k, v in overrides.items()})
    sim = Simulation(prog, seed)
    sim.run(steps)
    return sim


def _kind_rows(sim, kind: str) -> np.ndarray:
    return np.flatnonzero(sim.agents.cols["kind"] == sim.program.info.kind(kind).index)


def test_spring_on_a_longer_span_settles_equally_spaced():
    """The world used to be a fixed 240 x 80, so `--set span=250` was refused (the end
    robot outside the world); now the world grows with the chain."""
    sim = _run_program("spring1d.swarm", 600, span=250)
    x = np.sort(sim.agents.cols["believed"][:, 0])
    np.testing.assert_allclose(x, [0, 50, 100, 150, 200, 250], atol=1.0)


def test_spring_with_six_extensions_labels_and_spreads_them_all():
    """The extension count was fixed at 4 (and the end's id at 5): a user could not add
    robots with `--set`; now `extensions` sets both, and the span grows with it."""
    sim = _run_program("spring1d.swarm", 600, extensions=6)
    order = np.argsort(sim.agents.cols["believed"][:, 0])
    assert sim.agents.cols["lid"][order].tolist() == list(range(8))
    x = sim.agents.cols["believed"][order, 0]
    np.testing.assert_allclose(x, np.arange(8) * 250 / 7, atol=1.0)


def test_matrix_with_four_columns_comes_to_rest():
    """With `--set cols=4` the middle rows used to swing side to side for ever (each
    robot jumping to a target made from one-tick-old positions); now they come to rest,
    evenly spaced along the row."""
    sim = _run_program("matrix2d.swarm", 250, cols=4)
    cells = _kind_rows(sim, "cell")
    before = sim.agents.cols["believed"][cells].copy()
    sim.run(50)
    after = sim.agents.cols["believed"][cells]
    assert np.abs(after - before).max() < 0.05
    middle = after[(after[:, 1] > 20) & (after[:, 1] < 110)]
    for y in (43.33, 86.67):
        row = np.sort(middle[np.abs(middle[:, 1] - y) < 1, 0])
        assert row.size == 4
        inner_gap = row[2] - row[1]
        assert abs((row[1] - row[0]) - (row[3] - row[2])) < 0.1 and inner_gap < 40


def test_obstacle_covering_the_whole_world_is_a_located_error(assert_located_error):
    """Agents used to start inside it and stand still for the whole run, silently."""
    assert_located_error(
        "world { size 200 x 200 }\nobstacle all = rect(-10, -10, 210, 210)\n"
        "agent a { count 5; status s { velocity = (1, 0) } }\n",
        "3:7: obstacles cover the whole world (200 x 200): agents of `a` would start "
        "inside `all` and could never move")


def test_placing_agents_inside_an_obstacle_is_warned(compile_src):
    """A constant start or a region inside an obstacle used to freeze those agents
    without a word; now check names the obstacle at the `place` option."""
    prog = compile_src(
        "world { size 200 x 200 }\nobstacle rock = circle(100, 100, 50)\n"
        "nest home = circle(100, 100, 10)\n"
        "agent a { count 5; place in home; status s { velocity = (1, 0) } }\n"
        "agent b { count 5; place (40 * index, 100); status s { velocity = (1, 0) } }\n")
    said = {w.span.line: w.message for w in prog.info.warnings}
    assert said[4] == ("region `home` lies inside obstacle `rock`: agents of `a` placed "
                       "in it would start inside")
    assert said[5] == ("2 of 5 agents of `b` would start inside obstacle `rock`, the first "
                       "(index 2) at (80, 100)")


def test_a_talking_robot_of_body_zero_is_refused_not_deaf(assert_located_error,
                                                           compile_src):
    """`like kilobot; body 0` inherits a comm_range of two body diameters, 0: every
    `heard()` used to be empty without a word, while `comm_range 0` is refused."""
    agent = ("agent a {{ robot {r}; count 3; place (10 * index, 50); message x num; "
             "status s {{ broadcast(x, 1) }} }}\n")
    assert_located_error("robot r { like kilobot; body 0 }\n" + agent.format(r="r"),
                         "2:53: agents of `a` would hear no message: robot `r` hears two "
                         "body diameters away, and its body is 0")
    compile_src("robot r { like kilobot; body 0; comm_range 30 }\n" + agent.format(r="r"))


def test_an_infinite_belief_is_a_located_fault(run_src):
    """`believe((1 / z, 0))` with z = 0 used to run on, recording `believed_x` = inf for
    the rest of the run; now it stops at the action, naming the agent."""
    from swarmdsl.compiler.errors import SwarmRuntimeError

    with pytest.raises(SwarmRuntimeError) as err:
        run_src("agent a { count 2; var z = 0; status s { believe((1 / z, 0)) } }", steps=2)
    assert "test.swarm:1:50: error: the belief is infinite for agent 0 (kind `a`, status " \
        "`s`) at tick 0" in str(err.value)
