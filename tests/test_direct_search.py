"""Sums that search the cell list themselves: the pairs are never written, the bits are
those of the sums over the written pairs, and anything else that reads the pairs gets
them (and next tick the sums read them too)."""

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

pytest.importorskip("numba")

from conftest import assert_backends_agree  # noqa: E402

from swarmdsl.compiler import compile_source  # noqa: E402
from swarmdsl.compiler.errors import SwarmError  # noqa: E402
from swarmdsl.runtime import spatial  # noqa: E402
from swarmdsl.runtime.simulation import Simulation  # noqa: E402
from test_compiled import assert_same_state  # noqa: E402

FLOCK = """
world {{ size 40 x 30; edges {edges} }}
agent a {{
  count 150
  sense 5
  velocity (cos(index), sin(index))
  var u = index % 5
  var n = 0
  status s {{
    let near = neighbors(5)
    let push = sum(near where dist < 2 : (pos - other.pos) / max(dist, 0.01))
    let pull = mean(near : other.pos - pos)
    n = count(near)
    velocity = normalize(vel + 0.1 * push + 0.05 * pull + 0.01 * sum(neighbors() : other.vel))
    {extra}
  }}
}}
"""


def _run(text, steps=4, written=False, monkeypatch=None, threads=None):
    """A numba run of `text`; `written`: every sum reads the written pairs."""
    if written:
        monkeypatch.setattr(spatial.CellPairs, "filled", property(lambda self: True))
    if threads:
        from swarmdsl.runtime.compiled import threads as pool

        monkeypatch.setattr(pool, "MIN_PARALLEL", 0)
        monkeypatch.setattr(pool, "count", lambda: threads)
    sim = Simulation(compile_source(text, "test.swarm"), 5, backend="numba")
    sim.run(steps)
    if monkeypatch is not None:
        monkeypatch.undo()
    return sim


def assert_same_bits(a, b):
    for col, x in a.agents.cols.items():
        assert np.array_equal(x, b.agents.cols[col], equal_nan=x.dtype.kind == "f"), col


@pytest.mark.parametrize("edges", ["wrap", "wall"])
def test_sums_alone_never_write_the_pairs_and_keep_their_bits(edges):
    text = FLOCK.format(edges=edges, extra="")
    direct = _run(text)
    assert direct.backend.search_directly
    assert not direct.pairs.filled            # the last tick wrote no pair anywhere
    assert direct.agents.cols["n"].max() > 3   # ... though every agent has neighbours
    report = "\n".join(direct.backend.summary(direct.program))
    assert ("neighbour search: compiled cell list (in 4 of 4 ticks the sums searched the "
            "cells themselves and no pair was written)") in report
    reference = Simulation(compile_source(text, "test.swarm"), 5, backend="numpy")
    reference.run(4)    # the written pairs' bits (those of every other sum), no compile
    assert_same_bits(direct, reference)


def test_a_reader_of_the_pairs_gets_them_and_the_sums_follow_next_tick(monkeypatch):
    """`min` reads the written pairs: the tick it first runs, the sums before it have
    searched the cells and the pairs are written for it; from the next tick on the sums
    read the written pairs too (no double work). Same bits either way."""
    text = FLOCK.format(edges="wrap", extra="u = min(near : dist)")
    sim = Simulation(compile_source(text, "test.swarm"), 5, backend="numba")
    sim.step()
    assert sim.pairs.filled and sim.backend.search_directly
    sim.step()
    assert not sim.backend.search_directly
    sim.run(2)
    assert "searched the cells" not in "\n".join(sim.backend.summary(sim.program))
    written = _run(text, written=True, monkeypatch=monkeypatch)
    assert_same_bits(sim, written)


def test_sums_that_search_the_cells_on_two_threads_give_the_serial_bits(monkeypatch):
    text = FLOCK.format(edges="wrap", extra="")
    serial = _run(text)
    threaded = _run(text, monkeypatch=monkeypatch, threads=2)
    assert not threaded.pairs.filled
    assert_same_bits(serial, threaded)


def test_owners_summed_tile_by_tile_give_the_bits_of_one_tile(monkeypatch):
    """A search writes down a tile of owners' candidates, then sums them: tiles of a
    few owners each (the smallest that hold the fullest neighbourhood) give the bits
    of one tile holding every owner."""
    from swarmdsl.runtime.compiled import fused

    text = FLOCK.format(edges="wall", extra="")
    one_tile = _run(text)
    monkeypatch.setattr(fused, "TILE", 1)
    small = _run(text)
    monkeypatch.undo()
    assert not small.pairs.filled
    assert_same_bits(one_tile, small)


# ---- generated programs: direct sums beside filters, narrower sets, other aggregates ----

_DIRECT = ["count(near)", "sum(near : other.u - u)", "mean(near : other.vel - vel)",
           "sum(near where dist < 3 : (other.pos - pos) * u)", "any(near : other.u > u)",
           "all(near : other.u + 1 > u)", "sum(neighbors() : other.u * dist)",
           "count(neighbors(6))", "mean(neighbors() where other.u != u : other.pos - pos)"]
_WRITTEN = ["min(near : dist)", "max(near : other.u)", "count(neighbors(3))",
            "sum(near where other.u > 1 : dist)", "count(some)"]
_TARGET = {"count": "k", "sum": "k", "mean": "k", "any": "b", "all": "b", "min": "k",
           "max": "k"}


@st.composite
def direct_programs(draw):
    edges = draw(st.sampled_from(["wrap", "wall"]))
    statuses = draw(st.integers(1, 2))
    body = []
    for i in range(draw(st.integers(2, 6))):
        agg = draw(st.sampled_from(_DIRECT + _WRITTEN * draw(st.integers(0, 1))))
        vec = "(other.pos" in agg or "vel" in agg
        target = "v" if vec else _TARGET.get(agg.split("(")[0], "k")
        which = draw(st.integers(0, 8))
        if which == 0:   # a filtered set: a mask over the pairs, pending until read
            body.append(f"let some{i} = near where other.u != 2")
            agg = f"sum(some{i} : other.pos - pos)" if vec else f"sum(some{i} : other.u * dist)"
        elif which == 1:   # narrower than the table: a mask too
            body.append(f"let close{i} = neighbors(u + 2)")
            agg = f"mean(close{i} : other.vel)" if vec else f"count(close{i})"
        elif which == 2:   # a filter of a filtered set: the first mask is worked out
            body.append(f"let some{i} = near where other.u != 2")
            body.append(f"let more{i} = some{i} where dist > 2")
            agg = f"sum(more{i} : other.pos - pos)" if vec else f"count(more{i})"
        body.append(f"{target} = {agg}")
    if draw(st.booleans()):
        body.append("u = u + 1")
    stmts = "\n    ".join(body)
    switch = "when k > 2 -> t" if statuses == 2 else ""
    second = ("status t { v = sum(neighbors() : other.pos - pos); when k < 1 -> s }"
              if statuses == 2 else "")
    return f"""
world {{ size 24 x 16; edges {edges} }}
agent a {{
  count 50
  sense 6
  velocity (cos(index), sin(index))
  var u = index % 4
  var k = 0
  var b = false
  var v = (0, 0)
  status s {{
    let near = neighbors(6)
    {stmts}
    velocity = vel + 0.01 * v
    {switch}
  }}
  {second}
}}
"""


def assert_same_bits_searched_and_written(monkeypatch, text):
    try:
        compile_source(text, "test.swarm")
    except SwarmError:   # not an example: a program the checker refuses
        assume(False)
    direct = _run(text, steps=3)
    written = _run(text, steps=3, written=True, monkeypatch=monkeypatch)
    assert_same_bits(direct, written)


# The searched sums against the reference (the numpy backend: the bits of sums over
# written pairs, and nothing to compile); the slow test below also compiles every sum
# again over numba's written pairs.
@settings(max_examples=3, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(direct_programs())
def test_generated_programs_give_the_same_bits_searched_and_written(text):
    assert_backends_agree(text, assert_same_state)


@pytest.mark.slow
@settings(max_examples=300, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(direct_programs())
def test_generated_programs_searched_and_written_long(monkeypatch, text):
    assert_same_bits_searched_and_written(monkeypatch, text)
    assert_backends_agree(text, assert_same_state)
