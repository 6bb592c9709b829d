"""Fields and twins in the whole-tick kernel (`compiled/tick_fields.py`): readings,
deposits, decay and diffusion run whole ticks with the bits of the numpy reference
stepped tick by tick, grids included; what the kernel cannot hold is refused with its
line, and the run keeps its per-tick path."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytest.importorskip("numba")

from test_tick_kernel import _run, assert_same  # noqa: E402

from swarmdsl import load_program  # noqa: E402
from swarmdsl.compiler import compile_source  # noqa: E402
from swarmdsl.runtime.compiled import tick_run  # noqa: E402
from swarmdsl.runtime.compiled.plan import Unsupported  # noqa: E402
from swarmdsl.runtime.compiled.tick_plan import plan_tick  # noqa: E402

MODELS = Path(__file__).resolve().parents[1] / "benchmarks" / "models"

# Every reading and deposit the kernel holds, in one small kernel (its machine code
# serves every test here: the world, the rates and `grow` are numbers it is handed).
# Deposits into one field from two statuses and a `when`'s body, so their order is
# the reference's; a field that decays only, one that diffuses too; a twin read at a
# point, a vector twin read where the agent stands, a twin that changes every tick;
# `gradient`, `ahead` with a turn. `blow` makes that twin infinite at a chosen tick.
# `grow` makes a deposit infinite at a chosen tick (into `mark`, which nothing reads,
# so nothing else overflows first).
FIELDS = """param n = 10
param grow = 0
param decay = 0.05
param spread = 0.1
param side = 8
param spacing = 5.0
param blow = 1000000
world {{ size side * spacing x 6 * spacing; grid spacing; edges {edges} }}
field scent {{ decay decay; diffuse spread }}
field mark {{ decay 0.2 }}
field light {{ twin 10 - distance(pos, (20, 15)) / 4 }}
field wind {{ twin ((15 - pos.y) / 30, (pos.x - 20) / 40) }}
field warm {{ twin 3 * sin(pos.x / 7 - tick / 9) + 1 / (blow - tick) }}
agent ant {{
  count n
  velocity random_direction()
  var smelt = 0
  status roam {{
    deposit(scent, 1 + index % 3)
    deposit(mark, exp(tick * grow))
    smelt = ahead(scent, 3, 0.4) + light at (pos + (2, -1)) + warm at pos
    velocity = normalize(velocity + gradient(scent) + wind at pos)
    when smelt > 4 -> rest {{ deposit(mark, 2) }}
  }}
  status rest {{
    deposit(mark, smelt / 10)
    deposit(scent, 0.5)
    when chance(0.2) -> roam
  }}
}}
"""


def _grids(sim) -> dict:
    env = sim.environment
    return {**{n: f.values for n, f in env.fields.items()},
            **{n: np.stack([v.x.values, v.y.values]) for n, v in env.vectors.items()}}


def _whole_against_stepped(text: str, ticks: int, seed: int = 0, **overrides):
    """`text` run whole on numba (in calls of 1, 13 and the rest) and stepped on the
    numpy reference: the same agents, draws and grids, bit for bit, and the same fault;
    the whole run, its fault and its grids."""
    def load():
        return compile_source(text, "test.swarm",
                              {k: str(v) for k, v in overrides.items()} or None)
    whole, fault = _run(load(), "numba", ticks, whole=True, seed=seed, chunks=(1, 13))
    stepped, expected = _run(load(), "numpy", ticks, whole=False, seed=seed)
    assert_same(stepped, whole)
    assert fault == expected
    grids = _grids(whole)
    for name, values in _grids(stepped).items():
        assert grids[name].tobytes() == values.tobytes(), name
    assert tick_run.summary(whole.backend)[0].startswith("whole-tick kernel: yes (")
    return whole, fault, grids


def test_fields_run_whole_as_they_step():
    whole, fault, grids = _whole_against_stepped(FIELDS.format(edges="wrap"), 60)
    assert fault is None
    line = tick_run.summary(whole.backend)[0]
    assert line.startswith("whole-tick kernel: yes (60 ticks"), line
    assert set(whole.agents.cols["status"]) == {0, 1}   # both statuses deposited
    # every deposit is kept: the field that only decays holds what was put in less
    # its losses, and the diffusing one spread its scent beyond the agents' cells
    assert grids["mark"].sum() > 0 and (grids["scent"] > 0).mean() > 0.9


def test_a_twin_that_turns_infinite_stops_the_call_with_the_located_error():
    """`1 / (blow - tick)` at tick 30: the reference raises at the end of tick 29,
    working out the twin for tick 30, after the tick's agents moved; so does the run
    whole, its kernel stopping before tick 29 commits."""
    whole, fault, _grids_ = _whole_against_stepped(FIELDS.format(edges="wall"), 60,
                                                   blow=30)
    assert fault is not None and "the formula of field `warm` is not finite" in fault
    assert "at tick 30" in fault and whole.tick == 29


def test_an_infinite_deposit_stops_the_call_at_its_tick_with_the_located_error():
    """exp(71 * 10) overflows: the kernel stops before tick 71 commits, and the tick
    runs on the reference path, which raises the error located at the deposit."""
    whole, fault, _grids_ = _whole_against_stepped(FIELDS.format(edges="wrap"), 80,
                                                   grow=10)
    assert fault is not None and "a deposit into `mark` is not finite" in fault
    assert "tick 71" in fault and whole.tick == 71


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(edges=st.sampled_from(["wrap", "wall"]),
       decay=st.sampled_from([0.0, 0.02, 1.0]) | st.floats(0, 1),
       spread=st.sampled_from([0.0, 0.25]) | st.floats(0, 0.25),
       side=st.integers(1, 12), spacing=st.sampled_from([0.5, 1, 3, 7.5]),
       n=st.integers(2, 30), seed=st.integers(0, 2 ** 16))
def test_any_grid_and_rates_run_whole_as_they_step(edges, decay, spread, side, spacing, n,
                                                   seed):
    """One kernel for every world, grid and rate: each is a number the call is handed.
    A grid one node wide, a field that loses everything every tick, agents crowding one
    cell."""
    whole, fault, grids = _whole_against_stepped(
        FIELDS.format(edges=edges), 25, seed=seed, decay=decay, spread=spread, side=side,
        spacing=spacing, n=n)
    assert fault is None and whole.tick == 25


def test_chemotaxis_plans_whole():
    """The benchmark model of fields (a deposit and a gradient each tick) is planned
    with its grid: the kernel's deposit lands in row 0, field `chem`."""
    plan = plan_tick(load_program(MODELS / "chemotaxis.swarm"))
    assert plan.field_rows == ["chem"] and [d[0] for d in plan.deposits] == [0]


_BODY = ("world {{ size 50 x 50 }}\nfield f {{ decay 0.1 }}\nrobot r {{ range 20 }}\n"
         "agent a {{\n  count 3\n{robot}  status s {{\n    {stmt}\n  }}\n}}\n")


@pytest.mark.parametrize("stmt, robot, why", [
    ("deposit(f, 1, 12)", "", "a deposit with a radius at line 7"),
    ("velocity = (cone(f, 3, 0.5), 0)", "", "`cone(...)` at line 7"),
    ("velocity = (sample(f), 0)", "  robot r\n",
     "a field read through a robot's sensing model at line 8"),
    ("tree sequence { f at (pos + (1, 0)) > 0; velocity = (1, 0) }", "",
     "a field read at a point in a tree leaf at line 7"),
])
def test_what_the_kernel_cannot_hold_is_refused_with_its_line(stmt, robot, why):
    prog = compile_source(_BODY.format(robot=robot, stmt=stmt), "test.swarm")
    with pytest.raises(Unsupported) as err:
        plan_tick(prog)
    assert why in str(err.value)


def test_an_environment_that_changes_in_python_says_which_part():
    text = ("world { size 50 x 50 }\nobstacle rock = circle(20, 20, 5)\n"
            "field f { decay 0.1 }\nagent a { count 3; status s { deposit(f, 1) } }\n")
    with pytest.raises(Unsupported) as err:
        plan_tick(compile_source(text, "test.swarm"))
    assert str(err.value) == "its environment (obstacle `rock`) runs in Python every tick"
    aco = load_program(Path(__file__).resolve().parents[1] / "programs" / "aco.swarm")
    with pytest.raises(Unsupported) as err:
        plan_tick(aco)
    assert "(path memory `trail`, label set `known`)" in str(err.value)


def test_a_twin_drawing_random_numbers_every_tick_is_refused_with_its_line():
    text = ("world { size 50 x 50 }\nfield f { decay 0.1 }\n"
            "field noise { twin uniform(0, 1) * tick }\n"
            "agent a { count 3; status s { velocity = (noise at pos, 0) } }\n")
    with pytest.raises(Unsupported) as err:
        plan_tick(compile_source(text, "test.swarm"))
    assert str(err.value).startswith("the formula of twin `noise` at line 3 draws random "
                                     "numbers")


@pytest.mark.slow   # each a kernel of its own: 10-20 s to compile
@pytest.mark.parametrize("name, overrides", [
    ("chemotaxis.swarm", {"n": "60", "size": "16"}),
    ("beeclust.swarm", {"n": "30"}),
])
def test_the_field_models_run_whole_as_they_step(name, overrides):
    """The benchmark models of fields: chemotaxis (a deposit and a gradient per agent,
    decay and diffusion) and BEECLUST (a static twin read where a bee stops)."""
    def load():
        return load_program(MODELS / name, overrides)
    whole, fault = _run(load(), "numba", 300, whole=True, seed=2, chunks=(1, 13))
    stepped, expected = _run(load(), "numpy", 300, whole=False, seed=2)
    assert fault is None and expected is None
    assert_same(stepped, whole)
    for f, g in zip(_grids(stepped).values(), _grids(whole).values(), strict=True):
        assert f.tobytes() == g.tobytes()
    assert tick_run.summary(whole.backend)[0].startswith("whole-tick kernel: yes (300 ")
