"""The numba backend: the cell list against brute force, fused aggregates against the
reference closures, fallback, and the `--backend` option."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

pytest.importorskip("numba")

from conftest import REFERENCE, assert_backends_agree, cli_error, run_both  # noqa: E402
from swarmdsl.cli import main  # noqa: E402
from swarmdsl.compiler import compile_source  # noqa: E402
from swarmdsl.runtime.compiled.cells import (  # noqa: E402
    build_pairs_cells, cell_grid, split_work)
from swarmdsl.runtime.simulation import Simulation  # noqa: E402
from swarmdsl.runtime.spatial import build_pairs  # noqa: E402

# ---- the cell list ----


def brute_pairs(pos, radius, box):
    """Every ordered pair within `radius`, by the same arithmetic as build_pairs."""
    pts = pos
    if box is not None:
        pts = np.mod(pos, box)
        pts = np.where(pts >= box, 0.0, pts)
    delta = pts[None, :, :] - pts[:, None, :]
    if box is not None:
        b = np.asarray(box)
        delta -= b * np.round(delta / b)
    dist = np.sqrt(delta[..., 0] * delta[..., 0] + delta[..., 1] * delta[..., 1])
    keep = dist <= radius
    np.fill_diagonal(keep, False)
    i, j = np.nonzero(keep)
    return i, j, dist[i, j], delta[i, j]


def canonical(table):
    key = np.lexsort((table.j, table.i))
    return table.i[key], table.j[key], table.dist[key], table.delta[key]


@st.composite
def layouts(draw):
    """Agents in a world, many of them exactly on cell borders or on the world's edge."""
    w = draw(st.sampled_from([10.0, 37.5, 100.0]))
    h = draw(st.sampled_from([10.0, 20.0, 64.0]))
    radius = draw(st.sampled_from([0.5, 1.0, 2.5, 3.0, 7.0, 12.5, 40.0]))
    wrap = draw(st.booleans())
    n = draw(st.integers(2, 60))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    pos = rng.uniform(0, 1, (n, 2)) * (w, h)
    snap = rng.random(n) < draw(st.sampled_from([0.0, 0.5, 1.0]))
    box = (w, h) if wrap else None
    _x0, _y0, _nx, _ny, wx, wy = cell_grid(pos, radius, box)
    step = draw(st.sampled_from(["cell", "radius"]))
    grid = (wx, wy) if step == "cell" else (radius, radius)
    pos[snap] = np.round(pos[snap] / grid) * grid      # on cell borders / radius multiples
    pos[snap & (rng.random(n) < 0.3)] = 0.0             # on the world's edges
    edge = snap & (rng.random(n) < 0.3)
    pos[edge, 0] = w
    if box is None:
        pos = np.minimum(pos, (w, h))
    elif draw(st.booleans()):   # not wrapped yet: whole boxes away, or -0.0
        away = rng.random(n) < 0.3
        pos[away] += np.array([w, h]) * rng.integers(-3, 4, (int(away.sum()), 2))
        pos[rng.random(n) < 0.1] = -0.0
    return pos, radius, box


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(layouts())
def test_cell_list_finds_exactly_the_pairs_brute_force_finds(layout):
    pos, radius, box = layout
    table = build_pairs_cells(pos, radius, box)
    i, j, dist, delta = canonical(table)
    bi, bj, bd, bdelta = brute_pairs(pos, radius, box)
    assert np.array_equal(i, bi) and np.array_equal(j, bj)
    assert np.array_equal(dist, bd) and np.array_equal(delta, bdelta)
    # owners come out grouped in order, offsets index them
    assert np.all(np.diff(table.i) >= 0)
    assert np.array_equal(np.repeat(np.arange(len(pos)), np.diff(table.offsets)), table.i)
    # and the reference backend's search (a sweep along x for a few agents, else a
    # KD-tree) gives the same table, each owner's neighbours in the same order
    from swarmdsl.runtime import spatial

    for most in (spatial.SWEEP_MAX, 0):
        old, spatial.SWEEP_MAX = spatial.SWEEP_MAX, most
        try:
            ref = build_pairs(pos, radius, box)
        finally:
            spatial.SWEEP_MAX = old
        for got, want in zip((ref.i, ref.j, ref.dist, ref.delta),
                             (table.i, table.j, table.dist, table.delta), strict=True):
            assert np.array_equal(got, want)


def _layout_arrays(table):
    return table.soff, table.t, table.dist, table.delta, table.c_dist, table.c_delta


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(layouts(), st.sampled_from(["exact", "short", "long"]))
def test_every_way_of_building_the_cell_list_gives_the_same_table(monkeypatch, layout, hint):
    """Counted then filled, filled in one pass with room to spare, one pass that runs
    out of room (and falls back), split over threads, and a threaded one pass (each run
    of owners in its own region, closed up afterwards; room from a count or from last
    tick's offsets): the same pairs, same layout."""
    from swarmdsl.runtime.compiled import threads

    pos, radius, box = layout
    two_pass = build_pairs_cells(pos, radius, box)
    total = int(two_pass.soff[-1])
    room = {"exact": total, "short": max(total // 3, 1), "long": 4 * total + 1}[hint]
    one_pass = build_pairs_cells(pos, radius, box, hint=room)
    offsets = np.array(two_pass.soff)
    if hint == "short":   # last tick's offsets, but a third of the pairs in each run
        offsets //= 3
    with monkeypatch.context() as m:
        m.setattr(threads, "MIN_PARALLEL", 0)
        m.setattr(threads, "count", lambda: 2)
        threaded = build_pairs_cells(pos, radius, box)
        threaded_one_pass = build_pairs_cells(pos, radius, box, hint=room)
        from_offsets = build_pairs_cells(pos, radius, box, hint=offsets, spare=(
            np.zeros(3, np.int64), np.zeros(3), np.zeros((3, 2))))
    want = _layout_arrays(two_pass)
    for other in (one_pass, threaded, threaded_one_pass, from_offsets):
        for a, b in zip(want, _layout_arrays(other), strict=True):
            assert np.array_equal(a, b)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.integers(0, 200), min_size=1, max_size=60), st.integers(1, 12))
def test_threaded_runs_split_the_owners_by_their_pairs(pairs, chunks):
    """Runs cover every owner once, in order, and none carries much more than its share
    of the work (pairs plus one per owner): a dense flock in one corner of the cell
    order is split between threads, not handed to one."""
    off = np.concatenate([[7], 7 + np.cumsum(pairs)]).astype(np.int64)
    n = len(pairs)
    bounds = split_work(off, n, chunks)
    assert bounds[0] == 0 and bounds[-1] == n and (np.diff(bounds) >= 0).all()
    work = np.array(pairs) + 1
    share = work.sum() / chunks
    for c in range(chunks):
        assert work[bounds[c]:bounds[c + 1]].sum() <= share + work.max()


@given(st.floats(1e-3, 1e6), st.floats(-1, 1), st.sampled_from([None, "tie", "next", "prev"]))
def test_wrap_around_delta_without_division_has_the_formulas_bits(period, frac, near):
    """`d - period * rint(d / period)` (build_pairs' rule) for any |d| < period, ties at
    half the period (rint: half to even) and the floats either side of them included."""
    from swarmdsl.runtime.compiled.cells import _wrapped

    d = frac * period
    if near is not None:
        d = np.copysign(0.5 * period, frac)
        if near != "tie":
            d = np.nextafter(d, np.inf if near == "next" else -np.inf)
    assume(abs(d) < period)
    want = d - period * np.rint(d / period)
    got = _wrapped(d, period)
    assert np.float64(got).tobytes() == np.float64(want).tobytes()


@given(st.one_of(st.floats(0, 1e300), st.sampled_from([0.0, 1.0, 80.0, 5e-324, 1e154,
                                                       1e155, np.inf])),
       st.integers(-4, 4), st.floats(0, 2))
def test_the_kept_test_without_a_root_decides_as_the_root_does(radius, ulps, scale):
    """A candidate is kept when d2 <= reach2(radius): exactly when sqrt(d2) <= radius,
    the rule of build_pairs, for d2 at and a few floats either side of radius^2 (where
    the two could differ) and anywhere else."""
    from swarmdsl.runtime.compiled.cells import reach2

    within2 = reach2(radius)
    for d2 in (radius * radius, scale * radius * radius, within2):
        with np.errstate(over="ignore"):   # the float after the largest: inf
            for _ in range(abs(ulps)):
                d2 = np.nextafter(d2, np.inf if ulps > 0 else -np.inf)
        d2 = max(float(d2), 0.0)
        assert (d2 <= within2) == (np.sqrt(d2) <= radius), (radius, d2, within2)


def test_pair_arrays_are_written_again_only_when_nobody_holds_last_ticks_table():
    """The search reuses last tick's pair arrays (no page faults for fresh memory) once
    the simulation has dropped that table; a table someone still holds keeps its pairs,
    and reuse changes no result."""
    text = """
world { size 40 x 40; edges wrap }
agent a {
  count 300
  sense 4
  velocity random_direction()
  status go { velocity += sum(neighbors() : other.vel - vel) * 0.01 }
}
"""
    prog = compile_source(text, "test.swarm")
    reused, fresh = Simulation(prog, 0, backend="numba"), Simulation(prog, 0, backend="numba")
    reused.run(2)
    fresh.run(2)
    arrays = reused.pairs.buffers
    reused.step()
    assert reused.pairs.buffers[0] is arrays[0]        # last tick's memory, written again
    held = reused.pairs
    kept = [np.array(a) for a in (held.t, held.c_dist, held.c_delta)]
    reused.step()
    assert reused.pairs.buffers[0] is not held.buffers[0]
    assert all(np.array_equal(a, b) for a, b in zip(kept, (held.t, held.c_dist,
                                                           held.c_delta), strict=True))
    fresh.backend._spare = None
    for _ in range(2):
        fresh.backend._spare = None   # every tick on new arrays
        fresh.step()
    assert_same_columns(reused.agents.cols, fresh.agents.cols)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**63), st.lists(st.integers(0, 2**64 - 1), min_size=0, max_size=40),
       st.integers(1, 4), st.booleans())
def test_compiled_draws_have_the_bits_of_the_numpy_draws(seed, ids, lanes, open_low):
    """The numba backend's loop for the counter-based draws: the same uniforms (and so
    the same normal draws, directions, ...) for any agent ids, pair keys and lanes."""
    from swarmdsl.runtime.compiled.random import units
    from swarmdsl.runtime.randomness import RandomSource

    plain, fast = RandomSource(seed), RandomSource(seed)
    fast.compiled_units = units
    ids = np.array(ids, np.uint64)
    for stream in ("a/go", "a/go@3:7"):
        a, b = plain.agents(ids, stream), fast.agents(ids, stream)
        assert np.array_equal(a._unit((ids.size, lanes), open_low),
                              b._unit((ids.size, lanes), open_low))
        assert np.array_equal(a.standard_normal(), b.standard_normal())


def test_cell_list_on_a_lattice_keeps_pairs_exactly_at_the_radius():
    """Agents 1 apart on a grid with radius 1: every edge pair is exactly at the radius."""
    g = np.stack(np.meshgrid(np.arange(12.0), np.arange(9.0)), -1).reshape(-1, 2)
    for box in (None, (12.0, 9.0)):
        table = build_pairs_cells(g, 1.0, box)
        counts = np.diff(table.offsets)
        if box is None:
            assert counts.min() == 2 and counts.max() == 4   # corners and the inside
        else:
            assert np.all(counts == 4)                      # the torus has no corners
        assert np.array_equal(canonical(table)[1], brute_pairs(g, 1.0, box)[1])


def test_cell_list_with_a_sparse_huge_world_stays_small():
    pos = np.array([[0.0, 0.0], [1e9, 1e9], [1e9 + 0.5, 1e9]])
    _x0, _y0, nx, ny, _wx, _wy = cell_grid(pos, 1.0, None)
    assert nx * ny <= 64
    table = build_pairs_cells(pos, 1.0, None)
    assert table.i.tolist() == [1, 2] and table.j.tolist() == [2, 1]


# ---- fused aggregates against the reference ----

def assert_same_bits(a, b, what=""):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape and a.dtype == b.dtype, what
    assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), what


def assert_same_state(sims, prog):
    """Every agent column of the two backends' runs, bit for bit (DESIGN: the same
    program, parameters and seed give bit-identical results on either backend)."""
    ref, fast = sims
    for col in ref.agents.cols:
        assert_same_bits(ref.agents.cols[col], fast.agents.cols[col], col)


EVERY_AGGREGATE = """
param n = 40
world {{ size 30 x 20; edges {edges} }}
agent a {{
  count n
  sense 6
  place {place}
  velocity (sin(index), cos(index))
  var u = index % 5
  var b = index % 3 == 0
  var v = (index % 4, 1)
  var c = 0
  var s = (0, 0)
  var m = 0
  var lo = 0
  var hi = 0
  var k = 0
  var nv = (0, 0)
  var an = false
  var al = false
  var q = 0
  status idle {{
    let near = neighbors(5) where other.u != 2
    let w = 2 + u
    c = count(near where dist > 1)
    s = sum(neighbors() where other.b or dist < w : normalize(pos - other.pos) * w / max(dist, 0.01) + (cross(other.pos - pos, vel) + length(other.pos), angle(other.pos - pos) - distance(pos, other.pos) % 3) * 0.01)
    m = mean(near : other.u * dist ^ 2 - atan2(other.vel.y, other.vel.x) else -1)
    lo = min(near where other.status == busy : abs(other.u - u) + sqrt(dist) else 99)
    hi = max(neighbors(4) : if other.b then exp(-dist) else cos(angle(other.vel - vel)) else -7)
    k = nearest(near : other.u)
    nv = nearest(neighbors(3) : rotate(other.v, dist) + unit(u) else (5, 5))
    an = any(near : other.b and not b)
    al = all(neighbors(2) : dist >= 0.5 or other.u > u)
    q = mean(near : dot(other.vel - vel, v) + cross(other.v, vel) + clamp(length(other.v), 1, 9) + distance(vel, other.vel) % 3 + floor(dist) + round(dist) - sign(u - other.u))
    when tick % 2 == 1 and u > 2 -> busy
  }}
  status busy {{
    c = count(neighbors(4) where other.status == idle)
    s = mean(neighbors(4) : other.pos - pos else (1, 1))
    when tick % 3 == 0 -> idle
  }}
}}
"""


@pytest.mark.parametrize("edges", ["wrap", "wall", "repel 0.5"])
@pytest.mark.parametrize("place", ["uniform", "(index % 8 * 2.5, floor(index / 8) * 2.5)"])
def test_every_aggregate_and_filter_agrees_with_the_reference(edges, place, other_backend):
    """Each aggregate, `where` filters on a let-held set and on `neighbors(r)`, owner-only
    values, statuses that split the agents (pair rows gathered), wrap and wall worlds, and
    a lattice where many neighbours are equally near (nearest breaks ties the same way).
    Only `other.pos` and position differences lower differently with the edges (the
    neighbour's nearest image in a wrap-around world): they are all in the two `s`
    sums, so a walled world compiles those two kernels again, not every one."""
    text = EVERY_AGGREGATE.format(edges=edges, place=place)
    prog, sims = run_both(text, steps=4, other=other_backend)
    assert_same_state(sims, prog)
    summary = "\n".join(sims[1].backend.summary(prog))
    assert "numpy (" not in summary
    # the search, motion, the let-held filter (`where` on its own) and 12 aggregates
    assert summary.count(": compiled") == 2 + 1 + 12 and "23:16 where: compiled" in summary


def numba_run(prog, seed, steps, threaded=None):
    """The agents' columns after `steps` numba ticks; `threaded` (a monkeypatch) splits
    every kernel over two threads, whatever the swarm's size and the machine's cores."""
    if threaded is not None:
        from swarmdsl.runtime.compiled import threads

        threaded.setattr(threads, "MIN_PARALLEL", 0)
        threaded.setattr(threads, "count", lambda: 2)
    sim = Simulation(prog, seed, backend="numba")
    sim.run(steps)
    return sim.agents.cols, sim


def assert_same_columns(a, b):
    for col in a:
        assert np.array_equal(a[col], b[col]), col


def test_each_backend_is_bit_identical_to_itself_per_seed():
    prog = compile_source(EVERY_AGGREGATE.format(edges="wrap", place="uniform"), "t.swarm")
    assert_same_columns(numba_run(prog, 7, 5)[0], numba_run(prog, 7, 5)[0])


# Every aggregate once, with plain bodies: threading splits the owners of each kernel
# (the loop the aggregates share), so the bodies' variety (EVERY_AGGREGATE's) adds
# compile time, not cover; a parallel kernel compiles several times slower.
EVERY_AGGREGATE_PLAIN = """
param n = 300
world { size 30 x 20; edges wrap }
agent a {
  count n
  sense 6
  place uniform
  velocity (sin(index), cos(index))
  var u = index % 5
  var b = index % 3 == 0
  var c = 0
  var s = (0, 0)
  var m = 0
  var lo = 0
  var hi = 0
  var k = 0
  var an = false
  var al = false
  status idle {
    let near = neighbors(5) where other.u != 2
    c = count(near where dist > 1)
    s = sum(neighbors() : (other.pos - pos) / max(dist, 0.01))
    m = mean(near : other.u * dist)
    lo = min(near where other.status == busy : other.u else 99)
    hi = max(neighbors(4) : exp(-dist) else -7)
    k = nearest(near : other.u)
    an = any(near : other.b and not b)
    al = all(neighbors(2) : dist >= 0.5)
    when tick % 2 == 1 and u > 2 -> busy
  }
  status busy {
    c = count(neighbors(4) where other.status == idle)
    s = mean(neighbors(4) : other.pos - pos else (1, 1))
    when tick % 3 == 0 -> idle
  }
}
"""


# The smallest threaded case: every aggregate kernel splits its owners by the same code
# (a parallel loop over runs of owners: by pairs when every owner runs, by owners when
# a status holds some), so one kernel shows a split that loses, repeats or reorders an
# owner: a `nearest` of a vector that changes every tick (an owner left out keeps a
# stale value), which needs the written pairs, so the threaded cell list writes them;
# statuses split the agents, so the run covers both ways of splitting.
THREADED = """
world { size 30 x 20; edges wrap }
agent a {
  count 300; sense 6; velocity (sin(index), cos(index))
  var u = index % 5; var s = (0, 0)
  status idle {
    s = nearest(neighbors() : other.pos - pos else (-1, -1))
    when tick % 2 == 1 and u > 2 -> busy
  }
  status busy { when tick % 3 == 0 -> idle }
}
"""


@pytest.mark.parametrize("text", [
    # a parallel kernel compiles several times slower than a serial one: CI threads
    # one (THREADED), the slow suite every aggregate
    pytest.param(THREADED, id="one-kernel"),
    pytest.param(EVERY_AGGREGATE_PLAIN, id="every", marks=pytest.mark.slow)])
def test_threads_give_the_same_bits_as_one_thread(monkeypatch, text):
    """The cell list, the aggregates (both layouts: statuses split the agents) and the
    motion split over threads: the run is bit for bit the serial run, which is the
    reference's (the numpy backend's: the same bits, and nothing to compile)."""
    prog = compile_source(text, "test.swarm")
    serial = Simulation(prog, 3, backend="numpy")
    serial.run(4)
    assert_same_columns(serial.agents.cols, numba_run(prog, 3, 4, threaded=monkeypatch)[0])


def test_a_kernel_numba_cannot_thread_runs_serially_with_the_same_bits(monkeypatch):
    from swarmdsl.runtime.compiled import kernels

    def refused(body):
        def run(*args):
            raise RuntimeError("parfor lowering failed")
        return run

    text = EVERY_AGGREGATE.format(edges="wall", place="uniform")
    prog = compile_source(text, "test.swarm", {"n": "200"})
    serial = numba_run(prog, 5, 3)[0]
    monkeypatch.setattr(kernels, "_parallel", refused)
    threaded, sim = numba_run(prog, 5, 3, threaded=monkeypatch)
    assert "numpy (" not in "\n".join(sim.backend.summary(prog))
    assert_same_columns(serial, threaded)


def test_unsupported_parts_fall_back_visibly_and_give_the_same_answer():
    text = """
world { size 20 x 20; edges wrap }
agent a {
  count 30
  sense 5
  var r = 0
  var c = 0
  status idle {
    r = sum(neighbors() : random() * dist)
    c = count(neighbors() where dist < 3)
  }
}
"""
    prog, (ref, fast) = run_both(text, steps=3, other="numba")
    assert_same_state((ref, fast), prog)
    lines = fast.backend.summary(prog)
    assert any("sum: numpy (`random()` draws random numbers per pair)" in ln for ln in lines)
    assert any("count: compiled" in ln for ln in lines)
    assert fast.backend.parts and ref.backend.summary(prog) == ["backend: numpy"]


def test_filtered_sets_stay_masks_over_the_cell_order_pairs_and_read_alike_everywhere():
    """`let` of filtered sets (narrower `neighbors(r)`, a filter, a filter of a filtered
    set) under numba are masks over the tick's cell-order pairs, read as they are by
    fused aggregates and as rows by the reference path (a draw per pair, a nested
    `nearest`): the same answers as the numpy backend, owners split over two statuses."""
    text = """
world { size 20 x 20; edges wrap }
agent a {
  count 60
  sense 5
  var u = index % 4
  var c = 0
  var s = (0, 0)
  var r = 0
  var k = 0
  status idle {
    let near = neighbors(4) where other.u != 1
    let close = near where dist < 3 and other.u >= u
    c = count(near) + 10 * count(close)
    s = sum(close : other.pos - pos)
    r = sum(close : random() * dist)
    k = nearest(close : other.u else -1)
    when index % 3 == 0 -> busy
  }
  status busy {
    let far = neighbors(4.5) where dist > 2
    c = count(far)
    when tick % 2 == 0 -> idle
  }
}
"""
    prog, (ref, fast) = run_both(text, steps=4, other="numba")
    assert_same_state((ref, fast), prog)
    assert (ref.agents.cols["c"] >= 10).any()   # the filtered sets are not empty
    lines = fast.backend.summary(prog)
    assert sum("where: compiled" in ln for ln in lines) == 3
    assert any("sum: numpy (`random()` draws random numbers per pair)" in ln for ln in lines)


def test_a_fused_program_with_filtered_sets_never_builds_row_order_pairs():
    """Every reader of the filtered sets is fused: the tick's pairs stay in the cell-order
    layout the search wrote, with one byte per pair for each mask."""
    text = """
world { size 30 x 30; edges wrap }
agent a {
  count 200
  sense 3
  var s = (0, 0)
  status idle {
    let near = neighbors(2.5) where dist > 0.01
    s = sum(near where dist < 2 : (other.pos - pos) / dist ^ 2) / max(count(near), 1)
  }
}
"""
    prog = compile_source(text, "test.swarm")
    sim = Simulation(prog, 0, backend="numba")
    sim.run(3)
    assert sim.pairs._table is None
    assert (np.linalg.norm(sim.agents.cols["s"], axis=1) > 0).any()


# ---- generated programs ----

_NUM = st.sampled_from(["dist", "other.u", "u", "other.pos.x", "pos.y", "other.speed",
                        "speed", "1.5", "w", "tick", "other.heading", "other.id"])
_VEC = st.sampled_from(["other.pos - pos", "pos - other.pos", "other.vel", "vel", "v",
                        "other.v", "(1, 2)", "other.pos"])
_BOOL = st.sampled_from(["other.b", "b", "other.status == busy", "dist < 3",
                         "other.u >= u"])


def _num(inner_num, inner_vec, inner_bool):
    return st.one_of(
        st.tuples(inner_num, st.sampled_from(["+", "-", "*", "/", "^"]), inner_num).map(
            lambda t: f"({t[0]} {t[1]} {t[2]})"),
        st.tuples(st.sampled_from(["abs", "sqrt", "sin", "cos", "exp", "log", "floor"]),
                  inner_num).map(lambda t: f"{t[0]}({t[1]})"),
        st.tuples(st.sampled_from(["min", "max", "atan2"]), inner_num, inner_num).map(
            lambda t: f"{t[0]}({t[1]}, {t[2]})"),
        st.tuples(st.sampled_from(["length", "angle"]), inner_vec).map(
            lambda t: f"{t[0]}({t[1]})"),
        st.tuples(inner_vec, inner_vec).map(lambda t: f"dot({t[0]}, {t[1]})"),
        st.tuples(inner_bool, inner_num, inner_num).map(
            lambda t: f"(if {t[0]} then {t[1]} else {t[2]})"),
        inner_vec.map(lambda v: f"({v}).y"),
    )


def _exprs():
    leaves = st.tuples(_NUM, _VEC, _BOOL)

    def grow(inner):
        n, v, b = (inner.map(lambda t: t[0]), inner.map(lambda t: t[1]),
                   inner.map(lambda t: t[2]))
        return st.tuples(
            st.one_of(n, _num(n, v, b)),
            st.one_of(v, st.tuples(v, st.sampled_from(["+", "-"]), v).map(
                lambda t: f"({t[0]} {t[1]} {t[2]})"),
                st.tuples(v, n).map(lambda t: f"({t[0]} * {t[1]})"),
                v.map(lambda x: f"normalize({x})"),
                st.tuples(v, n).map(lambda t: f"rotate({t[0]}, {t[1]})")),
            st.one_of(b, st.tuples(n, st.sampled_from(["<", ">=", "!="]), n).map(
                lambda t: f"({t[0]} {t[1]} {t[2]})"),
                st.tuples(b, b).map(lambda t: f"({t[0]} and not {t[1]})")),
        )
    return st.recursive(leaves, grow, max_leaves=5)


_AGG = {"count": None, "sum": "n", "mean": "n", "min": "n", "max": "n", "nearest": "v",
        "any": "b", "all": "b"}


@st.composite
def generated_programs(draw):
    edges = draw(st.sampled_from(["wrap", "wall"]))
    e = draw(_exprs())
    name = draw(st.sampled_from(sorted(_AGG)))
    each = {"n": e[0], "v": e[1], "b": e[2], None: None}[_AGG[name]]
    if name in ("sum", "mean") and draw(st.booleans()):
        each = e[1]
    filt = draw(st.sampled_from(["", " where dist > 1", f" where {e[2]}"]))
    src = draw(st.sampled_from(["near", "neighbors(4)", "neighbors()"]))
    agg = f"{name}({src}{filt}" + (f" : {each}" if each else "") + ")"
    near_filter = draw(st.sampled_from(["", " where dist > 1", f" where {e[2]}"]))
    target = {"count": "x2", "sum": "x2", "mean": "x2", "min": "x2", "max": "x2",
              "nearest": "v2", "any": "b2", "all": "b2"}[name]
    if name in ("sum", "mean", "nearest") and each == e[1]:
        target = "v2"
    return f"""
world {{ size 24 x 16; edges {edges} }}
agent a {{
  count 30
  sense 5
  velocity (cos(index), sin(index))
  var u = index % 4
  var b = index % 3 == 0
  var v = (index % 5, 2)
  var x2 = 0
  var v2 = (0, 0)
  var b2 = false
  status idle {{
    let w = u + 1
    let near = neighbors(4.5) where other.u != 1{near_filter}
    {target} = {agg}
    when index % 2 == 0 -> busy
  }}
  status busy {{ x2 = count(neighbors() where other.status == idle); when b -> idle }}
}}
"""


@settings(max_examples=8, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(generated_programs())
def test_generated_programs_agree_with_the_reference(text):
    assert_backends_agree(text, assert_same_state)


@pytest.mark.slow
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(generated_programs())
def test_generated_programs_agree_long(text):
    assert_backends_agree(text, assert_same_state)


# ---- shipped programs and the command line ----

PROGRAMS = __import__("pathlib").Path(__file__).resolve().parent.parent / "programs"


@pytest.mark.parametrize("name", sorted(p.name for p in PROGRAMS.glob("*.swarm")))
def test_shipped_programs_agree_with_the_reference(name, other_backend):
    """Same seed, 15 ticks: every agent column has the same bits."""
    from swarmdsl.compiler import compile_file

    prog = compile_file(PROGRAMS / name)
    sims = []
    for backend in (REFERENCE, other_backend):
        sim = Simulation(prog, 3, backend=backend)
        sim.run(15)
        sims.append(sim)
    assert_same_state(sims, prog)


@pytest.mark.parametrize("name", sorted(p.name for p in PROGRAMS.glob("*.swarm")))
def test_a_program_compiled_without_fused_paths_runs_its_reference_closures(name):
    """`compile_file(..., lowering=REFERENCE)` (what `check` compiles) plans no fused
    part, and on the numba backend runs the reference closures to the numpy backend's
    state."""
    from swarmdsl.compiler import compile_file
    from swarmdsl.compiler.lowering import REFERENCE
    from swarmdsl.runtime.compiled.lowering import NUMBA

    plain, fused = (compile_file(PROGRAMS / name, lowering=x) for x in (REFERENCE, NUMBA))
    assert getattr(plain, "fused_parts", []) == []
    sims = []
    for prog, backend in ((fused, "numpy"), (plain, "numba")):
        sim = Simulation(prog, 3, backend=backend)
        sim.run(5)
        sims.append(sim)
    assert sims[1].backend.parts == {}
    assert_same_state(sims, fused)


def test_cli_backend_option_and_verbose_report(capsys):
    from swarmdsl.cli import main

    path = str(PROGRAMS / "vicsek.swarm")
    assert main(["run", path, "--headless", "--steps", "3", "--backend", "numba", "-v"]) == 0
    err = capsys.readouterr().err
    assert "backend: numba" in err and "kernel compilation" in err
    assert "neighbour search: compiled cell list" in err
    assert ": compiled" in err
    assert main(["run", path, "--headless", "--steps", "3", "--backend", "numpy", "-v"]) == 0
    assert "backend: numpy" in capsys.readouterr().err


def test_unknown_backend_from_the_environment_is_an_option_error(monkeypatch, capsys):
    from swarmdsl.cli import main

    monkeypatch.setenv("SWARMDSL_BACKEND", "cuda")
    assert main(["run", str(PROGRAMS / "vicsek.swarm"), "--headless", "--steps", "1"]) == 2
    assert "$SWARMDSL_BACKEND=cuda: not a backend" in capsys.readouterr().err


@pytest.mark.parametrize("command", [["run", "--headless", "--steps", "1"], ["test"]])
def test_the_numba_backend_asked_for_without_numba_is_refused_up_front(
        monkeypatch, capsys, command):
    """`SWARMDSL_BACKEND=numba` on a machine without numba: `swarmdsl test` reported
    every run's failure as a counterexample of the program."""
    from swarmdsl import runtime
    from swarmdsl.cli import main

    monkeypatch.setenv("SWARMDSL_BACKEND", "numba")
    monkeypatch.setattr(runtime.compiled, "numba_installed", lambda: False)
    assert main([command[0], str(PROGRAMS / "vicsek.swarm"), *command[1:]]) == 2
    err = capsys.readouterr().err
    assert "error: $SWARMDSL_BACKEND=numba: needs numba: pip install" in err
    assert "counterexample" not in err


def test_backends_doc_example_runs_and_its_report_is_what_the_doc_shows():
    """docs/backends.md: the example agrees across backends; `-v`'s part lines match."""
    import re

    doc = (PROGRAMS.parent / "docs" / "backends.md").read_text()
    (source,) = re.findall(r"```swarm\n(.*?)```", doc, re.S)
    prog, sims = run_both(source, steps=10, other="numba")
    assert_same_state(sims, prog)
    for line in sims[1].backend.summary(prog)[1:]:
        assert line in doc, line


@pytest.mark.slow
@pytest.mark.parametrize("name", ["boids.swarm", "vicsek.swarm"])
def test_long_chaotic_runs_keep_the_same_bits(name, other_backend):
    """Chaos amplifies any difference in the last bit; 600 ticks of 4 seeds of a flock
    and of the Vicsek model end with the same bits on both backends."""
    from swarmdsl.compiler import compile_file

    prog = compile_file(PROGRAMS / name)
    for seed in range(4):
        sims = []
        for backend in (REFERENCE, other_backend):
            sim = Simulation(prog, seed, backend=backend)
            sim.run(600)
            sims.append(sim)
        assert_same_state(sims, prog)


def _break_even(prog) -> int:
    """The fewest ticks of `prog` whose estimated saving repays numba's start-up."""
    from swarmdsl.runtime.compiled import choice

    n = sum(k.count for k in prog.kinds)
    cost, _how = choice.compile_estimate(prog)
    return int(cost / choice.saved(prog, n)) + 1


@pytest.fixture
def fresh_cache(monkeypatch, tmp_path):
    """No marker of an earlier numba run; the default's cost model as it stands without
    the tiered start (`SWARMDSL_TIERED=0`; the tiered start: tests/test_tiered.py)."""
    monkeypatch.delenv("SWARMDSL_BACKEND")
    monkeypatch.setenv("SWARMDSL_TIERED", "0")
    monkeypatch.setenv("SWARMDSL_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("SWARMDSL_KERNEL_CACHE", raising=False)     # on by default
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))


def test_default_backend_is_numba_when_the_run_repays_compiling(fresh_cache, monkeypatch):
    """A long run takes numba on its first run (the first big run used to wait for an
    earlier numba run of the program), a short one stays on numpy, and each says why;
    $SWARMDSL_BACKEND and the API's `backend=` still choose."""
    from swarmdsl.compiler import compile_file
    from swarmdsl.runtime.runner import Run

    prog = compile_file(PROGRAMS / "vicsek.swarm")
    ticks = _break_even(prog)
    n = sum(k.count for k in prog.kinds)
    short = Run(prog, steps=1)
    assert short.sim.backend.name == "numpy"
    assert short.sim.backend.choice.line.startswith(
        f"backend: numpy (short run: {n:,} agent-steps;")
    assert "short run" in short.sim.backend.summary(prog)[0]
    assert Run(prog, steps=ticks - 2).sim.backend.name == "numpy"
    long = Run(prog, steps=ticks)
    assert long.sim.backend.name == "numba"
    assert long.sim.backend.choice.line.startswith(
        "backend: numba (compiling kernels, ~") and "kept for later runs" in \
        long.sim.backend.choice.line
    assert Simulation(prog, 0).backend.name == "numba"      # the API: numba when installed
    assert Run(prog, steps=ticks, backend="numpy").sim.backend.choice is None
    monkeypatch.setenv("SWARMDSL_BACKEND", "numpy")
    assert Run(prog, steps=ticks * 10).sim.backend.name == "numpy"


def test_the_first_big_run_of_a_shipped_program_gets_numba(fresh_cache):
    """The first big runs a new user tried, from a cold cache: boids at 5,000 agents
    for 3,000 ticks, Vicsek at 10^4 for its 300; ten ticks of them stay on numpy."""
    import swarmdsl
    from swarmdsl.runtime.runner import Run

    boids = swarmdsl.load_program(PROGRAMS / "boids.swarm",
                                  {"n": 5000, "width": 3000, "height": 3000})
    vicsek = swarmdsl.load_program(PROGRAMS / "vicsek.swarm", {"n": 10000, "size": 50})
    assert Run(boids, steps=3000).sim.backend.name == "numba"
    assert Run(vicsek, steps=300).sim.backend.name == "numba"
    assert Run(boids, steps=10).sim.backend.name == "numpy"
    assert Run(vicsek, steps=10).sim.backend.name == "numpy"


def test_neighbours_make_numpy_slower_and_numba_pay_sooner():
    """The same agents and ticks in a denser world (more neighbours each) repay the
    same compile time sooner."""
    import swarmdsl
    from swarmdsl.runtime.compiled import choice

    sparse = swarmdsl.load_program(PROGRAMS / "boids.swarm",
                                   {"n": 1000, "width": 6000, "height": 6000})
    dense = swarmdsl.load_program(PROGRAMS / "boids.swarm", {"n": 1000})
    assert choice.neighbours(dense) > 10 * choice.neighbours(sparse)
    assert choice.saved(dense, 10**6) > 3 * choice.saved(sparse, 10**6)
    work = 2 * choice.compile_estimate(dense)[0] / choice.saved(dense, 1)
    assert choice.choose(dense, work, True).name == "numba"
    assert choice.choose(sparse, work, True).name == "numpy"



def test_the_compile_estimate_counts_the_loops_of_a_program_not_lowered_yet(fresh_cache):
    """The line a short run prints names what compiling would cost: each aggregate loop
    (sums sharing one count once) and statement of the program, counted before any
    backend lowered it, dearer from 2,000 agents (the threaded forms too); the count
    imports no numba (a short run must not pay its import)."""
    import subprocess
    import sys

    import swarmdsl
    from swarmdsl.runtime.compiled import choice

    boids = swarmdsl.load_program(PROGRAMS / "boids.swarm")
    assert boids.lowering is None
    assert choice.kernels(boids) == (1, 2)     # four sums in one loop; `steer`, velocity
    assert boids.lowering is None              # counted on a copy
    leader = swarmdsl.load_program(PROGRAMS / "boids_leader.swarm")
    assert choice.kernels(leader) == (2, 2)
    small, _ = choice.compile_estimate(boids)
    assert choice.compile_estimate(leader)[0] == small + choice.COMPILE_AGGREGATE
    big = swarmdsl.load_program(PROGRAMS / "boids.swarm", {"n": 5000})
    assert choice.compile_estimate(big)[0] > small
    line = choice.choose(boids, 1000, True).line
    assert f"for ~{small:.1f} s of compiling" in line
    code = ("import sys, swarmdsl\nfrom swarmdsl.runtime.compiled import choice\n"
            f"p = swarmdsl.load_program({str(PROGRAMS / 'vicsek.swarm')!r})\n"
            "assert choice.kernels(p) == (1, 2)\nassert 'numba' not in sys.modules\n")
    subprocess.run([sys.executable, "-c", code], check=True)

def test_without_numba_a_long_run_says_what_it_would_save(fresh_cache, monkeypatch,
                                                          tmp_path, capsys):
    """numba is an optional extra: without it a run takes numpy, silently when numba
    would not have paid, in one line naming the extra when it would."""
    from swarmdsl import cli
    from swarmdsl.runtime import compiled

    monkeypatch.setattr(compiled, "numba_installed", lambda: False)
    program = tmp_path / "p.swarm"
    program.write_text("world { size 20 x 20; edges wrap }\nagent a { count 400; sense 2\n"
                       "  status m { velocity = (count(neighbors(2)), 1) * 0.01 } }\n")
    assert cli.main(["run", str(program), "--headless", "--steps", "2"]) == 0
    assert "backend" not in capsys.readouterr().err
    from swarmdsl.compiler import compile_file
    from swarmdsl.runtime.compiled import choice

    ticks = _break_even(compile_file(program)) * 3
    got = choice.choose(compile_file(program), 400 * ticks, False)
    assert got.name == "numpy"
    assert got.line.startswith("backend: numpy (numba is not installed: it would save ~")
    assert got.line.endswith("(pip install swarmdsl[numba]))")


def test_the_cli_says_which_backend_the_default_chose(fresh_cache, tmp_path, capsys):
    from swarmdsl import cli

    program = tmp_path / "p.swarm"
    program.write_text("agent a { count 3; velocity (1, 0); status s { } }\n")
    assert cli.main(["run", str(program), "--headless", "--steps", "5"]) == 0
    err = capsys.readouterr().err
    assert "backend: numpy (short run: 15 agent-steps;" in err
    assert cli.main(["run", str(program), "--headless", "--steps", "5",
                     "--backend", "numpy"]) == 0
    assert "backend" not in capsys.readouterr().err


def test_a_program_compiled_here_takes_numba_for_shorter_runs(fresh_cache, monkeypatch):
    """After a numba run of a program kept all its kernels on disk, shorter runs of it
    take numba by default (loading them costs less than compiling); not another
    program, not with the kernel cache off, not before any numba run."""
    from swarmdsl.compiler import compile_file, compile_source
    from swarmdsl.runtime.compiled import disk_cache
    from swarmdsl.runtime.runner import Run

    prog = compile_file(PROGRAMS / "vicsek.swarm")
    cold = _break_even(prog)

    def default(program, ticks=cold // 2):
        return Run(program, steps=ticks).sim.backend
    before = default(prog)
    assert before.name == "numpy" and "compiling" in before.summary(prog)[0]
    monkeypatch.setattr(disk_cache, "not_kept", 1)     # a kernel compiled in memory only
    assert Run(prog, steps=2, backend="numba").execute() == "completed"
    assert default(prog).name == "numpy"
    monkeypatch.setattr(disk_cache, "not_kept", 0)
    assert Run(prog, steps=2, backend="numba").execute() == "completed"
    after = default(prog)
    assert after.name == "numba"
    assert "kernels kept from an earlier run" in after.summary(prog)[0]
    assert default(prog, 1).name == "numpy"
    other = compile_source(prog.source + "# another program\n", "v.swarm")
    assert default(other).name == "numpy"
    monkeypatch.setenv("SWARMDSL_KERNEL_CACHE", "0")
    assert default(prog).name == "numpy"


def test_a_small_program_whose_whole_ticks_are_kept_takes_numba_for_short_runs(
        fresh_cache):
    """Once a run took whole ticks from a kernel kept on disk, runs of a small swarm
    of the program take numba for as few ticks as repay loading it: each tick's fixed
    cost is what they save (BEECLUST: 1.2 s of numpy ticks against 0.12 s whole). Not
    a run too short to repay loading, not above the whole ticks' agents."""
    from swarmdsl.compiler import compile_file
    from swarmdsl.runtime.compiled import WHOLE_TICKS_MAX, choice, warm
    from swarmdsl.runtime.runner import Run

    prog = compile_file(PROGRAMS / "vicsek.swarm", {"n": "100"})
    ticks = 1500   # the per-agent saving alone would not repay loading the kernels
    assert Run(prog, steps=ticks).sim.backend.name == "numpy"   # nothing kept yet
    assert Run(prog, steps=2, backend="numba").execute() == "completed"
    assert warm.compiled_here(prog) and not warm.whole_here(prog)
    assert choice.whole_saving(prog, 100 * ticks) is None
    assert Run(prog, steps=ticks).sim.backend.name == "numpy"   # per-agent saving only
    sim = Simulation(prog, 0, backend="numba")
    assert sim.advance(3) == 3 and warm.whole_here(prog)
    long = Run(prog, steps=ticks).sim.backend
    assert long.name == "numba"
    assert "its whole-tick kernel too" in long.choice.line
    assert Run(prog, steps=10).sim.backend.name == "numpy"
    big = compile_file(PROGRAMS / "vicsek.swarm", {"n": str(WHOLE_TICKS_MAX + 1)})
    assert warm.whole_here(big) and choice.whole_saving(big, 10**6) is None


def test_an_unusable_cache_folder_only_means_no_shorter_numba_runs(fresh_cache, monkeypatch,
                                                                   tmp_path):
    from swarmdsl.compiler import compile_file
    from swarmdsl.runtime.runner import Run

    blocker = tmp_path / "a-file"
    blocker.write_text("")
    monkeypatch.setenv("SWARMDSL_CACHE_DIR", str(blocker))    # a folder cannot be made
    prog = compile_file(PROGRAMS / "vicsek.swarm")
    assert Run(prog, steps=2, backend="numba").execute() == "completed"
    assert Run(prog, steps=_break_even(prog) // 2).sim.backend.name == "numpy"


@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=1, max_size=20),
       st.floats(min_value=1e-300, max_value=1e300))
@settings(max_examples=300, deadline=None)
def test_the_wrap_of_the_compiled_move_has_the_bits_of_np_mod(xs, size):
    """Its fast path (a step across at most one edge) included: x near 0, -0.0, x on
    the edge, one step past it either way, far out, NaN and infinities."""
    from swarmdsl.runtime.compiled.motion import wrap_all

    xs = np.array(xs + [size, -size, 2 * size, np.nextafter(size, 0), -0.0, size * 1.5,
                        -size / 3, np.nextafter(-size, 0)])
    with np.errstate(invalid="ignore"):
        want = np.mod(xs, size)
    got = wrap_all(xs, size)
    assert np.array_equal(got, want, equal_nan=True)
    number = ~np.isnan(want)
    assert np.array_equal(np.signbit(got[number]), np.signbit(want[number]))   # -0.0


@pytest.mark.parametrize("edges", ["wrap", "wall", "repel 2.5 (7)"])
def test_compiled_motion_moves_agents_bit_for_bit_as_the_numpy_step(edges, other_backend):
    """Agents on the edges, at rest, too fast and within the edge range of the walls."""
    text = f"""
world {{ size 60 x 40; grid 4; edges {edges} }}
agent a {{
  count 200
  place (index % 20 * 3, floor(index / 20) * 4.4)
  velocity (sin(index) * (index % 7), cos(index * 3) * (index % 5))
  max_speed if index % 3 == 0 then 2 else inf
  status go {{ velocity += (0.1 * sin(tick + index), 0.1) }}
}}
"""
    prog = compile_source(text, "test.swarm")
    ref, fast = (Simulation(prog, 0, backend=b) for b in (REFERENCE, other_backend))
    for _ in range(25):
        ref.step()
        fast.step()
        assert np.array_equal(ref.agents.cols["pos"], fast.agents.cols["pos"])
        assert np.array_equal(ref.agents.cols["vel"], fast.agents.cols["vel"])
        assert np.array_equal(ref.agents.cols["heading"], fast.agents.cols["heading"])
    assert fast.backend.motion_compiled is True


@pytest.mark.parametrize("command", [["run", "--headless", "--steps", "2"],
                                     ["sweep", "--steps", "2", "--workers", "1"],
                                     ["test", "--examples", "2", "--quiet"]])
def test_a_bad_backend_variable_is_named_before_anything_runs(walk, tmp_path,
                                                              monkeypatch, capsys,
                                                              command):
    """`SWARMDSL_BACKEND=numab` said `unknown backend` without naming the variable; a
    sweep failed every run, and `swarmdsl test` called it a counterexample (exit 1)."""
    monkeypatch.setenv("SWARMDSL_BACKEND", "numab")
    monkeypatch.chdir(tmp_path)
    walk.write_text(walk.read_text().replace("  metric", "  invariant counted: laps >= 0\n"
                                             "  metric"))    # a property for `test` to test
    err = cli_error(capsys, [command[0], str(walk), *command[1:]])
    assert "error: $SWARMDSL_BACKEND=numab: not a backend; set it to numba or numpy" in err
    assert not (tmp_path / "walk-sweep").exists()


def test_the_backend_option_wins_over_a_bad_variable(walk, monkeypatch):
    monkeypatch.setenv("SWARMDSL_BACKEND", "numab")
    assert main(["run", str(walk), "--headless", "--steps", "2",
                 "--backend", "numpy"]) == 0
