"""`FIELD at POINT`: a field read at any point, with `sample`'s interpolation, edges and
sensing model, on scalar and vector twins, deposited fields and refined grids."""

from __future__ import annotations

import functools
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from swarmdsl.compiler import ast, compile_source
from swarmdsl.compiler.errors import SwarmError, SwarmRuntimeError
from swarmdsl.compiler.parse import parse
from swarmdsl.runtime.simulation import Simulation

W, H = 200.0, 120.0
SHIFT = np.array([37.0, -23.0])


def _lin(x, y):
    return 3 + 0.7 * x - 0.4 * y


def _flow(x, y):
    return np.stack([y / 10 - 2, 1 - x / 50], axis=-1)


PROBES = """world { size 200 x 120; grid 20; REFINE }
field lin { twin 3 + 0.7 * pos.x - 0.4 * pos.y }
field flow { twin (pos.y / 10 - 2, 1 - pos.x / 50) }
agent probe {
  count 12
  place uniform
  var here = 0
  var same = 0
  var there = 0
  var flow_here = (0, 0)
  var flow_same = (0, 0)
  var flow_there = (0, 0)
  status s {
    here = lin at pos
    same = sample(lin)
    there = lin at (pos + (37, -23))
    flow_here = flow at pos
    flow_same = sample(flow)
    flow_there = flow at (pos + (37, -23))
    velocity = (0, 0)
  }
}
"""
REFINEMENTS = {
    "uniform": "",
    "one level": "refine rect(0, 0, 100, 60) 1",
    "two levels": "refine circle(100, 60, 50) 2; refine rect(150, 0, 200, 40) 1",
}


@functools.cache
def _probes(refine: str):
    return compile_source(PROBES.replace("REFINE", refine), "probes.swarm")


def _read_at(refine: str, pts: np.ndarray, seed: int = 0):
    """The probes' readings with the agents standing at `pts` for one tick."""
    sim = Simulation(_probes(refine), seed)
    sim.agents.cols["pos"][:] = pts
    sim.step()
    return sim


def _world_points(n):
    return arrays(np.float64, (n, 2), elements=st.floats(0, 1)).map(
        lambda u: u * [W, H])


# ---- syntax: precedence and the other uses of the word `at` ----

def _value(src: str) -> ast.Expr:
    agent = parse(f"agent a {{ status s {{ x = {src} }} }}").decls[0]
    return agent.items[0].body[0].value


def test_at_binds_tighter_than_arithmetic_on_both_sides():
    e = _value("force at pos * 2")
    assert isinstance(e, ast.BinOp) and e.op == "*" and isinstance(e.left, ast.FieldAt)
    e = _value("a + heat at pos")
    assert isinstance(e, ast.BinOp) and e.op == "+" and isinstance(e.right, ast.FieldAt)
    e = _value("-heat at pos ^ 2")                   # like -x ^ 2: -((heat at pos) ^ 2)
    assert isinstance(e, ast.Neg) and isinstance(e.operand.left, ast.FieldAt)
    e = _value("heat at other.pos")                  # `.` binds tighter still
    assert isinstance(e.point, ast.Attr) and e.point.name == "pos"
    e = _value("heat at (pos + unit(heading) * 3)")
    assert isinstance(e.point, ast.BinOp) and e.point.op == "+"


def test_at_cannot_chain():
    with pytest.raises(SwarmError, match="1:35: error: unexpected `at`"):
        parse("agent a { status s { x = h at pos at pos } }", "t.swarm")


def test_at_stays_a_name_where_a_name_is_meant(backend, compile_src):
    """`at` as a message value, a variable and `msg.at` keep working."""
    prog = compile_src("""world { size 50 x 50; grid 10 }
field heat { twin pos.x }
agent a {
  count 5
  place uniform
  message seen bool at vec
  var at = 0
  var got = (0, 0)
  status s {
    at = heat at pos
    broadcast(at, pos)
    broadcast(seen, at > 10)
    got = mean(heard() : msg.at)
  }
}
""")
    layout = [a.id for o in prog.info.tree.decls[-1].items
              if isinstance(o, ast.Option) and o.name == "message" for a in o.args]
    assert layout == ["seen", "bool", "at", "vec"]
    sim = Simulation(prog, 0)
    sim.run(2)
    np.testing.assert_allclose(sim.agents.cols["at"], sim.agents.cols["pos"][:, 0],
                               atol=1e-9)


# ---- the same reading as `sample` ----

@pytest.mark.parametrize("refine", REFINEMENTS.values(), ids=list(REFINEMENTS))
def test_at_pos_is_sample_bit_for_bit(backend, refine):
    sim = Simulation(_probes(refine), 3)
    sim.step()
    cols = sim.agents.cols
    np.testing.assert_array_equal(cols["here"], cols["same"])
    np.testing.assert_array_equal(cols["flow_here"], cols["flow_same"])


DEPOSITED = """world { size 200 x 120; grid 20; refine rect(40, 20, 140, 100) 2 }
field trail { decay 0.01; diffuse 0.2 }
agent walker {
  count 40
  place uniform
  velocity random_direction() * 3
  var here = 0
  var same = 0
  var ahead_at = 0
  var ahead_sample = 0
  status s {
    here = trail at pos
    same = sample(trail)
    ahead_at = trail at (pos + unit(heading) * 7)
    ahead_sample = sample(trail, pos + unit(heading) * 7)
    deposit(trail, 1)
    velocity = rotate(velocity, 0.1)
  }
}
"""


def test_a_deposited_field_on_a_refined_grid_reads_as_sample_does(run_src):
    sim = run_src(DEPOSITED, steps=25)
    cols = sim.agents.cols
    assert cols["here"].max() > 0.1                  # something was laid and is read
    np.testing.assert_array_equal(cols["here"], cols["same"])
    np.testing.assert_array_equal(cols["ahead_at"], cols["ahead_sample"])
    assert not np.array_equal(cols["here"], cols["ahead_at"])


# ---- interpolation: exact on linear twins, clamped at walls ----

@settings(max_examples=30)
@given(pts=_world_points(12))
@pytest.mark.parametrize("refine", REFINEMENTS.values(), ids=list(REFINEMENTS))
def test_a_linear_twin_reads_its_formula_anywhere(backend, refine, pts):
    """Bilinear interpolation is exact on a linear field, on every refinement level;
    a point past a wall reads the field at the nearest point of the world."""
    cols = _read_at(refine, pts).agents.cols
    np.testing.assert_allclose(cols["here"], _lin(*pts.T), rtol=0, atol=1e-9)
    q = pts + SHIFT
    inside = np.clip(q, 0, [W, H])
    np.testing.assert_allclose(cols["there"], _lin(*inside.T), rtol=0, atol=1e-9)
    np.testing.assert_allclose(cols["flow_there"], _flow(*inside.T), rtol=0, atol=1e-9)


def test_a_point_far_past_the_walls_reads_the_corner(run_src):
    sim = run_src(PROBES.replace("REFINE", "").replace("(37, -23)", "(1000, 1000)"))
    np.testing.assert_allclose(sim.agents.cols["there"], _lin(W, H), atol=1e-9)
    np.testing.assert_allclose(sim.agents.cols["flow_there"],
                               np.broadcast_to(_flow(W, H), (12, 2)), atol=1e-9)


WRAPPED = """world { size 100 x 80; grid 10; edges wrap }
field lin { twin 3 + 0.7 * pos.x - 0.4 * pos.y }
agent probe {
  count 10
  place uniform
  var here = 0
  var round_once = 0
  var round_back = 0
  status s {
    here = lin at pos
    round_once = lin at (pos + (300, -160))
    round_back = lin at (pos - (100, 240))
    velocity = (0, 0)
  }
}
"""


@settings(max_examples=30)
@given(pts=arrays(np.float64, (10, 2), elements=st.floats(0, 1)).map(
    lambda u: u * [90.0, 70.0]))
def test_a_wrap_around_world_wraps_the_point(backend, pts):
    """Whole periods away is the same place. Off the seam cells (between the last node
    and the first, where the grid joins itself) a linear twin is exact."""
    sim = Simulation(_wrapped(), 0)
    sim.agents.cols["pos"][:] = pts
    sim.step()
    cols = sim.agents.cols
    want = _lin(*pts.T)
    for col in ("here", "round_once", "round_back"):
        np.testing.assert_allclose(cols[col], want, rtol=0, atol=1e-9)


@functools.cache
def _wrapped():
    return compile_source(WRAPPED, "wrapped.swarm")


NEIGHBOURS = """world { size 60 x 60; grid 10; edges wrap }
field heat { twin 5 + sin(pos.x / 60 * 2 * pi) + pos.y / 10 }
field wind { twin (cos(pos.y / 60 * 2 * pi), 0.5) }
agent bug {
  count 40
  place uniform
  sense 15
  var mine = 0
  var theirs_read = 0
  var theirs_told = 0
  var crowd = 0
  var pushed = (0, 0)
  status s {
    mine = sample(heat)
    theirs_read = sum(neighbors() : heat at other.pos)
    theirs_told = sum(neighbors() : other.mine)
    crowd = count(neighbors())
    pushed = wind at pos * 2
    velocity = (0, 0)
  }
}
"""


def test_in_an_aggregate_a_neighbour_is_read_where_it_stands(run_src):
    """`other.pos` is the neighbour's nearest image, maybe past the seam; the wrapped
    point is where the neighbour is, so the reading is what it read there itself."""
    sim = run_src(NEIGHBOURS, steps=2)   # tick 1 reads `other.mine` from tick 0
    cols = sim.agents.cols
    assert (cols["crowd"] > 0).mean() > 0.8
    np.testing.assert_allclose(cols["theirs_read"], cols["theirs_told"], atol=1e-9)
    x = cols["pos"][:, 1]
    np.testing.assert_allclose(cols["pushed"][:, 1], 1.0, atol=1e-12)
    assert np.abs(cols["pushed"][:, 0]).max() <= 2 + 1e-9 and x.std() > 0


# ---- sensing models ----

SENSED = """robot eye { range 30 }
world { size 200 x 120; grid 20 }
field lin { twin 3 + 0.7 * pos.x - 0.4 * pos.y }
agent KIND {
  ROBOT
  count 12
  place uniform
  var near = 0
  var far = 0
  var far_ahead = 0
  status s {
    near = lin at (pos + (18, -23))
    far = lin at (pos + (18, -25))
    far_ahead = lin at (pos + unit(heading) * 31)
    velocity = (0, 0)
  }
}
"""


def test_a_robot_reads_a_field_only_within_its_range(backend, compile_src):
    prog = compile_src(SENSED.replace("KIND", "a").replace("ROBOT", "robot eye"))
    warnings = [(w.span.line, w.span.col, w.message) for w in prog.info.warnings
                if "range" in w.message]
    assert warnings == [
        (13, 11, "this reading is 30.8058 from the agent, beyond the range 30 of robot "
                 "`eye`: it always reads 0"),
        (14, 17, "this reading is 31 from the agent, beyond the range 30 of robot `eye`: "
                 "it always reads 0")]
    sim = Simulation(prog, 0)
    sim.step()
    cols = sim.agents.cols
    q = np.clip(cols["pos"] + [18, -23], 0, [W, H])
    np.testing.assert_allclose(cols["near"], _lin(*q.T), atol=1e-9)   # 29.2 away: in range
    assert (cols["far"] == 0).all() and (cols["far_ahead"] == 0).all()


def test_without_a_sensing_range_any_point_is_read(backend, compile_src):
    prog = compile_src(SENSED.replace("KIND", "a").replace("ROBOT", ""))
    assert not [w for w in prog.info.warnings if "range" in w.message]
    sim = Simulation(prog, 0)
    sim.step()
    cols = sim.agents.cols
    q = np.clip(cols["pos"] + [18, -25], 0, [W, H])
    np.testing.assert_allclose(cols["far"], _lin(*q.T), atol=1e-9)


# ---- located mistakes ----

MISTAKES = """world { size 100 x 100; grid 10 }
field heat { twin pos.x }
field wind { twin (1, 0) }
nest home = circle(50, 50, 5)
agent a {
  var e = 0
  status s {
    BODY
  }
}
"""


@pytest.mark.parametrize("body, message", [
    ("e = hat at pos", "8:9: unknown field `hat`\n.*hint: did you mean 'heat'"),
    ("e = bogus at pos", "8:9: unknown field `bogus`\n.*hint: the fields are `heat`, "
                         "`wind`"),
    ("e = velocity at pos", "8:9: `velocity` is a vector, not a field: `at` reads a field "
                            "at a point"),
    ("e = nest at pos", "8:9: `nest` is a region, not a field"),
    ("e = (1, 2) at pos", "8:9: `at` reads a field at a point; its left side must be a "
                          "field's name, got a vector"),
    ("e = heat at 3", "8:17: the point after `at` must be a vector \\(x, y\\), got a "
                      "number"),
    ("e = heat at pos.x", "8:17: the point after `at` must be a vector"),
    ("e = wind at pos", "8:9: cannot assign a vector to `e`, which holds a number"),
    ("velocity = heat at pos", "8:16: cannot assign a number to `velocity`"),
    ("e = heat at other.pos", "8:17: `other` is only defined inside a neighbour filter"),
    ("let heat = 2\n    e = heat at pos", "8:9: `let heat` would hide the field `heat` "
                                          "\\(line 2\\)"),
])
def test_mistakes_are_located(compile_src, body, message):
    with pytest.raises(SwarmError) as err:
        compile_src(MISTAKES.replace("BODY", body))
    where, text = message.split(": ", 1)
    assert re.search(f"test.swarm:{where}: error: {text}", err.value.render(), re.S), \
        err.value.render()


def test_at_in_a_field_formula_is_an_error(compile_src):
    with pytest.raises(SwarmError, match="3:24: error: `at` reads an agent's surroundings"):
        compile_src("world { size 50 x 50; grid 10 }\nfield heat { twin pos.x }\n"
                    "field copy { twin heat at pos }\nagent a { status s { } }")


# ---- both backends ----

def test_numba_agrees_and_names_the_aggregate_it_leaves_to_numpy(tmp_path, capsys):
    pytest.importorskip("numba")
    from swarmdsl.cli import main

    prog = compile_source(NEIGHBOURS.replace("velocity = (0, 0)",
                                             "velocity = pushed + (theirs_read / 100, 0)"),
                          "n.swarm")
    runs = []
    for backend in ("numba", "numpy"):
        sim = Simulation(prog, 5, backend=backend)
        sim.run(20)
        runs.append(sim.agents.cols)
    for col in ("pos", "vel", "theirs_read", "crowd"):
        np.testing.assert_allclose(runs[0][col], runs[1][col], rtol=1e-9, atol=1e-9)
    path = tmp_path / "n.swarm"
    path.write_text(NEIGHBOURS)
    assert main(["run", str(path), "--headless", "--steps", "2", "--backend", "numba",
                 "-v"]) == 0
    err = capsys.readouterr().err
    assert "15:19 sum: numpy (a field read (`F at P`) has no compiled form per pair)" in err
    assert "16:19 sum: compiled" in err


@pytest.mark.parametrize("reading, col", [("heat at (pos * big * big)", 9),
                                          ("length(wind at (pos * big * big))", 16)])
def test_a_point_that_is_not_finite_is_a_located_fault(backend, compile_src, reading, col):
    """`big` grows 1e15-fold a tick: the point overflows before `big` itself does."""
    src = MISTAKES.replace("  var e = 0", "  count 3\n  var e = 0\n  var big = 0")
    src = src.replace("BODY", f"big = big * 1e15 + 1e15\n    e = {reading}")
    sim = Simulation(compile_src(src), 0)
    with pytest.raises(SwarmRuntimeError) as err:
        sim.run(30)
    assert f"test.swarm:11:{col}: error: the point where" in str(err.value)
    assert "the point where" in str(err.value) and "is not finite (kind `a`, status `s`, " \
        "tick" in str(err.value)


KILOBOT = """world { size 300 x 300; grid 10 }
field light { twin pos.x / 10 + pos.y / 7 }
agent bot {
  robot kilobot
  count 8
  place uniform
  var lit = 0
  var same = 0
  status s {
    lit = light at POINT
    same = sample(light)
    when lit > 1000 or same > 1000 -> s
  }
}
"""


def test_a_robot_without_a_position_sense_reads_where_it_stands(run_src, compile_src):
    """`light at pos` is `sample(light)`: a light sensor needs no idea of where it is,
    but a point built from `pos` does."""
    sim = run_src(KILOBOT.replace("POINT", "pos"), steps=3)
    np.testing.assert_array_equal(sim.agents.cols["lit"], sim.agents.cols["same"])
    assert sim.agents.cols["lit"].std() > 1
    with pytest.raises(SwarmError, match="10:21: error: `pos` needs the sense `position`, "
                                         "which robot `kilobot` lacks"):
        compile_src(KILOBOT.replace("POINT", "(pos + (1, 0))"))
