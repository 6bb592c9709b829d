"""The multi-agent framework's features on both array backends (a differential test):
sensing models, twins and refined grids give the same runs under numba and numpy."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")

from swarmdsl.compiler import compile_file, compile_source  # noqa: E402
from swarmdsl.runtime.simulation import Simulation  # noqa: E402

PROGRAMS = Path(__file__).resolve().parent.parent / "programs"

SENSED = """robot eye { range 50; fov cone 1.2; neighbor_noise 2; neighbor_dropout 0.2 }
world { size 300 x 300; grid 10; edges wrap }
agent a {
  robot eye
  count 60
  place uniform
  velocity random_direction() * 2
  sense 60
  var seen = 0
  var pull = 0
  status s {
    seen = count(neighbors())
    pull = length(sum(neighbors(40) : other.pos - pos))
    let near = neighbors() where dist < 30
    velocity = normalize(velocity + 0.05 * sum(near : other.pos - pos)
                         + 0.1 * mean(near : other.vel)) * 2
  }
}
"""


def _run(program, backend, steps):
    sim = Simulation(program, seed=4, backend=backend)
    sim.run(steps)
    return sim.agents.cols


@pytest.mark.parametrize("name, steps", [("boids_leader.swarm", 120),
                                         ("mas_environment.swarm", 60), (None, 40)])
def test_numba_and_numpy_agree_on_mas_programs(name, steps):
    program = compile_file(PROGRAMS / name) if name else compile_source(SENSED, "s.swarm")
    a, b = _run(program, "numba", steps), _run(program, "numpy", steps)
    for col in a:   # the same bits (DESIGN: either backend)
        np.testing.assert_array_equal(a[col], b[col], err_msg=col)
