"""Placements known at check time (compiler/placement.py): wholly outside the world is a
located error, partly outside a warning, and what the checker says matches where the
run really puts the agents."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import REFERENCE
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmdsl.cli import main
from swarmdsl.compiler import compile_source
from swarmdsl.compiler.errors import SwarmError
from swarmdsl.compiler.placement import _polygon_meets_box
from swarmdsl.runtime import regions as shapes
from swarmdsl.runtime.simulation import Simulation

WORLD = "(100 x 100)"
HINT = "the world spans (0, 0) to (100, 100)"


def _program(decl: str, place: str, count: int = 3) -> str:
    return f"{decl}\nagent a {{ count {count}; place {place}; status s {{ }} }}\n"


def _warnings(text: str) -> list[str]:
    return [str(w) for w in compile_source(text, "p.swarm").info.warnings]


@pytest.mark.parametrize(("decl", "place", "message"), [
    ("", "(1000, 1000)",
     f"2:26: agents of `a` would start at (1000, 1000), outside the world {WORLD}"),
    ("param x = -1", "(x, 50)",
     f"2:26: agents of `a` would start at (-1, 50), outside the world {WORLD}"),
    ("", "(200 + index, 50)",
     f"2:26: every agent of `a` would start outside the world {WORLD}: index 0 at (200, 50)"),
    ("nest n = circle(500, 500, 5)", "in n",
     f"2:29: region `n` lies outside the world {WORLD}: agents of `a` placed in it would "
     "start outside"),
    ("nest n = circle(-4, -4, 5)", "in n",      # its box meets the world, the disc not
     f"2:29: region `n` lies outside the world {WORLD}"),
    ("region r = rect(101, 0, 120, 100)", "in r", "2:29: region `r` lies outside"),
    ("region r = polygon((-10, 5), (5, -10), (-30, -30))", "in r",   # box meets it
     "2:29: region `r` lies outside"),
    ("food f = circle(-50, 50, 5)\nfood g = circle(500, 50, 5)", "in food",
     f"3:29: every `food` region lies outside the world {WORLD}: agents of `a` placed in "
     "them would start outside"),
    ("region r = polygon((0, 0), (10, 10), (20, 20))", "in r",
     "2:29: region `r` has no area: agents of `a` cannot be placed in it"),
])
def test_a_placement_wholly_outside_the_world_is_a_located_error(decl, place, message,
                                                                 assert_located_error):
    assert_located_error(_program(decl, place), message)


def test_the_cli_refuses_it_with_exit_2_and_a_hint(tmp_path, capsys):
    path = tmp_path / "far.swarm"
    path.write_text(_program("nest n = circle(500, 500, 5)", "in n"))
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith(f"{path}:2:29: error: region `n` lies outside the world")
    assert err[2].index("^") == len("   2 | ") + 28
    assert err[3].startswith(f"  hint: {HINT}")


def test_a_larger_world_or_a_set_param_makes_it_fit(backend, tmp_path, capsys):
    text = "param w = 100\nworld { size w x w }\n" + _program("nest n = circle(500, 500, 5)",
                                                               "in n")
    path = tmp_path / "fit.swarm"
    path.write_text(text)
    assert main(["check", str(path)]) == 2
    capsys.readouterr()
    assert main(["run", str(path), "--headless", "--steps", "1", "--set", "w=1000"]) == 0


@pytest.mark.parametrize(("decl", "place", "count", "message"), [
    ("nest n = circle(0, 0, 5)", "in n", 3,
     f"region `n` reaches outside the world {WORLD}: some agents of `a` placed in it would "
     "start outside"),
    ("region r = polygon((-10, 20), (20, -10), (-10, -10))", "in r", 3,
     "region `r` reaches outside"),
    ("food f = circle(50, 50, 5)\nfood g = circle(500, 50, 5)", "in food", 3,
     f"region `g` lies outside the world {WORLD}: some agents of `a` placed in it would "
     "start outside"),
    ("", "(10 * index, 50)", 20,
     f"9 of 20 agents of `a` would start outside the world {WORLD}, the first (index 11) "
     "at (110, 50)"),
])
def test_a_placement_partly_outside_is_a_warning(decl, place, count, message):
    warnings = [w for w in _warnings(_program(decl, place, count)) if "would start" in w]
    assert len(warnings) == 1 and message in warnings[0]
    assert warnings[0].startswith("p.swarm:") and ": warning: " in warnings[0]


def test_a_region_across_the_edge_of_a_wrapped_world_places_agents_in_the_world(backend):
    """In a wrap-around world a nest in a corner continues across the edges: no warning,
    and the agents drawn beyond an edge start across the other one, inside the world."""
    text = _program("world { size 100 x 100; edges wrap }\nnest n = circle(0, 0, 5)",
                    "in n", 200)
    assert _warnings(text) == []
    pos = Simulation(compile_source(text, "p.swarm"), 0).agents.cols["pos"]
    assert ((pos >= 0) & (pos < 100)).all()
    to_corner = np.minimum(pos, 100 - pos)
    assert (np.hypot(to_corner[:, 0], to_corner[:, 1]) <= 5 + 1e-9).all()
    assert (pos[:, 0] > 50).any() and (pos[:, 0] < 50).any()   # both sides of the edge


@pytest.mark.parametrize(("decl", "place", "count"), [
    ("", "(100, 0)", 3),                            # the edge is in the world
    ("", "(10 * index, 50)", 11),
    ("nest n = circle(50, 50, 50)", "in n", 3),
    ("region r = rect(0, 0, 100, 100)", "in r", 3),
    ("region r = rect(10, 10, 10, 20)", "in r", 3),  # a segment: agents on it
    ("", "(uniform(0, 1000), 5)", 3),               # not known before the run
    ("", "(100 / index, 5)", 3),                    # a fault for the run to locate
])
def test_placements_inside_or_unknown_are_silent(decl, place, count):
    assert _warnings(_program(decl, place, count)) == []


@pytest.mark.parametrize(("decl", "place", "count"), [
    ("nest n = circle(0, 0, 5)", "in n", 200),
    ("", "(10 * index, 50)", 20),
])
def test_the_warning_is_true_some_agents_do_start_outside(backend, decl, place, count):
    sim = Simulation(compile_source(_program(decl, place, count), "p.swarm"), 0)
    pos = sim.agents.cols["pos"]
    outside = ((pos < 0) | (pos > 100)).any(axis=1)
    assert outside.any() and not outside.all()


@settings(max_examples=60, deadline=None)
@given(pts=st.lists(st.tuples(st.integers(-60, 160), st.integers(-60, 160)), min_size=3,
                    max_size=5))
def test_a_polygon_said_to_miss_the_world_shares_no_point_with_it(pts):
    # any point found in both (world nodes inside it, its points in the world) refutes
    # "wholly outside", which is the verdict that turns into an error
    poly = shapes.Polygon(tuple((float(x), float(y)) for x, y in pts))
    vertices = np.asarray(poly.points)
    t = np.linspace(0, 1, 101)[:, None, None]
    on_edges = (vertices + t * (np.roll(vertices, -1, 0) - vertices)).reshape(-1, 2)
    grid = np.stack(np.meshgrid(np.linspace(0, 100, 51), np.linspace(0, 100, 51)),
                    -1).reshape(-1, 2)
    shared = ((on_edges >= 0) & (on_edges <= 100)).all(axis=1).any() or \
        poly.contains(grid).any()
    if shared:
        assert _polygon_meets_box(poly, 100.0, 100.0)


def test_count_zero_kind_placed_outside_is_still_refused():
    with pytest.raises(SwarmError, match="would start at"):
        compile_source(_program("", "(-5, -5)", 0), "p.swarm")


# ---- regions beyond the edges of a wrap-around world --------------------------------

WRAPPED = "world {{ size 100 x 60; edges {edges} }}\n{decl}\n" + """agent a {{
  count 40
  place in {region}
  var was_in = false
  var gap = -1
  status s {{
    was_in = inside({region})
    gap = distance_to({region})
  }}
}}
"""

# each region wholly outside a 100 x 60 world, and its copy a whole world away in it
FAR_REGIONS = [
    ("nest n = circle(150, 30, 5)", "n", "nest n = circle(50, 30, 5)"),
    ("region r = rect(-90, 130, -70, 150)", "r", "region r = rect(10, 10, 30, 30)"),
    ("region r = polygon((310, -50), (330, -50), (320, -35))", "r",
     "region r = polygon((10, 10), (30, 10), (20, 25))"),
    ("food f = circle(250, 90, 4)\nfood g = rect(-40, -40, -30, -30)", "food",
     "food f = circle(50, 30, 4)\nfood g = rect(60, 20, 70, 30)"),
]


def _about_placement(text: str) -> list[str]:
    return [w for w in _warnings(text) if "never read" not in w]


def _placed(text: str):
    """Where the agents started, and what `inside`/`distance_to` said after a tick."""
    sim = Simulation(compile_source(text, "p.swarm"), 0)
    start = sim.agents.cols["pos"].copy()
    sim.step()
    return start, sim.agents.cols["was_in"], sim.agents.cols["gap"]


@pytest.mark.parametrize(("decl", "region", "image"), FAR_REGIONS)
def test_a_region_beyond_a_wrapped_edge_places_agents_in_its_copy(backend, decl, region, image):
    """No error and no warning: agents start in the world, where the copy in it puts
    them, and read themselves inside the region (distance 0) as they would the copy."""
    text = WRAPPED.format(edges="wrap", decl=decl, region=region)
    assert _about_placement(text) == []
    start, was_in, gap = _placed(text)
    assert ((start >= 0) & (start < [100, 60])).all()
    copy_start, copy_in, _gap = _placed(WRAPPED.format(edges="wrap", decl=image,
                                                       region=region))
    assert was_in.all() and copy_in.all() and (gap == 0).all()
    np.testing.assert_allclose(start, copy_start, atol=1e-9)


@pytest.mark.parametrize("edges", ["wall", "repel"])
@pytest.mark.parametrize(("decl", "region", "_image"), FAR_REGIONS)
def test_beyond_a_bounded_worlds_edge_it_is_still_an_error_at_the_region(
        tmp_path, capsys, edges, decl, region, _image):
    path = tmp_path / "far.swarm"
    path.write_text(WRAPPED.format(edges=edges, decl=decl, region=region))
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err.splitlines()
    line = 3 + decl.count("\n") + 2
    col = len("  place in ") + 1
    assert err[0].startswith(f"{path}:{line}:{col}: error: ")
    assert "outside the world (100 x 60)" in err[0]
    assert err[1].startswith(f"{line:>4} |   place in {region}")
    assert err[2].index("^") == len(f"{line:>4} | ") + col - 1
    assert err[2].count("^") + err[2].count("~") == len(region)


@settings(max_examples=30, deadline=None)
@given(shape=st.sampled_from(["circle({x}, {y}, 6)", "rect({x}, {y}, {x} + 9, {y} + 4)",
                              "polygon(({x}, {y}), ({x} + 8, {y}), ({x}, {y} + 7))"]),
       x=st.integers(0, 90), y=st.integers(0, 50),
       kx=st.integers(-3, 3), ky=st.integers(-3, 3))
def test_a_region_moved_by_whole_worlds_is_the_same_region(backend, shape, x, y, kx, ky):
    """In a wrap-around world a region and its copy k worlds away start the agents at
    the same points and answer `inside` and `distance_to` alike."""
    here = shape.format(x=x, y=y)
    there = shape.format(x=x + 100 * kx, y=y + 60 * ky)
    runs = [_placed(WRAPPED.format(edges="wrap", decl=f"region r = {s}", region="r"))
            for s in (here, there)]
    assert _about_placement(WRAPPED.format(edges="wrap", decl=f"region r = {there}",
                                           region="r")) == []
    np.testing.assert_allclose(runs[0][0], runs[1][0], atol=1e-9)
    assert np.array_equal(runs[0][1], runs[1][1])
    np.testing.assert_allclose(runs[0][2], runs[1][2], atol=1e-9)


@pytest.mark.parametrize("place", ["(50, 30 + 60 * index)", "(-30, 250)",
                                   "(uniform(-200, -100), uniform(100, 200))"])
def test_a_point_beyond_a_wrapped_edge_starts_across_it(backend, place):
    """In a wrap-around world a placed point has no outside either: no warning, and the
    agents start (and are recorded at tick 0) at the matching point of the world."""
    text = WRAPPED.format(edges="wrap", decl="", region="n").replace(
        "place in n", f"place {place}").replace("inside(n)", "true").replace(
        "distance_to(n)", "0")
    assert _about_placement(text) == []
    sim = Simulation(compile_source(text, "p.swarm"), 0)
    start = sim.agents.cols["pos"]
    assert ((start >= 0) & (start < [100, 60])).all(), start
    if place == "(50, 30 + 60 * index)":
        np.testing.assert_array_equal(start, np.tile([50.0, 30.0], (40, 1)))


# ---- initial values read each other in the order they need (compiler/init_order.py) ----

def test_place_and_velocity_read_attrs_declared_in_the_kind(backend):
    """`place (r0, 100)` read r0 before it was computed: every agent started at x = 0."""
    src = """world { size 200 x 200 }
agent a {
  count 3
  attr r0 = 50 + 10 * index
  attr sp = 1 + index
  place (r0, 100)
  velocity (sp, 0)
  var start = pos.x + 1
  status s { }
}
"""
    sim = Simulation(compile_source(src, "p.swarm"), seed=0, backend=backend)
    cols = sim.agents.cols
    assert cols["pos"].tolist() == [[50, 100], [60, 100], [70, 100]]
    assert cols["vel"][:, 0].tolist() == [1, 2, 3]
    assert cols["start"].tolist() == [51, 61, 71]
    sim.step()
    assert cols["pos"][:, 0].tolist() == [51, 62, 73]


@pytest.mark.parametrize(("body", "where", "message"), [
    ("attr r0 = pos.x + 1\n  place (r0, 100)", (4, 3),
     "these initial values need each other: `place` reads `r0`; `r0` reads `pos`, which "
     "`place` sets"),
    ("place (pos.x, 100)", (3, 3), "`place` reads `pos`, which it sets itself"),
    ("attr h = heading\n  velocity (h, 1)", (4, 3),
     "these initial values need each other: `velocity` reads `h`; `h` reads `heading`, "
     "which `heading` sets; `heading` reads `velocity`, which `velocity` sets"),
])
def test_initial_values_that_need_each_other_are_located_errors(body, where, message):
    src = f"world {{ size 200 x 200 }}\nagent a {{\n  {body}\n  status s {{ }}\n}}\n"
    with pytest.raises(SwarmError) as info:
        compile_source(src, "p.swarm")
    err = info.value.diagnostics[0]
    assert err.message == message
    assert (err.span.line, err.span.col) == where


WALLED = """world {{ size 100 x 100; edges {edges} }}
obstacle wall = rect(0, 0, 60, 100)
obstacle post = circle(80, 50, 15)
agent a {{ count 400; status s {{ }} }}
"""


@pytest.mark.parametrize("edges", ["wall", "wrap"])
def test_place_uniform_draws_again_where_an_obstacle_stands(backend, edges):
    # `place uniform` drew over the whole world, so most agents began inside walls
    program = compile_source(WALLED.format(edges=edges), "walled.swarm")
    sims = [Simulation(program, seed, backend=backend) for seed in (4, 4, 5)]
    pos = sims[0].agents.cols["pos"]
    wall = shapes.Rect(0, 0, 60, 100)
    post = shapes.Circle(80, 50, 15)
    assert not (wall.contains(pos) | post.contains(pos)).any()
    assert ((pos >= 0) & (pos <= 100)).all()
    assert np.array_equal(pos, sims[1].agents.cols["pos"])      # per seed
    assert not np.array_equal(pos, sims[2].agents.cols["pos"])
    # uniform over the free area: as many on each side of x = 80, up to the draw
    left, right = (pos[:, 0] < 80).sum(), (pos[:, 0] >= 80).sum()
    assert abs(int(left) - int(right)) < 80


def test_place_uniform_around_obstacles_is_the_same_on_both_backends(other_backend):
    program = compile_source(WALLED.format(edges="wall"), "walled.swarm")
    a, b = (Simulation(program, 2, backend=name) for name in (REFERENCE, other_backend))
    assert np.array_equal(a.agents.cols["pos"], b.agents.cols["pos"])


def test_too_little_free_room_for_place_uniform_is_a_located_error(backend, tmp_path, capsys):
    path = tmp_path / "full.swarm"
    path.write_text("world { size 100 x 100 }\n"
                    "obstacle wall = rect(0, 0, 100, 99.9999)\n"
                    "agent a {\n  count 5\n  status s { }\n}\n")
    assert main(["run", str(path), "--headless", "--steps", "1"]) == 2
    err = capsys.readouterr().err
    assert "full.swarm:4:3: error: cannot place the agents of `a` outside the " \
           "obstacles" in err
    assert "Traceback" not in err


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
