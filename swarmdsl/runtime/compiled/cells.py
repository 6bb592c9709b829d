"""The compiled neighbour search: a cell list that writes the tick's pairs in cell order.

Agents are counting-sorted into square cells at least as wide as the table's radius, so
every neighbour of an agent lies in its own cell or one of the eight around it (in a
wrap-around world the cells tile the box exactly and the ring closes). The sort is done
when the table is built; the pairs are written when something first reads them
(`spatial.CellPairs`), and never in a tick whose sums all search the sorted agents
themselves (`kernels.direct_kernel`, with the same per-owner steps as here). Visiting
the owners in sorted order lays their blocks of pairs one after another: reads of the
sorted positions and writes of the pairs both walk memory in order, which matters once
the swarm outgrows the CPU's caches. Per pair the kernels compute `delta` and `dist`
with the same operations, in the same order, as `spatial.build_pairs`, so the two
searches keep exactly the same pairs (boundary included), in the same order (the
reference puts its candidates in this search's order: `spatial.cell_order`), with the
same bits.

The search splits the sorted agents into runs on numba's threads for big swarms
(`threads.py`); each owner's pairs are the same whichever thread writes them. The
kernels are plain functions of arrays, cached on disk by numba (`cache=True`): the
first run on a machine compiles them once, later runs load them.
"""

from __future__ import annotations


import numpy as np

from swarmdsl.runtime.compiled import threads
from swarmdsl.runtime.compiled.jit import njit, prange
from swarmdsl.runtime.spatial import (
    CellPairs, PairTable, build_pairs, cell_grid, positions_finite)

def build_pairs_cells(pos: np.ndarray, radius: float, box, hint=0, spare=None,
                      on_fill=None) -> PairTable:
    """The tick's pair table from a compiled cell list; same pairs as `build_pairs`.

    The agents are sorted into cells now; the pairs are written on first use
    (`CellPairs`), then `on_fill(table, soff, buffers)` is told. Sums that search the
    cell list themselves (`kernels.direct_kernel`) read only the sorted agents.
    `hint` is about how many pairs to expect: last tick's count, or its offsets (each
    run of owners then gets room for its own share). With room for them the search
    writes the pairs in one pass instead of counting them first; threaded, each run
    writes into its own region and the regions are closed up afterwards.
    `spare` is an earlier table's `buffers`, free to overwrite: written again, memory
    the process already holds costs no page faults (at a million agents, fresh pair
    arrays cost more than the threaded search that fills them).
    """
    n = pos.shape[0]
    if n < 2 or radius <= 0 or not positions_finite(pos):
        return build_pairs(pos, radius, box)  # nothing to search, or a fault to report
    pos = np.ascontiguousarray(pos, dtype=np.float64)
    if box is not None:
        bw, bh = float(box[0]), float(box[1])
    else:
        bw = bh = 0.0
    x0, y0, nx, ny, wx, wy = cell_grid(pos, radius, box)
    wrap = box is not None
    order, start, cell = _sort_by_cell(pos, wrap, bw, bh, x0, y0, nx, ny, wx, wy)
    scell, sp = np.empty(n, np.int64), np.empty((n, 2))
    chunks = threads.chunks(n)
    (_gather_sorted_par if chunks > 1 else _gather_sorted)(pos, wrap, bw, bh, order, cell,
                                                           scell, sp, chunks)
    grid = (sp, (scell, start, nx, ny), float(radius), box is not None, bw, bh)

    def fill(table):
        got = _write_pairs(grid, hint, spare)
        if on_fill is not None:
            on_fill(table, got[0], got[4])
        return got
    return CellPairs(float(radius), order, fill, grid)


def candidates_bound(cells: CellPairs) -> int:
    """At least as many candidates as any owner of `cells` has: nine times the fullest
    cell (an owner's cells are its own and the eight around it, each visited once)."""
    got = cells.__dict__.get("_candidates")
    if got is None:
        start = cells.grid[1][1]
        got = cells._candidates = 9 * int(np.max(start[1:] - start[:-1])) + 1
    return got


def _write_pairs(grid, hint, spare):
    """(soff, t, dist, delta, buffers): every owner's pairs, in one pass if `hint`
    leaves room for them, else counted first."""
    sp, (scell, start, nx, ny), radius, wrap, bw, bh = grid
    grid = (sp, scell, start, nx, ny, radius, wrap, bw, bh)
    n = sp.shape[0]
    chunks = threads.chunks(n)
    soff = np.zeros(n + 1, np.int64)
    total = int(hint[-1]) if isinstance(hint, np.ndarray) else int(hint)
    if total > 0 and chunks == 1:
        buffers = _pair_buffers(total + total // 8 + 64, spare)   # pairs change little
        total = _fill_once(*grid, soff, *buffers)                  # from tick to tick
        if total >= 0:
            return (soff, *_first(buffers, total), buffers)
        spare = buffers
    elif total > 0:
        if isinstance(hint, np.ndarray) and hint.size == n + 1:
            bounds = split_work(hint, n, chunks)   # last tick's pairs: a fair guess
        else:
            bounds = np.arange(chunks + 1, dtype=np.int64) * n // chunks
        region = _regions(hint, bounds, total)
        buffers = _pair_buffers(int(region[-1]), spare)
        ends = np.empty(chunks, np.int64)
        _fill_once_par(*grid, soff, *buffers, bounds, region, ends)
        if (ends >= 0).all():
            total = _compact(soff, *buffers, bounds, region, ends)
            return (soff, *_first(buffers, total), buffers)
        spare = buffers
    count, fill = (_count_par, _fill_par) if chunks > 1 else (_count, _fill)
    counts = np.empty(n, np.int64)
    count(*grid, counts, chunks)
    np.cumsum(counts, out=soff[1:])
    total = int(soff[-1])
    buffers = _pair_buffers(total, spare)
    t, dist, delta = _first(buffers, total)
    fill(*grid, soff, t, dist, delta, chunks)
    return soff, t, dist, delta, buffers


@njit(cache=True, nogil=True)
def split_work(off, n, chunks):
    """Bounds of `chunks` runs of n owners with about equal work each: their pairs (from
    the cumulative offsets `off`, n + 1 of them) plus one per owner. A tight flock puts
    most pairs in a few cells: equal numbers of owners per run left one thread with
    most of the work and two threads no faster than one."""
    bounds = np.empty(chunks + 1, np.int64)
    bounds[0] = 0
    total = off[n] - off[0] + n
    for c in range(1, chunks):
        target = total * c // chunks
        lo, hi = bounds[c - 1], n
        while lo < hi:
            mid = (lo + hi) // 2
            if off[mid] - off[0] + mid < target:
                lo = mid + 1
            else:
                hi = mid
        bounds[c] = lo
    bounds[chunks] = n
    return bounds


def _regions(hint, bounds: np.ndarray, total: int) -> np.ndarray:
    """Where each run of owners writes its pairs in a threaded one-pass fill: room for
    its share of last tick's pairs (from last tick's offsets `hint` when the swarm kept
    its size, else an equal share of the `total`) and an eighth more."""
    chunks = bounds.size - 1
    if isinstance(hint, np.ndarray) and hint.size == bounds[-1] + 1:
        share = hint[bounds[1:]] - hint[bounds[:-1]]
    else:
        share = np.full(chunks, total // chunks, np.int64)
    region = np.zeros(chunks + 1, np.int64)
    np.cumsum(share + share // 8 + 64, out=region[1:])
    return region


def _pair_buffers(size: int, spare):
    """(t, dist, delta) with room for `size` pairs: `spare` if it has it, else new ones
    with a quarter more (a flock that tightens tick by tick does not reallocate every
    tick)."""
    if spare is not None and spare[0].size >= size:
        return spare
    size += size // 4
    return np.empty(size, np.int64), np.empty(size, np.float64), np.empty((size, 2))


def _first(buffers, total: int):
    return tuple(b[:total] for b in buffers)


@njit(cache=True, nogil=True, error_model="numpy")
def _cell_of(x, y, x0, y0, nx, ny, wx, wy):
    cx = int((x - x0) / wx)
    cy = int((y - y0) / wy)
    cx = min(max(cx, 0), nx - 1)
    cy = min(max(cy, 0), ny - 1)
    return cx, cy


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _into_box(x, box):
    """`x` in [0, box) as `build_pairs` has it (np.mod, then box itself to 0); most
    agents are in the box already and cost one comparison."""
    if 0.0 <= x < box:
        return x + 0.0   # -0.0 becomes +0.0, as np.mod makes it
    m = np.mod(x, box)
    return 0.0 if m >= box else m


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _point(pos, a, wrap, bw, bh):
    if wrap:
        return _into_box(pos[a, 0], bw), _into_box(pos[a, 1], bh)
    return pos[a, 0], pos[a, 1]


@njit(cache=True, nogil=True, error_model="numpy")
def _sort_by_cell(pos, wrap, bw, bh, x0, y0, nx, ny, wx, wy):
    """Counting sort of agent rows by cell (wrapped into the box first if `wrap`): (rows
    in cell order, cell starts (C+1,), each agent's cell). Stable: within a cell, rows
    in order. Only the row numbers are scattered here; `_gather_sorted` then reads
    the rest in sorted order (scattering the positions too cost a third more at 10^6
    agents: random writes stall where random reads overlap)."""
    n = pos.shape[0]
    cell = np.empty(n, np.int64)
    start = np.zeros(nx * ny + 1, np.int64)
    for a in range(n):
        x, y = _point(pos, a, wrap, bw, bh)
        cx, cy = _cell_of(x, y, x0, y0, nx, ny, wx, wy)
        c = cy * nx + cx
        cell[a] = c
        start[c + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for a in range(n):
        c = cell[a]
        s = fill[c]
        order[s] = a
        fill[c] = s + 1
    return order, start, cell


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _gather_range(s0, s1, pos, wrap, bw, bh, order, cell, scell, sp):
    for s in range(s0, s1):
        a = order[s]
        scell[s] = cell[a]
        sp[s, 0], sp[s, 1] = _point(pos, a, wrap, bw, bh)


@njit(cache=True, nogil=True, error_model="numpy")
def _gather_sorted(pos, wrap, bw, bh, order, cell, scell, sp, chunks):
    """The sorted agents' cells and (wrapped) positions."""
    _gather_range(0, order.size, pos, wrap, bw, bh, order, cell, scell, sp)


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _gather_sorted_par(pos, wrap, bw, bh, order, cell, scell, sp, chunks):
    n = order.size
    for k in prange(chunks):
        _gather_range(k * n // chunks, (k + 1) * n // chunks, pos, wrap, bw, bh, order,
                      cell, scell, sp)


@njit(cache=True, nogil=True, error_model="numpy")
def _rows_of(c, n, wrap):
    """The neighbouring cell rows along y, each once: (first, count)."""
    if wrap and n < 3:
        return 0, n          # every row is a neighbour; visit each once
    return c - 1, 3


@njit(cache=True, nogil=True, error_model="numpy")
def _runs(cx, nx, wrap):
    """The neighbouring cells along x as up to two runs of consecutive cells.

    Cells of one row are consecutive in the sorted order, so a run of cells is one
    contiguous range of agents: (lo1, hi1, lo2, hi2), inclusive cell bounds, hi < lo
    for an empty run.
    """
    if wrap and nx < 3:
        return 0, nx - 1, 0, -1
    lo, hi = cx - 1, cx + 1
    if not wrap:
        return max(lo, 0), min(hi, nx - 1), 0, -1
    if lo < 0:
        return 0, hi, nx - 1, nx - 1
    if hi >= nx:
        return lo, nx - 1, 0, 0
    return lo, hi, 0, -1


@njit(cache=True, nogil=True, error_model="numpy")
def _ranges(c, nx, ny, wrap, start, lo, hi):
    """The agents of the cells around cell `c` as up to six ranges of the sorted order
    (three rows of cells, each up to two runs): writes `lo`/`hi`, returns how many."""
    cy, cx = c // nx, c % nx
    fy, ky = _rows_of(cy, ny, wrap)
    lo1, hi1, lo2, hi2 = _runs(cx, nx, wrap)
    k = 0
    for oy in range(ky):
        yy = fy + oy
        if wrap:
            yy %= ny
        elif yy < 0 or yy >= ny:
            continue
        for run in range(2):
            a, b = (lo1, hi1) if run == 0 else (lo2, hi2)
            if b < a:
                continue
            lo[k] = start[yy * nx + a]
            hi[k] = start[yy * nx + b + 1]
            k += 1
    return k


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def cell_ranges(s, cell, k, wx, wy, scell, nx, ny, wrap, start, lo, hi):
    """(cell, ranges, wrap along x, wrap along y) of sorted agent s: worked out again
    only when it is the first agent of a new cell."""
    if scell[s] != cell:
        c = scell[s]
        wx, wy = _wraps(c, nx, ny, wrap)
        return c, _ranges(c, nx, ny, wrap, start, lo, hi), wx, wy
    return cell, k, wx, wy


@njit(cache=True, nogil=True, error_model="numpy")
def solo_ranges(s, cell, k, wx, wy, G, wrap, lo, hi):
    """`cell_ranges` with the grid as `CellPairs.grid` holds it: G = (scell, start, nx,
    ny). A batch's grid has its own (`replica_cells.batch_ranges`); the kernels that
    search the cells take either."""
    scell, start, nx, ny = G
    return cell_ranges(s, cell, k, wx, wy, scell, nx, ny, wrap, start, lo, hi)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _wraps(c, nx, ny, wrap):
    """Whether a candidate of cell c's agents may be nearer the other way round the
    world, along x and along y. Only for the cells along the world's edge: with at
    least 5 cells a side, a candidate is at most two cells (2/5 of the world) away,
    never near the half where the way round starts, and `_wrapped` would return the
    difference itself (the sorted positions hold no -0.0, so not even its sign
    changes). A tenth of the candidates at 10^4 agents instead of all of them."""
    if not wrap:
        return False, False
    cy, cx = c // nx, c % nx
    return nx < 5 or cx == 0 or cx == nx - 1, ny < 5 or cy == 0 or cy == ny - 1


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _delta(ax, ay, bx, by, wx, wy, bw, bh):
    """other.pos - pos, the shortest way round along the axes that wrap (`_wraps`), as
    build_pairs."""
    dx = bx - ax
    dy = by - ay
    if wx:
        dx = _wrapped(dx, bw)
    if wy:
        dy = _wrapped(dy, bh)
    return dx, dy


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _wrapped(d, period):
    """`d - period * rint(d / period)` for |d| < period (both ends inside the box), with
    the same bits but no division: the rounding is -1, 0 or 1, decided by comparing
    with half the period; within a hair of a tie the formula itself decides."""
    half = 0.5 * period
    a = abs(d)
    if a >= half * (1.0 - 1e-12) and a <= half * (1.0 + 1e-12):
        return d - period * np.rint(d / period)
    if d > half:
        return d - period
    if d < -half:
        return d + period
    return d + 0.0   # d - period * (+-0.0): -0.0 becomes +0.0, as in the formula


@njit(cache=True, nogil=True, error_model="numpy")
def reach2(radius):
    """The largest squared distance d2 with sqrt(d2) <= radius: a pair is within the
    radius exactly when its d2 <= reach2(radius), the decision taking the root would
    give (the root is correctly rounded, so it never decreases as d2 grows), without
    the root and without a branch. Whether a candidate is kept is a coin toss the CPU
    cannot predict, so it is added, not branched on. NaN for a NaN radius (nothing is
    within it); -1 for a negative one."""
    if radius != radius:
        return radius
    if radius < 0.0:
        return -1.0
    x = radius * radius
    while np.sqrt(x) > radius:
        x = np.nextafter(x, -np.inf)
    while x < np.inf and np.sqrt(np.nextafter(x, np.inf)) <= radius:
        x = np.nextafter(x, np.inf)
    return x


@njit(cache=True, nogil=True, error_model="numpy")
def _count_range(s0, s1, sp, scell, start, nx, ny, radius, wrap, bw, bh, counts):
    """counts[s]: the pairs of the owners at sorted positions s0..s1-1."""
    within2 = reach2(radius)
    lo = np.empty(6, np.int64)
    hi = np.empty(6, np.int64)
    cell, k, wx, wy = -1, 0, wrap, wrap
    for s in range(s0, s1):
        cell, k, wx, wy = cell_ranges(s, cell, k, wx, wy, scell, nx, ny, wrap, start, lo,
                                      hi)
        ax, ay = sp[s, 0], sp[s, 1]
        got = -1   # the owner itself is in its own cell, at distance 0
        for q in range(k):
            for t in range(lo[q], hi[q]):
                dx, dy = _delta(ax, ay, sp[t, 0], sp[t, 1], wx, wy, bw, bh)
                got += dx * dx + dy * dy <= within2
        counts[s] = got


@njit(cache=True, nogil=True, error_model="numpy")
def write_owner(s, p, room, k, lo, hi, sp, within2, wx, wy, bw, bh, t_out, dist, delta):
    """Write owner s's pairs (those with d2 <= within2, see `reach2`) from slot p on:
    the slot after them, or -1 at `room`. Every candidate is written at the next free
    slot, which is kept only if the pair is: no unpredictable branch (the room test
    fails at most once, at the end)."""
    ax, ay = sp[s, 0], sp[s, 1]
    for q in range(k):
        for t in range(lo[q], hi[q]):
            if p >= room:
                return -1
            dx, dy = _delta(ax, ay, sp[t, 0], sp[t, 1], wx, wy, bw, bh)
            t_out[p] = t
            d2 = dx * dx + dy * dy
            dist[p] = np.sqrt(d2)
            delta[p, 0] = dx
            delta[p, 1] = dy
            p += (d2 <= within2) & (t != s)
    return p


@njit(cache=True, nogil=True, error_model="numpy")
def _fill_range(s0, s1, sp, scell, start, nx, ny, radius, wrap, bw, bh, offsets, t_out,
                dist, delta):
    """Write the pairs of the owners at sorted positions s0..s1-1 at `offsets[s]`, the
    neighbour as its sorted position: one block after another, in memory order."""
    within2 = reach2(radius)
    lo = np.empty(6, np.int64)
    hi = np.empty(6, np.int64)
    cell, k, wx, wy = -1, 0, wrap, wrap
    for s in range(s0, s1):
        cell, k, wx, wy = cell_ranges(s, cell, k, wx, wy, scell, nx, ny, wrap, start, lo,
                                      hi)
        write_owner(s, offsets[s], offsets[s + 1], k, lo, hi, sp, within2, wx, wy, bw, bh,
                    t_out, dist, delta)   # counted exactly: fills its block, stops


@njit(cache=True, nogil=True, error_model="numpy")
def _fill_once(sp, scell, start, nx, ny, radius, wrap, bw, bh, offsets, t_out, dist, delta):
    """Count and write every owner's pairs in one pass, each block right after the last;
    the total, or -1 if the arrays ran out of room (then count first, and fill)."""
    within2 = reach2(radius)
    lo = np.empty(6, np.int64)
    hi = np.empty(6, np.int64)
    cell, k, wx, wy, p = -1, 0, wrap, wrap, 0
    for s in range(sp.shape[0]):
        cell, k, wx, wy = cell_ranges(s, cell, k, wx, wy, scell, nx, ny, wrap, start, lo,
                                      hi)
        offsets[s] = p
        p = write_owner(s, p, t_out.size, k, lo, hi, sp, within2, wx, wy, bw, bh, t_out,
                        dist, delta)
        if p < 0:
            return -1
    offsets[sp.shape[0]] = p
    return p


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _fill_once_par(sp, scell, start, nx, ny, radius, wrap, bw, bh, offsets, t_out, dist,
                   delta, bounds, region, ends):
    """`_fill_once` on the thread pool: run c of the sorted owners writes its blocks one
    after another from `region[c]`; `ends[c]` is where they stop, or -1 if they ran out
    of room before `region[c + 1]`."""
    within2 = reach2(radius)
    for c in prange(bounds.size - 1):
        lo = np.empty(6, np.int64)
        hi = np.empty(6, np.int64)
        cell, k, wx, wy, p = -1, 0, wrap, wrap, region[c]
        for s in range(bounds[c], bounds[c + 1]):
            cell, k, wx, wy = cell_ranges(s, cell, k, wx, wy, scell, nx, ny, wrap, start,
                                          lo, hi)
            offsets[s] = p
            p = write_owner(s, p, region[c + 1], k, lo, hi, sp, within2, wx, wy, bw, bh,
                            t_out, dist, delta)
            if p < 0:
                break
        ends[c] = p


@njit(cache=True, nogil=True, error_model="numpy")
def _compact(offsets, t_out, dist, delta, bounds, region, ends):
    """Move each run's pairs down to right after the run before (in order, so a move
    never overwrites pairs not moved yet) and shift its offsets: the layout of a serial
    fill. Returns the number of pairs."""
    p = ends[0] - region[0]
    for c in range(1, bounds.size - 1):
        shift = region[c] - p
        if shift:
            for q in range(region[c], ends[c]):
                t_out[q - shift] = t_out[q]
                dist[q - shift] = dist[q]
                delta[q - shift, 0] = delta[q, 0]
                delta[q - shift, 1] = delta[q, 1]
            for s in range(bounds[c], bounds[c + 1]):
                offsets[s] -= shift
        p = ends[c] - shift
    offsets[bounds[-1]] = p
    return p


@njit(cache=True, nogil=True, error_model="numpy")
def _count(sp, scell, start, nx, ny, radius, wrap, bw, bh, counts, chunks):
    _count_range(0, sp.shape[0], sp, scell, start, nx, ny, radius, wrap, bw, bh,
                 counts)


@njit(cache=True, nogil=True, error_model="numpy")
def _fill(sp, scell, start, nx, ny, radius, wrap, bw, bh, offsets, t, dist, delta, chunks):
    _fill_range(0, sp.shape[0], sp, scell, start, nx, ny, radius, wrap, bw, bh, offsets, t,
                dist, delta)


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _count_par(sp, scell, start, nx, ny, radius, wrap, bw, bh, counts, chunks):
    """`_count` on the thread pool: equal runs of the sorted agents, one per chunk."""
    n = sp.shape[0]
    for c in prange(chunks):
        _count_range(c * n // chunks, (c + 1) * n // chunks, sp, scell, start, nx, ny,
                     radius, wrap, bw, bh, counts)


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _fill_par(sp, scell, start, nx, ny, radius, wrap, bw, bh, offsets, t, dist, delta,
              chunks):
    n = sp.shape[0]
    for c in prange(chunks):
        _fill_range(c * n // chunks, (c + 1) * n // chunks, sp, scell, start, nx, ny,
                    radius, wrap, bw, bh, offsets, t, dist, delta)
