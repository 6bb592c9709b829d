"""The numba backend's field kernels: bit for bit the numpy `Field`, errors included."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import REFERENCE
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("numba")

from swarmdsl.compiler import compile_file, compile_source  # noqa: E402
from swarmdsl.runtime.compiled import threads  # noqa: E402
from swarmdsl.runtime.compiled.fields import CompiledField  # noqa: E402
from swarmdsl.runtime.fields import Field, Grid  # noqa: E402
from swarmdsl.runtime.simulation import Simulation  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SPACINGS = (0.3, 0.7, 1.0, 2.5)
FINITE = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)


@st.composite
def grids(draw) -> Grid:
    """Periodic and bounded grids, spacing mostly not 1, with rows or columns of one node."""
    spacing = draw(st.sampled_from(SPACINGS))
    if draw(st.booleans()):
        nx, ny = draw(st.integers(1, 9)), draw(st.integers(1, 9))
        return Grid(nx * spacing, ny * spacing, spacing, periodic=True)
    size = st.one_of(st.just(0.0), st.floats(0, 3 * spacing), st.floats(0, 20))
    return Grid(draw(size), draw(size), spacing)


@st.composite
def coordinates(draw, grid: Grid, axis: int) -> float:
    """Anywhere, off the grid, exactly on a node, on the far edge or just below 0."""
    n, extent = (grid.nx, grid.width) if axis == 0 else (grid.ny, grid.height)
    return draw(st.one_of(
        st.floats(-2 * extent - 3, 2 * extent + 3),
        st.integers(-n, 2 * n).map(lambda k: k * grid.spacing),
        st.sampled_from([extent, n * grid.spacing, (n - 1) * grid.spacing, 0.0, -0.0,
                         -1e-300, -5e-324, -1e-17, extent - 1e-12]),
    ))


@st.composite
def cases(draw):
    grid = draw(grids())
    fld = draw(st.sampled_from([(0.0, 0.0), (0.1, 0.0), (0.0, 0.25), (0.05, 0.2)]))
    decay, diffuse = fld if draw(st.booleans()) else (draw(st.floats(0, 1)),
                                                      draw(st.floats(0, 0.25)))
    values = np.array(draw(st.lists(FINITE, min_size=grid.nx * grid.ny,
                                    max_size=grid.nx * grid.ny))).reshape(grid.shape)
    m = draw(st.integers(0, 12))
    pos = np.array([[draw(coordinates(grid, 0)), draw(coordinates(grid, 1))]
                    for _ in range(m)]).reshape(m, 2)
    amount = draw(st.one_of(FINITE, st.lists(FINITE, min_size=m, max_size=m).map(np.array)))
    # a cone deposit: none, narrower than a node spacing (the bilinear fallback), wider
    radius = draw(st.sampled_from([0.0, 0.4, 1.0, 2.7])) * grid.spacing
    return grid, decay, diffuse, values, pos, amount, radius


def both(grid, decay, diffuse, values):
    """The numpy field and the compiled one, holding the same values."""
    pair = Field("f", grid, decay, diffuse), CompiledField("f", grid, decay, diffuse)
    for f in pair:
        f.values = values
    return pair


def assert_compiled_matches_numpy(case) -> None:
    grid, decay, diffuse, values, pos, amount, radius = case
    ref, fast = both(grid, decay, diffuse, values)
    for _ in range(2):   # the second round reads what the first deposited and diffused
        assert np.array_equal(ref.sample(pos), fast.sample(pos))
        assert np.array_equal(ref.gradient(pos), fast.gradient(pos))
        ref.deposit(pos, amount, radius)
        fast.deposit(pos, amount, radius)
        assert np.array_equal(ref.values.view(np.int64), fast.values.view(np.int64))
        ref.step()
        fast.step()
        assert np.array_equal(ref.values, fast.values)


@settings(deadline=None)
@given(cases())
def test_compiled_field_is_bit_identical_to_numpy(case):
    assert_compiled_matches_numpy(case)


@pytest.mark.slow
@settings(max_examples=2000, deadline=None)
@given(cases())
def test_compiled_field_is_bit_identical_to_numpy_long(case):
    assert_compiled_matches_numpy(case)


@pytest.mark.parametrize("periodic", [False, True])
def test_many_agents_on_one_node_and_the_far_edge_accumulate_alike(periodic):
    """Deposits that land on shared nodes add in one order on both paths."""
    grid = Grid(6.3, 4.2, 0.7, periodic=periodic)
    rng = np.random.default_rng(4)
    pos = np.concatenate([np.full((50, 2), 2.1), [[6.3, 4.2]] * 30,
                          rng.uniform(-1, 8, (500, 2))])
    amount = rng.uniform(0, 1e6, len(pos)) * rng.choice([1e-9, 1.0, 1e9], len(pos))
    ref, fast = both(grid, 0.05, 0.2, rng.uniform(0, 5, grid.shape))
    for radius in (0.0, 0.3, 1.5, 0.0, 2.2):
        ref.deposit(pos, amount, radius)
        fast.deposit(pos, amount, radius)
        ref.step()
        fast.step()
    assert np.array_equal(ref.values, fast.values)
    assert np.array_equal(ref.gradient(pos), fast.gradient(pos))


def test_readings_ahead_and_in_a_cone_are_the_numpy_bits():
    grid = Grid(12, 12, 0.6, periodic=True)
    rng = np.random.default_rng(5)
    ref, fast = both(grid, 0.0, 0.0, rng.uniform(0, 1, grid.shape))
    pos, heading = rng.uniform(-3, 15, (200, 2)), rng.uniform(-7, 7, 200)
    assert np.array_equal(ref.sample_ahead(pos, heading, 1.7),
                          fast.sample_ahead(pos, heading, 1.7))
    assert np.array_equal(ref.sense_cone(pos, heading, 2.0, 0.6, samples=5),
                          fast.sense_cone(pos, heading, 2.0, 0.6, samples=5))


def test_threaded_readings_are_the_serial_bits(monkeypatch):
    grid = Grid(40, 30, 0.5, periodic=True)
    rng = np.random.default_rng(8)
    pos = rng.uniform(-10, 50, (3000, 2))
    _, fast = both(grid, 0.0, 0.0, rng.uniform(0, 1, grid.shape))
    serial = fast.sample(pos), fast.gradient(pos)
    monkeypatch.setattr(threads, "MIN_PARALLEL", 0)
    monkeypatch.setattr(threads, "count", lambda: 2)
    assert np.array_equal(serial[0], fast.sample(pos))
    assert np.array_equal(serial[1], fast.gradient(pos))


def test_the_compiled_field_has_its_own_loops():
    """Every hot path is its own, not the numpy `Field`'s (the bits would not tell)."""
    for name in ("sample", "gradient", "_splat", "_spread", "_diffuse"):
        assert getattr(CompiledField, name) is not getattr(Field, name), name


def big_grid_paths(monkeypatch) -> None:
    """Every grid counts as too big for the caches, every swarm as dense enough for a
    pass over all the nodes' gradients, and two threads deposit in bands of rows."""
    from swarmdsl.runtime.compiled import fields

    monkeypatch.setattr(fields, "LARGE_GRID", 0)
    monkeypatch.setattr(fields, "NODES_PER_AGENT", 10**9)
    monkeypatch.setattr(threads, "MIN_PARALLEL", 0)
    monkeypatch.setattr(threads, "count", lambda: 2)


@settings(deadline=None, max_examples=60)
@given(cases())
def test_big_grid_kernels_are_bit_identical_to_numpy(case):
    with pytest.MonkeyPatch.context() as mp:
        big_grid_paths(mp)
        assert_compiled_matches_numpy(case)


@pytest.mark.parametrize("periodic", [False, True])
def test_banded_deposits_on_shared_nodes_and_band_edges_add_alike(monkeypatch, periodic):
    """Agents on the rows where two threads' bands meet, and many on one node: each
    node still gets its shares in agent order."""
    grid = Grid(8.0, 8.0, 1.0, periodic=periodic)     # 8 rows: bands of 4
    rng = np.random.default_rng(9)
    pos = np.concatenate([np.full((40, 2), 3.5), np.column_stack(
        [rng.uniform(0, 8, 300), rng.choice([3.0, 3.9, 4.0, 4.1, 7.9, 0.0], 300)]),
        rng.uniform(-2, 10, (300, 2))])
    amount = rng.uniform(0, 1e6, len(pos)) * rng.choice([1e-9, 1.0, 1e9], len(pos))
    ref, fast = both(grid, 0.05, 0.2, rng.uniform(0, 5, grid.shape))
    big_grid_paths(monkeypatch)
    for _ in range(3):
        ref.deposit(pos, amount)
        fast.deposit(pos, amount)
        assert np.array_equal(ref.values, fast.values)
        assert np.array_equal(ref.gradient(pos), fast.gradient(pos))
        ref.step()
        fast.step()


BAD_CALLS = [
    ("sample", ([[1.0, math.nan]],), "positions must be finite"),
    ("gradient", ([[math.inf, 1.0]],), "positions must be finite"),
    ("gradient", ([1.0, 2.0],), "positions must have shape"),
    ("deposit", ([[1.0, -math.inf]], 1.0), "positions must be finite"),
    ("deposit", ([[1.0, 1.0]], math.nan), "deposit amount must be finite"),
    ("deposit", ([[1.0, 1.0], [2.0, 2.0]], [1.0, math.inf]), "deposit amount must be finite"),
    ("deposit", ([[1.0, 1.0]], [1.0, 2.0]), "deposit amount must be a number or have shape"),
    ("deposit", ([[1.0, 1.0]], 1.0, -1.0), "deposit radius must not be negative"),
]


@pytest.mark.parametrize(("method", "args", "message"), BAD_CALLS)
def test_bad_arguments_raise_the_numpy_error_and_change_nothing(method, args, message):
    grid = Grid(10, 10, 1.5)
    ref, fast = both(grid, 0.1, 0.1, np.arange(grid.nx * grid.ny).reshape(grid.shape))
    errors = []
    for f in (ref, fast):
        with pytest.raises(ValueError, match=message) as caught:
            getattr(f, method)(*args)
        errors.append(str(caught.value))
        assert np.array_equal(f.values, ref.values)
    assert errors[0] == errors[1]


def run_backends(prog, ticks: int, other: str, seed: int = 2):
    sims = [Simulation(prog, seed, backend=b) for b in (REFERENCE, other)]
    for sim in sims:
        sim.run(ticks)
    return sims


def assert_same_run(sims) -> None:
    """Positions, velocities, headings and fields bit for bit."""
    ref, fast = sims
    for col in ("pos", "vel", "heading"):
        assert np.array_equal(ref.agents.cols[col], fast.agents.cols[col]), col
    for name, f in ref.environment.fields.items():
        assert np.array_equal(f.values, fast.environment.fields[name].values), name


def test_chemotaxis_runs_bit_for_bit_on_both_backends(other_backend):
    prog = compile_file(ROOT / "benchmarks" / "models" / "chemotaxis.swarm",
                        {"n": "400", "size": "40"})
    sims = run_backends(prog, 12, other_backend)
    assert sims[0].environment.fields["chem"].total() > 0
    assert_same_run(sims)
    assert type(sims[1].environment.fields["chem"]) is CompiledField
    assert type(sims[0].environment.fields["chem"]) is Field
    summary = sims[1].backend.summary(prog)
    assert "fields (sample, gradient, deposit, decay and diffusion): compiled" in summary


WALLED = """
world { size 23.1 x 9.8; grid 0.7; edges wall }
field scent { decay 0.03; diffuse 0.21; initial pos.x / 10 }
field trail { diffuse 0.1 }
agent ant {
  count 150
  velocity random_direction() * 1.5
  status walk {
    deposit(trail, 0.5 + sample(scent))
    deposit(scent, trail at (pos + normalize(velocity) * 2), 1.2)
    velocity = rotate(velocity + gradient(trail) + gradient(scent),
                      (trail at (pos + (1, 0.5))) - sample(scent, pos - (0.3, 2)))
  }
}
"""


def test_a_walled_field_program_runs_bit_for_bit_on_both_backends(other_backend):
    """Bounded grid, spacing 0.7, initial values, a radius deposit (numpy on both),
    readings off the grid, agents pressed against the walls."""
    sims = run_backends(compile_source(WALLED, "walled.swarm"), 20, other_backend)
    assert_same_run(sims)
    assert sims[1].environment.fields["trail"].total() > 0
