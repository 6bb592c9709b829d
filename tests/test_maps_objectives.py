"""Internal maps (E) and objectives (O): what agents remember and where they steer."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmdsl.compiler import compile_source
from swarmdsl.runtime.simulation import Simulation

WALKER = """world { size 300 x 300; grid 10 }
field level { twin pos.x + 1000 * floor(tick / 4) }
agent w {
  count 1
  place (55, 55)
  map seen 10 20
  var here = 0
  var then_age = 0
  var best_x = 0
  status s {
    note(seen, sample(level))
    here = recall(seen)
    then_age = age(seen, (55, 55))
    best_x = best(seen).x
    velocity = if tick >= 3 then (10, 0) else (0, 0)
  }
}
"""


def test_the_map_holds_the_last_seen_value_and_its_age(run_src):
    sim = run_src(WALKER, steps=8)
    cols = sim.agents.cols
    # ticks 0-2 at (55, 55): the last note there was at tick 3 (it moved during tick 3)
    assert cols["then_age"][0] == 7 - 3
    m = sim.maps.maps["seen"]
    value, age = m.recall(cols, np.array([0]), cols["pos"], np.array([[55.0, 55.0]]), 8)
    assert value[0] == pytest.approx(55)          # seen at tick 3: 55 + 1000 * 0
    assert age[0] == 5
    assert cols["here"][0] == pytest.approx(cols["pos"][0, 0] - 10 + 1000)
    # best() is the centre of the highest cell seen, in world coordinates
    assert cols["best_x"][0] == pytest.approx(
        55 - 5 + 10 * math.floor((cols["pos"][0, 0] - 10 - 55) / 10 + 0.5 + 1e-9) + 5,
        abs=10)


SENSOR = """param reach = 30
world {{ size 400 x 400; grid 10 }}
field level {{ twin 1 + pos.y }}
{robot}
agent a {{
  {use}
  count 6
  place uniform
  sense reach
  map seen 5 160
  velocity random_direction() * 3
  status s {{
    let p = pos + random_direction() * uniform(0, 3 * reach)
    note(seen, sample(level))
    note(seen, sample(level, p), p)
  }}
}}
"""


@settings(max_examples=12)
@given(seed=st.integers(0, 10_000), reach=st.floats(5, 60),
       cone=st.sampled_from([None, 0.5, 1.5]))
def test_the_map_never_holds_what_the_agent_could_not_sense(seed, reach, cone):
    robot = "" if cone is None else f"robot eye {{ fov cone {cone} }}"
    use = "" if cone is None else "robot eye"
    src = SENSOR.format(robot=robot, use=use)
    sim = Simulation(compile_source(src, "m.swarm", {"reach": repr(reach)}), seed)
    m = sim.maps.maps["seen"]
    half = 5 * math.sqrt(0.5)                    # centre to corner of a 5-unit cell
    centres = (np.arange(160) + 0.5 - 80) * 5
    for _ in range(12):
        cols = sim.agents.cols
        pos, heading = cols["pos"].copy(), cols["heading"].copy()
        origin = cols[m.origin].copy()
        before = np.isfinite(cols[m.seen])
        sim.step()
        # every cell first noted this tick had some point the agent could sense then
        a, i, j = np.nonzero(np.isfinite(sim.agents.cols[m.seen]) & ~before)
        dx = origin[a, 0] + centres[j] - pos[a, 0]
        dy = origin[a, 1] + centres[i] - pos[a, 1]
        dist = np.hypot(dx, dy)
        sensible = dist <= reach + half
        if cone is not None:
            off = np.abs((np.arctan2(dy, dx) - heading[a] + np.pi) % (2 * np.pi) - np.pi)
            widen = np.arcsin(np.minimum(1.0, half / np.maximum(dist, 1e-9)))
            sensible &= off <= cone + widen
        sensible |= dist <= half                 # the cell it stands in
        assert sensible.all(), (a[~sensible], i[~sensible], j[~sensible])
    known = np.isfinite(sim.agents.cols[m.seen])
    assert known.any()


OBJECTIVES = """world { size 300 x 300; grid 10 }
nest home = circle(250, 250, 20)
agent leader {
  count 1
  place (150, 50)
  velocity (0, 0)
  status idle { }
}
agent bot {
  count 5
  place (20 + 10 * index, 20)
  var gx = 100
  objective spot = (gx, 200)
  objective base = home
  objective boss = leader
  var there = 0
  status going {
    velocity = approach(spot, 7)
    when arrived(spot) -> homing { there = tick }
  }
  status homing {
    velocity = toward(base) * 5
    when arrived(base, 0.5) -> meeting
  }
  status meeting {
    velocity = approach(boss, 4)
    when arrived(boss, 1) -> done
  }
  status done { velocity = (0, 0) }
}
"""


def test_objectives_steer_to_points_regions_and_agents(run_src):
    sim = run_src(OBJECTIVES, steps=1)
    kinds = sim.agents.cols["kind"]
    bots = np.flatnonzero(kinds == 1)
    sim.run(400)
    cols = sim.agents.cols
    names = [sim.program.status_display[s] for s in cols["status"][bots]]
    assert set(names) == {"bot.done"}
    assert (cols["there"][bots] > 0).all()
    np.testing.assert_allclose(cols["pos"][bots], np.tile([150, 50], (5, 1)), atol=1)


@pytest.mark.parametrize("src, message", [
    ("agent a { objective g = 3; status s { } }",
     "1:25: an objective is a point, a region or an agent kind, got a number"),
    ("agent a { status s { velocity = toward(a) } }",
     "1:40: `toward` needs an objective (declare it with `objective NAME = TARGET`), "
     "got an agent kind"),
    ("agent a { map m 10 1000; status s { } }", "1:20: a map is at most 256 cells a "
     "side, got 1000"),
    ("agent a { robot kilobot; map m 10 10; status s { note(m, 1) } }",
     "1:50: `note(...)` needs the sense `position`, which robot `kilobot` lacks"),
])
def test_map_and_objective_mistakes_are_located_errors(located_error, src, message):
    located_error(src, message)
