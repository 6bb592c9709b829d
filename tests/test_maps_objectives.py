"""Internal maps (E) and objectives (O): what agents remember and where they steer."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
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


def test_the_age_of_a_cell_never_noted_is_a_number_a_var_can_hold(backend):
    """It was `inf`, and storing it in a `var` stopped the run at tick 0."""
    src = """world { size 100 x 100 }
agent a {
  count 2
  place (20 + 40 * index, 50)
  map seen 5 20
  var old = 0
  var fresh = 0
  status s {
    old = age(seen, (90, 90))
    when index == 0 and not known(seen) -> s { note(seen, 1) }
    fresh = age(seen)
  }
}
"""
    sim = Simulation(compile_source(src, "m.swarm"), seed=0, backend=backend)
    sim.run(3)
    cols = sim.agents.cols
    assert cols["old"].tolist() == [1e15, 1e15]          # off the map: never noted
    assert cols["fresh"].tolist() == [2, 1e15]     # noted at tick 0; agent 1 never notes


SENSOR = """param reach = 30
world {{ size 400 x 400; grid 10 }}
field level {{ twin 1 + pos.y }}
{robot}
{kinds}
"""

SENSING_KIND = """agent {kind} {{
  {use}
  count 6
  place uniform
  sense reach
  map {map} {cell} {size}
  velocity random_direction() * 3
  status s {{
    let p = pos + random_direction() * uniform(0, 3 * reach)
    note({map}, sample(level))
    note({map}, sample(level, p), p)
  }}
}}
"""


def _wedge(polygon: list, a: float, b: float) -> list:
    """The part of a convex polygon (offsets from the agent) between the rays at angles
    ``a`` and ``b`` (``b - a <= pi``, so the wedge is convex): two half-plane clips."""
    for n in ((-math.sin(a), math.cos(a)), (math.sin(b), -math.cos(b))):
        kept = []
        for p, q in zip(polygon, polygon[1:] + polygon[:1]):
            sp, sq = n[0] * p[0] + n[1] * p[1], n[0] * q[0] + n[1] * q[1]
            if sp >= 0:
                kept.append(p)
            if (sp >= 0) != (sq >= 0):
                t = sp / (sp - sq)
                kept.append((p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])))
        polygon = kept
        if not polygon:
            break
    return polygon


def _nearest(polygon: list) -> float:
    """Distance from the agent (the offset origin) to a convex polygon it is outside."""
    best = math.inf
    for p, q in zip(polygon, polygon[1:] + polygon[:1]):
        ex, ey = q[0] - p[0], q[1] - p[1]
        span = ex * ex + ey * ey
        t = 0.0 if span == 0 else min(1.0, max(0.0, -(p[0] * ex + p[1] * ey) / span))
        best = min(best, math.hypot(p[0] + t * ex, p[1] + t * ey))
    return best


def _could_sense_some_of(lo, side: float, pos, heading: float, reach: float, cone) -> bool:
    """Whether some point of the closed square cell ``[lo, lo + side]`` is within
    ``reach`` of ``pos`` and, with a cone, within ``cone`` radians of ``heading``: the
    documented rule for `note(M, value, point)`, asked of every point of the cell."""
    x0, y0 = lo[0] - pos[0], lo[1] - pos[1]
    square = [(x0, y0), (x0 + side, y0), (x0 + side, y0 + side), (x0, y0 + side)]
    if x0 <= 0 <= x0 + side and y0 <= 0 <= y0 + side:
        return True                              # it stands in it: its own point
    halves = [square] if cone is None else [
        _wedge(square, heading - cone, heading), _wedge(square, heading, heading + cone)]
    return any(part and _nearest(part) <= reach for part in halves)


@example(seed=1, reach=5.0, cone=0.5)      # placed on a cell corner, facing away from it
@settings(max_examples=12)
@given(seed=st.integers(0, 10_000), reach=st.floats(5, 60),
       cone=st.sampled_from([None, 0.5, 1.5]))
def test_the_map_never_holds_what_the_agent_could_not_sense(backend, seed, reach, cone):
    robot = "" if cone is None else f"robot eye {{ fov cone {cone} }}"
    use = "" if cone is None else "robot eye"
    kinds = "".join(SENSING_KIND.format(kind=kind, use=use, map=name, cell=cell, size=size)
                    for kind, name, cell, size in (("a", "seen", 5, 160), ("b", "fine", 1, 256)))
    src = SENSOR.format(robot=robot, kinds=kinds)
    sim = Simulation(compile_source(src, "m.swarm", {"reach": repr(reach)}), seed)
    maps = sim.maps.maps.values()    # 5-unit cells; 1-unit ones see finer
    for _ in range(12):
        tick, cols = sim.tick, sim.agents.cols
        pos, heading = cols["pos"].copy(), cols["heading"].copy()
        before = {m: cols[m.origin].copy() for m in maps}
        sim.step()
        for m, origin in before.items():
            # the cell it stands in, by the map's rule floor((p - origin) / CELL + SIZE / 2)
            here = np.floor((pos - origin) / m.cell + m.size / 2).astype(np.int64)
            # every value kept this tick (the one a cell holds until it is noted again) is
            # where the agent stood or in a cell with some point it could sense then
            a, i, j = np.nonzero(sim.agents.cols[m.seen] == tick)
            for agent, iy, ix in zip(a, i, j):
                lo = origin[agent] + (np.array([ix, iy]) - m.size / 2) * m.cell
                assert (ix, iy) == tuple(here[agent]) or _could_sense_some_of(
                    lo, m.cell, pos[agent], heading[agent], reach, cone), \
                    (m.name, tick, agent, iy, ix, pos[agent], heading[agent])
    for m in maps:
        assert np.isfinite(sim.agents.cols[m.seen]).any()


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


WRAPPED = """world { size 100 x 100; edges wrap }
agent van { count 2; place (if index == 0 then 95 else 30, 50); status park { } }
agent c {
  count 1
  place (5, 50)
  objective boss = van
  objective spot = (60 + 38, 52)
  var spot_heading = 0
  status go {
    spot_heading = angle(toward(spot))
    velocity = approach(boss, 1)
    when arrived(boss) -> there
  }
  status there { velocity = (0, 0) }
}
"""


def test_objectives_take_the_short_way_round_a_wrapped_world(backend):
    """The van 10 units away across the edge is the nearest (not the one 25 away inside
    the world), and the courier crosses the edge to reach it: 10 ticks at speed 1, and it
    knows it has arrived on the next."""
    sim = Simulation(compile_source(WRAPPED, "wrap.swarm"), seed=0, backend=backend)
    sim.run(1)
    cols = sim.agents.cols
    c = np.flatnonzero(cols["kind"] == 1)[0]
    # (98, 52) from (5, 50) is 7 units back across the edge: west, slightly north
    assert cols["spot_heading"][c] == pytest.approx(math.atan2(2, -7))
    sim.run(10)
    cols = sim.agents.cols
    assert sim.program.status_display[cols["status"][c]] == "c.there"
    np.testing.assert_allclose(cols["pos"][c], [95, 50], atol=1e-9)


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
def test_map_and_objective_mistakes_are_located_errors(assert_located_error, src, message):
    assert_located_error(src, message)
