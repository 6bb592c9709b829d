"""The compiled neighbour search of a batch of replicas: one cell list per replica, in one call.

A batch (`runtime/batch.py`) needs every replica's pairs exactly as its solo numba run
finds them: the same pairs with the same bits, each owner's neighbours in the same
order (so sums round alike). This runs `cells.py`'s search replica by replica inside one
compiled call: each replica's own grid (`cell_grid`: in a world without edges it
depends on the replica's bounding box), the same counting sort, the same cell ranges,
the same per-candidate arithmetic. Only the layout differs: the pairs are written
straight into row order (each owner's block at its row, neighbours as batch rows), the
table the batch's aggregates read, instead of the solo run's cell order.
"""

from __future__ import annotations

import math

import numpy as np

from swarmdsl.runtime.compiled import threads
from swarmdsl.runtime.compiled.cells import (
    _CELLS_PER_AGENT,
    _MARGIN,
    _MIN_CELLS,
    _delta,
    _gather_range,
    _sort_by_cell,
    cell_ranges,
    reach2,
)
from swarmdsl.runtime.compiled.jit import njit, prange
from swarmdsl.runtime.spatial import PairTable


@njit(cache=True, nogil=True, error_model="numpy")
def _cells_along(extent, radius):
    """`cells._grid`."""
    if not extent > 0:
        return 1
    return max(1, int(math.floor(extent / (radius * _MARGIN))))


@njit(cache=True, nogil=True, error_model="numpy")
def _grid_of(pos, radius, wrap, bw, bh):
    """`cells.cell_grid` of one replica's positions."""
    n = pos.shape[0]
    if wrap:
        x0, y0, ex, ey = 0.0, 0.0, bw, bh
    else:
        x0, y0 = pos[0, 0], pos[0, 1]
        x1, y1 = x0, y0
        for a in range(1, n):
            x0 = min(x0, pos[a, 0])
            x1 = max(x1, pos[a, 0])
            y0 = min(y0, pos[a, 1])
            y1 = max(y1, pos[a, 1])
        ex, ey = x1 - x0, y1 - y0
    nx, ny = _cells_along(ex, radius), _cells_along(ey, radius)
    cap = max(_CELLS_PER_AGENT * n, _MIN_CELLS)
    while nx * ny > cap:
        nx, ny = max(1, nx // 2), max(1, ny // 2)
    wx = ex / nx if ex > 0 else radius
    wy = ey / ny if ey > 0 else radius
    return x0, y0, nx, ny, wx, wy


@njit(cache=True, nogil=True, error_model="numpy")
def _sort_replica(pos, lo, hi, radius, wrap, bw, bh, order, scell, sp, starts, soff, grids,
                  r):
    """Replica r's counting sort into its own grid: `order` (local rows), `scell`, `sp`
    at lo:hi, its cell starts at `starts[soff[r]:]`, (nx, ny) in `grids[r]`."""
    part = pos[lo:hi]
    x0, y0, nx, ny, wx, wy = _grid_of(part, radius, wrap, bw, bh)
    o, start, cell = _sort_by_cell(part, wrap, bw, bh, x0, y0, nx, ny, wx, wy)
    order[lo:hi] = o
    _gather_range(0, hi - lo, part, wrap, bw, bh, o, cell, scell[lo:hi], sp[lo:hi])
    starts[soff[r]:soff[r] + start.size] = start
    grids[r, 0], grids[r, 1] = nx, ny


@njit(cache=True, nogil=True, error_model="numpy")
def _search_replica(lo, hi, radius, wrap, bw, bh, order, scell, sp, start, nx, ny,
                    offsets, counting, i, j, dist, delta):
    """Count (`counting`: into offsets[lo + row + 1]) or write one replica's pairs,
    owner by owner in sorted order as `cells._fill_range` visits them."""
    within2 = reach2(radius)
    lo6 = np.empty(6, np.int64)
    hi6 = np.empty(6, np.int64)
    o, sc, p2 = order[lo:hi], scell[lo:hi], sp[lo:hi]
    cell, k, wx, wy = -1, 0, wrap, wrap
    for s in range(hi - lo):
        cell, k, wx, wy = cell_ranges(s, cell, k, wx, wy, sc, nx, ny, wrap, start, lo6,
                                      hi6)
        ax, ay = p2[s, 0], p2[s, 1]
        row = lo + o[s]
        if counting:
            got = 0
            for q in range(k):
                for t in range(lo6[q], hi6[q]):
                    dx, dy = _delta(ax, ay, p2[t, 0], p2[t, 1], wx, wy, bw, bh)
                    got += (dx * dx + dy * dy <= within2) & (t != s)
            offsets[row + 1] = got
            continue
        p = offsets[row]
        for q in range(k):
            for t in range(lo6[q], hi6[q]):
                dx, dy = _delta(ax, ay, p2[t, 0], p2[t, 1], wx, wy, bw, bh)
                d2 = dx * dx + dy * dy
                if d2 <= within2 and t != s:
                    i[p] = row
                    j[p] = lo + o[t]
                    dist[p] = np.sqrt(d2)
                    delta[p, 0] = dx
                    delta[p, 1] = dy
                    p += 1


@njit(cache=True, nogil=True, error_model="numpy")
def _sort_all(pos, bounds, radius, wrap, bw, bh, order, scell, sp, starts, soff, grids):
    for r in range(bounds.size - 1):
        _sort_replica(pos, bounds[r], bounds[r + 1], radius, wrap, bw, bh, order, scell,
                      sp, starts, soff, grids, r)


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _sort_all_par(pos, bounds, radius, wrap, bw, bh, order, scell, sp, starts, soff, grids):
    for r in prange(bounds.size - 1):
        _sort_replica(pos, bounds[r], bounds[r + 1], radius, wrap, bw, bh, order, scell,
                      sp, starts, soff, grids, r)


@njit(cache=True, nogil=True, error_model="numpy")
def _search_all(bounds, radius, wrap, bw, bh, order, scell, sp, starts, soff, grids,
                offsets, counting, i, j, dist, delta):
    for r in range(bounds.size - 1):
        _search_replica(bounds[r], bounds[r + 1], radius, wrap, bw, bh, order, scell, sp,
                        starts[soff[r]:soff[r + 1]], grids[r, 0], grids[r, 1], offsets,
                        counting, i, j, dist, delta)


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _search_all_par(bounds, radius, wrap, bw, bh, order, scell, sp, starts, soff, grids,
                    offsets, counting, i, j, dist, delta):
    for r in prange(bounds.size - 1):
        _search_replica(bounds[r], bounds[r + 1], radius, wrap, bw, bh, order, scell, sp,
                        starts[soff[r]:soff[r + 1]], grids[r, 0], grids[r, 1], offsets,
                        counting, i, j, dist, delta)


def replica_pairs(pos: np.ndarray, bounds: np.ndarray, radius: float, box) -> PairTable:
    """The row-order pair table of replicas `bounds[r]:bounds[r+1]` of `pos` (finite,
    each replica at least 2 agents): replica by replica the solo cell list's pairs,
    each owner's neighbours in its solo order. Counted first, then written in place:
    in row order, a one-pass write in sorted order needs a move of every block after
    it, which costs more than counting (measured at 100 x 100 agents)."""
    pos = np.ascontiguousarray(pos, dtype=np.float64)
    bounds = np.ascontiguousarray(bounds, dtype=np.int64)
    n, reps = pos.shape[0], bounds.size - 1
    wrap = box is not None
    bw, bh = (float(box[0]), float(box[1])) if wrap else (0.0, 0.0)
    sizes = np.diff(bounds)
    soff = np.zeros(reps + 1, np.int64)
    np.cumsum(np.maximum(_CELLS_PER_AGENT * sizes, _MIN_CELLS) + 1, out=soff[1:])
    order, scell = np.empty(n, np.int64), np.empty(n, np.int64)
    sp, starts = np.empty((n, 2)), np.empty(int(soff[-1]), np.int64)
    grids = np.empty((reps, 2), np.int64)
    par = threads.chunks(n) > 1 and reps > 1
    radius = float(radius)
    (_sort_all_par if par else _sort_all)(pos, bounds, radius, wrap, bw, bh, order, scell,
                                          sp, starts, soff, grids)
    grid = (order, scell, sp, starts, soff, grids)
    offsets = np.zeros(n + 1, np.int64)
    search = _search_all_par if par else _search_all
    none_j, none_d, none_dl = np.empty(0, np.int64), np.empty(0), np.empty((0, 2))
    search(bounds, radius, wrap, bw, bh, *grid, offsets, True, none_j, none_j, none_d,
           none_dl)
    np.cumsum(offsets, out=offsets)
    total = int(offsets[-1])
    i, j = np.empty(total, np.int64), np.empty(total, np.int64)
    dist, delta = np.empty(total), np.empty((total, 2))
    search(bounds, radius, wrap, bw, bh, *grid, offsets, False, i, j, dist, delta)
    return PairTable(radius, offsets, j, dist, delta, i)
