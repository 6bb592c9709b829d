"""The compiled cell list of a batch of replicas: every replica's own cell list, in one call.

A batch (`runtime/batch.py`) needs every replica's neighbours exactly as its solo numba
run finds them: the same pairs with the same bits, each owner's neighbours in the same
order (so sums round alike). Each replica gets its own grid (`spatial.cell_grids`, the
solo `cell_grid` of every replica at once: in a world without edges it depends on the
replica's spread) and the same counting sort as `cells.py`, and the replicas' sorted
agents and cells are laid end to end: sorted positions `bounds[r]:bounds[r+1]` are
replica r's, in its solo sort order, and its cells are `cbase[r]:cbase[r+1]` of one
`start` array (the cell starts as batch-wide sorted positions). An owner's cells are
then found by its solo steps (`cells._ranges`, `_wraps`) on its replica's slice of
`start`, so every owner visits its candidates exactly as its solo run does.

The result is a `spatial.CellPairs` like the solo search's: the sums search it directly
(`kernels.direct_kernel` with `batch_ranges`) and no pair is written unless something
reads them, which then get them in cell order (and the row-order table on first use).
"""

from __future__ import annotations

import numpy as np

from swarmdsl.runtime.compiled import threads
from swarmdsl.runtime.compiled.cells import (
    _cell_of,
    _delta,
    _point,
    _ranges,
    _wraps,
    reach2,
    write_owner,
)
from swarmdsl.runtime.compiled.jit import njit, prange
from swarmdsl.runtime.spatial import CellPairs, cell_grids


@njit(cache=True, nogil=True, error_model="numpy")
def batch_ranges(s, cell, k, wx, wy, G, wrap, lo, hi):
    """`cells.solo_ranges` for a batch's grid G = (scell, start, nx, ny, rep, cbase):
    sorted agent s's cells by its own replica's grid (`scell` holds batch-wide cell
    numbers, so a new replica always starts a new cell)."""
    scell, start, nx, ny, rep, cbase = G
    c = scell[s]
    if c != cell:
        r = rep[s]
        base = cbase[r]
        local = c - base
        wx, wy = _wraps(local, nx[r], ny[r], wrap)
        return c, _ranges(local, nx[r], ny[r], wrap, start[base:], lo, hi), wx, wy
    return cell, k, wx, wy


@njit(cache=True, nogil=True, error_model="numpy")
def _sort_replica(pos, lo, hi, x0, y0, nx, ny, wx, wy, base, wrap, bw, bh, order, scell,
                  sp, start):
    """`cells._sort_by_cell` and `_gather_sorted` of rows lo:hi into cells
    base..base+nx*ny (their starts written to `start`, as batch-wide positions)."""
    m = nx * ny
    cell = np.empty(hi - lo, np.int64)
    fill = np.zeros(m + 1, np.int64)
    for a in range(lo, hi):
        x, y = _point(pos, a, wrap, bw, bh)
        cx, cy = _cell_of(x, y, x0, y0, nx, ny, wx, wy)
        c = cy * nx + cx
        cell[a - lo] = c
        fill[c + 1] += 1
    for c in range(m):
        fill[c + 1] += fill[c]
    for c in range(m):
        fill[c] += lo
        start[base + c] = fill[c]
    for a in range(lo, hi):
        c = cell[a - lo]
        s = fill[c]
        order[s] = a
        fill[c] = s + 1
    for s in range(lo, hi):
        a = order[s]
        scell[s] = base + cell[a - lo]
        sp[s, 0], sp[s, 1] = _point(pos, a, wrap, bw, bh)


@njit(cache=True, nogil=True, error_model="numpy")
def _sort_all(pos, bounds, x0, y0, nx, ny, wx, wy, cbase, wrap, bw, bh, order, scell, sp,
              start):
    for r in range(bounds.size - 1):
        _sort_replica(pos, bounds[r], bounds[r + 1], x0[r], y0[r], nx[r], ny[r], wx[r],
                      wy[r], cbase[r], wrap, bw, bh, order, scell, sp, start)


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _sort_all_par(pos, bounds, x0, y0, nx, ny, wx, wy, cbase, wrap, bw, bh, order, scell,
                  sp, start):
    for r in prange(bounds.size - 1):
        _sort_replica(pos, bounds[r], bounds[r + 1], x0[r], y0[r], nx[r], ny[r], wx[r],
                      wy[r], cbase[r], wrap, bw, bh, order, scell, sp, start)


@njit(cache=True, nogil=True, error_model="numpy")
def _count_range(s0, s1, sp, G, radius, wrap, bw, bh, counts):
    """`cells._count_range` over a batch's grid."""
    within2 = reach2(radius)
    lo = np.empty(6, np.int64)
    hi = np.empty(6, np.int64)
    cell, k, wx, wy = -1, 0, wrap, wrap
    for s in range(s0, s1):
        cell, k, wx, wy = batch_ranges(s, cell, k, wx, wy, G, wrap, lo, hi)
        ax, ay = sp[s, 0], sp[s, 1]
        got = -1   # the owner itself is in its own cell, at distance 0
        for q in range(k):
            for t in range(lo[q], hi[q]):
                dx, dy = _delta(ax, ay, sp[t, 0], sp[t, 1], wx, wy, bw, bh)
                got += dx * dx + dy * dy <= within2
        counts[s] = got


@njit(cache=True, nogil=True, error_model="numpy")
def _fill_range(s0, s1, sp, G, radius, wrap, bw, bh, offsets, t_out, dist, delta):
    """`cells._fill_range` over a batch's grid: each owner's block at `offsets[s]`."""
    within2 = reach2(radius)
    lo = np.empty(6, np.int64)
    hi = np.empty(6, np.int64)
    cell, k, wx, wy = -1, 0, wrap, wrap
    for s in range(s0, s1):
        cell, k, wx, wy = batch_ranges(s, cell, k, wx, wy, G, wrap, lo, hi)
        write_owner(s, offsets[s], offsets[s + 1], k, lo, hi, sp, within2, wx, wy, bw, bh,
                    t_out, dist, delta)


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _count_par(sp, G, radius, wrap, bw, bh, counts, chunks):
    n = sp.shape[0]
    for c in prange(chunks):
        _count_range(c * n // chunks, (c + 1) * n // chunks, sp, G, radius, wrap, bw, bh,
                     counts)


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _fill_par(sp, G, radius, wrap, bw, bh, offsets, t_out, dist, delta, chunks):
    n = sp.shape[0]
    for c in prange(chunks):
        _fill_range(c * n // chunks, (c + 1) * n // chunks, sp, G, radius, wrap, bw, bh,
                    offsets, t_out, dist, delta)


def _write_pairs(grid, spare):
    """(soff, t, dist, delta, buffers): every owner's pairs in sorted order, counted
    first, then written (into `spare` when it has room)."""
    from swarmdsl.runtime.compiled.cells import _first, _pair_buffers

    sp, G, radius, wrap, bw, bh = grid
    n = sp.shape[0]
    chunks = threads.chunks(n)
    counts = np.empty(n, np.int64)
    if chunks > 1:
        _count_par(sp, G, radius, wrap, bw, bh, counts, chunks)
    else:
        _count_range(0, n, sp, G, radius, wrap, bw, bh, counts)
    soff = np.zeros(n + 1, np.int64)
    np.cumsum(counts, out=soff[1:])
    buffers = _pair_buffers(int(soff[-1]), spare)
    t, dist, delta = _first(buffers, int(soff[-1]))
    if chunks > 1:
        _fill_par(sp, G, radius, wrap, bw, bh, soff, t, dist, delta, chunks)
    else:
        _fill_range(0, n, sp, G, radius, wrap, bw, bh, soff, t, dist, delta)
    return soff, t, dist, delta, buffers


# The grids of the last batch searched in a world that wraps: they depend only on the
# box, the radius and the replicas' sizes, not on where the agents are, so a batch's
# ticks share them (computing them, with each agent's replica, took ~3 % of a tick of
# 100 replicas of 100 agents). The kernels only read them.
_WRAPPED: dict = {}


def _grids(pos, bounds, radius: float, box) -> tuple:
    """(x0, y0, nx, ny, wx, wy, cbase, rep): each replica's solo grid
    (`spatial.cell_grids`), where each replica's cells start among the batch's, and
    each agent's replica."""
    key = None
    if box is not None:
        key = (float(box[0]), float(box[1]), radius, bounds.tobytes())
        got = _WRAPPED.get(key)
        if got is not None:
            return got
    x0, y0, nx, ny, wx, wy = cell_grids(pos, bounds, radius, box)
    reps = bounds.size - 1
    cbase = np.zeros(reps + 1, np.int64)
    np.cumsum(nx * ny, out=cbase[1:])
    rep = np.repeat(np.arange(reps, dtype=np.int64), np.diff(bounds))
    got = (np.ascontiguousarray(x0, np.float64), np.ascontiguousarray(y0, np.float64),
           nx, ny, wx, wy, cbase, rep)
    if key is not None:
        _WRAPPED.clear()    # one batch's at a time: a sweep worker runs one after another
        _WRAPPED[key] = got
    return got


def replica_cells(pos: np.ndarray, bounds: np.ndarray, radius: float, box, spare=None,
                  on_fill=None) -> CellPairs:
    """The cell list of replicas `bounds[r]:bounds[r+1]` of `pos` (finite, each replica
    at least 2 agents): each replica sorted into its solo grid now; the pairs (replica
    by replica its solo cell list's, each owner's neighbours in its solo order) written
    on first use, then `on_fill(table, soff, buffers)` is told. `spare`: an earlier
    table's buffers, free to overwrite. `CellPairs.grid` is (sorted positions, G,
    radius, wrap, box width, box height) with G = (cells, starts, nx, ny, replica of
    each sorted agent, first cell of each replica), as `batch_ranges` reads it."""
    pos = np.ascontiguousarray(pos, dtype=np.float64)
    bounds = np.ascontiguousarray(bounds, dtype=np.int64)
    n, reps = pos.shape[0], bounds.size - 1
    wrap = box is not None
    bw, bh = (float(box[0]), float(box[1])) if wrap else (0.0, 0.0)
    radius = float(radius)
    x0, y0, nx, ny, wx, wy, cbase, rep = _grids(pos, bounds, radius, box)
    order, scell = np.empty(n, np.int64), np.empty(n, np.int64)
    sp, start = np.empty((n, 2)), np.empty(int(cbase[-1]) + 1, np.int64)
    start[-1] = n
    sort = _sort_all_par if threads.chunks(n) > 1 and reps > 1 else _sort_all
    sort(pos, bounds, x0, y0, nx, ny, wx, wy, cbase, wrap, bw, bh, order, scell, sp, start)
    grid = (sp, (scell, start, nx, ny, rep, cbase), radius, wrap, bw, bh)

    def fill(table):
        got = _write_pairs(grid, spare)
        if on_fill is not None:
            on_fill(table, got[0], got[4])
        return got
    return CellPairs(radius, order, fill, grid, batch=True)


def replica_pairs(pos: np.ndarray, bounds: np.ndarray, radius: float, box):
    """The row-order pair table of `replica_cells` (keeping no state between calls)."""
    return replica_cells(pos, bounds, radius, box).table
