"""Fields and regions in a batch of replicas are each replica's solo run, bit for bit.

A field of a batch holds one grid per replica (`runtime/batch_fields.py`): deposits,
decay, diffusion, readings and gradients of replica r touch only grid r and do the
arithmetic of its solo run, so at every tick each replica's grid, agent columns and
metrics equal its solo run's to the last bit, on both backends; and nothing diffuses
from one replica's grid into another's.

The solo runs are the reference backend's (`SOLO`): a numba solo run has the same bits
(`tests/test_compiled.py`, `tests/test_compiled_fields.py`), so a numba batch equal to
them is equal to its numba solo runs, and the test compiles only the batch's kernels.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from swarmdsl import load_program
from swarmdsl.cli import main
from swarmdsl.compiler import compile_source
from swarmdsl.errors import SwarmOptionError
from swarmdsl.runtime.batch import BatchedSimulation, batch_refusal
from swarmdsl.runtime.fields import Field, Grid
from swarmdsl.runtime.metrics import evaluate
from swarmdsl.runtime.simulation import Simulation

PROGRAMS = Path(__file__).resolve().parent.parent / "programs"
SEEDS = [3, 1, 2**40 + 7]
SOLO = "numpy"   # the backend of the solo runs a batch is compared with (above)
# Small runs of the shipped programs with fields or regions: the ants lay pheromone
# from about tick 8 (diffusing in aco here), a patrol robot goes to charge at once.
SHIPPED = {"aco": ({"diffusion": 0.1, "ants": 12}, 30),
           "aco_bt": (None, 30),
           "patrol": ({"low": 45}, 40),
           "mas_environment": ({"n": 12}, 15)}   # twins on a refined grid


def _grids(sim) -> dict[str, np.ndarray]:
    """Every grid of the run: its fields', and its vector twins' components."""
    env = sim.environment
    return {} if env is None else env.field_values(sim)


def assert_each_tick_is_the_solo_tick(program, seeds, backend, ticks) -> list:
    """Step a batch and a solo run per seed together; after every tick each replica's
    columns, field grids and metrics are its solo run's. Returns the solo runs."""
    batch = BatchedSimulation(program, seeds, backend=backend)
    solos = [Simulation(program, s, backend=SOLO) for s in seeds]
    for tick in range(ticks):
        batch.step()
        rows = batch.metric_rows()
        for r, solo in enumerate(solos):
            solo.step()
            view = batch.replica(r)
            for col, values in solo.agents.cols.items():
                assert view.agents.cols[col].tobytes() == values.tobytes(), (tick, r, col)
            mine, theirs = _grids(view), _grids(solo)
            assert mine.keys() == theirs.keys()
            for name, grid in theirs.items():
                assert mine[name].tobytes() == grid.tobytes(), (tick, r, name)
            assert rows[r].tobytes() == evaluate(program.metrics, solo).tobytes(), \
                (tick, r)
    return solos


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_field_and_region_programs_batch_to_their_solo_runs(name, backend):
    sets, ticks = SHIPPED[name]
    program = load_program(PROGRAMS / f"{name}.swarm", sets)
    assert batch_refusal(program) is None
    solos = assert_each_tick_is_the_solo_tick(program, SEEDS, backend, ticks)
    laid = {"aco": "pheromone", "aco_bt": "pheromone", "mas_environment": "visited"}
    if name in laid:   # the runs did lay something, and differently
        totals = [s.environment.fields[laid[name]].total() for s in solos]
        grids = [_grids(s)[laid[name]].tobytes() for s in solos]
        assert min(totals) > 0 and len(set(grids)) == len(grids), totals
        if name != "mas_environment":
            # every rover lays 1 a tick wherever it is, and decay and diffusion keep
            # the sum: its runs' totals agree but for rounding, and tell nothing apart
            assert len(set(totals)) == len(totals), totals
    else:              # robots went into the dock (a region test)
        assert any(s.status_counts()["charging"] for s in solos)


@pytest.mark.parametrize("name", ["aco", "mas_environment"])
def test_a_batched_runs_recorded_fields_are_its_solo_runs(backend, tmp_path, name):
    """`Batch(..., out=)` writes each replica's fields.npz (a refined grid's every
    node too), agents and metrics as `swarmdsl run --out` writes its seed's."""
    from conftest import assert_same_outputs

    import swarmdsl

    path = PROGRAMS / f"{name}.swarm"
    program = load_program(path)
    results = swarmdsl.Batch(program, runs=[5, 2], steps=20, every=4,
                             out=tmp_path / "batch", backend=backend).execute()
    assert [(r.replicas, r.solo) for r in results] == [(2, None)] * 2
    for r in results:
        solo = tmp_path / f"solo{r.seed}"
        assert main(["run", str(path), "--headless", "--seed", str(r.seed), "--steps",
                     "20", "--every", "4", "--out", str(solo), "--backend", SOLO]) == 0
        assert_same_outputs(r.out, solo)
        with np.load(r.out / "fields.npz") as got:
            laid = "pheromone" if name == "aco" else "visited.nodes"
            assert got[laid].shape[0] == 6 and got[laid][-1].sum() > 0
        assert json.loads((r.out / "run.json").read_text())["batch"]["replicas"] == 2


# ---- one grid per replica ----

def _field_class(backend):
    if backend == "numba":
        from swarmdsl.runtime.compiled.fields import CompiledField

        return CompiledField
    return Field


@pytest.mark.parametrize("periodic", [False, True])
def test_diffusion_never_crosses_into_another_replicas_grid(backend, periodic):
    """Replica 1 holds mass on every border node of its grid; after many ticks of the
    fastest stable diffusion replicas 0 and 2 still hold exactly nothing, and replica
    1's grid is the grid of a field of its own stepped as often."""
    cls = _field_class(backend)
    grid = Grid(60, 40, 10, periodic=periodic)
    both = cls("f", grid, decay=0.01, diffuse=0.25, replicas=3)
    alone = cls("f", grid, decay=0.01, diffuse=0.25)
    start = np.zeros(grid.shape)
    start[0, :] = start[-1, :] = start[:, 0] = start[:, -1] = 1.0
    alone.values = start
    both.values = np.stack([np.zeros(grid.shape), start, np.zeros(grid.shape)])
    for _ in range(50):
        both.step()
        alone.step()
    assert not both.values[0].any() and not both.values[2].any()
    assert both.values[1].tobytes() == alone.values.tobytes()
    assert alone.total() > 0


@st.composite
def _field_cases(draw):
    periodic = draw(st.booleans())
    nx, ny = draw(st.integers(1, 7)), draw(st.integers(1, 7))
    grid = Grid(nx * 5.0, ny * 5.0, 5.0, periodic=periodic) if periodic else \
        Grid((nx - 1) * 5.0, (ny - 1) * 5.0, 5.0)
    reps = draw(st.integers(1, 4))
    counts = draw(st.lists(st.integers(0, 6), min_size=reps, max_size=reps))
    coord = st.floats(-8.0, 45.0, allow_nan=False)
    # points on shared nodes too: several agents' shares land on one node
    point = st.one_of(st.tuples(coord, coord),
                      st.tuples(st.integers(0, 6).map(lambda i: i * 5.0),
                                st.integers(0, 6).map(lambda i: i * 5.0)))
    points = [draw(st.lists(point, min_size=c, max_size=c)) for c in counts]
    amounts = [draw(st.lists(st.floats(0, 3), min_size=c, max_size=c)) for c in counts]
    radius = draw(st.sampled_from([0.0, 0.0, 4.0, 9.0]))
    decay = draw(st.sampled_from([0.0, 0.05]))
    diffuse = draw(st.sampled_from([0.0, 0.1, 0.25]))
    return grid, points, amounts, radius, decay, diffuse


def _deposited_and_stepped(cls, grid, points, amounts, radius, decay, diffuse):
    """A field of replicas and one field per replica, each given its replica's points'
    deposits and stepped, twice: (both, alone, points, their replicas)."""
    reps = len(points)
    both = cls("f", grid, decay=decay, diffuse=diffuse, replicas=reps)
    alone = [cls("f", grid, decay=decay, diffuse=diffuse) for _ in range(reps)]
    pos = np.array([p for ps in points for p in ps], dtype=float).reshape(-1, 2)
    amt = np.array([a for am in amounts for a in am], dtype=float)
    rep = np.repeat(np.arange(reps), [len(p) for p in points])
    for _ in range(2):
        both.deposit(pos, amt, radius, rep)
        for r, f in enumerate(alone):
            f.deposit(pos[rep == r], amt[rep == r], radius)
        both.step()
        for f in alone:
            f.step()
    return both, alone, pos, rep


@settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
@given(_field_cases())
def test_a_field_of_replicas_is_its_replicas_fields(backend, case):
    """Deposits (shares on shared nodes summed in each replica's order), decay,
    diffusion, samples, gradients, look-aheads and cones of a field of replicas equal,
    replica by replica, those of a field of its own."""
    grid, points, amounts, radius, decay, diffuse = case
    cls = _field_class(backend)
    both, alone, pos, rep = _deposited_and_stepped(cls, grid, points, amounts, radius,
                                                   decay, diffuse)
    heading = np.linspace(-3, 3, len(pos))
    for r, f in enumerate(alone):
        assert both.values[r].tobytes() == f.values.tobytes(), r
        mine = pos[rep == r]
        rr = rep[rep == r]
        assert both.sample(mine, rr).tobytes() == f.sample(mine).tobytes()
        assert both.gradient(mine, rr).tobytes() == f.gradient(mine).tobytes()
        h = heading[rep == r]
        assert both.sample_ahead(mine, h, 3.0, rr).tobytes() == \
            f.sample_ahead(mine, h, 3.0).tobytes()
        assert both.sense_cone(mine, h, 4.0, 0.5, 3, replica=rr).tobytes() == \
            f.sense_cone(mine, h, 4.0, 0.5, 3).tobytes()


@settings(max_examples=25, deadline=None, suppress_health_check=list(HealthCheck))
@given(_field_cases(), st.sampled_from([1, 2]))
def test_a_refined_field_of_replicas_is_its_replicas_fields(case, levels):
    """The same on a refined grid: deposits (a radius's spread searched among the
    replica's own points), diffusion across the levels, samples and gradients."""
    from swarmdsl.runtime.refined_grid import RefinedField, RefinedGrid
    from swarmdsl.runtime.regions import Rect

    _grid, points, amounts, radius, decay, diffuse = case
    grid = RefinedGrid(Grid(40, 30, 10), [(Rect(0, 0, 20, 15), levels)])
    both, alone, pos, rep = _deposited_and_stepped(RefinedField, grid, points, amounts, radius,
                                                   decay, diffuse)
    for r, f in enumerate(alone):
        assert both.nodes[r].tobytes() == f.nodes.tobytes(), r
        assert both.values[r].tobytes() == f.values.tobytes(), r
        mine, rr = pos[rep == r], rep[rep == r]
        assert both.sample(mine, rr).tobytes() == f.sample(mine).tobytes()
        assert both.gradient(mine, rr).tobytes() == f.gradient(mine).tobytes()


def test_a_field_of_replicas_needs_each_points_replica():
    grid = Grid(20, 20, 5)
    both, alone = Field("f", grid, replicas=2), Field("f", grid)
    with pytest.raises(ValueError, match="replica of each of the 2 points"):
        both.sample(np.zeros((2, 2)), np.array([0]))
    with pytest.raises(ValueError, match="holds one run"):
        alone.sample(np.zeros((1, 2)), np.array([0]))


# ---- generated programs ----

from welltyped import programs as welltyped_programs  # noqa: E402


@settings(max_examples=5, deadline=None, derandomize=True,
          suppress_health_check=list(HealthCheck))
@given(welltyped_programs().filter(lambda text: "field heat" in text),
       st.lists(st.integers(0, 2**40), min_size=2, max_size=3, unique=True))
def test_generated_programs_with_fields_batch_to_their_solo_runs(backend, text, seeds):
    try:
        program = compile_source(text, "gen.swarm")
    except Exception:   # noqa: BLE001 - a generated program the checker refuses
        assume(False)
    assume(batch_refusal(program) is None)
    try:
        for s in seeds:
            Simulation(program, s, backend=SOLO).run(4)
    except Exception:   # noqa: BLE001 - faults are test_batch.py's (ReplicaFault)
        assume(False)
    assert_each_tick_is_the_solo_tick(program, seeds, backend, 4)


_READINGS = """world { size 60 x 60; grid 10 }
field heat { decay 0.05; diffuse 0.2 }
food snack = circle(30, 30, 8)
agent a { count 5
  var got = 0
  status s {
    velocity = random_direction() + normalize(gradient(heat)) * 0.5
    deposit(heat, 1 + index)
    got = cone(heat, 3, 0.5) + ahead(heat, 2, 0.3) + heat at (pos + (1, 0))
    when inside(snack) -> t {}
  }
  status t { velocity = random_direction(); deposit(heat, 2, 12)
    when distance_to(snack) > 5 -> s {} }
}
metric hot = mean(sample(heat))
metric near = count(touching(food, 3))
metric most = max(heat at pos)
"""


def test_every_field_reading_and_region_test_batches(backend):
    """Cones, look-aheads, `at`, gradients, deposits with and without a radius, region
    tests in statuses and in metrics (a metric reading a field: each replica's grid)."""
    program = compile_source(_READINGS, "readings.swarm")
    assert batch_refusal(program) is None
    solos = assert_each_tick_is_the_solo_tick(program, SEEDS, backend, 20)
    assert solos[0].status_counts()["t"] == 1   # one agent reached the snack


_CLIMBERS = """world { size 60 x 60; grid 5 }
field hill { initial 50 * exp(-(distance(pos, (40, 35)) / 15) ^ 2) + uniform(0, 3) }
agent bot { count 4
  place uniform
  var got = 0
  status climb {
    deposit(hill, 0.5)
    tree follow(hill, 1.5)
    on success -> done { got = tick }
    on failure -> done { got = -tick }
  }
  status done { }
}
"""


def test_climbing_each_replicas_own_field_batches(backend):
    """`follow` climbs the replica's own field, whose initial values draw per node
    (each run its own hills)."""
    program = compile_source(_CLIMBERS, "climb.swarm")
    solos = assert_each_tick_is_the_solo_tick(program, SEEDS, backend, 25)
    starts = {s.environment.fields["hill"].values.tobytes() for s in solos}
    assert len(starts) == len(SEEDS)
    assert all(s.status_counts()["done"] for s in solos)


# ---- physical twins ----

_TWINS = """world { size 100 x 80; grid 10; edges wrap }
field temp { twin 30 - distance(pos, (50 + 30 * cos(tick / 10), 40)) / 10 }
field wind { twin ((80 - pos.y) / 80 + normal(0, 0.1), pos.x / 100) }
field flow { twin (cos(tick / 7) * pos.y / 80, 0.3) }
field mark { decay 0.01; diffuse 0.2 }
agent a { count 6
  var felt = 0
  status s {
    felt = temp at pos
    velocity = sample(wind) + sample(flow) + normalize(gradient(temp)) + random_direction()
    deposit(mark, felt / 10)
  }
}
metric warm = mean(felt)
"""


def test_physical_twins_batch_to_their_solo_runs(backend):
    """A static twin that draws per node (each replica's own noise), twins sampled
    anew every tick (the same for every replica), scalar and vector, read and climbed."""
    program = compile_source(_TWINS, "twins.swarm")
    assert batch_refusal(program) is None
    solos = assert_each_tick_is_the_solo_tick(program, SEEDS, backend, 12)
    winds = [s.environment.vectors["wind"].x.values.tobytes() for s in solos]
    assert len(set(winds)) == len(winds)   # each replica its own static noise


# ---- what is still refused ----

_DRAWING_TWIN = """world { size 40 x 40; grid 10 }
field heat { twin pos.x / 10 + tick + uniform(0, 1) }
agent a { count 2
  status s { velocity = (sample(heat), 0) } }
"""


def test_a_twin_that_draws_every_tick_is_refused_naming_its_line():
    program = compile_source(_DRAWING_TWIN, "twin.swarm")
    assert batch_refusal(program) == ("a physical twin that draws at every tick is not "
                                      "batched yet (`field heat`, line 2)")
    with pytest.raises(SwarmOptionError, match="cannot run as a batch: a physical twin"):
        BatchedSimulation(program, [1, 2], backend="numpy")


def test_every_shipped_program_batches():
    for path in sorted(PROGRAMS.glob("*.swarm")):
        assert batch_refusal(load_program(path)) is None, path
