"""Field operations compiled: bilinear sampling, gradients, the bilinear deposit, diffusion.

A chemotaxis tick reads a gradient and deposits once per agent and diffuses the whole
grid; on numpy each of those is a dozen whole-array passes with temporaries. Here each
is one loop. `CompiledField` is the numpy `Field` with these loops in its hot paths;
the numba backend's environment builds its fields from it. Every loop does the numpy
path's arithmetic in the same order (a bilinear sum corner by corner, `np.add.at`'s
deposits in row order, the neighbour sum left/right, then the first and second vertical
neighbour), so fields, readings and agent positions are bit for bit those of the numpy
backend. Arguments are checked by the numpy code before any kernel runs, so errors are
the same too. A deposit with a radius (the cone) is two loops around numpy's own sums of
each point's weights, so each share has the reference's bits. A refined grid's fields
have their own loops: `refined.py`.

A field of replicas (a batch's, `(R, ny, nx)`) goes through the same loops: each point
carries where its replica's grid starts in the flat values (`off`; an empty array for a
field of one run), and diffusion runs the one-grid loop on each replica's grid.

On a grid too big for the caches (a million agents on four million nodes), an agent's
reads and writes of it wait on memory. There a dense swarm's gradients difference every
node once into a buffer and interpolate from it, and deposits run on several threads,
each adding to its own band of rows: the same sums in the same order, so the same bits.
"""

from __future__ import annotations

import math

import numpy as np

from swarmdsl.runtime.compiled import threads
from swarmdsl.runtime.compiled.jit import njit, prange
from swarmdsl.runtime.compiled.refined import CompiledRefinedField, CompiledRefinedGrid
from swarmdsl.runtime.fields import Field


@njit(cache=True, nogil=True, error_model="numpy")
def _next(k, n):
    """``(k + 1) % n`` for a node index ``0 <= k < n``, without an integer division."""
    return k + 1 if k + 1 < n else 0


@njit(cache=True, nogil=True, error_model="numpy")
def _axis(coord, n, spacing, periodic):
    """`Grid._axis_cells` for one coordinate: lower node, upper node, fraction."""
    if periodic:
        period = n * spacing
        wrapped = np.fmod(coord, period)    # as np.mod: then the sign of the period
        if wrapped != 0.0:
            if wrapped < 0.0:
                wrapped += period
        else:
            wrapped = 0.0
        frac = wrapped / spacing
        lower = np.floor(frac)
        i0 = int(lower)                       # 0 .. n: `% n` without the division
        i0 = i0 - n if i0 >= n else i0
        return i0, _next(i0, n), frac - lower
    frac = coord / spacing
    frac = frac if frac > 0.0 else 0.0        # np.clip(frac, 0, n - 1)
    top = float(n - 1)
    frac = frac if frac < top else top
    i0 = min(int(frac), max(n - 2, 0))
    return i0, min(i0 + 1, n - 1), frac - i0


@njit(cache=True, nogil=True, error_model="numpy")
def _corners(x, y, nx, ny, spacing, periodic):
    """`Grid.bilinear` for one point: the four nodes' (i, j) and weights, in its order."""
    i0, i1, tx = _axis(x, nx, spacing, periodic)
    j0, j1, ty = _axis(y, ny, spacing, periodic)
    sx, sy = 1.0 - tx, 1.0 - ty
    return i0, i1, j0, j1, sx * sy, tx * sy, sx * ty, tx * ty


@njit(cache=True, nogil=True, error_model="numpy")
def _central(values, k, other, n, stride, spacing, periodic):
    """`Field._central` at one node: the difference along one axis."""
    if periodic:
        kp, km = _next(k, n), (k - 1 if k > 0 else n - 1)
        return (values[other + kp * stride] - values[other + km * stride]) / (2.0 * spacing)
    kp, km = min(k + 1, n - 1), max(k - 1, 0)
    span = max(kp - km, 1) * spacing
    return (values[other + kp * stride] - values[other + km * stride]) / span


@njit(cache=True, nogil=True, error_model="numpy")
def _node_gradient(values, i, j, nx, ny, spacing, periodic, o=0):
    """The central differences (d/dx, d/dy) at node (i, j) of the grid starting at flat
    index `o`, as `Field.gradient` has them."""
    return (_central(values, i, j * nx + o, nx, 1, spacing, periodic),
            _central(values, j, i + o, ny, nx, spacing, periodic))


@njit(cache=True, nogil=True, error_model="numpy")
def _start(off, a):
    """Where point a's grid starts in the flat values: its replica's (`off`), or 0."""
    return off[a] if off.shape[0] > 0 else 0


@njit(cache=True, nogil=True, error_model="numpy")
def sample_at(values, x, y, nx, ny, spacing, periodic, o):
    """`Field.sample` at one point (x, y) of the grid starting at flat index `o`: the
    bilinear sum corner by corner. The whole-tick kernel reads a field with it too."""
    i0, i1, j0, j1, w0, w1, w2, w3 = _corners(x, y, nx, ny, spacing, periodic)
    return (values[o + j0 * nx + i0] * w0 + values[o + j0 * nx + i1] * w1
            + values[o + j1 * nx + i0] * w2 + values[o + j1 * nx + i1] * w3)


@njit(cache=True, nogil=True, error_model="numpy")
def gradient_at(values, x, y, nx, ny, spacing, periodic, o):
    """`Field.gradient` at one point: the four corners' central differences, weighted
    as the bilinear reading weighs them."""
    i0, i1, j0, j1, w0, w1, w2, w3 = _corners(x, y, nx, ny, spacing, periodic)
    x0, y0 = _node_gradient(values, i0, j0, nx, ny, spacing, periodic, o)
    x1, y1 = _node_gradient(values, i1, j0, nx, ny, spacing, periodic, o)
    x2, y2 = _node_gradient(values, i0, j1, nx, ny, spacing, periodic, o)
    x3, y3 = _node_gradient(values, i1, j1, nx, ny, spacing, periodic, o)
    return x0 * w0 + x1 * w1 + x2 * w2 + x3 * w3, y0 * w0 + y1 * w1 + y2 * w2 + y3 * w3


@njit(cache=True, nogil=True, error_model="numpy")
def splat_at(values, x, y, m, nx, ny, spacing, periodic, o):
    """One point's bilinear deposit of `m`, corner by corner (`np.add.at`'s order)."""
    i0, i1, j0, j1, w0, w1, w2, w3 = _corners(x, y, nx, ny, spacing, periodic)
    values[o + j0 * nx + i0] += w0 * m
    values[o + j0 * nx + i1] += w1 * m
    values[o + j1 * nx + i0] += w2 * m
    values[o + j1 * nx + i1] += w3 * m


@njit(cache=True, nogil=True, error_model="numpy")
def _sample_range(a0, a1, values, pos, nx, ny, spacing, periodic, out, off):
    for a in range(a0, a1):
        out[a] = sample_at(values, pos[a, 0], pos[a, 1], nx, ny, spacing, periodic,
                           _start(off, a))


@njit(cache=True, nogil=True, error_model="numpy")
def _gradient_range(a0, a1, values, pos, nx, ny, spacing, periodic, out, off):
    for a in range(a0, a1):
        out[a, 0], out[a, 1] = gradient_at(values, pos[a, 0], pos[a, 1], nx, ny, spacing,
                                           periodic, _start(off, a))


@njit(cache=True, nogil=True, error_model="numpy")
def _sample(values, pos, nx, ny, spacing, periodic, out, chunks, off):
    _sample_range(0, pos.shape[0], values, pos, nx, ny, spacing, periodic, out, off)


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _sample_par(values, pos, nx, ny, spacing, periodic, out, chunks, off):
    """`_sample` on numba's threads: each reading is its own (threads.py)."""
    n = pos.shape[0]
    for c in prange(chunks):
        _sample_range(c * n // chunks, (c + 1) * n // chunks, values, pos, nx, ny,
                      spacing, periodic, out, off)


@njit(cache=True, nogil=True, error_model="numpy")
def _gradient(values, pos, nx, ny, spacing, periodic, out, chunks, off):
    _gradient_range(0, pos.shape[0], values, pos, nx, ny, spacing, periodic, out, off)


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _gradient_par(values, pos, nx, ny, spacing, periodic, out, chunks, off):
    """`_gradient` on numba's threads: each reading is its own (threads.py)."""
    n = pos.shape[0]
    for c in prange(chunks):
        _gradient_range(c * n // chunks, (c + 1) * n // chunks, values, pos, nx, ny,
                        spacing, periodic, out, off)


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _node_gradients(values, nx, ny, spacing, periodic, G, chunks):
    """`_node_gradient` at every node into G (nodes, 2), in bands of rows on numba's
    threads: the same values the gradient of an agent differences on the fly."""
    for c in prange(chunks):
        for j in range(c * ny // chunks, (c + 1) * ny // chunks):
            for i in range(nx):
                gx, gy = _node_gradient(values, i, j, nx, ny, spacing, periodic)
                G[j * nx + i, 0] = gx
                G[j * nx + i, 1] = gy


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _gradient_of_nodes(G, pos, nx, ny, spacing, periodic, out, chunks):
    """`_gradient_range` reading the nodes' gradients from G: the same sums in the same
    order, so the same bits, from two rows of memory per agent instead of four."""
    n = pos.shape[0]
    for c in prange(chunks):
        for a in range(c * n // chunks, (c + 1) * n // chunks):
            i0, i1, j0, j1, w0, w1, w2, w3 = _corners(pos[a, 0], pos[a, 1], nx, ny,
                                                      spacing, periodic)
            k0, k1, k2, k3 = j0 * nx + i0, j0 * nx + i1, j1 * nx + i0, j1 * nx + i1
            out[a, 0] = G[k0, 0] * w0 + G[k1, 0] * w1 + G[k2, 0] * w2 + G[k3, 0] * w3
            out[a, 1] = G[k0, 1] * w0 + G[k1, 1] * w1 + G[k2, 1] * w2 + G[k3, 1] * w3


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _splat_bands(values, pos, amount, nx, ny, spacing, periodic, off, bands):
    """`_splat` on numba's threads, each adding only to its own band of grid rows. Every
    thread reads every agent in order, so each node still gets its shares in agent
    order: the same bits as one thread. Pays on a grid too big for the caches, where
    the serial deposit waits on memory."""
    for c in prange(bands):
        lo, hi = c * ny // bands, (c + 1) * ny // bands
        for a in range(pos.shape[0]):
            i0, i1, j0, j1, w0, w1, w2, w3 = _corners(pos[a, 0], pos[a, 1], nx, ny,
                                                      spacing, periodic)
            m = amount[a]
            o = _start(off, a)
            if lo <= j0 < hi:
                values[o + j0 * nx + i0] += w0 * m
                values[o + j0 * nx + i1] += w1 * m
            if lo <= j1 < hi:
                values[o + j1 * nx + i0] += w2 * m
                values[o + j1 * nx + i1] += w3 * m


@njit(cache=True, nogil=True, error_model="numpy")
def _splat(values, pos, amount, nx, ny, spacing, periodic, off):
    """`np.add.at` of the bilinear shares, in its order: agent by agent, corner by corner.

    Serial on purpose: agents landing on one node must add in the same order.
    """
    for a in range(pos.shape[0]):
        splat_at(values, pos[a, 0], pos[a, 1], amount[a], nx, ny, spacing, periodic,
                 _start(off, a))


@njit(cache=True, nogil=True, error_model="numpy")
def _neighbour_sum(v, out, periodic):
    """`Field._neighbour_sum`: per node (left + right) + first + second vertical.

    The vertical pair is added in the numpy path's order: on an inner row the row above,
    then the row below; on the first row row 1, then the wrapped or reflected one; on the
    last row the row before it, then the wrapped or reflected one.
    """
    ny, nx = v.shape
    for j in range(ny):
        if j == 0:
            first, second = 1, (ny - 1 if periodic else 0)
        elif j == ny - 1:
            first, second = ny - 2, (0 if periodic else ny - 1)
        else:
            first, second = j - 1, j + 1
        for i in range(nx):
            if nx == 1:
                h = v[j, i] * 2.0
            elif i == 0:
                h = v[j, 1] + (v[j, nx - 1] if periodic else v[j, 0])
            elif i == nx - 1:
                h = v[j, nx - 2] + (v[j, 0] if periodic else v[j, nx - 1])
            else:
                h = v[j, i - 1] + v[j, i + 1]
            if ny == 1:
                out[j, i] = h + 2.0 * v[j, i]
            else:
                out[j, i] = h + v[first, i] + v[second, i]


@njit(cache=True, nogil=True, error_model="numpy")
def _diffuse(v, nbsum, own, around, periodic):
    """Serial: a pass over the grid is a small part of a tick, threads would not repay."""
    _neighbour_sum(v, nbsum, periodic)
    for j in range(v.shape[0]):
        for i in range(v.shape[1]):
            v[j, i] = v[j, i] * own + nbsum[j, i] * around


@njit(cache=True, nogil=True, error_model="numpy")
def _diffuse_replicas(v, nbsum, own, around, periodic):
    """`_diffuse` on each replica's grid of `v (R, ny, nx)`, each within its borders."""
    for r in range(v.shape[0]):
        _diffuse(v[r], nbsum[r], own, around, periodic)


# A grid bigger than this (bytes) does not fit in the caches: an agent's random reads
# and writes of it wait on memory, and the kernels above change how they reach it.
LARGE_GRID = 1 << 22
# With at least one agent per this many nodes, a pass over every node's gradient costs
# less than differencing four rows of nodes per agent (10^6 agents on 4 x 10^6 nodes:
# 6 + 51 ms against 87 ms; 10^5 on 4 x 10^5: the same).
NODES_PER_AGENT = 8


@njit(cache=True, nogil=True, error_model="numpy")
def _disc(pos, radius, s, nx, ny, periodic, top_x, top_y, reach, idx, w):
    """`Field._disc_weights` point by point: for each point the (L, L) nodes around it
    (row by row, L = 2 reach + 2) and their cone weights, in its order and arithmetic
    (the clamp as `np.clip`'s, -0.0 kept; nodes off a bounded grid weigh 0)."""
    side = 2 * reach + 2
    for m in range(pos.shape[0]):
        px = pos[m, 0]
        py = pos[m, 1]
        if not periodic:
            px = px if px >= 0.0 else 0.0
            px = px if px <= top_x else top_x
            py = py if py >= 0.0 else 0.0
            py = py if py <= top_y else top_y
        bi = np.int64(math.floor(px / s))
        bj = np.int64(math.floor(py / s))
        for b in range(side):
            cj = bj - reach + b
            dy = cj * s - py
            for a in range(side):
                ci = bi - reach + a
                dx = ci * s - px
                dist = math.sqrt(dx * dx + dy * dy)
                v = 1.0 - dist / radius
                v = v if v >= 0.0 else 0.0
                i, j = ci, cj
                if periodic:
                    i, j = ci % nx, cj % ny
                else:
                    if ci < 0 or ci >= nx or cj < 0 or cj >= ny:
                        v = 0.0
                    i = min(max(ci, 0), nx - 1)
                    j = min(max(cj, 0), ny - 1)
                idx[m, b * side + a] = j * nx + i
                w[m, b * side + a] = v


@njit(cache=True, nogil=True, error_model="numpy")
def _spread_adds(flat, idx, w, norm, amount, corners, cw):
    """`Field._spread`'s `np.add.at`s in their order: every cone share of the points
    with some weight, point by point, then the bilinear shares of the others
    (`corners`, `cw`: theirs, in point order)."""
    for m in range(idx.shape[0]):
        if norm[m] > 0:
            scale = amount[m] / norm[m]
            for k in range(idx.shape[1]):
                flat[idx[m, k]] += w[m, k] * scale
    r = 0
    for m in range(idx.shape[0]):
        if not norm[m] > 0:
            for c in range(4):
                flat[corners[r, c]] += cw[r, c] * amount[m]
            r += 1


def _large(flat: np.ndarray) -> bool:
    return flat.nbytes > LARGE_GRID


_ONE_RUN = np.zeros(0, np.int64)   # `off` of a field of one run: every grid starts at 0


class CompiledField(Field):
    """A `Field` whose sampling, gradient, bilinear deposit and diffusion are compiled.
    A refined grid's fields and the grid itself are `refined`'s classes: the grid's
    reading of points and the fields' diffusion compiled (`compiled/refined.py`)."""

    refined = (CompiledRefinedGrid, CompiledRefinedField)

    def _starts(self, replica, m: int) -> np.ndarray:
        off = self._offsets(replica, m)
        return _ONE_RUN if off is None else np.ascontiguousarray(off, dtype=np.int64)

    def sample(self, pos, replica=None) -> np.ndarray:
        pos = np.ascontiguousarray(self.grid.check_positions(pos))
        off = self._starts(replica, len(pos))
        out = np.empty(len(pos))
        chunks = threads.chunks(len(pos))
        (_sample_par if chunks > 1 else _sample)(
            self._values.reshape(-1), pos, self.grid.nx, self.grid.ny, self.grid.spacing,
            self.grid.periodic, out, chunks, off)
        return out

    def gradient(self, pos, replica=None) -> np.ndarray:
        pos = np.ascontiguousarray(self.grid.check_positions(pos))
        off = self._starts(replica, len(pos))
        out = np.empty((len(pos), 2))
        chunks = threads.chunks(len(pos))
        g, flat = self.grid, self._values.reshape(-1)
        if off.size == 0 and _large(flat) and len(pos) * NODES_PER_AGENT >= flat.size:
            G = self.__dict__.get("_node_buf")
            if G is None or G.shape[0] != flat.size:
                G = self._node_buf = np.empty((flat.size, 2))
            _node_gradients(flat, g.nx, g.ny, g.spacing, g.periodic, G, chunks)
            _gradient_of_nodes(G, pos, g.nx, g.ny, g.spacing, g.periodic, out, chunks)
            return out
        (_gradient_par if chunks > 1 else _gradient)(
            flat, pos, g.nx, g.ny, g.spacing, g.periodic, out, chunks, off)
        return out

    def _splat(self, pos: np.ndarray, amount: np.ndarray, off=None) -> None:
        g, flat = self.grid, self._values.reshape(-1)
        off = _ONE_RUN if off is None else np.ascontiguousarray(off, dtype=np.int64)
        args = (flat, np.ascontiguousarray(pos), np.ascontiguousarray(amount), g.nx, g.ny,
                g.spacing, g.periodic, off)
        if _large(flat) and threads.chunks(len(pos)) > 1 and g.ny > 1:
            _splat_bands(*args, min(threads.count(), g.ny))
        else:
            _splat(*args)

    def _spread(self, pos, amount, radius: float, off) -> None:
        """`Field._spread` of one run's field: the cone weights and the adds compiled,
        the weights' sums per agent numpy's own (so each share has the reference's
        bits); a batch's replicas take the reference."""
        if off is not None:
            Field._spread(self, pos, amount, radius, off)
            return
        g = self.grid
        reach = math.ceil(radius / g.spacing)
        side = 2 * reach + 2
        idx = np.empty((len(pos), side * side), dtype=np.int64)
        w = np.empty((len(pos), side * side))
        _disc(pos, radius, g.spacing, g.nx, g.ny, g.periodic, float(g.grid_x[-1]),
              float(g.grid_y[-1]), reach, idx, w)
        norm = w.sum(axis=1)
        rest = ~(norm > 0)
        corners, cw = (g.bilinear(pos[rest]) if rest.any()
                       else (np.zeros((0, 4), np.int64), np.zeros((0, 4))))
        _spread_adds(self._values.reshape(-1), idx, w, norm, amount,
                     np.ascontiguousarray(corners, dtype=np.int64), np.ascontiguousarray(cw))

    def _diffuse(self, own: float, around: float) -> None:
        if self._values.ndim == 3:   # replicas: each grid on its own
            _diffuse_replicas(self._values, self._buf, own, around, self.grid.periodic)
        else:
            _diffuse(self._values, self._buf, own, around, self.grid.periodic)
