"""Field operations compiled: bilinear sampling, gradients, the bilinear deposit, diffusion.

A chemotaxis tick reads a gradient and deposits once per agent and diffuses the whole
grid; on numpy each of those is a dozen whole-array passes with temporaries. Here each
is one loop. `CompiledField` is the numpy `Field` with these loops in its hot paths;
the numba backend's environment builds its fields from it. Every loop does the numpy
path's arithmetic in the same order (a bilinear sum corner by corner, `np.add.at`'s
deposits in row order, the neighbour sum left/right, then the first and second vertical
neighbour), so fields, readings and agent positions are bit for bit those of the numpy
backend. Arguments are checked by the numpy code before any kernel runs, so errors are
the same too. A deposit with a radius and refined grids stay on numpy.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from swarmdsl.runtime.compiled import threads
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
def _node_gradient(values, i, j, nx, ny, spacing, periodic):
    """The central differences (d/dx, d/dy) at node (i, j), as `Field.gradient` has them."""
    return (_central(values, i, j * nx, nx, 1, spacing, periodic),
            _central(values, j, i, ny, nx, spacing, periodic))


@njit(cache=True, nogil=True, error_model="numpy")
def _sample_range(a0, a1, values, pos, nx, ny, spacing, periodic, out):
    for a in range(a0, a1):
        i0, i1, j0, j1, w0, w1, w2, w3 = _corners(pos[a, 0], pos[a, 1], nx, ny, spacing,
                                                  periodic)
        out[a] = (values[j0 * nx + i0] * w0 + values[j0 * nx + i1] * w1
                  + values[j1 * nx + i0] * w2 + values[j1 * nx + i1] * w3)


@njit(cache=True, nogil=True, error_model="numpy")
def _gradient_range(a0, a1, values, pos, nx, ny, spacing, periodic, out):
    for a in range(a0, a1):
        i0, i1, j0, j1, w0, w1, w2, w3 = _corners(pos[a, 0], pos[a, 1], nx, ny, spacing,
                                                  periodic)
        x0, y0 = _node_gradient(values, i0, j0, nx, ny, spacing, periodic)
        x1, y1 = _node_gradient(values, i1, j0, nx, ny, spacing, periodic)
        x2, y2 = _node_gradient(values, i0, j1, nx, ny, spacing, periodic)
        x3, y3 = _node_gradient(values, i1, j1, nx, ny, spacing, periodic)
        out[a, 0] = x0 * w0 + x1 * w1 + x2 * w2 + x3 * w3
        out[a, 1] = y0 * w0 + y1 * w1 + y2 * w2 + y3 * w3


@njit(cache=True, nogil=True, error_model="numpy")
def _sample(values, pos, nx, ny, spacing, periodic, out, chunks):
    _sample_range(0, pos.shape[0], values, pos, nx, ny, spacing, periodic, out)


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _sample_par(values, pos, nx, ny, spacing, periodic, out, chunks):
    """`_sample` on numba's threads: each reading is its own (threads.py)."""
    n = pos.shape[0]
    for c in prange(chunks):
        _sample_range(c * n // chunks, (c + 1) * n // chunks, values, pos, nx, ny,
                      spacing, periodic, out)


@njit(cache=True, nogil=True, error_model="numpy")
def _gradient(values, pos, nx, ny, spacing, periodic, out, chunks):
    _gradient_range(0, pos.shape[0], values, pos, nx, ny, spacing, periodic, out)


@njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _gradient_par(values, pos, nx, ny, spacing, periodic, out, chunks):
    """`_gradient` on numba's threads: each reading is its own (threads.py)."""
    n = pos.shape[0]
    for c in prange(chunks):
        _gradient_range(c * n // chunks, (c + 1) * n // chunks, values, pos, nx, ny,
                        spacing, periodic, out)


@njit(cache=True, nogil=True, error_model="numpy")
def _splat(values, pos, amount, nx, ny, spacing, periodic):
    """`np.add.at` of the bilinear shares, in its order: agent by agent, corner by corner.

    Serial on purpose: agents landing on one node must add in the same order.
    """
    for a in range(pos.shape[0]):
        i0, i1, j0, j1, w0, w1, w2, w3 = _corners(pos[a, 0], pos[a, 1], nx, ny, spacing,
                                                  periodic)
        m = amount[a]
        values[j0 * nx + i0] += w0 * m
        values[j0 * nx + i1] += w1 * m
        values[j1 * nx + i0] += w2 * m
        values[j1 * nx + i1] += w3 * m


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


class CompiledField(Field):
    """A `Field` whose sampling, gradient, bilinear deposit and diffusion are compiled."""

    def sample(self, pos) -> np.ndarray:
        pos = np.ascontiguousarray(self.grid.check_positions(pos))
        out = np.empty(len(pos))
        chunks = threads.chunks(len(pos))
        (_sample_par if chunks > 1 else _sample)(
            self._values.reshape(-1), pos, self.grid.nx, self.grid.ny, self.grid.spacing,
            self.grid.periodic, out, chunks)
        return out

    def gradient(self, pos) -> np.ndarray:
        pos = np.ascontiguousarray(self.grid.check_positions(pos))
        out = np.empty((len(pos), 2))
        chunks = threads.chunks(len(pos))
        (_gradient_par if chunks > 1 else _gradient)(
            self._values.reshape(-1), pos, self.grid.nx, self.grid.ny, self.grid.spacing,
            self.grid.periodic, out, chunks)
        return out

    def _splat(self, pos: np.ndarray, amount: np.ndarray) -> None:
        _splat(self._values.reshape(-1), np.ascontiguousarray(pos),
               np.ascontiguousarray(amount), self.grid.nx, self.grid.ny, self.grid.spacing,
               self.grid.periodic)

    def _diffuse(self, own: float, around: float) -> None:
        _diffuse(self._values, self._buf, own, around, self.grid.periodic)
