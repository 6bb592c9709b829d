"""A robot's field of view tested in the numba backend's own search of the cells: the
same neighbours as the reference's sensing model, and no pair written for it."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swarmdsl.compiler import compile_file, compile_source
from swarmdsl.runtime.sensing import View, in_view, view_tree
from swarmdsl.runtime.simulation import Simulation
from tests.conftest import PROGRAMS, assert_backends_agree, backend_names, run_both
from tests.test_compiled import assert_same_state

pytestmark = pytest.mark.skipif("numba" not in backend_names(),
                                reason="the numba backend is not installed")

VIEWS = ["fov cone 0.7", "fov cone 3.1", "fov front 0.5 3", "fov front 1.2",
         "range 3.5", "range 3.5; fov cone 1.4", "fov front 0.3 2; range 4"]
# How the set is made (the view alone, narrower, filtered, filtered twice, a radius
# that draws), and what is computed from it: sums that search the cells, a count, an
# extreme and a nearest (which read the mask), a filter of it inside a sum.
SETS = ["neighbors()", "neighbors(3)", "neighbors() where other.u != 1",
        "neighbors(4) where dist > 1 where other.b",
        "neighbors(uniform(2.5, 4.5))"]   # a radius that draws: drawn once, as the reference
READS = ["x2 = count({s})", "v2 = sum({s} : other.pos - pos)",
         "x2 = min({s} : dist else -1)", "v2 = nearest({s} : other.v else (0, 0))",
         "x2 = sum({s} where other.u > 1 : dist) + count({s})",
         "b2 = any({s} : other.b)"]


@st.composite
def viewed_programs(draw):
    view = draw(st.sampled_from(VIEWS))
    edges = draw(st.sampled_from(["wrap", "wall"]))
    reads = draw(st.lists(st.tuples(st.sampled_from(READS), st.sampled_from(SETS)),
                          min_size=1, max_size=3))
    body = "\n    ".join(r.format(s=f"({s})") for r, s in reads)
    return f"""
robot eye {{ {view} }}
world {{ size 24 x 16; edges {edges} }}
agent a {{
  robot eye
  count 40
  sense 5
  velocity (cos(index * 1.3), sin(index * 0.7))
  var u = index % 4
  var b = index % 3 == 0
  var v = (index % 5, 2)
  var x2 = 0
  var v2 = (0, 0)
  var b2 = false
  status s {{
    {body}
  }}
}}
"""


@settings(max_examples=6, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(viewed_programs())
def test_a_field_of_view_gives_the_references_neighbours(text):
    assert_backends_agree(text, assert_same_state)


@pytest.mark.slow
@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(viewed_programs())
def test_a_field_of_view_gives_the_references_neighbours_long(text):
    assert_backends_agree(text, assert_same_state)


@settings(max_examples=200, deadline=None)
@given(dx=st.floats(-6, 6), dy=st.floats(-6, 6), heading=st.floats(-7, 7),
       fov=st.sampled_from([0, 1, 2]), angle=st.floats(0, math.pi),
       reach=st.floats(0, 6), rng=st.sampled_from([2.5, 4.0, math.inf]),
       limit=st.sampled_from([3.0, 5.0]))
def test_the_compiled_condition_is_in_view_pair_by_pair(dx, dy, heading, fov, angle,
                                                        reach, rng, limit):
    """The tree the kernels compile, evaluated with the kernels' own scalar functions,
    keeps exactly the pairs `in_view` keeps (ties at the edges included: offsets on a
    grid of quarter units hit the range and the reach exactly)."""
    from swarmdsl.runtime.compiled.kernels import node

    dx, dy = round(dx * 4) / 4, round(dy * 4) / 4
    d = math.sqrt(dx * dx + dy * dy)
    view = View(fov, angle, reach, rng)
    S = np.array([view.columns(limit, heading)], dtype=np.float64)
    got = node(view_tree(fov))(S, np.zeros((1, 1)), 0, 0, d, dx, dy)
    want = d <= limit and bool(in_view(np.array([[dx, dy]]), np.array([heading]), fov,
                                       angle, reach, rng, np.array([d]))[0])
    assert got == want


def test_boids_with_a_field_of_view_write_no_pairs():
    """boids_leader at 2,000 agents: a sight of 160 units in 600 x 600 is ~450
    candidates each; the sums test the view as they search, so no pair is written
    (before, the sensing model had every candidate pair written: 3.6 GB at 10^4
    agents), and the state is the reference's."""
    prog = compile_file(PROGRAMS / "boids_leader.swarm", {"n": "2000"})
    sims = [Simulation(prog, 5, backend=b) for b in ("numpy", "numba")]
    for sim in sims:
        sim.run(3)
    assert_same_state(sims, prog)
    numba = sims[1].backend
    assert numba._tables == 3 and numba._writes == 0


def test_noise_keeps_the_reference_sensing():
    """A view with draws per pair (dropout) is the sensing model's to apply: the sums
    read the pairs it let through, with the reference's bits."""
    text = """
robot eye { fov cone 1.0; neighbor_dropout 0.3 }
world { size 40 x 40 }
agent a {
  robot eye
  count 60
  sense 8
  velocity (cos(index), sin(index))
  var x2 = 0
  status s { x2 = count(neighbors()) }
}
"""
    prog, sims = run_both(text, steps=3, seed=2, other="numba")
    assert_same_state(sims, prog)
    assert sims[1].agents.cols["x2"].sum() > 0


FRONT = """
robot eye { fov front 0.5 2; range 4 }
world { size 24 x 16; edges wrap }
agent a {
  robot eye
  count 40
  sense 5
  velocity (cos(index * 1.3), sin(index * 0.7))
  var u = index % 4
  var x2 = 0
  status s {
    let near = neighbors(3) where other.u != 1
    x2 = count(near)
    velocity = normalize(velocity + sum(near : other.pos - pos) * 0.01) * 0.5
  }
}
"""


def test_whole_ticks_test_a_robots_view_as_the_reference():
    """The whole-tick kernel takes a program whose robots see through a field of view:
    the two sums over the set share one loop and test its filter and view once a pair;
    12 ticks in two calls give the numpy reference's state, stepped."""
    from swarmdsl.runtime.compiled import tick_run

    prog = compile_source(FRONT, "test.swarm")
    whole, stepped = Simulation(prog, 4, backend="numba"), Simulation(prog, 4, backend="numpy")
    assert whole.advance(5) == 5 and whole.advance(7) == 7
    assert tick_run.summary(whole.backend)[0].startswith("whole-tick kernel: yes")
    stepped.run(12)
    assert_same_state([stepped, whole], prog)
    assert stepped.agents.cols["x2"].sum() > 0


@pytest.mark.slow   # a whole-tick kernel of its own per example: tens of seconds each
@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(viewed_programs())
def test_whole_ticks_test_the_view_as_the_reference_does(text):
    """The whole-tick kernel tests each robot's view in its pair loops: 12 ticks in
    whole calls give the numpy reference's state, stepped."""
    from swarmdsl.runtime.compiled import tick_plan
    from swarmdsl.runtime.compiled.plan import Unsupported

    prog = compile_source(text, "test.swarm")
    try:
        tick_plan.plan_tick(prog)
    except Unsupported:
        return   # a construct the kernel leaves to the per-tick path (min, nearest...)
    whole, stepped = Simulation(prog, 4, backend="numba"), Simulation(prog, 4, backend="numpy")
    assert whole.advance(5) == 5 and whole.advance(7) == 7
    stepped.run(12)
    assert_same_state([stepped, whole], prog)


MIXED = """
robot eye { fov cone 1.2; range 6 }
robot noisy { fov front 0.4 3; neighbor_dropout 0.2 }
world { size 30 x 30; edges wrap }
agent a {
  robot eye
  count 40
  sense 8
  velocity (cos(index), sin(index * 0.3))
  var x2 = 0
  var v2 = (0, 0)
  status s {
    let near = neighbors() where other.kind == b
    x2 = count(near) + count(neighbors(5))
    v2 = sum(near : other.pos - pos) + sum(neighbors() : other.vel)
  }
}
agent b {
  robot noisy
  count 30
  sense 7
  velocity (sin(index), cos(index))
  var x2 = 0
  status s {
    x2 = count(neighbors() where other.kind == a)
    velocity = velocity + (0.01, 0)
  }
}
"""


def test_a_view_beside_a_kind_with_draws_gives_the_references_state():
    """One kind's view tested in the search, another's dropout drawn by the sensing
    model, in one program: 25 ticks of the reference's state, and neighbours seen."""
    prog, sims = run_both(MIXED, steps=25, seed=7, other="numba")
    assert_same_state(sims, prog)
    assert sims[1].agents.cols["x2"].min() >= 0 and sims[1].agents.cols["x2"].sum() > 0


def test_a_radius_that_draws_is_drawn_once_as_the_reference_draws_it():
    """`neighbors(uniform(3, 5))` seen through a view: the compiled sum makes the set
    once, so the draws after it are the reference's (making it twice drew twice)."""
    text = """
robot eye { fov cone 1.2 }
world { size 30 x 30; edges wrap }
agent a {
  robot eye
  count 60
  sense 8
  velocity (cos(index), sin(index * 0.3))
  var x2 = 0
  status s { x2 = sum(neighbors(uniform(3, 5)) : dist) + uniform(0, 1) }
}
"""
    prog, sims = run_both(text, steps=10, seed=7, other="numba")
    assert_same_state(sims, prog)


def test_verbose_says_where_each_kinds_sensing_chose_its_neighbours():
    """`run -v` names each kind with a sensing model: its view tested in the compiled
    search, or the model's draws on numpy; whole ticks test the views too."""
    prog = compile_source(MIXED, "test.swarm")
    sim = Simulation(prog, 7, backend="numba")
    sim.run(3)
    lines = sim.backend.summary(prog)
    assert "sensing of `a`: compiled (its range and field of view tested in the search)" \
        in lines
    assert "sensing of `b`: numpy (the sensing model's dropout, noise or resolution)" \
        in lines
    assert sim.advance(2) == 2    # stepped: the kernel says why it does not take it
    assert "whole-tick kernel: no (a robot's sensing model draws in Python (its " \
        "dropout, noise or resolution))" in sim.backend.summary(prog)
    whole = compile_source(FRONT, "test.swarm")
    sim = Simulation(whole, 4, backend="numba")
    assert sim.advance(3) == 3
    assert "sensing of `a`: compiled (its range and field of view tested in the search)" \
        in sim.backend.summary(whole)
