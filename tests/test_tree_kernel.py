"""Behaviour trees and declared regions in the whole-tick kernel (`compiled/tree_plan.py`,
`compiled/tree_kernel.py`): runs taken whole on numba give the numpy reference's
stepped state bit for bit, tree memory columns included; what the kernel cannot walk
is refused with the construct and its line, and such runs keep the per-tick path."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

pytest.importorskip("numba")

from test_tick_kernel import _run, assert_same  # noqa: E402
from test_trees_reference import exits, pre_whens, program_text, tree_strategy  # noqa: E402

from swarmdsl import load_program  # noqa: E402
from swarmdsl.compiler import compile_source  # noqa: E402
from swarmdsl.compiler.errors import SwarmCheckError  # noqa: E402
from swarmdsl.runtime import trees  # noqa: E402
from swarmdsl.runtime.compiled import tick_run  # noqa: E402
from swarmdsl.runtime.compiled.plan import Unsupported  # noqa: E402
from swarmdsl.runtime.compiled.tick_plan import plan_tick, refusal  # noqa: E402
from swarmdsl.runtime.simulation import Simulation  # noqa: E402

PROGRAMS = Path(__file__).resolve().parents[1] / "programs"

# Every kind of node, named trees, a neighbour sum in a condition, `tree running` in a
# value, a transition back to the same status, and regions (circles across the edge of
# a wrap-around world, a kind of regions) read by `inside` and `distance_to`.
EVERY_NODE = """
param broken = 0      # 1: a `move_to` target turns NaN once `a` passes 8
world { size 60 x 60; edges wrap; steps 200 }

nest home = circle(58, 30, 6)
food near = circle(10, 10, 3)
food far = circle(50, 50, 4)

tree visit(p, tol) {
  sequence { move_to(p, tol, 1.5); wait(2) }
}

agent bot {
  count 14
  place uniform
  var a = index % 5
  var b = index % 3
  var c = 0
  status s0 {
    let crowd = neighbors(4) where other.status != s2
    tree reactive fallback {
      sequence { count(crowd) > 2; velocity = (0.3, 0.2) }
      sequence { inside(home); wait(2); c += 1 }
      parallel 2 {
        repeat 3 a += 1
        retry 2 b > 1
        timeout 4 visit((30, 30), 1)
        invert b < 0
      }
      cooldown 3 force failure c += 1
    }
    on success -> s1
    when c > 6 -> s0 { c = 0 }
  }
  status s1 {
    let d = distance_to(food)
    tree sequence {
      reactive parallel 1 { move_to((5, 5), 2); d < 2 }
      force success retry forever chance(0.3)
      fallback { a > 30; visit((55 + sqrt(broken * (8 - a) + 1 - broken), 30), 2) }
    }
    c += if tree running then 1 else 0
    on success -> s2
    when c > 40 -> s0 { c = 0 }
  }
  status s2 {
    tree repeat forever sequence { a -= 1; a > -3; velocity = (0.5, -0.25) }
    on failure -> s0 { a = 0 }
  }
}
"""


def _whole_against_stepped(text_or_path, ticks: int, seed: int = 0, fails=False,
                           **overrides):
    def load():
        if isinstance(text_or_path, Path):
            return load_program(text_or_path, overrides or None)
        return compile_source(text_or_path, "test.swarm", overrides or None)
    whole, f1 = _run(load(), "numba", ticks, whole=True, seed=seed, chunks=(1, 13))
    stepped, f2 = _run(load(), "numpy", ticks, whole=False, seed=seed)
    assert_same(stepped, whole)
    if fails:
        assert f1 is not None and f1 == f2
        assert tick_run.summary(whole.backend)[0].startswith("whole-tick kernel: yes (")
        return f1
    assert f1 is None and f2 is None, (f1, f2)
    assert tick_run.summary(whole.backend)[0].startswith(
        f"whole-tick kernel: yes ({ticks} ticks")
    return whole


@pytest.mark.slow   # a kernel of its own (about 22 s); SMALL checks the path in CI
def test_patrol_runs_whole_as_it_steps():
    """The shipped behaviour-tree program: a reactive fallback, `move_to`, a named tree
    with an assignment, `inside` a dock, a transition out of the tree's status."""
    sim = _whole_against_stepped(PROGRAMS / "patrol.swarm", 300)
    assert set(sim.agents.cols["status"]) == {0, 1}   # some robots are charging


# What CI compiles (a few seconds): a walk that keeps its running child, `wait`,
# `move_to` the short way round, `inside` a circle across the edge, a transition back to
# the same status.
SMALL = """
param broken = 0      # 1: the `move_to` target turns NaN from tick 40
world { size 60 x 60; edges wrap }
nest home = circle(55, 30, 15)
agent bot {
  count 12
  place uniform
  var a = 0
  status s0 {
    tree fallback {
      sequence { inside(home); wait(2); a += 1 }
      move_to((30 + sqrt(broken * (40 - tick) + 1 - broken), 30), 1, 1.5)
    }
    on success -> s0
  }
}
"""


@pytest.mark.parametrize("text", [
    SMALL, pytest.param(EVERY_NODE, marks=pytest.mark.slow)],   # EVERY_NODE: 36 s
    ids=["small", "every-node"])
def test_trees_run_whole_as_they_step(text):
    """One kernel (compiled once: a param is no part of its shape) for three checks:
    the runs agree; a `move_to` target turning NaN stops the call at that tick, which
    runs per tick and names the leaf; and a run recording each agent's active leaf and
    tree result (`--tree-leaf`, the studio's inspector) keeps them as the reference
    does, zeroed every tick."""
    sim = _whole_against_stepped(text, 300, seed=3)
    memory = [c for c in sim.agents.cols if c.startswith("tree")]
    assert len(memory) > 3        # the tree columns were compared too

    fault = _whole_against_stepped(text, 300, seed=3, fails=True, broken="1")
    assert "`move_to` produced a non-finite velocity at tick" in fault

    whole = Simulation(compile_source(text, "test.swarm"), 3, backend="numba")
    stepped = Simulation(compile_source(text, "test.swarm"), 3, backend="numpy")
    for s in (whole, stepped):
        trees.record_active_leaf(s)
    assert refusal(whole) is None
    seen = set()
    for _ in range(30):
        assert whole.advance(4) == 4
        for _ in range(4):
            stepped.step()
        assert_same(stepped, whole)
        seen |= set(whole.agents.cols[trees.LEAF_COLUMN].tolist())
    assert len(seen) > 2


@pytest.mark.parametrize("body, why", [
    ("tree sequence { wait(a); a += 1 }", "a tree count that is not a constant at line"),
    ("tree fallback { a > uniform(0, a); a += 1 }",
     "a draw in a tree leaf whose arguments vary at line"),
    ("tree sequence { inside(box); a += 1 }", "not a circle at line"),
    ("tree sequence { move_to(box, 1); a += 1 }", "`move_to` at a region at line"),
])
def test_what_the_kernel_cannot_walk_is_refused_with_its_line(body, why):
    prog = compile_source("world { size 50 x 50 }\nnest box = rect(5, 5, 10, 10)\n"
                          "agent bot {\n  count 4\n  var a = 1\n  status go {\n"
                          f"    {body}\n  }}\n}}\n", "test.swarm")
    with pytest.raises(Unsupported, match=why):
        plan_tick(prog)


def test_a_changing_environment_is_refused_naming_what_changes():
    prog = compile_source("world { size 50 x 50 }\nnest home = circle(5, 5, 3)\n"
                          "obstacle rock = circle(30, 30, 5)\nagent bot {\n  count 4\n"
                          "  status go {\n    tree sequence { inside(home); speed > 3 }"
                          "\n  }\n}\n", "test.swarm")
    with pytest.raises(Unsupported, match=r"its environment \(obstacle `rock`\) runs in "
                                          "Python every tick"):
        plan_tick(prog)
    with pytest.raises(Unsupported, match="path memory `trail`, label set `known`"):
        plan_tick(load_program(PROGRAMS / "aco.swarm"))


# ---- random trees (the reference interpreter's programs, counts constant) ----

_trees = tree_strategy(st.integers(0, 3), max_leaves=8)


@pytest.mark.slow   # each program is a kernel of its own: 20-40 s to compile
@settings(max_examples=6, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(spec=st.tuples(*[st.tuples(_trees, exits, pre_whens)] * 3))
def test_random_trees_run_whole_as_they_step(spec):
    text = program_text(spec)
    try:
        compile_source(text, "generated.swarm")
    except SwarmCheckError:
        assume(False)
    sim = _whole_against_stepped(text, 30)
    assert sim.tick == 30 and sim.agents.n == 6


# ---- declared circles anywhere: across an edge, beyond the world, of radius 0 ----

_circle = st.tuples(st.floats(-80, 180, allow_nan=False), st.floats(-80, 180, allow_nan=False),
                    st.floats(0, 30, allow_nan=False))


@pytest.mark.slow   # one kernel per kind of edges (about 15 s each); the circles are params
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(circles=st.lists(_circle, min_size=3, max_size=3), wrap=st.booleans(),
       seed=st.integers(0, 3))
def test_inside_and_distance_to_of_any_circles_run_whole_as_they_step(circles, wrap, seed):
    params = "\n".join(f"param c{k}{a} = {v!r}" for k, c in enumerate(circles)
                       for a, v in zip("xyr", c, strict=True))
    text = f"""{params}
world {{ size 100 x 80; edges {"wrap" if wrap else "wall"} }}
food f0 = circle(c0x, c0y, c0r)
food f1 = circle(c1x, c1y, c1r)
nest n0 = circle(c2x, c2y, c2r)
agent bot {{
  count 30
  place uniform
  var d = 0
  var seen = 0
  status go {{
    d = distance_to(food)
    seen += if inside(n0) then 1 else 0
    velocity = random_direction() * 9
  }}
}}
"""
    sim = _whole_against_stepped(text, 12, seed=seed)
    cols = sim.agents.cols
    assert (cols["d"] >= 0).all() and ((cols["seen"] >= 0) & (cols["seen"] <= 12)).all()
