"""Whole ticks in one compiled call (`compiled/tick_kernel.py`, `Simulation.advance`):
the same bits as stepping tick by tick, on both backends; and which programs it takes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytest.importorskip("numba")

from swarmdsl import load_program  # noqa: E402
from swarmdsl.compiler import compile_source  # noqa: E402
from swarmdsl.errors import SwarmError  # noqa: E402
from swarmdsl.runtime.compiled import tick_run  # noqa: E402
from swarmdsl.runtime.compiled.plan import Unsupported  # noqa: E402
from swarmdsl.runtime.compiled.tick_plan import plan_tick  # noqa: E402
from swarmdsl.runtime.simulation import Simulation  # noqa: E402

PROGRAMS = Path(__file__).resolve().parents[1] / "programs"
MODELS = Path(__file__).resolve().parents[1] / "benchmarks" / "models"
# The shipped programs and benchmark models the whole-tick kernel takes; every other one
# says why not (path memories, messages, robot profiles, sensing: extensions in Python).
# chemotaxis's fields are checked whole in tests/test_field_kernel.py.
# patrol's behaviour tree is checked whole in tests/test_tree_kernel.py.
WHOLE = {"vicsek.swarm", "boids.swarm", "boids_leader.swarm"}
PLANNED = WHOLE | {"patrol.swarm"}
WHOLE_MODELS = {"studio_walkers.swarm", "swarmalators.swarm", "chemotaxis.swarm",
                "beeclust.swarm"}


def assert_same(a: Simulation, b: Simulation) -> None:
    """Every agent column, the tick and the random source's state, bit for bit."""
    assert a.tick == b.tick
    assert a.agents.cols.keys() == b.agents.cols.keys()
    for name, x in a.agents.cols.items():
        y = b.agents.cols[name]
        assert x.dtype == y.dtype and x.shape == y.shape, name
        assert x.tobytes() == y.tobytes(), name
    assert a.rng.state() == b.rng.state()


def _run(prog, backend: str, ticks: int, whole: bool, seed: int = 0, chunks=(7,)):
    sim = Simulation(prog, seed, backend=backend)
    fault = None
    try:
        if whole:
            left = ticks
            for k in (*chunks, ticks):
                k = min(k, left)
                assert sim.advance(k) == k
                left -= k
                if not left:
                    break
        else:
            for _ in range(ticks):
                sim.step()
    except SwarmError as err:
        fault = str(err)
    return sim, fault


def _whole_and_reference(text: str, ticks: int, seed: int = 0):
    """`text` run whole on numba and stepped on the numpy reference: ((sim, fault), ...)."""
    return (_run(compile_source(text, "test.swarm"), "numba", ticks, whole=True, seed=seed),
            _run(compile_source(text, "test.swarm"), "numpy", ticks, whole=False, seed=seed))


@pytest.mark.parametrize("path, whole", [
    *((p, PLANNED) for p in sorted(PROGRAMS.glob("*.swarm"))),
    *((p, WHOLE_MODELS) for p in sorted(MODELS.glob("*.swarm")))],
    ids=lambda v: v.name if isinstance(v, Path) else "")
def test_shipped_programs_and_benchmark_models_plan_or_say_why(path, whole):
    prog = load_program(path)
    try:
        plan_tick(prog)
        taken = True
    except Unsupported as exc:
        taken = False
        assert str(exc)
    assert taken == (path.name in whole)


@pytest.mark.slow   # a kernel of its own: compiles for tens of seconds
def test_the_swarmalators_advance_as_they_step():
    """A `let` of a filtered neighbour set (`neighbors(r) where dist > 0.01`), the
    sums over it sharing a loop, a draw per agent."""
    prog = load_program(MODELS / "swarmalators.swarm", {"n": 80, "size": 12})
    stepped, f1 = _run(prog, "numpy", 30, whole=False, seed=2)
    advanced, f2 = _run(load_program(MODELS / "swarmalators.swarm", {"n": 80, "size": 12}),
                        "numba", 30, whole=True, seed=2)
    assert f1 is None and f2 is None
    assert_same(stepped, advanced)
    assert tick_run.summary(advanced.backend)[0].startswith("whole-tick kernel: yes")


# boids_leader's kernel (a field of view in five sums) compiles for 30 s: its whole
# ticks are checked on a small program of the same constructs in CI
# (tests/test_view_search.py), on boids_leader itself in the slow run.
@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow)
                                  if n == "boids_leader.swarm" else n
                                  for n in sorted(WHOLE)])
@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_shipped_programs_advance_as_they_step(name, backend):
    prog = load_program(PROGRAMS / name, {"n": 60})
    stepped, f1 = _run(prog, backend, 40, whole=False, seed=5)
    advanced, f2 = _run(load_program(PROGRAMS / name, {"n": 60}), backend, 40,
                        whole=True, seed=5, chunks=(1, 13))
    assert f1 is None and f2 is None
    assert_same(stepped, advanced)
    if backend == "numba":
        line = tick_run.summary(advanced.backend)[0]
        assert line.startswith("whole-tick kernel: yes (40 ticks")
        numpy_run, _f = _run(load_program(PROGRAMS / name, {"n": 60}), "numpy", 40,
                             whole=False, seed=5)
        assert_same(numpy_run, advanced)


def test_a_refused_program_advances_by_stepping():
    prog = load_program(PROGRAMS / "aco.swarm")
    a, fa = _run(prog, "numba", 6, whole=True)
    b, fb = _run(load_program(PROGRAMS / "aco.swarm"), "numba", 6, whole=False)
    assert fa == fb
    assert_same(a, b)
    assert tick_run.summary(a.backend)[0].startswith("whole-tick kernel: no (")


# A program of the constructs the kernel takes: two statuses with transitions both ways
# (first match wins, actions), lets, assignments of numbers and vectors, every draw,
# sums with filters and limits, a mean with a default, any / all, min / max / nearest
# (numbers, a vector, a boolean, with and without an else); its edges, sizes and
# params drawn by hypothesis (one kernel shape: params are constants, not its shape).
TEMPLATE = """
param n = 12
param size = 20
param r = 4
param a = 0.5
param b = 0.2
param c = 1.0
param lo = -0.3
world {{ size size x size; grid 2; edges {edges}; steps 100 }}
agent bug {{
  count n
  sense r
  velocity random_direction() * 0.5
  max_speed 1.5
  var energy = 1
  var drift = (0, 0)
  status roam {{
    let near = neighbors(r)
    let crowd = count(near)
    let pull = sum(near where dist > a : other.pos - pos) / max(crowd, 1)
    let calm = mean(near : other.energy else energy)
    let low = min(near where dist > b : other.energy else -1)
    let top = max(near : other.energy + dist)
    let toward = nearest(near where other.energy > lo : other.pos - pos else (0, 0))
    when crowd > c * 3 and energy > 0.5 -> rest {{ energy -= 0.5 }}
    when any(near where dist < b : other.energy < 0.2) -> rest
    drift += normal(0, b) * (1, 0)
    velocity = (velocity + a * pull + drift * 0.1 + unit(uniform(lo, -lo)) * 0.05
                + toward * 0.01)
    energy = energy + 0.01 * calm + 0.001 * (low + top)
  }}
  status rest {{
    let here = neighbors()
    velocity = velocity * 0.5 + mean(here : other.vel) * 0.1
    energy += 0.1 + random() * 0.01
    when energy > 2 and all(here : other.energy > 0) -> roam
    when nearest(here : other.energy > 1.5) -> roam
    when chance(0.05) -> roam {{ velocity = (cos(random() * 6), sin(speed)) }}
  }}
}}
"""
EDGES = {"wrap": "wrap", "wall": "wall", "repel": "repel 1.0 (3)"}


def _template(edges: str, params: dict):
    text = TEMPLATE.format(edges=EDGES[edges])
    return compile_source(text, "test.swarm", {k: str(v) for k, v in params.items()})


def test_the_template_is_taken_whole():
    plan = plan_tick(_template("wrap", {}))
    assert plan.bodies and plan.radius > 0


@pytest.mark.slow   # a long property run: each edge rule's kernel compiles for many seconds
@settings(max_examples=25, deadline=None, suppress_health_check=list(HealthCheck))
@given(edges=st.sampled_from(sorted(EDGES)), n=st.integers(2, 40),
       size=st.sampled_from([6, 10, 20, 31.5]), r=st.floats(0.5, 6),
       a=st.floats(0, 2), b=st.floats(0, 1), c=st.floats(0, 3),
       lo=st.floats(-1, 0), seed=st.integers(0, 2**31))
def test_generated_runs_advance_as_they_step(edges, n, size, r, a, b, c, lo, seed):
    params = {"n": n, "size": size, "r": r, "a": a, "b": b, "c": c, "lo": lo}
    stepped, f1 = _run(_template(edges, params), "numpy", 12, whole=False, seed=seed)
    advanced, f2 = _run(_template(edges, params), "numba", 12, whole=True, seed=seed,
                        chunks=(5,))
    assert f1 == f2
    assert_same(stepped, advanced)


def test_a_failing_check_stops_the_kernel_and_the_tick_raises_located():
    text = """
param n = 5
world { size 10 x 10; edges wrap; steps 10 }
agent a {
  count n
  var fuel = 1
  status s {
    fuel = fuel - 1
    let y = sqrt(fuel - 0.5) + tick
    velocity = (y, 0)
  }
}
"""
    (a, fa), (b, fb) = _whole_and_reference(text, 5)
    assert fa is not None and fa == fb
    assert "NaN" in fa
    assert_same(a, b)


def test_a_nan_in_a_when_comparison_stops_the_kernel_as_a_step_does():
    """A `when`'s own comparison of a NaN is a located error on every path (the
    whole-tick kernel checks it before the tick commits), never silently false."""
    text = """
param n = 5
world { size 10 x 10; edges wrap; steps 10 }
agent a {
  count n
  var fuel = 2
  status s {
    fuel = fuel - 1
    when sqrt(fuel) > 5 -> t
  }
  status t { }
}
"""
    (a, fa), (b, fb) = _whole_and_reference(text, 5)
    assert fa is not None and fa == fb
    assert "NaN" in fa
    assert_same(a, b)


def test_statuses_take_the_first_transition_that_fires():
    text = """
param n = 30
world { size 10 x 10; edges wall; steps 10 }
agent a {
  count n
  var k = 0
  status one {
    k += 1
    when index % 3 == 0 -> two { k += 100 }
    when index % 2 == 0 -> three
    k += 10
  }
  status two { when k > 200 -> one }
  status three { k -= 1 }
}
"""
    (a, fa), (b, fb) = _whole_and_reference(text, 4)
    assert fa is None and fb is None
    assert_same(a, b)
    assert np.unique(a.agents.cols["status"]).size == 3


def test_a_batch_of_replicas_does_not_run_whole():
    from swarmdsl.runtime.batch import BatchedSimulation

    prog = load_program(PROGRAMS / "vicsek.swarm", {"n": 20})
    batch = BatchedSimulation(prog, [1, 2], backend="numba")
    assert batch.backend.advance(batch, 3) == -1


def test_kinds_of_their_own_sense_and_statuses_run_whole():
    """Two kinds, each sensing at its own radius (the pair table's is the larger),
    reading the other's status and speed; their status codes do not start at 0. The
    prey start on a lattice, so most have several neighbours at exactly their sense
    radius: `nearest` must take the lowest row among them, as the reference does (the
    `index` it reads tells which it took). The lattice runs against the cell order (the
    rows from the top right), so the first of them in the cell list is not the lowest
    row. A `let` of a filtered set filters with the owner's values where it stands
    (`alert` changes after it), and another filters it further."""
    text = """
param n = 16
world { size 12 x 12; edges wrap; steps 10 }
agent prey {
  count n
  sense 2
  place (11 - index % 4 * 2, 11 - floor(index / 4) * 2)
  velocity random_direction() * 0.2
  var alert = 0
  status grazing {
    let near = neighbors()
    when count(near where other.status == hunting) > 0 -> fleeing
    let buddy = nearest(near : other.index else -1)
    velocity = rotate(velocity, normal(0, 0.3)) + (buddy, 0) * 0.001
  }
  status fleeing {
    let calm = neighbors(1.5) where other.speed < 0.3 + alert
    alert += 0.05
    let calmer = calm where dist > 0.1
    velocity = (normalize(velocity + mean(calmer : other.vel else (0, 0))) * 0.4
                * (1 + 0.1 * count(calm)))
    when random() < 0.2 -> grazing
  }
}
agent hunter {
  count 3
  sense 4
  velocity (0.1, 0)
  status hunting {
    let prey_near = neighbors(3)
    velocity = velocity + sum(prey_near where other.speed > 0.3 : other.pos - pos) * 0.01
  }
}
"""
    plan_tick(compile_source(text, "test.swarm"))
    (a, fa), (b, fb) = _whole_and_reference(text, 15, seed=4)
    assert fa is None and fb is None
    assert_same(a, b)
    assert tick_run.summary(a.backend)[0].startswith("whole-tick kernel: yes")


def test_a_run_hands_the_ticks_between_records_to_the_compiled_kernel(tmp_path, monkeypatch):
    """`swarmdsl run --every K`: once the whole-tick kernel is compiled (here by a
    throwaway simulation; in a first run by the tiered start's background process), the
    ticks no output needs run whole, and the recorded run is the reference's, bit for
    bit; `SWARMDSL_WHOLE_TICKS=0` keeps every tick one by one."""
    from conftest import assert_same_outputs

    from swarmdsl.runtime.runner import Run

    monkeypatch.setenv("SWARMDSL_WHOLE_TICKS", "1")
    prog = load_program(PROGRAMS / "vicsek.swarm", {"n": 60})
    warm = Simulation(prog, 0, backend="numba")
    warm.advance(2)
    assert tick_run.ready(warm.backend, warm)
    outs = {}
    for backend in ("numba", "numpy"):
        run = Run(prog, seed=3, steps=45, every=10, out=tmp_path / backend, backend=backend)
        run.show_progress = False
        assert run.execute() == "completed"
        outs[backend] = run
    line = tick_run.summary(outs["numba"].sim.backend)[0]
    assert line.startswith("whole-tick kernel: yes"), line
    assert_same_outputs(tmp_path / "numba", tmp_path / "numpy")
    monkeypatch.setenv("SWARMDSL_WHOLE_TICKS", "0")     # the switch says no
    run = Run(prog, seed=3, steps=45, every=10, backend="numba")
    run.show_progress = False
    assert run.execute() == "completed"
    assert tick_run.summary(run.sim.backend) == []
