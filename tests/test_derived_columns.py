"""Values of the neighbour alone (`normalize(other.vel)`, `length(other.vel)`) worked out
once per agent a tick instead of once per pair: the same bits as pair by pair, on one
thread and on two, in wrap-around and walled worlds, and what the numpy backend gives."""

from collections import Counter

import pytest

pytest.importorskip("numba")

from swarmdsl.compiler import compile_source  # noqa: E402
from swarmdsl.runtime.compiled import fused, plan  # noqa: E402
from swarmdsl.runtime.simulation import Simulation  # noqa: E402
from test_compiled import assert_same_state  # noqa: E402
from test_direct_search import assert_same_bits  # noqa: E402

PROGRAM = """
world {{ size 40 x 30; edges {edges} }}
agent a {{
  count 160
  sense 5
  velocity (cos(index), sin(index)) * (1 + index % 3)
  var phase = index * 0.37
  var hot = index % 3 == 0
  var m = 0
  var n = 0
  var z = (0, 0)
  var q = false
  status s {{
    let near = neighbors(5)
    let h = sum(near : normalize(other.vel))
    m = mean(near where length(other.vel) > 1.5 : other.speed ^ 2 + cos(other.phase))
    n = max(near : sin(other.phase) * other.speed)
    z = nearest(near : normalize(other.vel))
    q = any(near where other.hot != (other.speed > other.phase) : dist > 1)
    phase += 0.1 * sum(near : sin(other.phase - phase))
    velocity = normalize(vel + 0.1 * h + 0.01 * z) * (1 + m / 100 + n / 100)
  }}
}}
"""


def _parts(prog):
    return {(p.span.line, p.span.col): p for p in prog.fused_parts}


def _run(text, monkeypatch=None, hoist=True, threads=None, backend="numba", steps=5):
    if monkeypatch is not None and not hoist:   # every value pair by pair, as before
        monkeypatch.setattr(plan.Planner, "_derived", lambda self, e, t: None)
    if threads:
        from swarmdsl.runtime.compiled import threads as pool

        monkeypatch.setattr(pool, "MIN_PARALLEL", 0)
        monkeypatch.setattr(pool, "count", lambda: threads)
    sim = Simulation(compile_source(text, "test.swarm"), 3, backend=backend)
    sim.run(steps)
    if monkeypatch is not None:
        monkeypatch.undo()
    return sim


def test_the_neighbours_own_values_are_hoisted_and_mixed_ones_are_not():
    from swarmdsl.runtime.compiled.lowering import NUMBA

    prog = compile_source(PROGRAM.format(edges="wrap"), "test.swarm", lowering=NUMBA)
    parts = _parts(prog)

    def derived(line_col):
        return [col for cat, col, _vt in parts[line_col].plan.others if cat == "derived"]

    assert len(derived((15, 13))) == 2               # normalize(other.vel): x and y
    assert all(t[0] == "o" for t in parts[(15, 13)].plan.each)   # the sum reads columns
    assert len(derived((16, 9))) == 2                # length(...) in the filter; the value
    assert len(derived((17, 9))) == 1                # sin(other.phase) * other.speed
    assert derived((18, 9)) == []                    # nearest: one value per owner
    assert len(derived((19, 9))) == 1                # a boolean of the neighbour's own
    assert derived((20, 20)) == []                   # sin(other.phase - phase): mixed


# Edges and threads change different parts of the kernels: two runs cover both of each.
@pytest.mark.parametrize(("edges", "threads"), [("wrap", None), ("wall", 2)])
def test_hoisted_values_give_the_bits_of_pair_by_pair(monkeypatch, edges, threads):
    text = PROGRAM.format(edges=edges)
    hoisted = _run(text, monkeypatch, threads=threads)
    pairwise = _run(text, monkeypatch, hoist=False)   # threads keep the bits
    assert hoisted.agents.cols["q"].any() and not hoisted.agents.cols["q"].all()
    assert_same_bits(hoisted, pairwise)
    report = "\n".join(hoisted.backend.summary(hoisted.program))
    assert ("15:13 sum: compiled (2 parts of the neighbour alone worked out once per agent)"
            in report)
    assert "18:9 nearest: compiled\n" in report + "\n"


@pytest.mark.parametrize("edges", ["wrap", "wall"])
def test_hoisted_values_agree_with_the_numpy_backend(edges):
    text = PROGRAM.format(edges=edges)
    sims = [_run(text, backend=b, steps=2) for b in ("numpy", "numba")]
    assert_same_state(sims, None)


def test_a_derived_column_is_worked_out_once_a_tick_for_every_loop_that_reads_it(
        monkeypatch):
    calls = []
    real = fused._Derived.__call__

    def counted(self, whole):
        calls.append(self.tree)
        return real(self, whole)
    monkeypatch.setattr(fused._Derived, "__call__", counted)
    text = PROGRAM.format(edges="wrap").replace(
        "let h = sum(near : normalize(other.vel))",
        "let h = sum(near : normalize(other.vel)) + mean(near : normalize(other.vel))")
    _run(text, steps=3)
    times = Counter(calls)
    assert len(times) == 6   # h's x and y, x's filter and value, y's value, q's filter
    assert set(times.values()) == {3}
