"""Runtime semantics, each asserted on numbers: synchronous ticks, aggregates over empty
neighbourhoods, transitions, edges, the speed clamp, determinism and located faults."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from conftest import by_id, shipped

from swarmdsl.compiler.errors import SwarmRuntimeError
from swarmdsl.runtime.simulation import Simulation

SWAP = """
world { size 100 x 100 }
agent a {
  count 2
  place (10 + 20 * index, 50)
  var v = index + 1
  status s { v = nearest(neighbors(50) : other.v) }
}
"""


def test_synchronous_update_swaps_values(run_src):
    sim = run_src(SWAP, steps=1)
    assert by_id(sim, "v").tolist() == [2.0, 1.0]
    sim.run(1)
    assert by_id(sim, "v").tolist() == [1.0, 2.0]


def test_own_writes_are_visible_to_self_but_not_to_neighbours(run_src):
    src = """
world { size 100 x 100 }
agent a {
  count 2
  place (10 + 20 * index, 50)
  var v = 0
  var seen = -1
  status s {
    v = 5
    seen = sum(neighbors(50) : other.v) + v
  }
}
"""
    sim = run_src(src, steps=1)
    # neighbours still read v = 0 (start of tick); the agent itself reads its new v = 5
    assert by_id(sim, "seen").tolist() == [5.0, 5.0]


def test_aggregates_over_empty_neighbourhoods(run_src):
    src = """
world { size 1000 x 1000 }
agent a {
  count 2
  place (100 + 500 * index, 100)
  var c = -1
  var total = -1
  var m = -1
  var lo = -1
  var lo2 = -1
  var near = (-1, -1)
  var anyone = true
  var everyone = false
  status s {
    let ns = neighbors(10)
    c = count(ns)
    total = sum(ns : other.speed)
    m = mean(ns : dist)
    lo = min(ns : dist)
    lo2 = min(ns : dist else 99)
    near = nearest(ns : other.pos else (7, 8))
    anyone = any(ns : true)
    everyone = all(ns : false)
  }
}
"""
    sim = run_src(src, steps=1)
    cols = sim.agents.cols
    assert cols["c"].tolist() == [0, 0]
    assert cols["total"].tolist() == [0, 0]
    assert cols["m"].tolist() == [0, 0]
    assert cols["lo"].tolist() == [0, 0]
    assert cols["lo2"].tolist() == [99, 99]
    assert cols["near"].tolist() == [[7, 8], [7, 8]]
    assert cols["anyone"].tolist() == [False, False]
    assert cols["everyone"].tolist() == [True, True]  # vacuously true


def test_aggregates_with_filters_on_neighbour_status_and_vars(run_src):
    src = """
world { size 100 x 100 }
agent a {
  count 5
  place (10 + 10 * index, 50)
  initial if index < 2 then red else blue
  var w = index
  var reds = 0
  var heavy = 0
  var far = 0
  status red { }
  status blue {
    let ns = neighbors(100)
    reds = count(ns where other.status == red)
    heavy = sum(ns where other.w >= 3 : other.w)
    far = max(ns where dist > 15 : dist)
  }
}
"""
    sim = run_src(src, steps=1)
    assert by_id(sim, "reds").tolist() == [0, 0, 2, 2, 2]
    assert by_id(sim, "heavy").tolist() == [0, 0, 7, 4, 3]
    assert by_id(sim, "far").tolist() == [0, 0, 20, 30, 40]


def test_first_matching_transition_wins_and_runs_its_actions(run_src):
    src = """
agent a {
  count 3
  place (10 + 10 * index, 50)
  var k = index
  var after = 0
  status start {
    when k >= 1 -> second { k += 100 }
    when k >= 0 -> third
    after = 1
  }
  status second { }
  status third { }
}
"""
    sim = run_src(src, steps=1)
    assert sim.status_counts() == {"start": 0, "second": 2, "third": 1}
    assert by_id(sim, "k").tolist() == [0, 101, 102]
    # statements after a transition that fired do not run for that agent
    assert by_id(sim, "after").tolist() == [0, 0, 0]


def test_speed_clamp(run_src):
    src = """
world { size 1000 x 1000 }
agent a {
  count 1
  place (500, 500)
  max_speed 2
  status s { velocity += (30, 40) }
}
"""
    sim = run_src(src, steps=1)
    assert np.allclose(sim.agents.cols["vel"][0], [1.2, 1.6])
    assert np.allclose(sim.agents.cols["pos"][0], [501.2, 501.6])


@pytest.mark.parametrize("edges, pos, vel", [
    ("wrap", [1.0, 50.0], [2.0, 0.0]),
    ("wall", [99.0, 50.0], [-2.0, 0.0]),
])
def test_edge_modes(run_src, edges, pos, vel):
    src = f"""
world {{ size 100 x 100; edges {edges} }}
agent a {{
  count 1
  place (99, 50)
  velocity (2, 0)
  status s {{ }}
}}
"""
    sim = run_src(src, steps=1)
    assert np.allclose(sim.agents.cols["pos"][0], pos)
    assert np.allclose(sim.agents.cols["vel"][0], vel)


def test_repel_edges_push_agents_back_inside(run_src):
    src = """
world { size 100 x 100; grid 10; edges repel 1.0 20 }
agent a {
  count 2
  place (if index == 0 then 95 else 50, 50)
  velocity (1, 0)
  max_speed 5
  status s { }
}
"""
    sim = run_src(src, steps=1)
    vel = by_id(sim, "vel")
    assert vel[0, 0] < 0          # the agent near the right wall turned back
    assert abs(vel[0, 1]) < 1e-9  # symmetric along the wall: no sideways push
    assert vel[1].tolist() == [1.0, 0.0]  # the agent in the middle feels nothing



@pytest.mark.parametrize("grid", [10, 5, 2])
def test_edge_push_adds_up_every_edge_node_in_range(compile_src, backend, grid):
    """docs/language.md's worked example, at three spacings: an agent half a spacing
    from the left wall, level with a node, range the default two spacings. Three nodes
    are in range: the one level with it pushes (R/d)^2 = 16, the two beside it 3.2 each
    at d^2 = 1.25 g^2, of which the x parts (times p/d) count; the next ones are beyond
    R. The push is the sum, 18.86, whatever the spacing (all distances scale with g)."""
    src = (f"world {{ size 100 x 100; grid {grid}; edges repel 1.0 }}\n"
           f"agent a {{ count 1; place ({grid / 2}, 50); status s {{ }} }}\n")
    sim = Simulation(compile_src(src), seed=0, backend=backend)
    sim.run(1)
    p, d = 0.5, np.sqrt(0.5 ** 2 + 1)          # in grid spacings
    push = (2 / p) ** 2 + 2 * (2 / d) ** 2 * (p / d)
    assert push == pytest.approx(18.862, abs=1e-3)
    assert sim.agents.cols["vel"][0].tolist() == pytest.approx([push, 0.0], rel=1e-12)
    assert sim.agents.cols["pos"][0].tolist() == pytest.approx([grid / 2 + push, 50],
                                                               rel=1e-12)


def _edge_nodes(width: float, height: float, g: float) -> set[tuple[float, float]]:
    """Every edge node once, as docs/language.md lists them: each side's nodes one
    spacing apart from its low corner, the sides' shared corners one node each."""
    def along(length):
        return [k * g for k in range(int(np.floor(length / g + 1e-9)) + 1)]
    nodes = {(x, y) for x in (0.0, width) for y in along(height)}
    nodes |= {(x, y) for y in (0.0, height) for x in along(width)}
    return {(round(x, 9), round(y, 9)) for x, y in nodes}


@settings(max_examples=60, deadline=None)
@given(width=st.sampled_from([100.0, 95.0, 103.5]), height=st.sampled_from([80.0, 87.0]),
       x=st.floats(0.0, 1.0), y=st.floats(0.0, 1.0), corner=st.integers(0, 3))
def test_edge_push_counts_each_edge_node_once(backend, width, height, x, y, corner):
    """Near a corner the nodes of both sides push, the corner node once: the push equals
    the sum over the set of edge nodes, whether or not a side's length is a whole number
    of spacings (then its last node is short of the far corner). Both backends' push,
    before the weight, the speed clamp and the walls' bounce."""
    from swarmdsl.runtime.world import World, corner_nodes

    g, r = 10.0, 20.0
    px = 15 * x if corner in (0, 2) else width - 15 * x
    py = 15 * y if corner in (0, 1) else height - 15 * y
    want = np.zeros(2)
    for nx, ny in _edge_nodes(width, height, g):
        off = np.array([px - nx, py - ny])
        d = float(np.hypot(*off))
        if 1e-6 < d < r:                       # an agent on a node: that node is skipped
            want += off / d * (r / d) ** 2
        elif d <= 1e-6:
            return                             # too near a node for a finite comparison
    if backend == "numpy":
        got = World(width, height, g, "repel", 1.0, r).edge_push(np.array([[px, py]]))[0]
    else:
        from swarmdsl.runtime.compiled.motion import _push

        got = _push(px, py, width, height, g, r, 2, corner_nodes(width, height, g))
    assert np.asarray(got) == pytest.approx(want, rel=1e-9, abs=1e-9)


def test_wrap_world_neighbours_see_across_the_edge(run_src):
    src = """
world { size 100 x 100; edges wrap }
agent a {
  count 2
  place (if index == 0 then 2 else 98, 50)
  var offset = (0, 0)
  status s { offset = sum(neighbors(10) : other.pos - pos) }
}
"""
    sim = run_src(src, steps=1)
    assert np.allclose(by_id(sim, "offset"), [[-4, 0], [4, 0]])


def test_same_seed_same_run_other_seed_differs(compile_src):
    prog = compile_src("""
world { size 200 x 200; edges wrap }
agent a {
  count 50
  velocity random_direction() * 2
  status s { velocity = rotate(velocity, normal(0, 0.3)) }
}
""")
    a, b, c = Simulation(prog, 7), Simulation(prog, 7), Simulation(prog, 8)
    for s in (a, b, c):
        s.run(20)
    assert np.array_equal(a.agents.cols["pos"], b.agents.cols["pos"])
    assert not np.allclose(a.agents.cols["pos"], c.agents.cols["pos"])


def test_runtime_fault_names_kind_status_and_line(compile_src):
    prog = compile_src("""agent bug {
  count 2
  var z = 0
  status broken {
    z = 1 / (index - index)
  }
}
""")
    sim = Simulation(prog, 0)
    with pytest.raises(SwarmRuntimeError) as info:
        sim.step()
    err = info.value
    assert err.span.line == 5
    assert "kind `bug`, status `broken`" in err.message
    assert "infinite" in err.message


def test_placement_and_initial_status_by_expression(run_src):
    src = """
agent a {
  count 4
  place (30 * index, 7)
  initial if index == 0 then base else moving
  status base { }
  status moving { }
}
"""
    sim = run_src(src, steps=0)
    assert by_id(sim, "pos").tolist() == [[0, 7], [30, 7], [60, 7], [90, 7]]
    assert sim.status_counts() == {"base": 1, "moving": 3}


def test_uniform_placement_stays_in_the_world(run_src):
    sim = run_src("world { size 40 x 30 }\nagent a { count 500; status s { } }", steps=0)
    pos = sim.agents.cols["pos"]
    assert (pos >= 0).all() and (pos[:, 0] <= 40).all() and (pos[:, 1] <= 30).all()
    assert pos[:, 0].std() > 8  # spread out, not piled up


def test_two_kinds_see_each_other_and_keep_their_statuses(run_src):
    src = """
world { size 100 x 100 }
agent prey {
  count 1
  place (50, 50)
  status grazing { }
}
agent hunter {
  count 2
  place (40 + 20 * index, 50)
  var prey_near = 0
  status hunting { prey_near = count(neighbors(15) where other.kind == prey) }
}
"""
    sim = run_src(src, steps=1)
    assert sim.status_counts() == {"prey.grazing": 1, "hunter.hunting": 2}
    assert by_id(sim, "prey_near").tolist()[1:] == [1, 1]


def test_editing_a_snapshots_grid_leaves_the_simulation_alone(backend):
    """A snapshot's arrays are the caller's: zeroing its grid coordinates (a plot that
    shifts them in place) once moved the grid the simulation samples its fields on."""
    edited, untouched = shipped("mas_environment.swarm"), shipped("mas_environment.swarm")
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
