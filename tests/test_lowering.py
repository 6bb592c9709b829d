"""The seam between the compiler and its backends (`compiler/lowering.py`): a program
compiled without a lowering is lowered by the backend that runs it, once, to the same
closures an eager lowering builds; the reference lowering changes nothing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from swarmdsl.compiler import compile_file, compile_source
from swarmdsl.compiler.lowering import REFERENCE, Reference
from swarmdsl.runtime.compiled.lowering import NUMBA
from swarmdsl.runtime.simulation import Simulation

pytest.importorskip("numba")

BOIDS = Path(__file__).resolve().parent.parent / "programs" / "boids.swarm"


def _state(sim) -> dict:
    return {name: np.array(col) for name, col in sim.agents.cols.items()}


def test_the_numba_backend_lowers_a_program_compiled_without_a_lowering():
    lazy, eager = compile_file(BOIDS), compile_file(BOIDS, lowering=NUMBA)
    assert lazy.lowering is None and getattr(lazy, "fused_parts", []) == []
    sims = [Simulation(p, 3, backend="numba") for p in (lazy, eager)]
    for sim in sims:
        sim.run(4)
    assert lazy.lowering is NUMBA
    assert len(lazy.fused_parts) == len(eager.fused_parts) > 0
    ran = [sum(calls[0] for calls in sim.backend.parts.values()) for sim in sims]
    assert ran[0] == ran[1] > 0          # compiled calls, as many as the eager program's
    for col, ref in _state(sims[1]).items():
        np.testing.assert_array_equal(_state(sims[0])[col], ref, err_msg=col)


def test_a_numpy_run_leaves_the_program_as_compiled():
    prog = compile_file(BOIDS)
    Simulation(prog, 3, backend="numpy").run(2)
    assert prog.lowering is None and getattr(prog, "fused_parts", []) == []


def test_a_program_compiled_with_the_reference_lowering_keeps_it_on_numba():
    prog = compile_file(BOIDS, lowering=REFERENCE)
    sim = Simulation(prog, 3, backend="numba")
    sim.run(2)
    assert prog.lowering is REFERENCE and sim.backend.parts == {}


def test_plug_ins_added_after_compiling_survive_the_lowering():
    """`run --check` adds its monitor to a compiled program; lowering it for a numba
    run must not drop the monitor, or the run would check nothing."""
    from swarmdsl.testing.monitor import PropertyViolation, enable_checks

    text = BOIDS.read_text().replace("speed <= cruise * 1.000001", "speed <= 0")
    prog = compile_source(text, str(BOIDS))
    enable_checks(prog, ["at_most_cruise"])
    sim = Simulation(prog, 3, backend="numba")
    assert prog.lowering is NUMBA
    with pytest.raises(PropertyViolation):
        sim.run(3)


class _Counting(Reference):
    """The identity, counting what the code generator hands it."""

    name = "counting"

    def __init__(self):
        self.seen = {"aggregate": 0, "filter": 0, "statement": 0, "statement_list": 0}

    def aggregate(self, gen, call, reference):
        self.seen["aggregate"] += 1
        return super().aggregate(gen, call, reference)

    def filter(self, gen, where, source, reference):
        self.seen["filter"] += 1
        return super().filter(gen, where, source, reference)

    def statement(self, gen, stmt, reference, built, target_type=None, nonfinite=None,
                  let_guard=None):
        self.seen["statement"] += 1
        return super().statement(gen, stmt, reference, built, target_type, nonfinite,
                                 let_guard)

    def statement_list(self, gen, stmts):
        self.seen["statement_list"] += 1


PROGRAM = """
world { size 20 x 20 }
agent a {
  count 30
  sense 4
  var s = 0
  status go {
    let near = neighbors() where other.s >= 0
    s = count(near) + sum(near : dist)
    velocity = (1, 0)
    when s > 1e9 -> go { s = 0 }
  }
}
"""


def test_every_aggregate_filter_and_statement_reaches_the_lowering():
    lowering = _Counting()
    prog = compile_source(PROGRAM, "count.swarm", lowering=lowering)
    # 2 aggregates, 1 filter; a let, 3 assignments (one inside the `when`); 2 bodies
    assert lowering.seen == {"aggregate": 2, "filter": 1, "statement": 4,
                             "statement_list": 2}
    plain = compile_source(PROGRAM, "count.swarm", lowering=REFERENCE)
    sims = [Simulation(p, 5, backend="numpy") for p in (prog, plain)]
    for sim in sims:
        sim.run(3)
    np.testing.assert_array_equal(sims[0].agents.cols["s"], sims[1].agents.cols["s"])
    assert sims[0].agents.cols["s"].max() > 0
