"""Refinable grids: a uniform base grid with finer nodes in declared regions, and the
fields that live on all of its nodes.

The scheme (docs/language-mas.md, "Refined grids"):

* Level 0 is the base grid (spacing ``H``). Level ``l`` has spacing ``H / 2**l`` and
  refines every level-``(l-1)`` cell that overlaps a region declared with at least ``l``
  levels and lies inside the level-``(l-1)`` refinement (so levels nest). A refined
  cell gets the 3 x 3 lattice points of its four children; a point shared with a
  coarser level is one node, not two. Every node has an id; ``positions[id]`` is where
  it sits and ``weight[id] = 4 ** -level`` the share of a base cell it stands for, its
  level being the finest lattice it lies on.
* A field's node value is a **density in base-cell units**: the amount a node holds is
  ``value * weight``, and a field's total is ``sum(value * weight)``. On the unrefined
  part this is exactly the uniform grid's convention (weight 1: value = amount).
* Sampling finds the finest level whose refinement contains the point and interpolates
  bilinearly between that level's four cell corners (all of them are nodes). Deposit
  is the exact adjoint: ``amount * w_k / weight_k`` is added to each corner's value, so
  the total grows by exactly ``amount``.
* Diffusion exchanges amount along the grid's edges: the lattice edges of every level
  whose midpoint is not itself a node (a coarse edge split by finer nodes is replaced
  by its halves). Each edge carries ``D * (c_j - c_i)`` from i to j per step (in 2-D the
  face-to-distance ratio of a square cell is 1 at every level), so whatever leaves one
  node enters another and the total is conserved up to float rounding. The explicit
  step is stable while ``D_step * degree_i / weight_i <= 1`` at every node; a tick takes
  as many equal sub-steps as that needs (a level-2 refinement with ``diffuse 0.25``
  takes 16).

Everything is whole-array numpy: a loop runs over levels (a handful), never over nodes
or agents.
"""

from __future__ import annotations

import math

import numpy as np

from swarmdsl.ops import portable
from swarmdsl.runtime.fields import Field, Grid, replica_starts
from swarmdsl.runtime.regions import Circle, Rect

MAX_LEVELS = 4


def _overlaps(shape, x0, y0, h) -> np.ndarray:
    """Which closed cells ``[x0, x0+h] x [y0, y0+h]`` overlap ``shape`` with some area."""
    if isinstance(shape, Rect):
        return ((x0 < shape.x1) & (shape.x0 < x0 + h) & (y0 < shape.y1)
                & (shape.y0 < y0 + h))
    if isinstance(shape, Circle):
        dx = np.clip(shape.cx, x0, x0 + h) - shape.cx
        dy = np.clip(shape.cy, y0, y0 + h) - shape.cy
        return portable.hypot_array(dx, dy) < shape.r
    centres = np.stack([(x0 + h / 2).ravel(), (y0 + h / 2).ravel()], axis=1)
    return (shape.distance(centres) < h * math.sqrt(0.5)).reshape(x0.shape)


def _closed_cover(cover: np.ndarray) -> np.ndarray:
    """The closed refined cells of a level, on a lattice twice as fine: ``[2j+1, 2i+1]``
    cell (i, j) itself, ``[2j+1, 2i]`` the line between cells i-1 and i of row j (on it
    if either is refined), ``[2j, 2i+1]`` the line below cell (i, j), ``[2j, 2i]`` the
    corner four cells share. So a point's level is one lookup per level, not four."""
    rows, cols = cover.shape
    closed = np.zeros((2 * rows, 2 * cols), dtype=bool)
    closed[1::2, 1::2] = cover
    left = cover.copy()
    left[:, 1:] |= cover[:, :-1]
    closed[1::2, 0::2] = left
    below = cover.copy()
    below[1:, :] |= cover[:-1, :]
    closed[0::2, 1::2] = below
    corner = left.copy()
    corner[1:, :] |= left[:-1, :]
    closed[0::2, 0::2] = corner
    return closed


class RefinedGrid:
    """A base ``Grid`` refined in regions: ``refinements`` is ``[(shape, levels), ...]``."""

    def __init__(self, base: Grid, refinements):
        if base.periodic:
            raise ValueError("a refined grid cannot wrap around")
        self.base = base
        self.spacing = base.spacing
        self.grid_x, self.grid_y = base.grid_x, base.grid_y
        self.shape = base.shape
        self.levels = min(max((lv for _, lv in refinements), default=0), MAX_LEVELS)
        ny, nx = base.shape
        self.index = [np.arange(ny * nx, dtype=np.int64).reshape(ny, nx)]  # per level
        self.covered: list[np.ndarray] = []   # per level l >= 1: refined level-(l-1) cells
        exists = [np.ones((ny, nx), dtype=bool)]
        count = ny * nx
        for lv in range(1, self.levels + 1):
            h = self.spacing / 2 ** (lv - 1)
            cy, cx = exists[-1].shape[0] - 1, exists[-1].shape[1] - 1
            y0, x0 = np.meshgrid(np.arange(cy) * h, np.arange(cx) * h, indexing="ij")
            cover = np.zeros((cy, cx), dtype=bool)
            for shape, levels in refinements:
                if levels >= lv:
                    cover |= _overlaps(shape, x0, y0, h)
            if lv > 1:   # inside the previous level's refinement only
                cover &= np.repeat(np.repeat(self.covered[-1], 2, 0), 2, 1)
            self.covered.append(cover)
            ex = np.zeros((2 * cy + 1, 2 * cx + 1), dtype=bool)
            for a in range(3):
                for b in range(3):
                    ex[a:a + 2 * cy:2, b:b + 2 * cx:2] |= cover
            idx = np.full(ex.shape, -1, dtype=np.int64)
            idx[::2, ::2] = np.where(ex[::2, ::2], self.index[-1], -1)
            new = ex & (idx < 0)
            idx[new] = count + np.arange(int(new.sum()))
            count += int(new.sum())
            self.index.append(idx)
            exists.append(ex)
        self.n = count
        self._closed = [_closed_cover(c) for c in self.covered]   # for `level_at`
        self.level = np.zeros(count, dtype=np.int64)     # the finest lattice a node is on
        self.positions = np.empty((count, 2))
        for lv, idx in enumerate(self.index):
            h = self.spacing / 2 ** lv
            j, i = np.nonzero(idx >= 0)
            self.level[idx[j, i]] = lv
            self.positions[idx[j, i]] = np.stack([i * h, j * h], axis=1)
        self.weight = 0.25 ** self.level                  # (n,) base cells per node
        self.edges = self._edges(exists)                  # (E, 2) node ids
        self._tree = None   # a scipy cKDTree over the nodes, built on first radius deposit

    def _edges(self, exists) -> np.ndarray:
        out = []
        for lv, idx in enumerate(self.index):
            ex = exists[lv]
            finer = exists[lv + 1] if lv + 1 < len(exists) else None
            horiz = ex[:, :-1] & ex[:, 1:]
            vert = ex[:-1, :] & ex[1:, :]
            if finer is not None:
                horiz &= ~finer[::2, 1::2]
                vert &= ~finer[1::2, ::2]
            j, i = np.nonzero(horiz)
            out.append(np.stack([idx[j, i], idx[j, i + 1]], axis=1))
            j, i = np.nonzero(vert)
            out.append(np.stack([idx[j, i], idx[j + 1, i]], axis=1))
        return np.concatenate(out).astype(np.int64)

    def __repr__(self) -> str:
        return f"RefinedGrid({self.base!r}, levels={self.levels})  # {self.n} nodes"

    # ---- positions -> nodes ----
    def check_positions(self, pos) -> np.ndarray:
        return self.base.check_positions(pos)

    def node_positions(self) -> np.ndarray:
        """``(n, 2)`` node positions, in node id order."""
        return self.positions

    def base_ids(self) -> np.ndarray:
        """``(ny, nx)`` node ids of the base grid's nodes (ids ``0 .. ny*nx-1``)."""
        return self.index[0]

    def level_at(self, pos: np.ndarray) -> np.ndarray:
        """``(M,)`` the finest level whose refinement contains each point.

        Refined cells are closed: a point on the boundary of a refinement belongs to it,
        so a hanging node (a fine node on a coarse cell's edge) is read at its own level.
        """
        return self._levels(pos[:, 0], pos[:, 1])

    def _levels(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """`level_at` of the points (x, y)."""
        lv = np.zeros(len(x), dtype=np.int64)
        for k, cover in enumerate(self.covered, start=1):
            h = self.spacing / 2 ** (k - 1)
            fx, fy = x / h, y / h
            ci = np.minimum(np.maximum(fx.astype(np.int64), 0), cover.shape[1] - 1)
            cj = np.minimum(np.maximum(fy.astype(np.int64), 0), cover.shape[0] - 1)
            # on the left edge of cell ci (x) or its bottom edge (y): the closed cover's
            # line between two cells, else the cell's inside (`_closed_cover`)
            ax = 2 * ci + 1 - ((fx == ci) & (ci > 0))
            ay = 2 * cj + 1 - ((fy == cj) & (cj > 0))
            hit = self._closed[k - 1][ay, ax]
            lv[(lv == k - 1) & hit] = k
        return lv

    def bilinear(self, pos) -> tuple[np.ndarray, np.ndarray]:
        """Node ids ``(M, 4)`` and bilinear weights ``(M, 4)`` (summing to 1) at ``pos``."""
        pos = self.check_positions(pos)
        x = np.clip(pos[:, 0], 0.0, self.grid_x[-1])
        y = np.clip(pos[:, 1], 0.0, self.grid_y[-1])
        lv = self._levels(x, y)
        ids = np.empty((len(pos), 4), dtype=np.int64)
        w = np.empty((len(pos), 4))
        count = np.bincount(lv, minlength=len(self.index))
        for k in np.flatnonzero(count):    # each level present, in order
            rows = slice(None) if count[k] == len(pos) else np.flatnonzero(lv == k)
            idx = self.index[k]
            h = self.spacing / 2 ** k
            fx, fy = x[rows] / h, y[rows] / h
            i0 = np.minimum(fx.astype(np.int64), max(idx.shape[1] - 2, 0))
            j0 = np.minimum(fy.astype(np.int64), max(idx.shape[0] - 2, 0))
            i1 = np.minimum(i0 + 1, idx.shape[1] - 1)
            j1 = np.minimum(j0 + 1, idx.shape[0] - 1)
            tx, ty = fx - i0, fy - j0
            got = np.stack([idx[j0, i0], idx[j0, i1], idx[j1, i0], idx[j1, i1]], 1)
            # A corner past a refinement's edge is no node; its weight is exactly 0 there
            # (the point lies on the edge), so stand the first corner in for it.
            ids[rows] = np.where(got < 0, got[:, :1], got)
            w[rows] = np.stack([(1 - tx) * (1 - ty), tx * (1 - ty), (1 - tx) * ty, tx * ty], 1)
        return ids, w

    def spacing_at(self, pos: np.ndarray) -> np.ndarray:
        """``(M,)`` the local node spacing at each point."""
        return self.spacing / 2.0 ** self.level_at(pos)

    def tree(self):
        from scipy.spatial import cKDTree   # loaded only when used: compiling stays light

        if self._tree is None:
            self._tree = cKDTree(self.positions)
        return self._tree


class RefinedField:
    """One scalar quantity on every node of a ``RefinedGrid`` (see the module's scheme).

    With ``replicas=R`` it holds R runs' nodes, ``(R, n)`` (a batch of replicas,
    `runtime/batch_fields.py`): readers and ``deposit`` take each point's replica, and
    every replica's nodes get exactly the arithmetic of a field of their own.
    """

    sample_ahead = Field.sample_ahead
    sense_cone = Field.sense_cone

    def __init__(self, name: str, grid: RefinedGrid, decay: float = 0.0,
                 diffuse: float = 0.0, replicas: int | None = None):
        probe = Field(name, grid.base, decay, diffuse)    # validates the rates
        self.name, self.grid = name, grid
        self.decay, self.diffuse = probe.decay, probe.diffuse
        self.replicas = replicas
        shape = (grid.n,) if replicas is None else (int(replicas), grid.n)
        self.nodes = np.zeros(shape)                       # ([R,] n) densities, base-cell units
        degree = np.bincount(grid.edges.ravel(), minlength=grid.n)
        worst = float((degree / grid.weight).max()) if grid.n else 0.0
        self.substeps = max(1, math.ceil(self.diffuse * worst - 1e-12))

    # ---- values ----
    @property
    def values(self) -> np.ndarray:
        """``([R,] ny, nx)`` values at the base grid's nodes (what `fields.npz` records)."""
        return self.nodes[..., self.grid.base_ids()]

    def set_nodes(self, values) -> None:
        """Every node from ``(n,)`` values in node id order (every replica's alike), or
        ``(R * n,)`` for replicas, replica-major."""
        values = np.asarray(values, dtype=np.float64)
        if values.shape not in ((self.grid.n,), (self.nodes.size,)) or \
                not np.isfinite(values).all():
            raise ValueError(f"field '{self.name}' needs {self.grid.n} finite node values")
        self.nodes[...] = values if values.shape == (self.grid.n,) else \
            values.reshape(self.nodes.shape)

    def node_values(self) -> np.ndarray:
        return self.nodes.reshape(-1)

    def total(self) -> float:
        """Amount held by the whole field: ``sum(value * weight)`` (what diffusion keeps)."""
        return float((self.nodes @ self.grid.weight).sum())

    def _offsets(self, replica, m: int) -> np.ndarray | None:
        return replica_starts(self, replica, m, self.grid.n)

    # ---- time stepping ----
    def step(self) -> None:
        if self.decay:
            self.nodes *= 1.0 - self.decay
        if not self.diffuse:
            return
        n = self.grid.n
        a, b = self.grid.edges[:, 0], self.grid.edges[:, 1]
        if self.replicas is not None:   # each replica's edges among its own nodes
            first = (np.arange(self.replicas) * n)[:, None]
            a, b, n = (a + first).ravel(), (b + first).ravel(), n * self.replicas
        rate = self.diffuse / self.substeps
        inv_w = 1.0 / self.grid.weight
        v = self.nodes.reshape(-1)
        for _ in range(self.substeps):
            flow = rate * (v[b] - v[a])                     # amount a -> gains from b
            change = np.bincount(a, flow, n) - np.bincount(b, flow, n)
            self.nodes += change.reshape(self.nodes.shape) * inv_w

    # ---- agents write ----
    def deposit(self, pos, amount, radius: float = 0.0, replica=None) -> None:
        """Add ``amount`` at each position (bilinear, or cone-spread within ``radius``)."""
        pos = self.grid.check_positions(pos)
        amount = np.broadcast_to(np.asarray(amount, dtype=np.float64), (len(pos),))
        if not np.isfinite(amount).all():
            raise ValueError("deposit amount must be finite")
        off = self._offsets(replica, len(pos))
        if len(pos) == 0:
            return
        ids, w = self.grid.bilinear(pos)
        share = w * amount[:, None]
        if radius > 0 and off is None:
            ids, share = self._disc(pos, amount, radius, ids, share)
        elif radius > 0:
            ids, share = self._replicas_disc(pos, amount, radius, ids, share, replica)
        elif off is not None:
            ids = ids + off[:, None]
        flat = ids.ravel()
        np.add.at(self.nodes.reshape(-1), flat,
                  share.ravel() / self.grid.weight[flat % self.grid.n])

    def _replicas_disc(self, pos, amount, radius, ids, share, replica):
        """`_disc` replica by replica (a loop over replicas, not agents): the order of a
        node's shares comes from a search over the replica's own points, as in its solo
        run; ids shifted to each replica's nodes."""
        replica = np.asarray(replica)
        out_ids, out_share = [], []
        for r in np.unique(replica):
            rows = np.flatnonzero(replica == r)
            got, part = self._disc(pos[rows], amount[rows], radius, ids[rows], share[rows])
            out_ids.append(got + int(r) * self.grid.n)
            out_share.append(part)
        return np.concatenate(out_ids), np.concatenate(out_share)

    def _disc(self, pos, amount, radius, ids, share):
        """Cone weights ``1 - d / radius`` times node weight, normalised per agent."""
        from scipy.spatial import cKDTree

        g = self.grid
        clamped = np.stack([np.clip(pos[:, 0], 0, g.grid_x[-1]),
                            np.clip(pos[:, 1], 0, g.grid_y[-1])], axis=1)
        near = cKDTree(clamped).sparse_distance_matrix(g.tree(), radius, output_type="coo_matrix")
        agent, node, d = near.row, near.col, near.data
        cw = np.maximum(1.0 - d / radius, 0.0) * g.weight[node]
        norm = np.bincount(agent, cw, len(pos))
        has = norm > 0
        keep = has[agent]
        disc_ids = node[keep][:, None]
        disc_share = (cw[keep] * amount[agent[keep]] / norm[agent[keep]])[:, None]
        return (np.concatenate([ids[~has].reshape(-1, 1), disc_ids]),
                np.concatenate([share[~has].reshape(-1, 1), disc_share]))

    # ---- agents read ----
    def sample(self, pos, replica=None) -> np.ndarray:
        ids, w = self.grid.bilinear(pos)
        off = self._offsets(replica, len(ids))
        if off is not None:
            ids = ids + off[:, None]
        return (self.nodes.reshape(-1)[ids] * w).sum(axis=1)

    def gradient(self, pos, replica=None) -> np.ndarray:
        """``(M, 2)`` central differences of `sample` one local spacing either side."""
        pos = self.grid.check_positions(pos)
        h = self.grid.spacing_at(pos)
        top = (self.grid.grid_x[-1], self.grid.grid_y[-1])
        out = np.empty((len(pos), 2))
        for axis in (0, 1):   # one-sided where a step would leave the grid
            hi, lo = pos.copy(), pos.copy()
            hi[:, axis] = np.minimum(pos[:, axis] + h, top[axis])
            lo[:, axis] = np.maximum(pos[:, axis] - h, 0.0)
            span = hi[:, axis] - lo[:, axis]
            diff = self.sample(hi, replica) - self.sample(lo, replica)
            out[:, axis] = np.divide(diff, span, out=np.zeros_like(diff), where=span > 0)
        return out
