"""Neighbour pairs from one spatial index per tick, and segment reductions over them."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class PairTable:
    """Every ordered pair (i, j), i != j, within `radius`, sorted by i (CSR layout).

    `offsets[i]:offsets[i+1]` indexes the pairs of agent i. `delta` is `pos[j] - pos[i]`,
    the shortest way round in a wrap-around world. `build_pairs` keeps only pairs with
    `dist <= radius`, so a query as wide as the table needs no distance filter. The
    arrays are read-only: frames hand them out without copying.
    """

    radius: float
    offsets: np.ndarray   # (N+1,) int64
    j: np.ndarray         # (P,) int64
    dist: np.ndarray      # (P,) float64
    delta: np.ndarray     # (P, 2) float64
    i: np.ndarray | None = None  # (P,) int64, the owner of each pair (sorted)

    def __post_init__(self):
        if self.i is None:
            self.i = np.repeat(np.arange(self.offsets.size - 1), np.diff(self.offsets))
        for a in (self.offsets, self.j, self.dist, self.delta, self.i):
            a.flags.writeable = False

    def select(self, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Pairs whose i is in `idx` (sorted): (seg (P',) local row in idx, rows (P',)).

        `rows` index this table's arrays; None means every pair, in order (when `idx`
        holds every agent, `seg` is then `i` itself and nothing is copied).
        """
        if idx.size == self.offsets.size - 1:  # sorted, unique, all agents: arange(N)
            return self.i, None
        starts = self.offsets[idx]
        counts = self.offsets[idx + 1] - starts
        total = int(counts.sum())
        seg = np.repeat(np.arange(idx.size), counts)
        if total == 0:
            return seg, np.zeros(0, np.int64)
        first = np.cumsum(counts) - counts
        rows = np.arange(total) - np.repeat(first - starts, counts)
        return seg, rows

    def gather(self, idx: np.ndarray):
        """Pairs whose i is in `idx` (sorted): (seg (P',) local row in idx, j, dist, delta)."""
        seg, rows = self.select(idx)
        if rows is None:
            return seg, self.j, self.dist, self.delta
        return (seg, np.take(self.j, rows), np.take(self.dist, rows),
                np.take(self.delta, rows, axis=0))


class CellPairs:
    """The tick's pairs grouped by owner in cell order, as the compiled search writes them.

    The compiled search visits the owners cell by cell, so it writes each owner's block
    right after the previous one (in row order, every block would land at a random
    place: several cache misses per agent, the most expensive part of a tick with a
    million agents). `order[s]` is the row of the agent at sorted position `s`;
    `soff[s]:soff[s+1]` indexes its pairs in `t` (the neighbour's sorted position),
    `c_dist` and `c_delta`. The compiled aggregates read this layout as it is; every
    other reader sees the row-order `PairTable` (`offsets`, `j`, `dist`, `delta`, `i`,
    `select`, `gather`), built on first use.

    The pairs themselves are written on first use too (`fill(self)` -> (soff, t, dist,
    delta, buffers)): a tick whose neighbour sums all search the sorted agents `grid`
    themselves (`compiled.kernels.direct_kernel`) never writes them.
    """

    def __init__(self, radius: float, order, fill, grid=None, batch: bool = False):
        self.radius = radius
        self.order = order
        self.batch = batch   # every replica of a batch, each in its own grid
        # (sorted positions, G, radius, wrap, box width, box height), G the cells and
        # their starts: cells.py (`solo_ranges`), a batch's replica_cells.py
        self.grid = grid
        self._fill = fill
        self._pairs: tuple | None = None
        self._table: PairTable | None = None
        self._cell_index: np.ndarray | None = None
        order.flags.writeable = False

    @property
    def filled(self) -> bool:
        """Whether the pairs have been written (read by anything) this tick."""
        return self._pairs is not None

    def _written(self) -> tuple:
        if self._pairs is None:
            got = self._fill(self)
            for a in got[:4]:
                a.flags.writeable = False
            self._pairs, self._fill = got, None
        return self._pairs

    soff = property(lambda self: self._written()[0])
    t = property(lambda self: self._written()[1])
    c_dist = property(lambda self: self._written()[2])
    c_delta = property(lambda self: self._written()[3])
    # The writable arrays `t`, `c_dist` and `c_delta` are views of (reused next tick).
    buffers = property(lambda self: self._written()[4])

    @property
    def table(self) -> PairTable:
        """The same pairs grouped by owner row: each owner's block as the search wrote it."""
        if self._table is None:
            n = self.order.size
            per_sorted = np.diff(self.soff)
            counts = np.empty(n, np.int64)
            counts[self.order] = per_sorted
            offsets = np.zeros(n + 1, np.int64)
            np.cumsum(counts, out=offsets[1:])
            first = np.empty(n, np.int64)
            first[self.order] = self.soff[:-1]
            src = np.repeat(first - offsets[:-1], counts)
            src += np.arange(src.size)
            j = np.take(self.order, np.take(self.t, src))
            self._table = PairTable(self.radius, offsets, j, np.take(self.c_dist, src),
                                    np.take(self.c_delta, src, axis=0))
            src.flags.writeable = False
            self._cell_index = src
        return self._table

    @property
    def cell_index(self) -> np.ndarray:
        """(P,): where each pair of the row-order `table` sits in the cell-order arrays
        (a mask over cell-order pairs, read through it, selects row-order pairs)."""
        self.table
        return self._cell_index

    offsets = property(lambda self: self.table.offsets)
    j = property(lambda self: self.table.j)
    dist = property(lambda self: self.table.dist)
    delta = property(lambda self: self.table.delta)
    i = property(lambda self: self.table.i)

    def select(self, idx: np.ndarray):
        return self.table.select(idx)

    def gather(self, idx: np.ndarray):
        return self.table.gather(idx)


def positions_finite(pos: np.ndarray) -> bool:
    """Whether every coordinate is finite. A sum is NaN or infinite whenever a term is,
    so one pass without a temporary decides almost always; only a sum that overflows
    (or a real fault) pays for the exact test."""
    with np.errstate(over="ignore", invalid="ignore"):
        if np.isfinite(np.add.reduce(pos, axis=None)):
            return True
    return bool(np.isfinite(pos).all())


# Up to this many agents the pairs come from a sort along x instead of a KD-tree, so a
# run of a small swarm need not import scipy (about 0.2 s, half of `swarmdsl run
# --steps 1`). The sweep measures more candidates: as fast as the tree up to about 50
# agents, about 0.03 ms a tick slower at 128. The numpy backend is the default only
# for runs too short to repay numba's compile time (`compiled/choice.py`: at 128
# agents, about 2 x 10^6 agent-steps), so the longest such run loses about what the
# import costs; shorter ones gain.
SWEEP_MAX = 128


def build_pairs(pos: np.ndarray, radius: float, box: tuple[float, float] | None) -> PairTable:
    """All neighbour pairs within `radius` (a KD-tree, or for a few agents a sweep along
    x; `box` makes the world wrap around). Either way the candidates are then measured
    here, by the same arithmetic as the compiled cell list, and put in its order
    (`cell_order`), so every search keeps the same pairs, in the same order, with the
    same bits."""
    n = pos.shape[0]
    if n < 2 or radius <= 0:
        return PairTable(radius, np.zeros(n + 1, np.int64), np.zeros(0, np.int64),
                         np.zeros(0), np.zeros((0, 2)))
    pts = _in_box(pos, box)
    if n <= SWEEP_MAX:
        i, j = _sweep_candidates(pts, radius, box)
    else:
        i, j = _tree_candidates(pts, radius, box)
    return _measured(pts, i, j, radius, box)


def _in_box(pos: np.ndarray, box) -> np.ndarray:
    """The positions the search measures: wrapped into [0, box) in a wrap-around world."""
    if box is None:
        return pos
    pts = np.mod(pos, box)
    # cKDTree needs points strictly inside [0, box); mod can return box for -tiny.
    return np.where(pts >= box, 0.0, pts)


def _measured(pts, i, j, radius: float, box, bounds=None) -> PairTable:
    """The table of the candidates (i, j) within `radius`, each measured here by the
    same arithmetic whichever search proposed it, in the cell list's order (per
    replica of a batch split by `bounds`)."""
    n = pts.shape[0]
    delta = np.take(pts, j, axis=0)  # take: 10x faster than pts[j] on (N, 2) rows
    delta -= np.take(pts, i, axis=0)
    if box is not None:
        b = np.asarray(box)
        delta -= b * np.round(delta / b)
    dist = np.einsum("ij,ij->i", delta, delta)
    np.sqrt(dist, out=dist)
    keep = dist <= radius  # the tree's distances and ours may differ in the last bit
    keep &= i != j         # the sweep's candidates include each agent itself
    if not keep.all():
        i, j, dist, delta = i[keep], j[keep], dist[keep], delta[keep]
    order = cell_order(pts, i, j, radius, box, bounds)
    i, j, dist, delta = i[order], j[order], dist[order], delta[order]
    offsets = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(i, minlength=n), out=offsets[1:])
    return PairTable(radius, offsets, j, dist, delta, i)


# The cell list's grid (the compiled search's, `compiled/cells.py`, and the order of
# every table's pairs). Cells are made this much wider than the radius, so rounding in
# `x / width` can never put two agents closer than the radius two cells apart.
_MARGIN = 1.0 + 1e-6
# At most this many cells per agent (plus a floor): a sparse world with a small radius
# gets bigger cells rather than a grid of empty ones.
_CELLS_PER_AGENT = 4
_MIN_CELLS = 64


def cell_grid(pts: np.ndarray, radius: float, box) -> tuple[float, float, int, int, float,
                                                            float]:
    """(x0, y0, nx, ny, cell width, cell height) for the agents at `pts`: `cell_grids`
    of one replica, in Python numbers (every tick of a numba run asks; a pass of numpy
    calls over one-element arrays cost it a tenth of a 100-agent tick)."""
    n = pts.shape[0]
    if box is not None:
        x0, y0 = 0.0, 0.0
        ex, ey = float(box[0]), float(box[1])
    else:
        x0, y0 = float(pts[:, 0].min()), float(pts[:, 1].min())
        ex, ey = float(pts[:, 0].max()) - x0, float(pts[:, 1].max()) - y0
    nx, ny = _cells_along_one(ex, radius), _cells_along_one(ey, radius)
    cap = max(_CELLS_PER_AGENT * n, _MIN_CELLS)
    while nx * ny > cap:   # coarser cells: fewer, each still wider than the radius
        nx, ny = max(1, nx // 2), max(1, ny // 2)
    wx = ex / nx if ex > 0 else radius
    wy = ey / ny if ey > 0 else radius
    return x0, y0, nx, ny, wx, wy


def _cells_along_one(extent: float, radius: float) -> int:
    """`_cells_along` of one extent."""
    if not extent > 0:
        return 1
    fit = extent / (radius * _MARGIN)
    return int(min(max(math.floor(fit), 1), 2**31)) if fit < 2.0**31 else 2**31


def cell_grids(pts: np.ndarray, bounds: np.ndarray, radius: float, box) -> tuple:
    """`cell_grid` of every replica `bounds[r]:bounds[r+1]` (non-empty) of a batch's
    `pts`: (x0, y0, nx, ny, wx, wy) as arrays, one value per replica, each what that
    replica's solo run would use (a world that does not wrap takes its grid from the
    agents' own spread)."""
    sizes = np.diff(bounds)
    if box is not None:
        x0 = y0 = np.zeros(sizes.size)
        ex, ey = np.full(sizes.size, float(box[0])), np.full(sizes.size, float(box[1]))
    else:
        first = bounds[:-1]
        x0 = np.minimum.reduceat(pts[:, 0], first)
        y0 = np.minimum.reduceat(pts[:, 1], first)
        ex = np.maximum.reduceat(pts[:, 0], first) - x0
        ey = np.maximum.reduceat(pts[:, 1], first) - y0
    nx, ny = _cells_along(ex, radius), _cells_along(ey, radius)
    cap = np.maximum(_CELLS_PER_AGENT * sizes, _MIN_CELLS)
    while True:   # coarser cells: fewer, each still wider than the radius
        over = nx * ny > cap
        if not over.any():
            break
        nx = np.where(over, np.maximum(1, nx // 2), nx)
        ny = np.where(over, np.maximum(1, ny // 2), ny)
    with np.errstate(divide="ignore", invalid="ignore"):
        wx = np.where(ex > 0, ex / nx, radius)
        wy = np.where(ey > 0, ey / ny, radius)
    return x0, y0, nx, ny, wx, wy


def _cells_along(extent: np.ndarray, radius: float) -> np.ndarray:
    """How many cells of width >= radius fit along each `extent` (at least one)."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        fit = np.floor(extent / (radius * _MARGIN))
    fit = np.where(extent > 0, fit, 1.0)    # (a NaN extent too)
    return np.clip(fit, 1.0, 2.0**31).astype(np.int64)   # nx * ny fits an int64


def cell_order(pts: np.ndarray, i: np.ndarray, j: np.ndarray, radius: float,
               box, bounds: np.ndarray | None = None) -> np.ndarray:
    """The order that puts pairs (i, j) within `radius` as the compiled cell list
    visits them: by owner, then each owner's neighbours cell by cell as
    `compiled.cells._ranges` walks them (three rows of cells from the one below; along a
    row, up to two runs of consecutive cells), within a cell by row. Sums add their
    terms in this order on both backends, so they round alike (DESIGN: either backend,
    the same bits). `pts` are the positions as searched (in the box for a world that
    wraps); `bounds` splits a batch's rows into replicas, each in its solo order."""
    n = pts.shape[0]
    if i.size == 0 or not positions_finite(pts):   # a fault the caller reports
        return np.argsort(i, kind="stable")
    if bounds is None:   # one run: its grid in Python numbers (numpy calls over
        bounds = np.array([0, n])   # one-element arrays cost a small run's tick more)
        x0, y0, nx, ny, wx, wy = ([g] for g in cell_grid(pts, radius, box))
    else:
        bounds = np.asarray(bounds)
        x0, y0, nx, ny, wx, wy = cell_grids(pts, bounds, radius, box)
    sizes = np.diff(bounds)
    if sizes.size > 1:   # per agent, from its replica's grid
        rep = np.repeat(np.arange(sizes.size), sizes)
        first = np.cumsum(nx * ny) - nx * ny   # a replica's cells after the last's
        cells = np.repeat(first, sizes)
        x0, y0, nx, ny, wx, wy = (g[rep] for g in (x0, y0, nx, ny, wx, wy))
    else:
        x0, y0, nx, ny, wx, wy = (g[0] for g in (x0, y0, nx, ny, wx, wy))
        cells = 0
    wrap = box is not None
    cx = np.clip(((pts[:, 0] - x0) / wx).astype(np.int64), 0, nx - 1)
    cy = np.clip(((pts[:, 1] - y0) / wy).astype(np.int64), 0, ny - 1)
    spot = np.empty(n, np.int64)      # each agent's place in the cell list's sort
    spot[np.argsort(cells + cy * nx + cx, kind="stable")] = np.arange(n)
    if sizes.size > 1:   # the owner's replica's grid
        nx, ny = np.take(nx, i), np.take(ny, i)
    cyi, cyj = np.take(cy, i), np.take(cy, j)
    row = cyj - cyi + 1
    if wrap:   # few rows: every row once, from the first; else the ring closes
        row = np.where(ny < 3, cyj, row % ny)
    key = i * 6
    key += 2 * np.clip(row, 0, 2)
    if wrap:   # the run past the world's edge, after the row's first run
        cxi, cxj = np.take(cx, i), np.take(cx, j)
        past = ((cxi == 0) & (cxj == nx - 1)) | ((cxi == nx - 1) & (cxj == 0))
        key += past & (nx >= 3)
    key *= n
    key += np.take(spot, j)
    return _argsort_unique(key, 6 * n * n)


def _argsort_unique(key: np.ndarray, bound: int) -> np.ndarray:
    """`np.argsort` of distinct keys in [0, bound): packed with their positions into
    one int64 and sorted when the bits allow, which numpy does several times faster."""
    p = key.size
    shift = max(p - 1, 1).bit_length()
    if shift + max(bound - 1, 1).bit_length() > 62:
        return np.argsort(key)
    key <<= shift
    key |= np.arange(p, dtype=np.int64)
    key.sort()
    key &= (1 << shift) - 1
    return key


def build_replica_pairs(pos: np.ndarray, bounds: np.ndarray, radius: float,
                        box) -> PairTable | None:
    """`build_pairs` of every replica `bounds[r]:bounds[r+1]` of `pos` at once, laid end
    to end in row order (a batch's table, `runtime/batch.py`): the same pairs with the
    same bits, each owner's neighbours in its solo order. Replicas of 2 to `SWEEP_MAX`
    agents only, whose sweep window is not the whole way round; None otherwise (the
    caller then searches replica by replica)."""
    sizes = np.diff(bounds)
    if radius <= 0 or sizes.min() < 2 or sizes.max() > SWEEP_MAX:
        return None
    pts = _in_box(pos, box)
    got = _sweep_replicas(pts, bounds, sizes, radius, box)
    if got is None:
        return None
    return _measured(pts, *got, radius, box, bounds)


def _sweep_replicas(pts, bounds, sizes, radius: float, box):
    """`_sweep_candidates` of every replica in one pass: agents sorted by (replica, x)
    (complex numbers sort by real part, then imaginary part), each agent's windows
    searched within its own replica's block. (i, j) in batch rows, or None when a
    window is the whole way round or a coordinate is not finite."""
    n = pts.shape[0]
    x = pts[:, 0]
    if not np.isfinite(x).all():
        return None
    rep = np.repeat(np.arange(sizes.size), sizes)
    reach = radius * (1 + 1e-9) + 8 * np.finfo(np.float64).eps * np.maximum.reduceat(
        np.abs(x), bounds[:-1])
    if box is not None and (2 * reach >= box[0] * (1 - 1e-9)).any():
        return None
    key = rep + 1j * x
    order = np.argsort(key, kind="stable")
    keys = key[order]
    r_of = reach[rep]
    start = bounds[:-1][rep]
    lo = np.zeros((n, 2), np.int64)
    hi = np.zeros((n, 2), np.int64)
    lo[:, 0] = np.searchsorted(keys, rep + 1j * (x - r_of), "left")
    hi[:, 0] = np.searchsorted(keys, rep + 1j * (x + r_of), "right")
    lo[:, 1] = hi[:, 1] = start   # no second range: empty, within the replica's block
    if box is not None:
        width = box[0]
        under, over = x - r_of < 0, x + r_of >= width
        lo[under, 1] = np.searchsorted(keys, rep[under] + 1j * (x[under] - r_of[under]
                                                                 + width), "left")
        hi[under, 1] = bounds[1:][rep[under]]
        hi[over, 1] = np.searchsorted(keys, rep[over] + 1j * (x[over] + r_of[over]
                                                               - width), "right")
    counts = (hi - lo).ravel()
    first = np.cumsum(counts) - counts
    at = np.arange(int(counts.sum())) - np.repeat(first - lo.ravel(), counts)
    return np.repeat(np.arange(n), counts.reshape(n, 2).sum(axis=1)), order[at]


def _tree_candidates(pts, radius: float, box) -> tuple[np.ndarray, np.ndarray]:
    """(i, j) of the pairs a KD-tree finds within `radius`, both ways."""
    from scipy.spatial import cKDTree  # here, not at the top: `check` never needs scipy

    # the quicker build (about a fifth at 10^4 agents): the order it reports pairs in
    # reaches no result, since `cell_order` puts them in the cell list's order
    fast = {"balanced_tree": False, "compact_nodes": False}
    tree = cKDTree(pts, boxsize=box, **fast) if box is not None else cKDTree(pts, **fast)
    half = tree.query_pairs(radius, output_type="ndarray")  # (H, 2), each pair once
    half = half.astype(np.int64, copy=False)
    return half.T.ravel(), half[:, ::-1].T.ravel()


def _sweep_candidates(pts, radius: float, box) -> tuple[np.ndarray, np.ndarray]:
    """(i, j) for every j whose x is within a hair over `radius` of i's (the short way
    round in a wrap-around world), i itself included, grouped by i: a superset of the
    pairs within `radius`, for the caller to measure. The hair covers the rounding of
    `x +- radius`, so no pair within the radius is missed."""
    n = pts.shape[0]
    x = pts[:, 0]
    reach = radius * (1 + 1e-9) + 8 * np.finfo(np.float64).eps * float(np.abs(x).max())
    if box is not None and 2 * reach >= box[0] * (1 - 1e-9):
        # the window is the whole way round (or within rounding of it): every j
        return np.repeat(np.arange(n), n), np.tile(np.arange(n), n)
    order = np.argsort(x, kind="stable")
    xs = x[order]
    lo = np.zeros((n, 2), np.int64)   # two ranges of the x order per agent
    hi = np.zeros((n, 2), np.int64)
    lo[:, 0] = np.searchsorted(xs, x - reach, "left")
    hi[:, 0] = np.searchsorted(xs, x + reach, "right")
    if box is not None:   # the part of the window past an edge, from the other edge
        width = box[0]
        under, over = x - reach < 0, x + reach >= width
        lo[under, 1] = np.searchsorted(xs, x[under] - reach + width, "left")
        hi[under, 1] = n
        hi[over, 1] = np.searchsorted(xs, x[over] + reach - width, "right")
    counts = (hi - lo).ravel()
    first = np.cumsum(counts) - counts
    at = np.arange(int(counts.sum())) - np.repeat(first - lo.ravel(), counts)
    return np.repeat(np.arange(n), counts.reshape(n, 2).sum(axis=1)), order[at]


def segment_sum(values: np.ndarray, seg: np.ndarray, m: int) -> np.ndarray:
    """Sum of `values` per segment; works for (P,) and (P, 2)."""
    if values.ndim == 2:
        return np.stack([np.bincount(seg, weights=values[:, c], minlength=m)
                         for c in range(values.shape[1])], axis=1)
    return np.bincount(seg, weights=values.astype(np.float64), minlength=m)


def segment_count(seg: np.ndarray, m: int) -> np.ndarray:
    return np.bincount(seg, minlength=m).astype(np.float64)


def segment_extreme(ufunc, values: np.ndarray, seg: np.ndarray, m: int, default) -> np.ndarray:
    """`ufunc.reduceat` per non-empty segment of a sorted `seg`; `default` elsewhere."""
    out = np.empty(m, dtype=np.float64)
    out[...] = default
    if seg.size == 0:
        return out
    starts = np.flatnonzero(np.r_[True, seg[1:] != seg[:-1]])
    out[seg[starts]] = ufunc.reduceat(values.astype(np.float64), starts)
    return out


def segment_argmin(keys: np.ndarray, seg: np.ndarray, m: int,
                   tie: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """For each non-empty segment, the row of its smallest key: (segments, rows).

    Equal keys go to the smallest `tie` (when given), else to the earliest row.
    """
    if seg.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    order = np.lexsort((keys, seg) if tie is None else (tie, keys, seg))
    sorted_seg = seg[order]
    first = np.r_[True, sorted_seg[1:] != sorted_seg[:-1]]
    return sorted_seg[first], order[first]
