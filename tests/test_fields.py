"""Grid, Field and the direction choice: exact invariants, oracles and property tests."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.stats import chisquare

from swarmdsl.runtime.choice import (
    direction_angles,
    direction_weights,
    heading_index,
    weighted_direction_choice,
)
from swarmdsl.runtime.fields import (
    MAX_STABLE_DIFFUSION,
    Field,
    Grid,
    stable_diffusion_limit,
)

PROPS = settings(max_examples=60, deadline=None)


# -- Grid -------------------------------------------------------------------------------


def test_grid_nodes_follow_the_floor_rule():
    g = Grid(105, 50, 10)
    assert (g.nx, g.ny) == (11, 6)
    np.testing.assert_array_equal(g.grid_x, np.arange(11) * 10.0)
    np.testing.assert_array_equal(g.grid_y, np.arange(6) * 10.0)
    assert g.shape == (6, 11)
    x, y = g.nodes()
    assert x.shape == y.shape == (6, 11)
    assert x[2, 3] == 30 and y[2, 3] == 20


def test_grid_keeps_the_edge_node_despite_float_division():
    assert Grid(0.3, 0.3, 0.1).nx == 4


def test_periodic_grid_has_one_node_per_period_cell():
    g = Grid(100, 50, 10, periodic=True)
    assert g.shape == (5, 10)
    assert g.grid_x[-1] == 90
    with pytest.raises(ValueError, match="whole multiple of the grid spacing"):
        Grid(105, 50, 10, periodic=True)


@pytest.mark.parametrize("args", [(10, 10, 0), (10, 10, -1), (-1, 10, 1), (10, math.nan, 1)])
def test_grid_rejects_bad_sizes(args):
    with pytest.raises(ValueError):
        Grid(*args)


# -- decay and diffusion ----------------------------------------------------------------


def test_decay_multiplies_by_one_minus_rate_exactly():
    rng = np.random.default_rng(1)
    f = Field("p", Grid(50, 30, 1), decay=0.05)
    f.values = rng.random(f.grid.shape)
    expected = f.values.copy()
    for _ in range(5):
        f.step()
        expected = expected * (1 - 0.05)
        np.testing.assert_array_equal(f.values, expected)


def test_stability_limit_and_message():
    assert MAX_STABLE_DIFFUSION == 0.25 == stable_diffusion_limit()
    assert stable_diffusion_limit(1) == 0.5
    with pytest.raises(ValueError) as err:
        Field("p", Grid(10, 10, 1), diffuse=0.3)
    assert str(err.value) == (
        "diffusion rate 0.3 is unstable on a 2-D grid: it must be at most 0.25"
    )
    Field("p", Grid(10, 10, 1), diffuse=0.25)  # the limit itself is allowed


@pytest.mark.parametrize("kwargs", [{"decay": -0.1}, {"decay": 1.5}, {"diffuse": -0.01}])
def test_bad_rates_rejected(kwargs):
    with pytest.raises(ValueError):
        Field("p", Grid(10, 10, 1), **kwargs)


def _reference_step(v, decay, diffuse, periodic):
    """Decay then diffusion written the slow, obvious way with a padded copy."""
    v = v * (1 - decay)
    p = np.pad(v, 1, mode="wrap" if periodic else "edge")
    lap = p[:-2, 1:-1] + p[2:, 1:-1] + p[1:-1, :-2] + p[1:-1, 2:] - 4 * v
    return v + diffuse * lap


field_cases = st.tuples(
    st.integers(1, 12),  # ny
    st.integers(1, 12),  # nx
    st.floats(0, MAX_STABLE_DIFFUSION),
    st.booleans(),
).flatmap(
    lambda t: st.tuples(
        st.just(t),
        arrays(np.float64, (t[0], t[1]), elements=st.floats(0, 1e3, allow_subnormal=False)),
    )
)


@PROPS
@given(field_cases)
def test_diffusion_conserves_mass_without_decay(case):
    (ny, nx, rate, periodic), init = case
    grid = Grid(nx * 2.0 if periodic else (nx - 1) * 2.0,
                ny * 2.0 if periodic else (ny - 1) * 2.0, 2.0, periodic=periodic)
    f = Field("p", grid, diffuse=rate, init=init)
    before = init.sum()
    for _ in range(10):
        f.step()
    assert math.isclose(f.total(), before, rel_tol=1e-12, abs_tol=0.0)
    assert (f.values >= 0).all()  # the stable scheme never creates negative amounts


@PROPS
@given(field_cases, st.floats(0, 1))
def test_step_matches_padded_reference(case, decay):
    (ny, nx, rate, periodic), init = case
    grid = Grid(nx if periodic else nx - 1, ny if periodic else ny - 1, 1.0, periodic=periodic)
    f = Field("p", grid, decay=decay, diffuse=rate, init=init)
    f.step()
    expected = _reference_step(init, decay, rate, periodic)
    np.testing.assert_allclose(f.values, expected, rtol=1e-12, atol=1e-12)


def test_periodic_diffusion_wraps_across_the_edge():
    f = Field("p", Grid(10, 10, 1, periodic=True), diffuse=0.25)
    f.values[0, 0] = 1.0
    f.step()
    assert f.values[0, -1] == f.values[-1, 0] == f.values[0, 1] == 0.25


# -- deposit and sample -----------------------------------------------------------------


def test_deposit_on_a_node_reads_back_the_amount():
    """Values are amounts per node, so a deposit at a node samples back unchanged."""
    f = Field("p", Grid(100, 60, 10))
    f.deposit([[30.0, 20.0]], 2.5)
    assert f.values[2, 3] == 2.5
    assert f.sample([[30.0, 20.0]])[0] == 2.5
    assert f.total() == 2.5


def test_bilinear_deposit_splits_by_distance():
    f = Field("p", Grid(100, 60, 10))
    f.deposit([[32.5, 20.0]], 1.0)
    assert f.values[2, 3] == 0.75 and f.values[2, 4] == 0.25


def test_deposits_at_one_node_accumulate():
    f = Field("p", Grid(100, 60, 10))
    f.deposit(np.full((7, 2), 40.0), np.arange(7.0))
    assert f.values[4, 4] == 21.0


edge_coord = st.one_of(
    st.floats(-20, 120, allow_nan=False), st.sampled_from([0.0, 100.0, 99.999999, 60.0])
)


@PROPS
@given(
    st.lists(st.tuples(edge_coord, edge_coord), min_size=1, max_size=30),
    st.floats(0.0, 1e3),
    st.booleans(),
    st.sampled_from([0.0, 0.0, 3.0, 10.0, 27.5]),
)
def test_deposited_total_equals_the_amount(pts, amount, periodic, radius):
    f = Field("p", Grid(100, 60, 10, periodic=periodic))
    pos = np.array(pts)
    amounts = np.linspace(0.5, 1.5, len(pos)) * amount
    f.deposit(pos, amounts, radius=radius)
    assert math.isclose(f.total(), amounts.sum(), rel_tol=1e-12, abs_tol=1e-12)
    assert (f.values >= 0).all()


def test_radius_deposit_spreads_symmetrically():
    f = Field("p", Grid(100, 100, 1))
    f.deposit([[50.0, 50.0]], 1.0, radius=3.0)
    v = f.values
    assert math.isclose(v.sum(), 1.0, rel_tol=1e-12)
    assert v[50, 50] == v.max()
    np.testing.assert_allclose(v, v.T, atol=1e-15)
    np.testing.assert_allclose(v, v[::-1, ::-1], atol=1e-15)
    assert v[50, 53] == 0 and v[50, 52] > 0  # cone weight is 0 at the radius


def test_small_radius_far_from_nodes_falls_back_to_bilinear():
    a, b = Field("a", Grid(100, 100, 10)), Field("b", Grid(100, 100, 10))
    a.deposit([[55.0, 55.0]], 1.0, radius=2.0)
    b.deposit([[55.0, 55.0]], 1.0)
    np.testing.assert_array_equal(a.values, b.values)


def test_deposit_validates_shapes():
    f = Field("p", Grid(100, 100, 10))
    with pytest.raises(ValueError, match=r"shape \(M, 2\)"):
        f.deposit(np.zeros((3, 3)), 1.0)
    with pytest.raises(ValueError, match=r"shape \(3,\)"):
        f.deposit(np.zeros((3, 2)), [1.0, 2.0])
    with pytest.raises(ValueError, match="finite"):
        f.deposit([[math.nan, 1.0]], 1.0)
    f.deposit(np.empty((0, 2)), 1.0)
    assert f.total() == 0


def _linear(x, y):
    return 3.0 * x - 2.0 * y + 7.0


@pytest.mark.parametrize("periodic", [False, True])
def test_linear_formula_sampled_and_differentiated_exactly(periodic):
    f = Field("t", Grid(100, 60, 10, periodic=periodic))
    f.set_from_formula(_linear)
    x, y = f.grid.nodes()
    np.testing.assert_array_equal(f.values, _linear(x, y))
    pos = np.random.default_rng(3).uniform([0, 0], [f.grid.grid_x[-1], f.grid.grid_y[-1]],
                                           size=(500, 2))
    np.testing.assert_allclose(f.sample(pos), _linear(pos[:, 0], pos[:, 1]),
                               rtol=1e-12, atol=1e-10)
    if not periodic:  # a linear field is not periodic, so only the bounded case has a slope
        grad = f.gradient(np.vstack([pos, [[0, 0], [100, 60]]]))
        np.testing.assert_allclose(grad, np.tile([3.0, -2.0], (502, 1)), rtol=1e-12)


def test_periodic_gradient_of_a_sine():
    f = Field("t", Grid(100, 100, 1, periodic=True))
    f.set_from_formula(lambda x, y: np.sin(2 * np.pi * x / 100))
    pos = np.array([[0.0, 5.0], [25.0, 5.0], [99.5, 7.0]])
    grad = f.gradient(pos)
    np.testing.assert_allclose(grad[:, 0], 2 * np.pi / 100 * np.cos(2 * np.pi * pos[:, 0] / 100),
                               rtol=2e-3, atol=1e-4)
    np.testing.assert_allclose(grad[:, 1], 0.0, atol=1e-15)


def test_set_from_formula_checks_shape_and_accepts_constants():
    f = Field("t", Grid(100, 60, 10))
    f.set_from_formula(lambda x, y: 4.0)
    assert (f.values == 4.0).all()
    with pytest.raises(ValueError, match=r"expected \(7, 11\)"):
        f.set_from_formula(lambda x, y: np.zeros(3))


def test_sample_clamps_off_grid_positions():
    f = Field("t", Grid(100, 60, 10))
    f.set_from_formula(_linear)
    np.testing.assert_allclose(f.sample([[-50, -50], [500, 30]]),
                               [_linear(0, 0), _linear(100, 30)])


def test_sample_ahead_and_cone():
    f = Field("t", Grid(100, 100, 1))
    f.set_from_formula(lambda x, y: x)
    pos = np.array([[50.0, 50.0], [20.0, 30.0]])
    heading = np.array([0.0, np.pi / 2])
    np.testing.assert_allclose(f.sample_ahead(pos, heading, 10.0), [60.0, 20.0])
    np.testing.assert_allclose(f.sample_ahead(pos, heading, np.array([1.0, 2.0])), [51.0, 20.0])
    cone = f.sense_cone(pos, heading, 10.0, np.pi / 4, samples=5)
    angles = np.linspace(-np.pi / 4, np.pi / 4, 5)
    np.testing.assert_allclose(cone[0], 50 + 10 * np.cos(angles).mean())
    np.testing.assert_allclose(cone[1], 20.0, atol=1e-12)  # symmetric about the y axis
    np.testing.assert_allclose(f.sense_cone(pos, heading, 10.0, 1.0, samples=1), [60.0, 20.0])
    with pytest.raises(ValueError):
        f.sense_cone(pos, heading, 10.0, 1.0, samples=0)


# -- direction choice -------------------------------------------------------------------


def test_direction_weights_follow_persistence():
    w = direction_weights(np.array([0.0]), 8, 0.5)[0]
    np.testing.assert_array_equal(w, [1, 0.5, 0.25, 0.125, 0, 0.125, 0.25, 0.5])
    np.testing.assert_allclose(direction_angles(4), [0, np.pi / 2, np.pi, 3 * np.pi / 2])
    assert heading_index(np.array([2 * np.pi - 0.01, np.pi / 2 + 0.1]), 4).tolist() == [0, 1]


@PROPS
@given(
    st.integers(1, 24).map(lambda h: 2 * h),
    st.floats(0, 1),
    st.lists(st.floats(-50, 50), min_size=1, max_size=40),
    st.integers(0, 2**32 - 1),
    st.booleans(),
)
def test_choice_never_reverses_and_never_picks_zero_weight(k, persistence, headings, seed,
                                                           sparse_extra):
    rng = np.random.default_rng(seed)
    heading = np.array(headings)
    extra = rng.random((len(heading), k))
    if sparse_extra:
        extra[extra < 0.7] = 0.0
    chosen = weighted_direction_choice(rng, heading, k, persistence, extra)
    current = heading_index(heading, k)
    assert chosen.dtype == np.int64 and chosen.shape == heading.shape
    assert ((chosen >= 0) & (chosen < k)).all()
    assert (chosen != (current + k // 2) % k).all()
    w = direction_weights(heading, k, persistence, extra)
    picked = w[np.arange(len(w)), chosen]
    dead = w.sum(axis=1) == 0
    assert (picked[~dead] > 0).all()
    assert (chosen[dead] == current[dead]).all()  # fall back to straight on


def test_choice_matches_weights_in_distribution():
    k, m = 24, 20_000
    rng = np.random.default_rng(12345)
    heading = np.full(m, 3 * 2 * np.pi / k)  # direction 3
    extra_row = np.random.default_rng(7).random(k) * 3
    extra_row[[10, 11]] = 0.0
    chosen = weighted_direction_choice(rng, heading, k, 0.8, np.tile(extra_row, (m, 1)))
    counts = np.bincount(chosen, minlength=k)
    w = direction_weights(heading[:1], k, 0.8, extra_row[None])[0]
    assert (counts[w == 0] == 0).all()
    live = w > 0
    expected = w[live] / w[live].sum() * m
    assert chisquare(counts[live], expected).pvalue > 0.001


def test_choice_is_deterministic_and_draws_once_per_call():
    heading = np.linspace(0, 6, 50)
    a = weighted_direction_choice(np.random.default_rng(5), heading, 24, 0.6)
    rng = np.random.default_rng(5)
    b = weighted_direction_choice(rng, heading, 24, 0.6, np.zeros((50, 24)))
    np.testing.assert_array_equal(a, weighted_direction_choice(np.random.default_rng(5),
                                                               heading, 24, 0.6))
    np.testing.assert_array_equal(b, heading_index(heading, 24))  # all-zero rows go straight
    ref = np.random.default_rng(5)
    ref.random(50)
    assert rng.random() == ref.random()


@pytest.mark.parametrize(
    "kwargs",
    [{"k": 0}, {"k": 2.5}, {"persistence": 1.5}, {"weights_extra": -np.ones((3, 8))},
     {"weights_extra": np.ones((3, 7))}],
)
def test_choice_rejects_bad_arguments(kwargs):
    args = {"k": 8, "persistence": 0.5, "weights_extra": None} | kwargs
    with pytest.raises(ValueError):
        weighted_direction_choice(np.random.default_rng(0), np.zeros(3), **args)
