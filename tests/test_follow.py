"""`follow(FIELD[, speed])` ends its climb at a peak the agent really reaches, never
on a slope, on both backends (the leaf in runtime/tree_leaves.py)."""

from __future__ import annotations

import math

import numpy as np
from conftest import REFERENCE
from hypothesis import example, given, settings
from hypothesis import strategies as st

from swarmdsl.compiler import compile_source
from swarmdsl.runtime.simulation import Simulation


def _climber(field: str, start, speed: float, grid: float = 1, edges: str = "wall",
             count: int = 1) -> str:
    """One kind that follows `field` from `start`, noting the tick it succeeded (`got`)
    or failed (`lost`) in a status of its own."""
    return f"""world {{ size 100 x 100; edges {edges}; grid {grid:g} }}
field hill {{ initial {field} }}
agent bot {{
  count {count}
  place ({start[0]!r}, {start[1]!r})
  var t = 0
  var got = 0
  var lost = 0
  status climb {{
    t += 1
    tree follow(hill, {speed!r})
    on success -> done {{ got = t }}
    on failure -> done {{ lost = t }}
  }}
  status done {{ }}
}}"""


def _bump(cx: float, cy: float, width: float) -> str:
    return f"100 * exp(-(distance(pos, ({cx!r}, {cy!r})) / {width!r}) ^ 2)"


def _run(src: str, ticks: int, backend: str = "numpy") -> Simulation:
    sim = Simulation(compile_source(src, "f.swarm"), seed=0, backend=backend)
    sim.run(ticks)
    return sim


def test_an_agent_near_a_peak_off_the_grid_reaches_it_and_moves_on(backend):
    """The peak sits between nodes and the agent comes at it diagonally, so the
    gradient never reads exactly 0: the climb still ends, next to the peak."""
    sim = _run(_climber(_bump(52.3, 47.7, 15), (40, 62), 1), 40, backend)
    cols = sim.agents.cols
    assert cols["got"][0] > 0 and cols["lost"][0] == 0
    assert sim.program.status_display[int(cols["status"][0])].endswith("done")
    assert np.linalg.norm(cols["pos"][0] - [52.3, 47.7]) <= 0.5
    assert cols["vel"][0].tolist() == [0, 0]     # it stops where it succeeded


def test_both_backends_climb_alike(other_backend):
    src = _climber(_bump(52.3, 47.7, 15), (40, 62), 0.7, count=1)
    runs = [_run(src, 40, backend) for backend in (REFERENCE, other_backend)]
    for col in ("pos", "got", "status"):
        assert np.array_equal(runs[0].agents.cols[col], runs[1].agents.cols[col]), col


@settings(deadline=None, max_examples=40)
# hopped across the peak between two points each a hair higher than the last
@example(cx=30.0, cy=30.0, width=8.0, reach=3.0, angle=1.0, speed=2.0, grid=1)
# a step cut to the top, then cut again and again on a coarse grid's flat top
@example(cx=51.0, cy=56.0, width=8.0, reach=2.0, angle=1.0, speed=1.0, grid=5)
@given(cx=st.floats(30, 70), cy=st.floats(30, 70), width=st.floats(8, 25),
       reach=st.floats(2, 25), angle=st.floats(0, 2 * math.pi),
       speed=st.floats(0.2, 3), grid=st.sampled_from([0.5, 1, 2, 5]))
def test_a_climb_from_anywhere_near_a_peak_succeeds_next_to_it(cx, cy, width, reach, angle,
                                                                speed, grid):
    """Within the ticks the distance takes (and two more), the agent is in `done`, no
    further from the peak than a step and a grid spacing: the interpolated field's own
    top lies within a spacing of the formula's."""
    start = (cx + reach * math.cos(angle), cy + reach * math.sin(angle))
    sim = _run(_climber(_bump(cx, cy, width), start, speed, grid), int(reach / speed) + 3)
    cols = sim.agents.cols
    assert cols["got"][0] > 0 and cols["lost"][0] == 0
    assert np.linalg.norm(cols["pos"][0] - [cx, cy]) <= speed + grid


@settings(deadline=None, max_examples=40)
@given(angle=st.floats(0, 2 * math.pi), slope=st.floats(1e-3, 10),
       speed=st.floats(0.2, 3), grid=st.sampled_from([0.5, 1, 2, 5]),
       edges=st.sampled_from(["wall", "wrap"]))
def test_on_a_slope_the_climb_keeps_running_and_climbing(angle, slope, speed, grid, edges):
    """A plane rising toward `angle`, the agent started in the middle with room for
    every step: no tick ends the climb, and every tick goes higher."""
    gx, gy = slope * math.cos(angle), slope * math.sin(angle)
    field = f"{gx!r} * pos.x + {gy!r} * pos.y"
    ticks = 12     # at most 36 units from the middle: never reaching an edge
    sim = Simulation(compile_source(_climber(field, (50, 50), speed, grid, edges),
                                    "f.swarm"), seed=0)
    height = []
    for _ in range(ticks):
        sim.step()
        x, y = sim.agents.cols["pos"][0]
        height.append(gx * x + gy * y)
    assert sim.agents.cols["got"][0] == 0 and sim.agents.cols["lost"][0] == 0
    assert (np.diff(height) > 0).all()


def test_an_empty_field_fails_and_a_plateau_succeeds_at_once():
    empty = _run(_climber("0", (50, 50), 1), 3).agents.cols
    plateau = _run(_climber("5", (50, 50), 1), 3).agents.cols
    assert (empty["lost"][0], empty["got"][0]) == (1, 0)
    assert (plateau["got"][0], plateau["lost"][0]) == (1, 0)


def test_the_step_is_cut_to_max_speed_so_the_peak_is_not_judged_from_afar():
    """Asked for steps of 20 but allowed 1 a tick, the agent must still get next to the
    peak: judged by a step of 20 it would stop up to 10 away."""
    src = _climber(_bump(50.5, 50.5, 15), (30, 50), 20).replace(
        "count 1", "count 1\n  max_speed 1")
    cols = _run(src, 40).agents.cols
    assert cols["got"][0] > 0
    assert np.linalg.norm(cols["pos"][0] - [50.5, 50.5]) <= 1.5


def test_a_field_rising_into_a_wall_is_climbed_to_the_wall():
    """The top of a field that rises out of the world is at the wall: the climb ends
    there, where a bounce off the wall would land lower."""
    cols = _run(_climber("pos.x", (90.5, 50), 1), 14).agents.cols
    assert 0 < cols["got"][0] <= 11
    assert cols["pos"][0, 0] >= 99.5
