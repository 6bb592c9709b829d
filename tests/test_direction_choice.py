"""`choose(K, persistence, attraction...)` in the numba backend's two loops: the same
direction as the reference's array forms, agent by agent, for fields and region kinds,
in wrap-around and walled worlds, with gains of either sign and known foods hidden."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swarmdsl.compiler import compile_source
from swarmdsl.runtime import environment
from swarmdsl.runtime.simulation import Simulation
from tests.conftest import backend_names, run_both
from tests.test_compiled import assert_same_state

pytestmark = pytest.mark.skipif("numba" not in backend_names(),
                                reason="the numba backend is not installed")

ATTRACTIONS = ["{g} * trail", "{g} * food", "{g} * unknown(food, known)",
               "{g} * (1 + id % 3) * trail", "{g} * nest"]


@st.composite
def choosing_programs(draw):
    edges = draw(st.sampled_from(["wrap", "wall"]))
    foods = draw(st.lists(st.tuples(st.integers(0, 60), st.integers(0, 40),
                                    st.sampled_from([2, 3.5, 6, 9])), min_size=1, max_size=4))
    gains = st.sampled_from([1, 2.5, 30, -4, 0])
    attractions = draw(st.lists(st.sampled_from(ATTRACTIONS), min_size=1, max_size=3))
    k = draw(st.sampled_from([3, 4, 8, 24]))
    persistence = draw(st.sampled_from([0, 0.35, 0.9, 1]))
    sense = draw(st.sampled_from(["sense 12", "sense 3", ""]))   # none: a grid spacing
    regions = "\n".join(f"food f{i} = circle({x}, {y}, {r})"
                        for i, (x, y, r) in enumerate(foods))
    parts = ", ".join(a.format(g=draw(gains)) for a in attractions)
    return f"""
world {{ size 60 x 40; grid 4; edges {edges} }}
field trail {{ decay 0.1; diffuse 0.05 }}
nest home = circle(30, 20, 5)
{regions}
agent ant {{
  count 12
  {sense}
  labels known
  status go {{
    when touching(food) -> go {{ learn(known, touched(food)) }}
    deposit(trail, 1, 4)
    velocity = unit(choose({k}, {persistence}, {parts})) * 1.5
  }}
}}
"""


def _counting(monkeypatch) -> list:
    """For each `choose` on numba, whether the compiled loops made it (the reference's
    ticks never ask)."""
    taken = []
    real = environment.Environment._choose_compiled

    def spy(self, *args):
        got = real(self, *args)
        taken.append(got is not None)
        return got
    monkeypatch.setattr(environment.Environment, "_choose_compiled", spy)
    return taken


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(text=choosing_programs(), seed=st.integers(0, 3))
def test_the_compiled_choice_picks_the_references_directions(text, seed, monkeypatch):
    taken = _counting(monkeypatch)
    prog, sims = run_both(text, steps=25, seed=seed, other="numba")
    assert_same_state(sims, prog)
    assert taken == [True] * 25   # numba's ticks only, every one


def test_a_region_kind_of_other_shapes_keeps_the_array_forms(monkeypatch):
    """A rectangle's distance is its shape's own: the choice falls back, same result."""
    taken = _counting(monkeypatch)
    text = """
world { size 60 x 40; edges wrap }
food f1 = rect(10, 10, 18, 15)
food f2 = circle(40, 30, 4)
agent ant { count 9; sense 30
  status go { velocity = unit(choose(8, 0.5, 5 * food)) } }
"""
    prog, sims = run_both(text, steps=15, seed=2, other="numba")
    assert_same_state(sims, prog)
    assert taken == [False] * 15
    moved = np.abs(sims[0].agents.cols["heading"]).sum()
    assert moved > 0


@settings(max_examples=60, deadline=None)
@given(m=st.integers(1, 6), k=st.sampled_from([1, 2, 3, 8, 24]), a=st.integers(1, 3),
       persistence=st.sampled_from([0.0, 0.35, 1.0]), data=st.data())
def test_the_pick_loop_has_the_array_forms_bits(m, k, a, persistence, data):
    """The logits, weights and draw of `weighted_direction_choice` (`extra = exp(logits
    - max)`), loop against array forms: scores with exact zeros and negatives, gains of
    either sign, huge and infinite (an infinite one is the reference's error)."""
    from swarmdsl.ops import portable, portable_runtime
    from swarmdsl.runtime.choice import steps_table, weighted_direction_choice
    from swarmdsl.runtime.compiled.direction_choice import loops

    score = st.one_of(st.sampled_from([0.0, -0.0, -1.0, 1.0]),
                      st.floats(0, 5, allow_nan=False))
    S = np.array(data.draw(st.lists(score, min_size=a * m * k, max_size=a * m * k)),
                 dtype=np.float64).reshape(a, m, k)
    G = np.array(data.draw(st.lists(st.sampled_from([0.0, 1.0, -3.0, 30.0, 1e300, -1e300,
                                                     np.inf]),
                                    min_size=a * m, max_size=a * m))).reshape(a, m)
    heading = np.array(data.draw(st.lists(st.floats(-10, 10), min_size=m, max_size=m)))
    # draws that land exactly on a cumulative weight, and 0, as well as any
    draws = np.array(data.draw(st.lists(st.one_of(st.sampled_from([0.0, 0.25, 0.5]),
                                                  st.floats(0, 1, exclude_max=True)),
                                        min_size=m, max_size=m)))
    logits = np.zeros((m, k))
    with np.errstate(invalid="ignore"):   # inf * 0 and inf - inf: NaN, as meant
        for t in range(a):
            logits += G[t][:, None] * portable_runtime.log1p_array(np.maximum(S[t], 0.0))
        logits -= logits.max(axis=1, keepdims=True)
        extra = portable.exp_array(logits)
    try:
        want = weighted_direction_choice(_Draws(draws), heading, k, persistence, extra)
    except ValueError as err:
        want = str(err)
    out = np.empty(m, np.int64)
    bad = loops()[1](S, G, steps_table(k, persistence), heading, k / (2.0 * np.pi),
                     draws, out)
    if isinstance(want, str):
        assert bad == 1 and "weights_extra must be finite" in want
    else:
        assert bad == 0 and out.tolist() == want.tolist()


class _Draws:
    """A stream whose `random(m)` gives chosen numbers."""

    def __init__(self, values):
        self.values = values

    def random(self, m):
        assert m == len(self.values)
        return self.values.copy()


WRAPPED = """
world {{ size 60 x 40; grid 4; edges {edges} }}
food f0 = circle(1, 1, 3)
food f1 = circle(59, 20, 2)
food f2 = circle(30, 39.5, 4)
food f3 = circle(30, 20, 6)
food f4 = circle(10, 30, 2)
food f5 = circle(20, 30, 2)
agent ant {{ count 1; labels known
  status go {{ velocity = unit(choose(8, 0.5, food)) }} }}
"""


@settings(max_examples=40, deadline=None)
@given(edges=st.sampled_from(["wrap", "wall"]), k=st.sampled_from([3, 8, 24]),
       data=st.data())
def test_the_scores_loop_has_the_array_forms_bits(edges, k, data):
    """Each direction's closeness to the nearest food in sight, loop against
    `Environment._bearing_scores`: points anywhere, near the edges most (where the
    nearest copy of a food is across the edge in a wrap-around world), foods hidden by
    known labels, sight from nothing to the whole world."""
    from swarmdsl.runtime.choice import angles_of
    from swarmdsl.runtime.compiled.direction_choice import loops

    sim = Simulation(compile_source(WRAPPED.format(edges=edges), "t.swarm"), 0,
                     backend="numpy")
    env = sim.environment
    m = data.draw(st.integers(1, 12))
    # (15, 30) sees f4 and f5 at one distance: the first is the nearest, as argmin's
    coord = st.one_of(st.floats(0, 59.99),
                      st.sampled_from([0.0, 0.5, 59.5, 39.5, 30.0, 15.0]))
    pos = np.array(data.draw(st.lists(st.tuples(coord, coord), min_size=m, max_size=m)),
                   dtype=np.float64) % [60.0, 40.0]
    look = np.array(data.draw(st.lists(st.sampled_from([0.5, 3.0, 8.0, 25.0, 80.0]),
                                       min_size=m, max_size=m)))
    known = np.array(data.draw(st.lists(st.integers(0, 63), min_size=m, max_size=m)),
                     dtype=np.int64)
    angles = angles_of(k)
    want = env._bearing_scores("food", pos, look, angles, known)
    cx, cy, r = (np.asarray(a, np.float64) for a in env._circle_table("food"))
    bits, centers = env._bearing_table("food")
    box = np.array([60.0, 40.0] if edges == "wrap" else [0.0, 0.0])
    got = np.empty((m, k))
    loops()[0](pos, look, cx, cy, r, bits, known, centers, angles, box, box, got)
    assert got.tobytes() == want.tobytes()


@pytest.mark.parametrize("draw", [0.0, 0.5, 0.9999999999999999])
def test_with_no_persistence_an_ant_keeps_its_direction_whatever_it_draws(draw):
    """Persistence 0 leaves one direction of positive weight, the heading's own: the
    pick is that one for every draw, 0 included (the cumulative weights before it are 0,
    and a draw of 0 is not past them)."""
    from swarmdsl.runtime.choice import steps_table, weighted_direction_choice
    from swarmdsl.runtime.compiled.direction_choice import loops

    k = 8
    heading = np.array([3 * 2 * np.pi / k, -2 * np.pi / k, 0.0])
    draws = np.full(3, draw)
    out = np.empty(3, np.int64)
    bad = loops()[1](np.zeros((1, 3, k)), np.zeros((1, 3)), steps_table(k, 0.0), heading,
                     k / (2 * np.pi), draws, out)
    want = weighted_direction_choice(_Draws(draws), heading, k, 0.0, np.ones((3, k)))
    assert bad == 0 and out.tolist() == want.tolist() == [3, 7, 0]
