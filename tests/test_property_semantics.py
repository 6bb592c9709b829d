"""`always P -> eventually Q within N`, neighbour queries in properties and `final`
statuses, against plain reference checkers over recorded traces."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmdsl.analysis.render import to_dot, to_mermaid
from swarmdsl.compiler import compile_source
from swarmdsl.compiler.errors import SwarmError
from swarmdsl.compiler.status_graph import kind_graphs
from swarmdsl.runtime.simulation import Simulation
from swarmdsl.testing import Monitor, state_arrays

RESPONSE = """world {{ size 30 x 30 }}
agent a {{
  count {n}
  var p = chance({pp})
  var q = false
  status s {{ p = chance({pp}); q = chance({pq}) }}
  always answered: p -> eventually q within {within}
}}
always swarm_answered: count(p) >= 2 -> eventually any(q) within {within}
"""


def _trace(text: str, steps: int, seed: int, cols):
    """(states by tick, every violation the monitor reports) over one run."""
    prog = compile_source(text, "trace.swarm")
    sim = Simulation(prog, seed)
    monitor = Monitor(prog)
    states, found = [], []
    for t in range(steps + 1):
        if t:
            sim.step()
        s = state_arrays(sim)
        states.append({c: s[c] for c in cols})
        found += monitor.check(sim, t)
    return states, found


def _first_response_failure(p, q, within):
    """Reference: (tick, rows) of the first P at t with no Q in t..t+N (p, q: (T, M))."""
    first = None
    ticks = p.shape[0]
    for t in range(ticks):
        if t + within >= ticks:
            break
        late = p[t] & ~q[t:t + within + 1].any(axis=0)
        if late.any():
            tick = t + within
            if first is None or tick < first[0]:
                first = (tick, set(np.flatnonzero(late)))
            elif tick == first[0]:
                first[1].update(np.flatnonzero(late))
    return first


@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 6), pp=st.sampled_from([0.05, 0.3, 0.7]),
       pq=st.sampled_from([0.0, 0.1, 0.4, 0.9]), within=st.integers(1, 4),
       seed=st.integers(0, 10_000))
def test_bounded_response_matches_a_reference_checker(backend, n, pp, pq, within, seed):
    text = RESPONSE.format(n=n, pp=pp, pq=pq, within=within)
    states, found = _trace(text, 20, seed, ("id", "p", "q"))
    p = np.array([s["p"] for s in states])
    q = np.array([s["q"] for s in states])
    ids = states[0]["id"]
    for name, (pp_, qq_) in (("a.answered", (p, q)),
                             ("swarm_answered", ((p.sum(axis=1) >= 2)[:, None],
                                                 q.any(axis=1)[:, None]))):
        want = _first_response_failure(pp_, qq_, within)
        got = [v for v in found if v.name == name]
        if want is None:
            assert not got
            continue
        assert got, f"{name}: expected a failure at tick {want[0]}"
        v = got[0]
        assert v.tick == want[0] and v.since == want[0] - within
        if name == "a.answered":
            assert set(v.agent_ids) == {int(ids[r]) for r in want[1]}
        assert "triggered at tick" in v.message()


LEADERS = """param r = {r}
world {{ size 40 x 40; edges wall }}
agent robot {{
  count {n}
  velocity random_direction() * 2
  status follower {{ when chance(0.2) -> leader }}
  status leader {{ when chance(0.3) -> follower }}
  invariant alone: count(neighbors(r) where other.status == leader) == 0 or status != leader
}}
"""


@settings(max_examples=20, deadline=None)
@given(n=st.integers(2, 12), r=st.sampled_from([3.0, 8.0, 20.0]), seed=st.integers(0, 999))
def test_neighbour_queries_in_properties_match_brute_force(backend, n, r, seed):
    states, found = _trace(LEADERS.format(n=n, r=r), 12, seed, ("id", "pos", "status_name"))
    want = None
    for t, s in enumerate(states):
        leader = s["status_name"] == "leader"
        d = np.linalg.norm(s["pos"][:, None] - s["pos"][None], axis=2)
        near = (d <= r) & ~np.eye(len(d), dtype=bool)
        bad = leader & (near & leader[None, :]).any(axis=1)
        if bad.any():
            want = (t, {int(i) for i in s["id"][bad]})
            break
    got = [v for v in found if v.name == "robot.alone"]
    if want is None:
        assert not got
    else:
        assert got and (got[0].tick, set(got[0].agent_ids)) == want


def test_a_property_neighbour_query_does_not_widen_what_the_program_senses():
    prog = compile_source(LEADERS.format(n=4, r=30), "p.swarm")
    assert prog.pair_radius == 0           # the program itself senses nothing


@pytest.mark.parametrize(("text", "message"), [
    ("agent a { count 1; status s { } }\ninvariant x: count(neighbors(3)) == 0",
     "2:20: only a per-agent property can query neighbours"),
    ("agent a { count 1; status s { }\n invariant x: count(neighbors()) == 0 }",
     "2:21: `neighbors` in a property takes one argument: the radius"),
    ("agent a { count 1; var p = 1; status s { }\n always x: p -> eventually true within 2 }",
     "2:12: the trigger of an `always` must be a condition (a boolean), got a number"),
    ("agent a { count 1; var p = 1; status s { }\n always x: true -> eventually p > 1 "
     "within 0 }", "2:44: `within` takes a whole number of ticks of at least 1, got 0"),
])
def test_bad_new_properties_are_located_errors(text, message):
    with pytest.raises(SwarmError) as info:
        compile_source(text, "bad.swarm")
    where, _, text = message.partition(": ")
    assert f"bad.swarm:{where}: error: {text}" in str(info.value)


DOCKING = """world {{ size 20 x 20 }}
agent a {{
  count 2
  var t = 0
  status seek {{ t = t + 1; when t > 5 -> docked }}
  {final}status docked {{ {leave} }}
}}
"""


def _warnings(text):
    return [str(w) for w in compile_source(text, "d.swarm").info.warnings]


def test_final_statuses_are_intended_ends():
    plain = _warnings(DOCKING.format(final="", leave=""))
    assert any("`docked` of `a` has no way out" in w for w in plain)
    final = DOCKING.format(final="final ", leave="")
    assert not any("no way out" in w for w in _warnings(final))
    leaving = _warnings(DOCKING.format(final="final ", leave="when t > 9 -> seek"))
    assert any("`docked` of `a` is final, but this `when` leaves it for `seek`" in w
               for w in leaving)
    info = compile_source(final, "d.swarm").info
    (g,) = kind_graphs(info.kinds, info.params)
    assert g.final == {"docked"} and g.dead_ends == []
    assert "docked --> [*]" in to_mermaid([g], final)
    assert "doubleoctagon" in to_dot([g], final)


def test_final_statuses_run_like_any_other(backend):
    prog = compile_source(DOCKING.format(final="final ", leave=""), "d.swarm")
    sim = Simulation(prog, 0)
    sim.run(8)
    assert sim.status_counts() == {"seek": 0, "docked": 2}
