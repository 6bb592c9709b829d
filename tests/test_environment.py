"""Fields, regions, memories and direction choice through the language (programs in,
recorded outcomes out)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import stats

from swarmdsl.compiler.errors import SwarmError
from swarmdsl.runtime.runner import Run

WORLD = "world { size 100 x 80; grid 10; steps 50 }\n"


def _one_agent(body: str, extra: str = "", agent_opts: str = "", place="(40, 40)") -> str:
    return (WORLD + extra + f"""
agent a {{
  count 1
  place {place}
  {agent_opts}
  status s {{
{body}
  }}
}}
""")


# ---- fields ----

def test_decay_is_the_declared_fraction_per_tick(run_src):
    src = _one_agent("    deposit(pheromone, if tick == 0 then 8 else 0)",
                     "field pheromone { decay 0.05 }\n")
    sim = run_src(src, steps=1)
    f = sim.environment.fields["pheromone"]
    before = f.total()
    assert before == pytest.approx(8 * 0.95, rel=1e-12)
    for _ in range(10):
        prev = f.values.copy()
        sim.step()
        nz = prev > 0
        np.testing.assert_allclose(f.values[nz] / prev[nz], 0.95, rtol=1e-12)


def test_diffusion_without_decay_conserves_mass(run_src):
    src = _one_agent("    deposit(heat, if tick == 0 then 100 else 0)",
                     "field heat { diffuse 0.2 }\n")
    sim = run_src(src, steps=1)
    f = sim.environment.fields["heat"]
    sim.run(200)
    assert f.total() == pytest.approx(100.0, rel=1e-12)
    assert (f.values > 0).sum() > 50          # it spread


def test_deposit_then_sample_round_trip(run_src):
    src = _one_agent("""    deposit(scent, if tick == 0 then 3 else 0)
    seen = sample(scent)""", "field scent { }\n", "var seen = 0", place="(40, 30)")
    sim = run_src(src, steps=2)
    # tick 0 deposits on a node (after the tick); tick 1 reads back exactly that amount
    assert sim.agents.cols["seen"][0] == pytest.approx(3.0, rel=1e-12)


def test_initial_formula_is_evaluated_at_the_nodes(run_src):
    src = _one_agent("    seen = sample(warm) + ahead(warm, 10) * 0 + cone(warm, 5, 0.5) * 0",
                     "field warm { initial pos.x * 2 + pos.y }\n", "var seen = 0",
                     place="(30, 20)")
    sim = run_src(src, steps=1)
    f = sim.environment.fields["warm"]
    x, y = np.meshgrid(f.grid.grid_x, f.grid.grid_y)
    np.testing.assert_allclose(f.values, 2 * x + y)
    assert sim.agents.cols["seen"][0] == pytest.approx(80.0)


def test_gradient_points_up_the_field(run_src):
    src = _one_agent("    g = gradient(warm)", "field warm { initial pos.x * 3 }\n",
                     "var g = (0, 0)")
    sim = run_src(src, steps=1)
    np.testing.assert_allclose(sim.agents.cols["g"][0], [3.0, 0.0], atol=1e-12)


def test_unstable_diffusion_is_a_located_error(compile_src):
    with pytest.raises(SwarmError) as info:
        compile_src(WORLD + "field heat { diffuse 0.3 }\nagent a { count 1; status s { } }\n")
    err = info.value
    assert (err.span.line, err.span.col) == (2, 22)
    assert "numerically unstable" in err.message


# ---- regions ----

def test_regions_in_run_json_and_placement(backend, tmp_path, compile_src):
    src = (WORLD + """nest home = circle(20, 30, 5)
food alpha = circle(70, 40, 4)
obstacle wall = rect(50, 0, 55, 30)
agent a {
  count 40
  place in home
  status s { }
}
""")
    run = Run(compile_src(src), steps=2, out=tmp_path)
    run.execute()
    regions = json.loads((tmp_path / "run.json").read_text())["world"]["regions"]
    assert regions[0] == {"name": "home", "kind": "nest", "label": None, "shape": "circle",
                          "center": [20.0, 30.0], "radius": 5.0}
    assert regions[1]["kind"] == "food" and regions[1]["label"] == "alpha"
    assert regions[2] == {"name": "wall", "kind": "obstacle", "label": None,
                          "shape": "rect", "min": [50.0, 0.0], "max": [55.0, 30.0]}
    pos = run.sim.agents.cols["pos"]
    assert (np.hypot(pos[:, 0] - 20, pos[:, 1] - 30) <= 5).all()
    with np.load(tmp_path / "fields.npz") as data:
        assert list(data["grid_x"]) == list(np.arange(11) * 10.0)


def test_region_tests_and_food_labels(run_src):
    src = (WORLD + """nest home = circle(20, 30, 5)
food alpha = circle(20, 30, 2)
food beta = circle(70, 40, 4)
agent a {
  count 2
  place if index == 0 then (20, 30) else (72, 40)
  labels known
  var in_home = false
  var near = false
  var far = 0
  var knows_beta = false
  status s {
    in_home = inside(home)
    near = touching(nest, 1)
    far = distance_to(beta)
    learn(known, touched(food))
    knows_beta = knows(known, beta)
  }
}
""")
    sim = run_src(src, steps=1)
    c = sim.agents.cols
    assert list(c["in_home"]) == [True, False]
    assert list(c["near"]) == [True, False]
    assert c["far"][0] == pytest.approx(np.hypot(50, 10) - 4) and c["far"][1] == 0
    assert list(c["knows_beta"]) == [False, True]
    assert list(c["known:bits"]) == [1, 2]   # alpha is label 0, beta label 1


WRAP_REGIONS = """world { size 100 x 100; edges wrap }
region small = circle(98, 50, 1)
region across = circle(99, 20, 3)
region spike = polygon((97, 80), (104, 80), (100, 86))
food alpha = rect(97, 15, 103, 25)
agent a {
  count 3
  labels known
  place if index == 0 then (2, 50) else if index == 1 then (1.5, 20) else (50, 20)
  objective home = small
  var d = 0
  var d_spike = 0
  var in_across = false
  var near_alpha = false
  var knows_alpha = false
  var goal = (0, 0)
  status s {
    d = distance_to(small)
    d_spike = distance_to(spike)
    in_across = inside(across)
    near_alpha = touching(alpha, 1.5)
    learn(known, touched(alpha, 1.5))
    knows_alpha = knows(known, alpha)
    goal = target(home)
  }
}
"""


def test_regions_repeat_across_the_edges_of_a_wrapped_world(other_backend):
    """A wrap-around world is a torus: a region near one edge is near the agents just
    across the other, and a circle crossing the right edge holds points at the left one
    (measured as if the world had walls, the first distance was 95, not 3)."""
    from conftest import run_both

    _prog, sims = run_both(WRAP_REGIONS, other=other_backend)
    for sim in sims:
        c = sim.agents.cols
        assert c["d"][0] == pytest.approx(3.0)
        assert c["d_spike"][0] == pytest.approx(30.0)                # (2, 50) to (102, 80)
        assert list(c["in_across"]) == [False, True, False]
        assert list(c["near_alpha"]) == [False, True, False]
        assert list(c["knows_alpha"]) == [False, True, False]
        np.testing.assert_allclose(c["goal"][0], [99.0, 50.0])      # across the edge
    for col in ("d", "d_spike", "in_across", "goal"):
        np.testing.assert_array_equal(sims[0].agents.cols[col], sims[1].agents.cols[col])


def test_an_obstacle_across_the_edge_of_a_wrapped_world_cannot_be_entered(run_src):
    src = """world { size 100 x 100; edges wrap }
obstacle wall = rect(-5, 0, 3, 100)
agent a {
  count 1
  place (50, 50)
  status s { velocity = (2, 0) }
}
"""
    sim = run_src(src, steps=40)
    assert 50 < sim.agents.cols["pos"][0, 0] < 95   # stopped before the wall's copy at 95


def test_obstacles_cannot_be_entered(run_src):
    src = _one_agent("    velocity = (3, 0)", "obstacle wall = rect(50, 0, 60, 80)\n")
    sim = run_src(src, steps=20)
    assert sim.agents.cols["pos"][0, 0] < 50


# ---- memory ----

def test_retrace_returns_exactly_to_the_start(run_src):
    src = WORLD + """nest home = circle(13.3, 17.7, 0.5)
agent a {
  count 5
  place in home
  memory trail 30
  var start = (0, 0)
  status out {
    when tick == 0 -> out { start = pos }
    velocity = unit(choose(24, 0.8)) * 3.7
    remember(trail)
    when len(trail) >= 12 -> back { velocity = (0, 0) }
  }
  status back {
    retrace(trail)
    when len(trail) == 0 -> home_again
  }
  status home_again { velocity = (0, 0) }
}
"""
    sim = run_src(src, steps=40)
    c = sim.agents.cols
    assert (c["status"] == 2).all()
    np.testing.assert_array_equal(c["pos"], c["start"])   # bit for bit


def test_retrace_crosses_back_over_the_edge_of_a_wrapped_world(backend):
    """A path that crossed the edge of a wrap-around world is retraced back across it,
    step by step at the speed it was walked, to exactly the start (the long way round,
    cut short by max_speed, ended the retrace 85 units from the start)."""
    from swarmdsl.compiler import compile_source
    from swarmdsl.runtime.simulation import Simulation

    src = """world { size 100 x 100; edges wrap }
agent a {
  count 1
  place (98.3, 50.7)
  max_speed 2
  memory trail 100
  status out {
    remember(trail)
    velocity = (1.7, -0.3)
    when len(trail) >= 6 -> back
  }
  status back {
    retrace(trail)
    when len(trail) == 0 -> home
  }
  status home { velocity = (0, 0) }
}
"""
    sim = Simulation(compile_source(src, "wrap.swarm"), seed=0, backend=backend)
    sim.run(20)
    c = sim.agents.cols
    assert sim.program.status_display[c["status"][0]] == "home"
    np.testing.assert_array_equal(c["pos"][0], [98.3, 50.7])   # bit for bit


def test_a_full_memory_forgets_its_oldest_point(run_src):
    src = _one_agent("""    velocity = (1, 0)
    remember(trail)
    n = len(trail)""", agent_opts="memory trail 5\n  var n = 0")
    sim = run_src(src, steps=9)
    assert sim.agents.cols["n"][0] == 5
    mem = sim.environment.memories["trail"]
    rows = np.array([0])
    pts = [mem.pop(sim.agents.cols, rows)[0][0, 0] for _ in range(5)]
    assert pts == [48.0, 47.0, 46.0, 45.0, 44.0]


# ---- choice ----

def _choice_program(k=8, persistence=0.5, extra=""):
    return WORLD + f"""{extra}
agent a {{
  count 4000
  place (50, 40)
  heading 0
  var angle = 0
  status s {{
    angle = choose({k}, {persistence}{', 3 * food' if extra else ''})
  }}
}}
"""


def test_choose_never_picks_the_reverse_and_matches_the_weights(run_src):
    sim = run_src(_choice_program(), steps=1, seed=3)
    idx = np.rint(sim.agents.cols["angle"] / (2 * np.pi / 8)).astype(int) % 8
    counts = np.bincount(idx, minlength=8)
    assert counts[4] == 0                       # straight back: never
    w = 0.5 ** np.array([0, 1, 2, 3, 0, 3, 2, 1], dtype=float)
    w[4] = 0
    expected = w / w.sum() * counts.sum()
    keep = expected > 0
    assert stats.chisquare(counts[keep], expected[keep]).pvalue > 0.01


def test_choose_is_drawn_toward_sensed_food(run_src):
    src = _choice_program(extra="food alpha = circle(50, 55, 3)").replace(
        "place (50, 40)", "place (50, 40)\n  sense 20")
    sim = run_src(src, steps=1, seed=1)
    idx = np.rint(sim.agents.cols["angle"] / (2 * np.pi / 8)).astype(int) % 8
    counts = np.bincount(idx, minlength=8)
    angles = 2 * np.pi * np.arange(8) / 8
    w = 0.5 ** np.array([0, 1, 2, 3, 0, 3, 2, 1], dtype=float)
    w[4] = 0
    w *= (1 + np.maximum(np.cos(angles - np.pi / 2), 0)) ** 3   # food straight up, gain 3
    expected = w / w.sum() * counts.sum()
    keep = expected > 0
    assert counts[~keep].sum() == 0
    assert stats.chisquare(counts[keep], expected[keep]).pvalue > 0.01
    assert counts[2] > 2.5 * 0.25 / 2.75 * counts.sum()   # up: far likelier than without


# ---- outputs ----

def test_snapshot_and_fields_npz_carry_fields_and_regions(backend, tmp_path, compile_src):
    src = _one_agent("    deposit(pheromone, 1)\n    velocity = (1, 0)",
                     "field pheromone { decay 0.1 }\nfield warmth { initial 2 }\n"
                     "food alpha = circle(70, 40, 4)\n")
    run = Run(compile_src(src), steps=6, out=tmp_path, every=2)
    run.execute()
    snap = run.sim.snapshot()
    assert set(snap.fields) == {"pheromone", "warmth"}
    assert snap.fields["pheromone"].shape == (9, 11)
    assert snap.regions[0]["label"] == "alpha"
    with np.load(tmp_path / "fields.npz") as data:
        assert list(data["ticks"]) == [0, 2, 4, 6]
        assert data["pheromone"].shape == (4, 9, 11)
        assert data["pheromone"][0].sum() == 0 and data["pheromone"][-1].sum() > 0
        np.testing.assert_array_equal(data["warmth"], 2.0)
        np.testing.assert_array_equal(data["grid_y"], np.arange(9) * 10.0)


def test_a_negative_gain_repels(run_src):
    extra = "field smell { initial if pos.y > 50 then 5 else 0 }"
    src = _choice_program(extra="").replace("angle = choose(8, 0.5)",
                                            "angle = choose(8, 0.5, -4 * smell)")
    src = src.replace("agent a {", extra + "\nagent a {").replace(
        "place (50, 40)", "place (50, 40)\n  sense 20")
    sim = run_src(src, steps=1, seed=2)
    up = np.sin(sim.agents.cols["angle"]) > 0.1
    down = np.sin(sim.agents.cols["angle"]) < -0.1
    assert down.sum() > 5 * up.sum()     # the smell lies north: agents turn south


def test_misspelt_field_gets_a_hint(compile_src):
    with pytest.raises(SwarmError) as info:
        compile_src("field pheromone { }\nagent a { count 1; var v = 0\n"
                    "  status s { v = sample(pheromon) } }\n")
    assert info.value.hint == "did you mean 'pheromone'?"


def test_at_edge_clear_and_label_count(run_src):
    src = WORLD + """food alpha = circle(50, 40, 3)
agent a {
  count 2
  place if index == 0 then (95, 40) else (50, 40)
  memory trail 10
  labels known
  var edge = false
  var near = false
  var n = 0
  var k = 0
  status s {
    edge = at_edge()
    near = at_edge(35)
    remember(trail)
    remember(trail)
    learn(known, alpha)
    n = len(trail)
    k = len(known)
    when index == 0 -> s { clear(trail); clear(known) }
  }
}
"""
    sim = run_src(src, steps=1)
    c = sim.agents.cols
    assert list(c["edge"]) == [True, False]
    assert list(c["near"]) == [True, False]
    assert list(c["n"]) == [2, 2] and list(c["k"]) == [1, 1]
    assert list(c["trail:len"]) == [0, 2] and list(c["known:bits"]) == [0, 1]
