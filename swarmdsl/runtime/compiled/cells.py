"""The compiled neighbour search: a cell list that writes the CSR pair table directly.

Agents are counting-sorted into square cells at least as wide as the table's radius, so
every neighbour of an agent lies in its own cell or one of the eight around it (in a
wrap-around world the cells tile the box exactly and the ring closes). Two passes over
the agents, one counting each owner's pairs and one writing them, produce the table
already grouped by owner: no sort. Per pair the kernels compute `delta` and `dist` with
the same operations, in the same order, as `spatial.build_pairs`, so the two searches
keep exactly the same pairs (boundary included) with the same bits; only the order of
an owner's neighbours differs.

The kernels are plain functions of arrays, cached on disk by numba (`cache=True`): the
first run on a machine compiles them once, later runs load them.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from swarmdsl.runtime.spatial import PairTable, build_pairs

# Cells are made this much wider than the radius, so rounding in `x / width` can never
# put two agents closer than the radius two cells apart.
_MARGIN = 1.0 + 1e-6
# At most this many cells per agent (plus a floor): a sparse world with a small radius
# gets bigger cells rather than a grid of empty ones.
_CELLS_PER_AGENT = 4
_MIN_CELLS = 64


def _grid(extent: float, radius: float) -> int:
    """How many cells of width >= radius fit along `extent` (at least one)."""
    if not extent > 0:
        return 1
    return max(1, int(math.floor(extent / (radius * _MARGIN))))


def cell_grid(pts: np.ndarray, radius: float, box) -> tuple[float, float, int, int, float,
                                                            float]:
    """(x0, y0, nx, ny, cell width, cell height) for the agents at `pts`."""
    n = pts.shape[0]
    if box is not None:
        x0, y0 = 0.0, 0.0
        ex, ey = float(box[0]), float(box[1])
    else:
        x0, y0 = float(pts[:, 0].min()), float(pts[:, 1].min())
        ex, ey = float(pts[:, 0].max()) - x0, float(pts[:, 1].max()) - y0
    nx, ny = _grid(ex, radius), _grid(ey, radius)
    cap = max(_CELLS_PER_AGENT * n, _MIN_CELLS)
    while nx * ny > cap:   # coarser cells: fewer, each still wider than the radius
        nx, ny = max(1, nx // 2), max(1, ny // 2)
    wx = ex / nx if ex > 0 else radius
    wy = ey / ny if ey > 0 else radius
    return x0, y0, nx, ny, wx, wy


def build_pairs_cells(pos: np.ndarray, radius: float, box) -> PairTable:
    """The tick's pair table from a compiled cell list; same pairs as `build_pairs`."""
    n = pos.shape[0]
    if n < 2 or radius <= 0 or not np.isfinite(pos).all():
        return build_pairs(pos, radius, box)  # nothing to search, or a fault to report
    if box is not None:
        pts = np.mod(pos, box)
        pts = np.where(pts >= box, 0.0, pts)   # as build_pairs: mod can return box
        bw, bh = float(box[0]), float(box[1])
    else:
        pts = np.ascontiguousarray(pos, dtype=np.float64)
        bw = bh = 0.0
    x0, y0, nx, ny, wx, wy = cell_grid(pts, radius, box)
    order, start = _sort_by_cell(pts, x0, y0, nx, ny, wx, wy)
    sp = np.take(pts, order, axis=0)   # positions in cell order
    wrap, r = box is not None, float(radius)
    counts = np.zeros(n, np.int64)
    offsets = np.zeros(n + 1, np.int64)
    none_i, none_f = np.zeros(0, np.int64), np.zeros((0, 2))
    _scan(sp, order, start, nx, ny, r, wrap, bw, bh, offsets, none_i, none_i,
          none_f[:, 0], none_f, counts, False)
    np.cumsum(counts, out=offsets[1:])
    total = int(offsets[-1])
    owner = np.empty(total, np.int64)
    j = np.empty(total, np.int64)
    dist = np.empty(total, np.float64)
    delta = np.empty((total, 2), np.float64)
    _scan(sp, order, start, nx, ny, r, wrap, bw, bh, offsets, owner, j, dist, delta,
          counts, True)
    return PairTable(float(radius), offsets, j, dist, delta, owner)


@njit(cache=True, nogil=True, error_model="numpy")
def _cell_of(x, y, x0, y0, nx, ny, wx, wy):
    cx = int((x - x0) / wx)
    cy = int((y - y0) / wy)
    cx = min(max(cx, 0), nx - 1)
    cy = min(max(cy, 0), ny - 1)
    return cx, cy


@njit(cache=True, nogil=True, error_model="numpy")
def _sort_by_cell(pts, x0, y0, nx, ny, wx, wy):
    """Counting sort of agent rows by cell: (rows in cell order, cell starts (C+1,))."""
    n = pts.shape[0]
    cell = np.empty(n, np.int64)
    start = np.zeros(nx * ny + 1, np.int64)
    for a in range(n):
        cx, cy = _cell_of(pts[a, 0], pts[a, 1], x0, y0, nx, ny, wx, wy)
        c = cy * nx + cx
        cell[a] = c
        start[c + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for a in range(n):
        c = cell[a]
        order[fill[c]] = a
        fill[c] += 1
    return order, start


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
def _pair(ax, ay, bx, by, wrap, bw, bh, far2):
    """(dx, dy, dist) from a to b, as build_pairs computes them; dist is inf (without a
    square root) when the squared distance exceeds `far2`, a hair above radius^2."""
    dx = bx - ax
    dy = by - ay
    if wrap:
        dx -= bw * np.rint(dx / bw)
        dy -= bh * np.rint(dy / bh)
    d2 = dx * dx + dy * dy
    if d2 > far2:
        return dx, dy, np.inf
    return dx, dy, np.sqrt(d2)


@njit(cache=True, nogil=True, error_model="numpy")
def _scan(sp, order, start, nx, ny, radius, wrap, bw, bh, offsets, owner, j, dist, delta,
          counts, fill):
    """Visit every owner cell by cell (neighbours sit close in memory); count each
    owner's pairs into `counts`, or, with `fill`, write them at `offsets[owner]`."""
    far2 = radius * radius * (1.0 + 1e-9)   # sqrt is exact to half an ulp: never misses
    for cy in range(ny):
        fy, ky = _rows_of(cy, ny, wrap)
        for cx in range(nx):
            lo1, hi1, lo2, hi2 = _runs(cx, nx, wrap)
            here = cy * nx + cx
            for s in range(start[here], start[here + 1]):
                a = order[s]
                ax, ay = sp[s, 0], sp[s, 1]
                got = 0
                p = offsets[a] if fill else 0
                for oy in range(ky):
                    yy = fy + oy
                    if wrap:
                        yy %= ny
                    elif yy < 0 or yy >= ny:
                        continue
                    for run in range(2):
                        lo, hi = (lo1, hi1) if run == 0 else (lo2, hi2)
                        if hi < lo:
                            continue
                        for t in range(start[yy * nx + lo], start[yy * nx + hi + 1]):
                            if t == s:
                                continue
                            dx, dy, d = _pair(ax, ay, sp[t, 0], sp[t, 1], wrap, bw, bh,
                                              far2)
                            if d <= radius:
                                if fill:
                                    owner[p] = a
                                    j[p] = order[t]
                                    dist[p] = d
                                    delta[p, 0] = dx
                                    delta[p, 1] = dy
                                    p += 1
                                else:
                                    got += 1
                if not fill:
                    counts[a] = got
