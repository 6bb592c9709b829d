"""Refined grids: nodes on every level, twins sampled exactly, conservative deposit and
diffusion across refinement boundaries, and the figure 3.3 program."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from swarmdsl.compiler import compile_file
from swarmdsl.runtime.fields import Grid
from swarmdsl.runtime.refined_grid import RefinedField, RefinedGrid
from swarmdsl.runtime.regions import Circle, Rect
from swarmdsl.runtime.simulation import Simulation

PROGRAMS = Path(__file__).resolve().parent.parent / "programs"
GRID = RefinedGrid(Grid(200, 120, 20), [(Rect(0, 80, 60, 120), 2), (Circle(170, 20, 25), 1)])


def _temperature(x, y, t):
    cx, cy = 200 + 120 * np.cos(t / 100), 200 + 120 * np.sin(t / 100)
    return 30 - np.hypot(x - cx, y - cy) / 10


def test_the_grid_has_nodes_on_every_level_and_each_point_once():
    assert GRID.levels == 2
    assert set(np.unique(GRID.level)) == {0, 1, 2}
    pts = GRID.positions
    assert len(np.unique(np.round(pts, 9), axis=0)) == GRID.n
    fine = pts[GRID.level == 2]              # spacing 5 inside the refined corner
    assert fine[:, 0].max() <= 60 + 20 and fine[:, 1].min() >= 80 - 1e-9
    assert np.allclose(fine % 5, 0)
    # the base grid's nodes keep ids 0 .. ny*nx-1, in (ny, nx) order
    np.testing.assert_array_equal(GRID.positions[GRID.base_ids()[2, 3]], [60, 40])


def test_twin_equals_the_formula_at_every_node_of_every_level(backend):
    sim = Simulation(compile_file(PROGRAMS / "mas_environment.swarm"), 0)
    env = sim.environment
    grid = env.grid
    for _ in range(3):
        x, y = grid.positions[:, 0], grid.positions[:, 1]
        want = _temperature(x, y, sim.tick)
        temp = env.fields["temperature"]
        np.testing.assert_allclose(temp.node_values(), want, rtol=0, atol=1e-12)
        np.testing.assert_allclose(temp.sample(grid.positions), want, rtol=0, atol=1e-12)
        assert set(np.unique(grid.level)) == {0, 2}   # base and twice-refined corners
        cur = env.vectors["current"].sample(grid.positions)
        np.testing.assert_allclose(cur[:, 0], 0.6 * (200 - y) / 200, atol=1e-12)
        sim.step()


@settings(max_examples=40)
@given(a=st.floats(-5, 5), b=st.floats(-1, 1), c=st.floats(-1, 1),
       pts=arrays(np.float64, (20, 2), elements=st.floats(0, 1)))
def test_linear_fields_are_sampled_exactly_on_every_level(a, b, c, pts):
    f = RefinedField("lin", GRID)
    p = GRID.positions
    f.set_nodes(a + b * p[:, 0] + c * p[:, 1])
    q = pts * [200, 120]
    np.testing.assert_allclose(f.sample(q), a + b * q[:, 0] + c * q[:, 1], atol=1e-9)
    inner = q[(q[:, 0] > 10) & (q[:, 0] < 190) & (q[:, 1] > 10) & (q[:, 1] < 110)]
    if len(inner):
        np.testing.assert_allclose(f.gradient(inner), np.tile([b, c], (len(inner), 1)),
                                   atol=1e-9)


@settings(max_examples=40)
@given(values=arrays(np.float64, (GRID.n,), elements=st.floats(0, 100)),
       rate=st.floats(0, 0.25), steps=st.integers(1, 5))
def test_diffusion_across_refinement_boundaries_conserves_mass(values, rate, steps):
    f = RefinedField("m", GRID, diffuse=rate)
    f.set_nodes(values)
    before = f.total()
    for _ in range(steps):
        f.step()
    assert f.total() == pytest.approx(before, rel=1e-12, abs=1e-9)
    assert f.node_values().min() >= -1e-9              # stable: no negative overshoot
    assert f.node_values().max() <= values.max() + 1e-9


@settings(max_examples=40)
@given(pts=arrays(np.float64, (8, 2), elements=st.floats(-0.1, 1.1)),
       amounts=arrays(np.float64, (8,), elements=st.floats(0, 10)),
       radius=st.sampled_from([0.0, 3.0, 12.0, 30.0]))
def test_deposit_adds_exactly_the_amount_anywhere(pts, amounts, radius):
    f = RefinedField("d", GRID)
    f.deposit(pts * [200, 120], amounts, radius)
    assert f.total() == pytest.approx(amounts.sum(), rel=1e-12, abs=1e-12)


def test_diffusion_spreads_a_spike_to_uniform_density_across_levels():
    f = RefinedField("s", GRID, diffuse=0.25)
    f.deposit(np.array([[10.0, 110.0]]), 100.0)         # inside the finest corner
    for _ in range(3000):
        f.step()
    level = f.total() / GRID.weight.sum()
    np.testing.assert_allclose(f.node_values(), level, rtol=1e-3)


def test_figure_3_3_program_records_base_nodes_and_agents_respond(backend, tmp_path):
    from swarmdsl.cli import main

    out = tmp_path / "run"
    assert main(["run", str(PROGRAMS / "mas_environment.swarm"), "--headless", "--steps",
                 "150", "--seed", "1", "--every", "50", "--out", str(out)]) == 0
    data = np.load(out / "fields.npz")
    assert data["temperature"].shape == (4, 21, 21)
    x, y = np.meshgrid(data["grid_x"], data["grid_y"])
    np.testing.assert_allclose(data["temperature"][-1], _temperature(x, y, 150), atol=1e-9)
    import pandas as pd

    agents = pd.read_parquet(out / "agents.parquet")
    felt = agents.groupby("tick")["felt"].mean()
    assert felt.loc[150] > 20                            # they found the warm spot


@pytest.mark.parametrize("world, message", [
    ("edges wrap; refine rect(0, 0, 50, 50) 1", "1:46: a wrap-around world cannot be "
     "refined"),
    ("refine rect(0, 0, 50, 50) 5", "1:60: the number of refinement levels is a whole "
     "number from 1 to 4, got 5"),
    ("refine home 1", "1:41: unknown region `home` to refine"),
    ("refine square(1, 2) 1", "1:41: a refined region is `refine rect(x0, y0, x1, y1) "
     "LEVELS`, `refine circle(x, y, r) LEVELS` or `refine REGION LEVELS`"),
])
def test_refine_mistakes_are_located_errors(assert_located_error, world, message):
    text = "world { size 100 x 100; grid 10; " + world + " }\nagent a { status s { } }"
    assert_located_error(text, message)


def _environment(sim):
    from swarmdsl.runtime.environment import Environment

    return next(ext for ext in sim.extensions if isinstance(ext, Environment))


def test_fields_npz_records_every_node_of_a_refined_grid(tmp_path, backend):
    # fields.npz held the base grid's nodes only: a refined region's finer values were
    # lost with the run
    from swarmdsl.runtime.runner import Run
    from swarmdsl.runtime.spool import open_fields

    program = compile_file(PROGRAMS / "mas_environment.swarm")
    out = tmp_path / "run"
    assert Run(program, seed=2, steps=40, every=20, out=out,
               backend=backend).execute() == "completed"
    halfway = Simulation(program, 2, backend=backend)
    halfway.run(20)
    ends = {20: _environment(halfway)}
    whole = Simulation(program, 2, backend=backend)
    whole.run(40)
    ends[40] = _environment(whole)
    with open_fields(out) as data:
        grid = ends[40].grid
        np.testing.assert_array_equal(data["nodes_x"], grid.node_positions()[:, 0])
        np.testing.assert_array_equal(data["nodes_y"], grid.node_positions()[:, 1])
        assert data["nodes_level"].max() == 2 and data["nodes_level"].shape == (grid.n,)
        assert (data["nodes_level"] == 2).sum() > 0
        assert list(data["ticks"]) == [0, 20, 40]
        for row, tick in ((1, 20), (2, 40)):
            env = ends[tick]
            for name in ("visited", "temperature", "current.x", "current.y"):
                part = env.fields.get(name) or env._vector_part(name)
                np.testing.assert_array_equal(data[name + ".nodes"][row],
                                              part.node_values())
        # the base grid's frames are the first ny * nx nodes, row by row
        ny, nx = data["visited"].shape[1:]
        np.testing.assert_array_equal(data["visited.nodes"][:, :ny * nx].reshape(-1, ny, nx),
                                      data["visited"])
        fine = data["nodes_level"] > 0          # what only the new frames hold
        assert fine.sum() > 0 and data["visited.nodes"][-1][fine].any()
        # the amounts on every node sum to the field's total (weight 4 ** -level)
        weight = 0.25 ** data["nodes_level"]
        assert data["visited.nodes"][-1] @ weight == pytest.approx(
            ends[40].fields["visited"].total(), rel=1e-12)


def test_a_uniform_grid_records_no_node_frames(tmp_path):
    from swarmdsl.runtime.runner import Run

    Run(compile_file(PROGRAMS / "aco.swarm"), seed=0, steps=2, out=tmp_path / "r").execute()
    with np.load(tmp_path / "r" / "fields.npz") as data:
        assert not [k for k in data.files if k.startswith("nodes_") or k.endswith(".nodes")]


def test_a_resumed_refined_run_keeps_its_node_frames(tmp_path):
    from conftest import assert_same_outputs

    from swarmdsl.cli import main

    path = str(PROGRAMS / "mas_environment.swarm")
    common = ["run", path, "--headless", "--every", "10", "--seed", "1"]
    assert main([*common, "--steps", "30", "--out", str(tmp_path / "whole")]) == 0
    split = tmp_path / "split"
    assert main([*common, "--steps", "20", "--out", str(split),
                 "--checkpoint-every", "10"]) == 0
    assert main(["run", path, "--headless", "--resume", str(split), "--steps", "30"]) == 0
    assert_same_outputs(tmp_path / "whole", split)
    with np.load(split / "fields.npz") as data:
        assert data["visited.nodes"].shape[0] == 4 and "nodes_level" in data.files


def _bits(a) -> np.ndarray:
    return np.asarray(a, dtype=np.float64).view(np.int64)


def test_the_compiled_reading_of_points_is_the_reference_bit_for_bit():
    """The numba backend's refined grid (`compiled/refined.py`) finds the same level,
    corners and weights for every point: every point of a 2.5-unit lattice over the
    grid and past its edges (the cell edges and corners of every level, a refinement's
    boundary), and random points."""
    pytest.importorskip("numba")
    from swarmdsl.runtime.compiled.refined import CompiledRefinedGrid

    fast = CompiledRefinedGrid(GRID.base, [(Rect(0, 80, 60, 120), 2),
                                           (Circle(170, 20, 25), 1)])
    gx, gy = np.meshgrid(np.arange(-4, 85) * 2.5, np.arange(-4, 53) * 2.5)
    lattice = np.stack([gx.ravel(), gy.ravel()], axis=1)
    scattered = np.random.default_rng(7).uniform([-10, -10], [210, 130], (2000, 2))
    zeros = np.array([[-0.0, 50.0], [0.0, -0.0], [-0.0, -0.0], [200.0, -0.0]])
    for p in (lattice, scattered, lattice[:0], zeros, scattered.T.copy().T):
        np.testing.assert_array_equal(fast.level_at(p), GRID.level_at(p))
        ids, w = fast.bilinear(p)
        want_ids, want_w = GRID.bilinear(p)
        np.testing.assert_array_equal(ids, want_ids)
        np.testing.assert_array_equal(_bits(w), _bits(want_w))
    for bad in ([[1.0, np.nan]], [[np.inf, 2.0]], [1.0, 2.0]):
        with pytest.raises(ValueError) as got:
            fast.bilinear(np.array(bad))
        with pytest.raises(ValueError) as want:
            GRID.bilinear(np.array(bad))
        assert str(got.value) == str(want.value)


def test_the_compiled_diffusion_is_the_reference_bit_for_bit():
    """The numba backend's refined field (`compiled/refined.py`) diffuses and decays
    exactly as the reference, sub-step by sub-step, alone and as a batch's replicas."""
    pytest.importorskip("numba")
    from swarmdsl.runtime.compiled.refined import CompiledRefinedField

    rng = np.random.default_rng(3)
    for replicas in (None, 3):
        ref = RefinedField("c", GRID, decay=0.01, diffuse=0.2, replicas=replicas)
        fast = CompiledRefinedField("c", GRID, decay=0.01, diffuse=0.2, replicas=replicas)
        assert ref.substeps > 1
        start = rng.uniform(0, 50, ref.nodes.shape)
        ref.nodes[...] = start
        fast.nodes[...] = start
        for _ in range(5):
            ref.step()
            fast.step()
        np.testing.assert_array_equal(_bits(fast.nodes), _bits(ref.nodes))
