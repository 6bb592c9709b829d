"""Per-agent random streams: draws depend on (seed, id, tick, stream, call), not on the swarm."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import kstest

from swarmdsl.runtime.randomness import RandomSource
from swarmdsl.runtime.simulation import Simulation

# Programs without interactions: every agent's path depends only on its own draws.
LONERS = [
    """world {{ size 60 x 60; edges wrap }}
agent walker {{ count {n}; velocity random_direction()
  var t = uniform(0, 5)
  status go {{ velocity = velocity + (normal(0, 0.3), normal(0, 0.3)); t = t + random()
    when chance(0.05) -> rest }}
  status rest {{ velocity = (0, 0); when random() < 0.3 -> go }} }}""",
    """world {{ size 40 x 30 }}
nest home = circle(20, 15, 8)
agent ant {{ count {n}; place in home
  status roam {{ velocity = unit(choose(8, 0.7)) * 1.5
    when chance(0.02) -> roam }} }}""",
]


def _walk(text, n, seed, drop=(), steps=12):
    sim = Simulation(_compile(text.format(n=n)), seed)
    if drop:
        sim.agents.remove(np.isin(sim.agents.cols["id"], list(drop)))
    out = {}
    for t in range(steps):
        sim.step()
        cols = sim.agents.cols
        for i, p in zip(cols["id"], cols["pos"], strict=True):
            out.setdefault(int(i), []).append(tuple(p))
        assert t == sim.tick - 1
    return out


def _compile(text):
    from swarmdsl.compiler import compile_source
    return compile_source(text, "loners.swarm")


@settings(max_examples=15, deadline=None)
@given(prog=st.sampled_from(range(len(LONERS))), n=st.integers(2, 12), seed=st.integers(0, 2**40),
       data=st.data())
def test_removing_agents_leaves_every_other_trajectory_unchanged(backend, prog, n, seed, data):
    text = LONERS[prog]
    drop = data.draw(st.sets(st.integers(0, n - 1), min_size=1, max_size=n - 1))
    full = _walk(text, n, seed)
    fewer = _walk(text, n, seed, drop)
    assert set(fewer) == set(full) - drop
    for i, path in fewer.items():
        assert path == full[i], f"agent {i} changed when {sorted(drop)} were removed"


def test_a_larger_swarm_keeps_the_smaller_swarms_agents(backend):
    text = LONERS[1]
    small, big = _walk(text, 5, 3, steps=4), _walk(text, 9, 3, steps=4)
    assert all(big[i] == small[i] for i in small)


def test_same_seed_is_bit_identical_and_another_seed_differs(backend):
    a, b, c = (_walk(LONERS[0], 20, s, steps=8) for s in (4, 4, 5))
    assert a == b
    assert a != c


def test_draws_are_uniform_and_normal_and_independent_across_ids_ticks_and_calls():
    src = RandomSource(11)
    ids = np.arange(200_000)
    src.begin_tick(0)
    view = src.agents(ids, "k/s")
    u1, u2 = view.random(ids.size), view.random(ids.size)
    assert kstest(u1, "uniform").pvalue > 1e-4
    assert abs(np.corrcoef(u1, u2)[0, 1]) < 0.01          # two calls, one site
    assert abs(np.corrcoef(u1[:-1], u1[1:])[0, 1]) < 0.01  # neighbouring ids
    z = view.standard_normal(ids.size)
    assert kstest(z, "norm").pvalue > 1e-4
    src.begin_tick(1)
    u3 = src.agents(ids, "k/s").random(ids.size)
    assert abs(np.corrcoef(u1, u3)[0, 1]) < 0.01          # the next tick
    assert not np.array_equal(u1, src.agents(ids, "k/t").random(ids.size))  # another stream


def test_state_restores_the_same_draws():
    src = RandomSource(2)
    src.begin_tick(5)
    view = src.agents(np.arange(10), "a/b")
    view.random(10)
    saved = src.state()
    want = view.random(10)
    other = RandomSource(99)
    other.set_state(saved)
    np.testing.assert_array_equal(other.agents(np.arange(10), "a/b").random(10), want)


def test_a_draw_must_have_one_value_per_agent():
    view = RandomSource(0).agents(np.arange(4), "x")
    with pytest.raises(ValueError, match=r"size \(4, \.\.\.\)"):
        view.random(5)
    assert view.uniform(0, 1, (4, 2)).shape == (4, 2)
