"""The pair table equals a brute-force O(N^2) neighbour list, in open and wrapped worlds,
and segment reductions equal per-agent Python reductions."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from swarmdsl.runtime import spatial
from swarmdsl.runtime.spatial import (
    build_pairs,
    segment_argmin,
    segment_count,
    segment_extreme,
    segment_sum,
)


def _brute(pos, radius, box):
    d = pos[None, :, :] - pos[:, None, :]
    if box is not None:
        d -= np.asarray(box) * np.round(d / np.asarray(box))
    dist = np.sqrt((d ** 2).sum(-1))
    i, j = np.nonzero((dist <= radius) & ~np.eye(len(pos), dtype=bool))
    return set(zip(i.tolist(), j.tolist(), strict=True)), dist


@given(n=st.integers(0, 60), radius=st.floats(0.5, 30), wrap=st.booleans(),
       seed=st.integers(0, 2**32 - 1))
def test_pairs_match_brute_force(n, radius, wrap, seed):
    rng = np.random.default_rng(seed)
    box = (50.0, 40.0) if wrap else None
    pos = rng.uniform((0, 0), (50, 40), (n, 2))
    table = build_pairs(pos, radius, box)
    expected, dist = _brute(pos, radius, box)
    i = np.repeat(np.arange(n), np.diff(table.offsets))
    got = set(zip(i.tolist(), table.j.tolist(), strict=True))
    # pairs exactly at the radius may fall either way by rounding: compare away from it
    def robust(pairs):
        return {p for p in pairs if abs(dist[p] - radius) > 1e-9}
    assert robust(got) == robust(expected)
    if len(i):
        assert np.allclose(table.dist, dist[i, table.j])
        assert np.all(np.diff(i) >= 0)  # sorted by agent: CSR layout


@given(n=st.integers(2, 90), radius=st.sampled_from([0.5, 1.0, 2.5, 7.0, 19.9, 20.0, 25.0]),
       wrap=st.booleans(), snap=st.sampled_from([0.0, 0.5, 1.0]),
       seed=st.integers(0, 2**32 - 1))
def test_the_sweep_and_the_tree_find_the_same_pairs_with_the_same_bits(n, radius, wrap,
                                                                        snap, seed):
    """A small swarm's pairs come from a sweep along x, a big one's from a KD-tree: for
    the same agents both give every pair once, with the same `dist` and `delta` bits,
    agents on a lattice (pairs exactly at the radius), on the world's edges and a radius
    near or past half the world included."""
    rng = np.random.default_rng(seed)
    box = (40.0, 30.0) if wrap else None
    pos = rng.uniform((0, 0), (40, 30), (n, 2))
    on = rng.random(n) < snap
    pos[on] = np.round(pos[on] / radius) * radius
    pos[on & (rng.random(n) < 0.2), 0] = 40.0 if wrap else 0.0
    if not wrap:
        pos = np.minimum(pos, (40, 30))
    tables = []
    for most in (10**9, 0):   # every swarm swept, then none
        old, spatial.SWEEP_MAX = spatial.SWEEP_MAX, most
        try:
            tables.append(build_pairs(pos, radius, box))
        finally:
            spatial.SWEEP_MAX = old
    swept, tree = tables
    for t in tables:
        assert np.all(np.diff(t.i) >= 0)
        assert len(set(zip(t.i.tolist(), t.j.tolist(), strict=True))) == t.j.size
    a, b = (np.lexsort((t.j, t.i)) for t in tables)
    assert np.array_equal(swept.i[a], tree.i[b]) and np.array_equal(swept.j[a], tree.j[b])
    assert np.array_equal(swept.dist[a], tree.dist[b])
    assert np.array_equal(swept.delta[a], tree.delta[b])
    assert np.array_equal(swept.offsets, tree.offsets)


def test_gather_returns_the_rows_of_the_selected_agents():
    pos = np.array([[0, 0], [1, 0], [2, 0], [10, 10]], float)
    table = build_pairs(pos, 1.5, None)
    seg, j, dist, _delta = table.gather(np.array([1, 3]))
    assert sorted(zip(seg.tolist(), j.tolist(), strict=True)) == [(0, 0), (0, 2)]
    assert np.allclose(dist, 1.0)


@given(st.lists(st.tuples(st.integers(0, 4), st.floats(-100, 100)), max_size=40))
def test_segment_reductions(rows):
    rows.sort(key=lambda r: r[0])
    seg = np.array([r[0] for r in rows], dtype=np.int64)
    vals = np.array([r[1] for r in rows], dtype=float)
    m = 5
    for k in range(m):
        mine = [v for s, v in rows if s == k]
        assert segment_count(seg, m)[k] == len(mine)
        assert np.isclose(segment_sum(vals, seg, m)[k], sum(mine))
        assert segment_extreme(np.minimum, vals, seg, m, -7.0)[k] == (min(mine) if mine else -7)
    segs, picked = segment_argmin(vals, seg, m)
    for s, r in zip(segs.tolist(), picked.tolist(), strict=True):
        assert vals[r] == min(v for k, v in rows if k == s)


# ---- fast paths: the same results as the plain numpy forms they replace ----

@given(st.lists(st.integers(0, 2**20), max_size=200, unique=True), st.booleans())
def test_packed_argsort_is_the_argsort(keys, wide):
    from swarmdsl.runtime.spatial import _argsort_unique

    key = np.array(keys, dtype=np.int64)
    bound = 2**60 if wide else 2**21   # too wide to pack: numpy's own argsort
    assert _argsort_unique(key.copy(), bound).tolist() == np.argsort(key).tolist()


@given(st.lists(st.integers(1, 40), min_size=1, max_size=4), st.booleans(),
       st.sampled_from([1e-300, 0.3, 2.0, 50.0, 1e300]), st.integers(0, 2**32 - 1))
def test_a_batchs_cell_grids_are_its_replicas_solo_grids(sizes, wrap, radius, seed):
    from swarmdsl.runtime.spatial import cell_grid, cell_grids

    rng = np.random.default_rng(seed)
    box = (30.0, 20.0) if wrap else None
    pos = rng.uniform((0, 0), (30, 20), (sum(sizes), 2))
    pos[: sizes[0]] = pos[0]           # a replica with no spread, or of one agent
    bounds = np.concatenate([[0], np.cumsum(sizes)])
    grids = cell_grids(pos, bounds, radius, box)
    for r in range(len(sizes)):
        solo = cell_grid(pos[bounds[r]:bounds[r + 1]], radius, box)
        assert solo == tuple(g[r].item() for g in grids)


@given(n=st.integers(2, 60), wrap=st.booleans(), radius=st.sampled_from([0.7, 3.0, 12.0]),
       seed=st.integers(0, 2**32 - 1))
def test_each_owners_neighbours_come_cell_by_cell(n, wrap, radius, seed):
    """The order sums add their terms in (the compiled cell list's, on both backends):
    by owner; then by the row of cells, from the one below; within a row by cell, the
    cells past a wrapped edge last; within a cell by agent row."""
    from swarmdsl.runtime.spatial import cell_grid

    rng = np.random.default_rng(seed)
    box = (30.0, 20.0) if wrap else None
    pos = rng.uniform((0, 0), (30, 20), (n, 2))
    table = build_pairs(pos, radius, box)
    x0, y0, nx, ny, wx, wy = cell_grid(pos, radius, box)
    cx = np.minimum(((pos[:, 0] - x0) / wx).astype(int), nx - 1)
    cy = np.minimum(((pos[:, 1] - y0) / wy).astype(int), ny - 1)
    for i in range(n):
        got = table.j[table.offsets[i]:table.offsets[i + 1]].tolist()

        def visit(j, i=i):
            row = (cy[j] - cy[i] + 1) % ny if wrap and ny >= 3 else (
                cy[j] if wrap else cy[j] - cy[i] + 1)
            past = wrap and nx >= 3 and abs(int(cx[j]) - int(cx[i])) == nx - 1
            return (row, past, cx[j] if not past else 0, j)
        assert got == sorted(got, key=visit)


@given(n=st.integers(2, 40), wrap=st.booleans(), seed=st.integers(0, 2**32 - 1))
def test_select_matches_the_pairs_of_the_selected_agents(n, wrap, seed):
    rng = np.random.default_rng(seed)
    box = (50.0, 40.0) if wrap else None
    table = build_pairs(rng.uniform((0, 0), (50, 40), (n, 2)), 12.0, box)
    assert np.all(table.dist <= table.radius)
    seg, rows = table.select(np.arange(n))  # every agent: the table itself, no copy
    assert seg is table.i and rows is None
    idx = np.flatnonzero(rng.random(n) < 0.5)[: n - 1]  # not every agent
    seg, rows = table.select(idx)
    mine = np.isin(table.i, idx)
    assert rows.tolist() == np.flatnonzero(mine).tolist()
    assert idx[seg].tolist() == table.i[mine].tolist()
    gseg, j, dist, delta = table.gather(idx)
    assert gseg.tolist() == seg.tolist() and j.tolist() == table.j[mine].tolist()
    assert np.array_equal(dist, table.dist[mine]) and np.array_equal(delta, table.delta[mine])


def test_pair_table_is_read_only():
    table = build_pairs(np.array([[0.0, 0.0], [1.0, 0.0]]), 2.0, None)
    for a in (table.i, table.j, table.dist, table.delta, table.offsets):
        assert not a.flags.writeable


POSITION_DIFFERENCES = """
world {{ size 60 x 50; edges {edges} }}
agent a {{
  count 40
  place (if index < 2 then 3 else (index * 7.3) % 60, if index < 2 then 5 else (index * 4.1) % 50)
  var fast = (0, 0)
  var plain = (0, 0)
  var back = (0, 0)
  var plain_back = (0, 0)
  var ang = 0
  var plain_ang = 0
  status s {{
    let near = neighbors(15) where dist > 2 or dist < 1
    fast = sum(near : other.pos - pos)
    plain = sum(near : 1 * other.pos - pos)
    back = sum(near where dist < 9 : normalize(pos - other.pos) * dist)
    plain_back = sum(near where dist < 9 : normalize(pos - 1 * other.pos) * dist)
    ang = sum(near : angle(pos - other.pos))
    plain_ang = sum(near : angle(pos - 1 * other.pos))
  }}
}}
"""


def assert_position_differences_are_the_plain_forms(sim, edges):
    cols = sim.agents.cols
    assert np.abs(cols["fast"]).sum() > 0
    for a, b in (("fast", "plain"), ("back", "plain_back"), ("ang", "plain_ang")):
        assert np.array_equal(cols[a], cols[b]), (edges, a)


# numba compiles each world's sums (searching the cells themselves) anew, and in a
# wrap-around world it builds both forms from the same pair delta (`other.pos` is the
# neighbour's nearest image: pos + delta), so CI runs that world on numpy only; the
# walled world is where numba reads the delta and the neighbour's column apart.
def test_position_differences_over_pairs_are_bit_identical_to_the_plain_forms(run_src,
                                                                               backend):
    # `other.pos - pos` and `pos - other.pos` read the pair table's deltas; `1 * other.pos`
    # takes the plain path. Agents 0 and 1 share a position: the sign of a zero.
    for edges in ("repel 1.0", "wrap") if backend == "numpy" else ("repel 1.0",):
        sim = run_src(POSITION_DIFFERENCES.format(edges=edges), steps=2)
        assert_position_differences_are_the_plain_forms(sim, edges)


@pytest.mark.slow
def test_position_differences_in_a_wrapped_world_are_the_plain_forms_on_numba():
    pytest.importorskip("numba")
    from swarmdsl.compiler import compile_source
    from swarmdsl.runtime.simulation import Simulation

    sim = Simulation(compile_source(POSITION_DIFFERENCES.format(edges="wrap"), "test.swarm"),
                     0, backend="numba")
    sim.run(2)
    assert_position_differences_are_the_plain_forms(sim, "wrap")
