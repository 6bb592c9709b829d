"""Values of the neighbour alone (`normalize(other.vel)`, `length(other.vel)`) worked out
once per agent a tick instead of once per pair: the same bits as pair by pair, on one
thread and on two, in wrap-around and walled worlds, and what the numpy backend gives."""

import re
from collections import Counter

import pytest

pytest.importorskip("numba")

from swarmdsl.compiler import compile_source  # noqa: E402
from swarmdsl.runtime.compiled import fused  # noqa: E402
from swarmdsl.runtime.simulation import Simulation  # noqa: E402
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


def _run(text, monkeypatch=None, threads=None, backend="numba", steps=5):
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


# The reference (the numpy backend) has the bits of pair by pair and compiles nothing.
# PROGRAM reads no position: both worlds compile the same kernels, and differ in the
# pairs they are given.
@pytest.mark.parametrize("edges", ["wrap", "wall"])
def test_hoisted_values_give_the_bits_of_pair_by_pair(edges):
    text = PROGRAM.format(edges=edges)
    hoisted = _run(text)
    pairwise = _run(text, backend="numpy")
    assert hoisted.agents.cols["q"].any() and not hoisted.agents.cols["q"].all()
    assert_same_bits(hoisted, pairwise)
    report = "\n".join(hoisted.backend.summary(hoisted.program))
    assert ("15:13 sum: compiled (2 parts of the neighbour alone worked out once per agent)"
            in report)
    assert "18:9 nearest: compiled\n" in report + "\n"


def test_hoisted_values_on_two_threads_give_the_bits_of_pair_by_pair(monkeypatch):
    """The hoisted columns are worked out in runs of agents on the threads, and the
    aggregates that read them split their owners: a hoisted max (it reads the written
    pairs; coming first, the sum after it reads them too, and searches no cell) and sum
    show a split that loses or repeats an agent (a threaded kernel compiles several
    times slower than a serial one, so not every aggregate of PROGRAM)."""
    text = re.sub(r"\n    (m|n|z|q|phase) .*", "", PROGRAM.format(edges="wall")).replace(
        "    let h =", "    n = max(near : sin(other.phase) * other.speed)\n    let h =").replace(
        "velocity = normalize(vel + 0.1 * h + 0.01 * z) * (1 + m / 100 + n / 100)",
        "velocity = normalize(vel + 0.1 * h) * (1 + n / 100)")
    threaded = _run(text, monkeypatch, threads=2)
    assert "(2 parts of the neighbour alone worked out once per agent)" in "\n".join(
        threaded.backend.summary(threaded.program))
    assert_same_bits(threaded, _run(text, backend="numpy"))


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
