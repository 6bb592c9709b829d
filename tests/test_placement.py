"""Placements known at check time (compiler/placement.py): wholly outside the world is a
located error, partly outside a warning, and what the checker says matches where the
run really puts the agents."""

from __future__ import annotations

import numpy as np
import pytest
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


def test_a_larger_world_or_a_set_param_makes_it_fit(tmp_path, capsys):
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
    warnings = _warnings(_program(decl, place, count))
    assert len(warnings) == 1 and message in warnings[0]
    assert warnings[0].startswith("p.swarm:") and ": warning: " in warnings[0]


def test_a_region_across_the_edge_of_a_wrapped_world_places_agents_in_the_world():
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
def test_the_warning_is_true_some_agents_do_start_outside(decl, place, count):
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
