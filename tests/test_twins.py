"""Physical twins: fields given by a formula of position and time, scalar and vector."""

from __future__ import annotations

import numpy as np
import pytest



def _formula(x, y, t):
    return 20 + 10 * np.sin(x / 30 + t / 10) - (y / 40) ** 2


TWINS = """world { size 200 x 120; grid 10 }
field temp { twin 20 + 10 * sin(pos.x / 30 + tick / 10) - (pos.y / 40) ^ 2 }
field still { twin random() }
field wind { twin (10, 0) }
agent w {
  count 4
  place (20 + 40 * index, 60)
  var felt = 0
  var dx = 0
  status drift {
    felt = sample(temp)
    dx = sample(wind).x
    velocity = sample(wind)
  }
}
"""


def test_twin_equals_its_formula_at_every_node_every_tick(run_src):
    sim = run_src(TWINS, steps=0)
    for t in range(4):
        grid = sim.environment.grid
        x, y = grid.nodes()
        got = sim.environment.fields["temp"].values
        np.testing.assert_allclose(got, _formula(x, y, sim.tick), rtol=0, atol=1e-12)
        sim.step()
        assert sim.tick == t + 1


def test_agents_read_the_formula_at_the_current_tick(run_src):
    sim = run_src(TWINS, steps=3)   # `felt` was set during tick 2 at the tick-2 position
    order = np.argsort(sim.agents.cols["id"])
    felt = sim.agents.cols["felt"][order]
    x0 = 20 + 40 * np.arange(4) + 10 * 2          # moved 10 per tick: on nodes
    np.testing.assert_allclose(felt, _formula(x0, 60.0, 2), atol=1e-9)


def test_a_vector_twin_moves_agents_with_it(run_src):
    sim = run_src(TWINS, steps=5)
    order = np.argsort(sim.agents.cols["id"])
    np.testing.assert_allclose(sim.agents.cols["pos"][order][:, 0],
                               np.minimum(20 + 40 * np.arange(4) + 50.0, 200))
    assert (sim.agents.cols["dx"] == 10).all()


def test_a_static_twin_is_sampled_once_and_a_timed_one_every_tick(run_src):
    sim = run_src(TWINS, steps=0)
    still = sim.environment.fields["still"].values.copy()
    temp = sim.environment.fields["temp"].values.copy()
    assert still.std() > 0.1                      # random per node ...
    sim.run(3)
    np.testing.assert_array_equal(sim.environment.fields["still"].values, still)
    assert not np.allclose(sim.environment.fields["temp"].values, temp)


def test_vector_twin_is_recorded_by_component(backend, tmp_path):
    from swarmdsl import load_program
    from swarmdsl.runtime.runner import Run

    prog = tmp_path / "t.swarm"
    prog.write_text(TWINS.replace("(10, 0)", "(pos.y / 10, -pos.x / 10)"))
    Run(load_program(prog), steps=2, out=str(tmp_path / "out"), seed=1).execute()
    data = np.load(tmp_path / "out" / "fields.npz")
    x, y = np.meshgrid(data["grid_x"], data["grid_y"])
    np.testing.assert_allclose(data["wind.x"][0], y / 10)
    np.testing.assert_allclose(data["wind.y"][-1], -x / 10)


@pytest.mark.parametrize("body, message", [
    ("field t { twin (1, 0); diffuse 0.1 }", "1:24: field `t` is a physical twin: its "
     "values come from its formula, so it takes no `diffuse`"),
    ("field t { twin heading }", "1:16: a twin is a formula of the node position `pos` "
     "and the time `tick`; `heading` is not known there"),
    ("field t { twin pos.x > 3 }", "1:16: a twin's formula must give a number or a "
     "vector, got a boolean"),
    ("field t { twin (1, 2) }\nagent a { status s { velocity = gradient(t) } }",
     "2:42: `gradient` needs a field here, got a vector field"),
    ("field t { twin pos.x }\nagent a { status s { deposit(t, 1) } }",
     "2:30: field `t` is a physical twin: its values come from its formula and cannot "
     "be deposited into"),
])
def test_twin_mistakes_are_located_errors(assert_located_error, body, message):
    assert_located_error(body + "\nagent b { status s { } }", message)
