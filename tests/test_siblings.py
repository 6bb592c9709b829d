"""Sums over one set share one loop over its pairs: same bits, never a stale value."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytest.importorskip("numba")

from conftest import assert_backends_agree, by_id, run_both  # noqa: E402

from swarmdsl.compiler import compile_source  # noqa: E402
from swarmdsl.runtime.compiled import siblings  # noqa: E402
from swarmdsl.runtime.simulation import Simulation  # noqa: E402
from test_compiled import assert_same_state  # noqa: E402

WRITE_BETWEEN = """
world { size 30 x 30; edges wrap }
agent a {
  count 60
  sense 4
  var q = index % 5
  var gap = 0
  var n = 0
  status s {
    let near = neighbors(4) where dist > 0.5
    let before = sum(near : other.q - q)
    q = q + 1
    let after = sum(near : other.q - q)
    n = count(near)
    gap = before - after
  }
}
"""


def _numba(text, steps, monkeypatch=None, alone=False):
    if alone:
        monkeypatch.setattr(siblings, "group", lambda cg, stmts: None)
    sim = Simulation(compile_source(text, "test.swarm"), 3, backend="numba")
    sim.run(steps)
    return sim


def test_a_sum_after_a_write_it_reads_sees_the_new_value(capsys):
    """`after` reads `q` after `q = q + 1`: it must not join `before`'s loop (it would
    see the old q); `count(near)` reads nothing written in between and joins it."""
    prog, sims = run_both(WRITE_BETWEEN, steps=3, other="numba")
    assert_same_state(sims, prog)
    gap, n = by_id(sims[1], "gap"), by_id(sims[1], "n")
    assert n.max() > 0
    np.testing.assert_allclose(gap, n, rtol=0, atol=1e-9)   # each neighbour: q one higher
    lines = "\n".join(sims[1].backend.summary(prog))
    assert "11:18 sum: compiled (one pair loop with 14:9)" in lines
    assert "13:17 sum: compiled\n" in lines
    assert "14:9 count: compiled (one pair loop with 11:18)" in lines


def test_boids_sums_share_one_loop_with_the_same_bits():
    """The shipped boids: separation, cohesion, alignment and the count in one loop,
    bit for bit what the reference gives (the numpy backend: a loop of its own for
    each sum, which is also what numba gives without shared loops, and it compiles
    nothing)."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "programs" / "boids.swarm").read_text()
    prog, sims = run_both(text, steps=5, seed=3, other="numba")
    lines = "\n".join(sims[1].backend.summary(prog))
    assert lines.count("(one pair loop with") == 4
    assert_same_state(sims, prog)


INLINE_SETS = """
world { size 30 x 30; edges wall }
agent a {
  count 80
  sense 5
  var q = index % 5
  var r = 2 + index % 3
  var k = 0
  var s = 0
  var t = 0
  var u = 0
  status s1 {
    k = count(neighbors(r + 1))
    s = sum(neighbors(r + 1) : other.q * dist)
    t = sum(neighbors(r) : other.q)
    u = sum(neighbors(uniform(2, 4)) : other.q) + count(neighbors(uniform(2, 4)))
  }
}
"""


def test_sums_over_neighbors_with_the_same_radius_share_a_loop():
    """`neighbors(r + 1)` twice is one set; `neighbors(r)` another; a radius that draws
    is a new set each time it is evaluated, so its sums keep their own loops (and the
    draws their order)."""
    prog, sims = run_both(INLINE_SETS, steps=3, other="numba")
    assert_same_state(sims, prog)
    assert by_id(sims[1], "k").max() > 0
    lines = "\n".join(sims[1].backend.summary(prog))
    assert "13:9 count: compiled (one pair loop with 14:9)" in lines
    assert "14:9 sum: compiled (one pair loop with 13:9)" in lines
    assert "15:9 sum: compiled\n" in lines
    assert lines.count("one pair loop") == 2


# ---- generated statement lists: sums of one set with writes, lets and `when`s between ----

# `{w}`: the latest numeric `let`, so a sum may read a `let` made after an earlier sum.
_SUMS = ["count(near)", "sum(near : other.q - q)", "mean(near : other.vel - vel)",
         "sum(near where dist < 3 : (other.pos - pos) * {w})", "any(near : other.q > q)",
         "all(near : other.q + {w} > 1)", "mean(near where other.q != q : dist * q)",
         "sum(near : normalize(vel) * other.q)", "count(near where other.q < {w})",
         "count(neighbors(4))", "sum(neighbors(4) : other.q * {w})",
         "mean(neighbors(q + 2) where dist > 1 : other.vel)", "count(neighbors(q + 2))"]
_OTHER = ["q = q + 1", "velocity = rotate(vel, 0.3)", "let w{i} = q * 2",
          "when q > 3 -> s", "v = (q, {w})", "k = k + {w}"]
_TARGET = {"count": "k", "sum": "k", "mean": "k", "any": "b", "all": "b"}


@st.composite
def sibling_programs(draw):
    edges = draw(st.sampled_from(["wrap", "wall"]))
    body, w = [], "w"
    for i in range(draw(st.integers(3, 8))):
        if draw(st.booleans()):
            agg = draw(st.sampled_from(_SUMS)).format(w=w)
            vec = "(other.pos" in agg or "vel" in agg
            target = "v" if vec else _TARGET[agg.split("(")[0]]
            body.append(f"let t{i} = {agg}" if draw(st.booleans()) else f"{target} = {agg}")
        else:
            line = draw(st.sampled_from(_OTHER))
            body.append(line.format(i=i, w=w))
            if line.startswith("let w"):
                w = f"w{i}"
    stmts = "\n    ".join(body)
    return f"""
world {{ size 24 x 16; edges {edges} }}
agent a {{
  count 40
  sense 5
  velocity (cos(index), sin(index))
  var q = index % 4
  var k = 0
  var b = false
  var v = (0, 0)
  status s {{
    let w = 1.5
    let near = neighbors(4.5) where other.q != 1
    {stmts}
  }}
}}
"""


def assert_same_bits_with_and_without_shared_loops(monkeypatch, text):
    shared = _numba(text, 3)
    alone = _numba(text, 3, monkeypatch, alone=True)
    monkeypatch.undo()
    for col, a in shared.agents.cols.items():
        assert np.array_equal(a, alone.agents.cols[col], equal_nan=a.dtype.kind == "f"), col


# Each numba run is checked against the reference (the numpy backend: a loop of its
# own for each sum), which compiles nothing; comparing with numba's own loops without
# sharing as well (the slow test below) compiles every sum a second time.
@settings(max_examples=6, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(sibling_programs())
def test_generated_statement_lists_give_the_reference_bits_with_shared_loops(text):
    assert_backends_agree(text, assert_same_state)


@pytest.mark.slow
@settings(max_examples=300, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(sibling_programs())
def test_generated_statement_lists_long(monkeypatch, text):
    assert_same_bits_with_and_without_shared_loops(monkeypatch, text)
    assert_backends_agree(text, assert_same_state)
