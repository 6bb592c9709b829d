"""A refined grid's reading of points compiled: each point's level and bilinear corners.

`RefinedGrid.bilinear` (the numpy reference, `runtime/refined_grid.py`) finds each
point's finest level and its four corners with a few dozen whole-array operations per
level. A small swarm on a refined grid (the multi-agent environment: 60 agents, two
physical twins, a gradient) reads the grid a dozen times a tick, a few points at a
time, so those calls are the tick: about 190 us each, against a few us for one loop
here. The loop does the reference's arithmetic point by point in the same order (the
cell by truncation, the clamps, `fx - i0`, the four products), so ids and weights are
bit for bit the reference's; the clamp onto the grid and the check of the positions
stay the reference's numpy code, so errors are the same too. Diffusion (`RefinedField.step`:
a dozen sub-steps of four whole-array passes over the edges each) is one loop too, with
the reference's sums in its order (`np.bincount`'s: edge after edge). The deposit and
the sums of `sample` stay numpy.
"""

from __future__ import annotations

import math

import numpy as np

from swarmdsl.runtime.compiled.jit import njit
from swarmdsl.runtime.refined_grid import RefinedField, RefinedGrid


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _level(x, y, hs, cover, rows, cols):
    """`RefinedGrid.level_at` of the point (x, y): `hs[l]` the spacing of level l's
    cells (l = 0 .. L-1), `cover[l, :rows[l], :cols[l]]` which of them level l + 1
    refines."""
    lv = 0
    for lev in range(hs.shape[0]):
        h = hs[lev]
        fx = x / h
        fy = y / h
        ci = min(max(np.int64(fx), 0), cols[lev] - 1)
        cj = min(max(np.int64(fy), 0), rows[lev] - 1)
        lx = fx == ci and ci > 0                   # on the left edge of cell ci
        ly = fy == cj and cj > 0
        hit = cover[lev, cj, ci]
        if lx and cover[lev, cj, ci - 1]:
            hit = True
        if ly and cover[lev, cj - 1, ci]:
            hit = True
        if lx and ly and cover[lev, cj - 1, ci - 1]:
            hit = True
        if lv == lev and hit:
            lv = lev + 1
    return lv


@njit(cache=True, nogil=True, error_model="numpy")
def _levels(pos, hs, cover, rows, cols, out):
    for p in range(pos.shape[0]):
        out[p] = _level(pos[p, 0], pos[p, 1], hs, cover, rows, cols)


@njit(cache=True, nogil=True, error_model="numpy")
def _bilinear(pos, top_x, top_y, cell_h, cover, cover_rows, cover_cols, hs, index, rows,
              cols, ids, w):
    """`RefinedGrid.bilinear`'s corners and weights of the points `pos`, clamped onto
    the grid as `np.clip` clamps (-0.0 kept): `hs[k]` level k's spacing,
    `index[k, :rows[k], :cols[k]]` its node ids. False, with nothing written, when a
    position is not finite (the reference's check then says so)."""
    for p in range(pos.shape[0]):
        if not (math.isfinite(pos[p, 0]) and math.isfinite(pos[p, 1])):
            return False
    for p in range(pos.shape[0]):
        x = pos[p, 0] if pos[p, 0] >= 0.0 else 0.0
        x = x if x <= top_x else top_x
        y = pos[p, 1] if pos[p, 1] >= 0.0 else 0.0
        y = y if y <= top_y else top_y
        k = _level(x, y, cell_h, cover, cover_rows, cover_cols)
        h = hs[k]
        fx = x / h
        fy = y / h
        i0 = min(np.int64(fx), max(cols[k] - 2, 0))
        j0 = min(np.int64(fy), max(rows[k] - 2, 0))
        i1 = min(i0 + 1, cols[k] - 1)
        j1 = min(j0 + 1, rows[k] - 1)
        tx = fx - i0
        ty = fy - j0
        a = index[k, j0, i0]
        b = index[k, j0, i1]
        c = index[k, j1, i0]
        d = index[k, j1, i1]
        # A corner past a refinement's edge is no node (weight exactly 0): the first
        # corner stands in for it, as in the reference.
        ids[p, 0] = a
        ids[p, 1] = b if b >= 0 else a
        ids[p, 2] = c if c >= 0 else a
        ids[p, 3] = d if d >= 0 else a
        w[p, 0] = (1 - tx) * (1 - ty)
        w[p, 1] = tx * (1 - ty)
        w[p, 2] = (1 - tx) * ty
        w[p, 3] = tx * ty
    return True


def _stacked(arrays, fill, dtype):
    """`arrays` (2-D, of different shapes) padded with `fill` into one 3-D array, and
    their row and column counts."""
    rows = np.array([a.shape[0] for a in arrays], dtype=np.int64)
    cols = np.array([a.shape[1] for a in arrays], dtype=np.int64)
    out = np.full((len(arrays), max(rows.max(initial=1), 1), max(cols.max(initial=1), 1)),
                  fill, dtype=dtype)
    for k, a in enumerate(arrays):
        out[k, :a.shape[0], :a.shape[1]] = a
    return out, rows, cols


class CompiledRefinedGrid(RefinedGrid):
    """A `RefinedGrid` whose `level_at` and `bilinear` are the loops above."""

    def __init__(self, base, refinements):
        super().__init__(base, refinements)
        # spacings computed as the reference computes them, so the divisions match
        self._cell_h = np.array([self.spacing / 2 ** (k - 1)
                                 for k in range(1, len(self.covered) + 1)], dtype=np.float64)
        self._node_h = np.array([self.spacing / 2 ** k for k in range(len(self.index))],
                                dtype=np.float64)
        self._cover, self._cover_rows, self._cover_cols = _stacked(
            self.covered or [np.zeros((1, 1), dtype=bool)], False, np.bool_)
        self._index, self._index_rows, self._index_cols = _stacked(self.index, -1, np.int64)
        self._top_x, self._top_y = float(self.grid_x[-1]), float(self.grid_y[-1])

    def level_at(self, pos: np.ndarray) -> np.ndarray:
        pos = np.asarray(pos, dtype=np.float64)
        out = np.empty(len(pos), dtype=np.int64)
        _levels(pos, self._cell_h, self._cover, self._cover_rows, self._cover_cols, out)
        return out

    def bilinear(self, pos) -> tuple[np.ndarray, np.ndarray]:
        pos = np.asarray(pos, dtype=np.float64)
        if pos.ndim != 2 or pos.shape[1] != 2:
            self.check_positions(pos)     # raises, naming the fix
        ids = np.empty((len(pos), 4), dtype=np.int64)
        w = np.empty((len(pos), 4))
        if not _bilinear(pos, self._top_x, self._top_y, self._cell_h, self._cover,
                         self._cover_rows, self._cover_cols, self._node_h, self._index,
                         self._index_rows, self._index_cols, ids, w):
            self.check_positions(pos)     # raises: a position is not finite
        return ids, w


@njit(cache=True, nogil=True, error_model="numpy")
def _diffuse(v, a, b, rate, inv_w, substeps):
    """`RefinedField.step`'s sub-steps on flat node values `v` (every replica's), edges
    (a, b) already shifted to each replica's nodes, `inv_w` one grid's 1 / weight."""
    n = v.shape[0]
    per = inv_w.shape[0]
    gain = np.empty(n)
    loss = np.empty(n)
    for _ in range(substeps):
        gain[:] = 0.0
        loss[:] = 0.0
        for e in range(a.shape[0]):
            flow = rate * (v[b[e]] - v[a[e]])      # amount a gains from b
            gain[a[e]] += flow
            loss[b[e]] += flow
        for i in range(n):
            v[i] += (gain[i] - loss[i]) * inv_w[i % per]


class CompiledRefinedField(RefinedField):
    """A `RefinedField` whose diffusion is the loop above."""

    def step(self) -> None:
        if not self.diffuse or not self.nodes.flags.c_contiguous:
            RefinedField.step(self)   # decay alone; or a view the loop cannot write
            return
        if self.decay:
            self.nodes *= 1.0 - self.decay
        edges = self._edges
        if edges is None:
            n = self.grid.n
            a, b = self.grid.edges[:, 0], self.grid.edges[:, 1]
            if self.replicas is not None:   # each replica's edges among its own nodes
                first = (np.arange(self.replicas) * n)[:, None]
                a, b = (a + first).ravel(), (b + first).ravel()
            edges = self._edges = (np.ascontiguousarray(a, dtype=np.int64),
                                   np.ascontiguousarray(b, dtype=np.int64),
                                   1.0 / self.grid.weight)
        a, b, inv_w = edges
        _diffuse(self.nodes.reshape(-1), a, b, self.diffuse / self.substeps, inv_w,
                 self.substeps)

    _edges = None   # (a, b, 1 / weight), made on the first step
