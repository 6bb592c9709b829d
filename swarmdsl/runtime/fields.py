"""Grids of nodes and the scalar fields on them: decay, diffusion, deposit and sampling.

Conventions (every kernel here follows them, and the language documents them):

* Nodes sit at ``x = i * spacing``, ``y = j * spacing``; arrays are ``(ny, nx)`` so that
  ``values[j, i]`` is the node at ``(grid_x[i], grid_y[j])`` (row = y, as the recorder's
  ``fields.npz`` stores them).
* A node's value is the **amount held by that node**, not a density: ``values.sum()`` is
  the total in the field, a deposit of ``a`` adds exactly ``a`` to that sum, and a deposit
  of ``a`` exactly on a node reads back ``a`` there. (Divide by ``spacing ** 2`` for a
  density.) Amounts being per node keeps thresholds such as "pheromone above 0.1"
  independent of the grid spacing's units.
* Rates are per tick and dimensionless: ``decay`` is the fraction lost per tick,
  ``diffuse`` the fraction of a node's difference to each neighbour that flows per tick.
* Off-grid positions are clamped onto the grid (bounded worlds) or wrapped (periodic).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from swarmdsl.ops import portable

#: The largest stable rate of the explicit 5-point scheme on a 2-D grid: ``1 / (2 * 2)``.
MAX_STABLE_DIFFUSION = 0.25


def stable_diffusion_limit(ndim: int = 2) -> float:
    """Largest ``D`` for which ``v += D * laplacian(v)`` stays stable and non-negative.

    The explicit scheme keeps ``1 - 2 * ndim * D`` of a node's own value; above
    ``1 / (2 * ndim)`` that weight turns negative and checkerboard noise grows each tick.
    """
    return 1.0 / (2 * ndim)


def _check_finite_number(name: str, value: float) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(number):
        raise ValueError(f"{name} must be finite, got {number}")
    return number


class Grid:
    """Uniform nodes over a ``width x height`` world with the origin at (0, 0).

    Bounded grids (the default) have ``nx = floor(width / spacing) + 1`` nodes per row,
    the first at 0 and the last at or just before ``width``. A periodic grid wraps
    around, so the node that would sit at ``x = width`` *is* the node at 0: it has
    ``nx = width / spacing`` distinct nodes (``width`` must be a multiple of ``spacing``)
    and the period is exactly the world's size.
    """

    def __init__(self, width: float, height: float, spacing: float, periodic: bool = False):
        self.width = _check_finite_number("grid width", width)
        self.height = _check_finite_number("grid height", height)
        self.spacing = _check_finite_number("grid spacing", spacing)
        if self.spacing <= 0:
            raise ValueError(f"grid spacing must be positive, got {self.spacing:g}")
        if self.width < 0 or self.height < 0:
            raise ValueError(
                f"world size must not be negative, got {self.width:g} x {self.height:g}"
            )
        self.periodic = bool(periodic)
        self.nx = self._count("width", self.width)
        self.ny = self._count("height", self.height)
        self.grid_x = np.arange(self.nx, dtype=np.float64) * self.spacing  # (nx,)
        self.grid_y = np.arange(self.ny, dtype=np.float64) * self.spacing  # (ny,)

    def _count(self, what: str, extent: float) -> int:
        cells = extent / self.spacing
        # Tolerate 0.3 / 0.1 == 2.9999999999999996: a world edge that lands on a node
        # should get its node.
        near = round(cells)
        if abs(cells - near) <= 1e-9 * max(1.0, cells):
            cells = float(near)
        if not self.periodic:
            return math.floor(cells) + 1
        if cells < 1 or cells != near:
            raise ValueError(
                f"a periodic grid needs the world {what} ({extent:g}) to be a whole "
                f"multiple of the grid spacing ({self.spacing:g})"
            )
        return int(near)

    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nx)``: the shape of every field on this grid."""
        return (self.ny, self.nx)

    def nodes(self) -> tuple[np.ndarray, np.ndarray]:
        """Node coordinates as two ``(ny, nx)`` arrays ``(x, y)``, for formulas and masks."""
        return np.meshgrid(self.grid_x, self.grid_y)

    def node_positions(self) -> np.ndarray:
        """``(ny * nx, 2)`` node positions in the order of ``values.ravel()``."""
        x, y = self.nodes()
        return np.stack([x.ravel(), y.ravel()], axis=1)

    def __repr__(self) -> str:
        kind = ", periodic=True" if self.periodic else ""
        return (
            f"Grid({self.width:g}, {self.height:g}, {self.spacing:g}{kind})"
            f"  # {self.ny} x {self.nx} nodes"
        )

    # -- positions -> nodes ---------------------------------------------------------

    def check_positions(self, pos) -> np.ndarray:
        """Return ``pos`` as a float64 ``(M, 2)`` array, or raise naming the fix."""
        pos = np.asarray(pos, dtype=np.float64)
        if pos.ndim != 2 or pos.shape[1] != 2:
            raise ValueError(f"positions must have shape (M, 2), got {pos.shape}")
        if not np.isfinite(pos).all():
            raise ValueError("positions must be finite (got NaN or infinity)")
        return pos

    def _axis_cells(self, coord: np.ndarray, n: int) -> tuple[np.ndarray, ...]:
        """Lower node, upper node and fraction toward the upper one along one axis.

        Bounded: clamp onto [0, (n-1) * spacing]; periodic: wrap by ``n * spacing``.
        """
        if self.periodic:
            frac_pos = np.mod(coord, n * self.spacing) / self.spacing  # in [0, n]
            lower = np.floor(frac_pos)
            t = frac_pos - lower
            i0 = lower.astype(np.intp) % n
            i1 = (i0 + 1) % n
        else:
            frac_pos = np.clip(coord / self.spacing, 0.0, n - 1)
            i0 = np.minimum(frac_pos.astype(np.intp), max(n - 2, 0))
            t = frac_pos - i0
            i1 = np.minimum(i0 + 1, n - 1)
        return i0, i1, t

    def bilinear(self, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Flat node indices ``(M, 4)`` and bilinear weights ``(M, 4)`` summing to 1.

        One helper for deposit, sample and gradient so that a deposit and a later sample
        at the same point use exactly the same four nodes and weights.
        """
        pos = self.check_positions(pos)
        i0, i1, tx = self._axis_cells(pos[:, 0], self.nx)
        j0, j1, ty = self._axis_cells(pos[:, 1], self.ny)
        idx = np.stack(
            [j0 * self.nx + i0, j0 * self.nx + i1, j1 * self.nx + i0, j1 * self.nx + i1],
            axis=1,
        )  # (M, 4) flat indices into values.ravel()
        sx, sy = 1.0 - tx, 1.0 - ty
        w = np.stack([sx * sy, tx * sy, sx * ty, tx * ty], axis=1)  # (M, 4)
        return idx, w


def replica_starts(field, replica, m: int, size: int) -> np.ndarray | None:
    """``(M,)`` where each of ``m`` points' replica's nodes start in the flat values of
    a field of replicas (``size`` nodes a replica), or None for a field of one run."""
    if field.replicas is None:
        if replica is not None:
            raise ValueError(f"field '{field.name}' holds one run: no replica")
        return None
    replica = np.asarray(replica, dtype=np.intp)
    if replica.shape != (m,):
        raise ValueError(f"field '{field.name}' needs the replica of each of the {m} "
                         f"points, got shape {replica.shape}")
    return replica * size


class Field:
    """One scalar quantity on a grid (pheromone, attractant, temperature ...).

    ``values`` is ``(ny, nx) float64`` and owned by the field. ``step()`` applies decay
    then diffusion once; the language calls it once per tick after agents have
    deposited.

    With ``replicas=R`` the field is R runs' grids at once (a batch of replicas,
    `runtime/batch_fields.py`): ``values`` is ``(R, ny, nx)``, each reader and
    ``deposit`` takes ``replica``, the replica of each point, and every grid is worked
    on with exactly the arithmetic of a field of its own: nothing crosses from one
    replica's grid to another's (diffusion stops at each grid's own border).
    """

    def __init__(
        self,
        name: str,
        grid: Grid,
        decay: float = 0.0,
        diffuse: float = 0.0,
        init: float | np.ndarray | None = None,
        replicas: int | None = None,
    ):
        self.name = name
        self.grid = grid
        self.replicas = replicas
        shape = grid.shape if replicas is None else (int(replicas), *grid.shape)
        self.decay = _check_finite_number(f"decay rate of field '{name}'", decay)
        if not 0.0 <= self.decay <= 1.0:
            raise ValueError(
                f"decay rate {self.decay:g} of field '{name}' must be between 0 and 1 "
                "(the fraction lost per tick)"
            )
        self.diffuse = _check_finite_number(f"diffusion rate of field '{name}'", diffuse)
        if self.diffuse < 0:
            raise ValueError(f"diffusion rate {self.diffuse:g} must not be negative")
        if self.diffuse > MAX_STABLE_DIFFUSION:
            raise ValueError(
                f"diffusion rate {self.diffuse:g} is unstable on a 2-D grid: "
                f"it must be at most {MAX_STABLE_DIFFUSION:g}"
            )
        self._values = np.zeros(shape, dtype=np.float64)  # ([R,] ny, nx)
        self._buf = np.empty(shape, dtype=np.float64)  # ([R,] ny, nx) step scratch
        if init is not None:
            self.values = init

    @property
    def values(self) -> np.ndarray:
        """``(ny, nx) float64`` node amounts (``(R, ny, nx)`` for replicas); assign a
        scalar or an array to reset them (a ``(ny, nx)`` one resets every replica)."""
        return self._values

    @values.setter
    def values(self, new) -> None:
        new = np.asarray(new, dtype=np.float64)
        if new.ndim != 0 and new.shape not in (self.grid.shape, self._values.shape):
            raise ValueError(
                f"field '{self.name}' values must have shape {self._values.shape} "
                f"({'R, ' if self.replicas is not None else ''}ny, nx), got {new.shape}"
            )
        if not np.isfinite(new).all():
            raise ValueError(f"field '{self.name}' values must be finite")
        self._values[...] = new

    def total(self) -> float:
        """Amount held by the whole field (what diffusion conserves)."""
        return float(self._values.sum())

    def set_nodes(self, values: np.ndarray) -> None:
        """Set every node from ``(ny * nx,)`` values in ``grid.node_positions()`` order
        (every replica's grid alike), or ``([R *] ny * nx,)`` values."""
        values = np.asarray(values, dtype=np.float64)
        shape = self.grid.shape if values.size == self.grid.nx * self.grid.ny \
            else self._values.shape
        self.values = values.reshape(shape)

    def node_values(self) -> np.ndarray:
        """``(ny * nx,)`` node values in ``grid.node_positions()`` order (a view;
        ``(R * ny * nx,)`` for replicas, replica-major)."""
        return self._values.reshape(-1)

    # -- time stepping ----------------------------------------------------------------

    def step(self) -> None:
        """Decay then diffuse once, in place, in a handful of whole-grid numpy passes.

        Diffusion is ``v += D * laplacian(v)`` with the 5-point Laplacian. Bounded grids
        reflect (a missing neighbour is replaced by the node itself, i.e. no flux leaves
        the grid), so every pairwise exchange is counted once each way and the total is
        conserved exactly up to float rounding. Periodic grids wrap around.
        Because the neighbour sum is linear, decay folds into the two scale factors:
        ``v <- (1-r) * ((1 - 4D) v + D * neighbour_sum(v))``.
        """
        keep = 1.0 - self.decay
        if self.diffuse == 0.0:
            if self.decay != 0.0:
                self._values *= keep
            return
        self._diffuse(keep * (1.0 - 4.0 * self.diffuse), keep * self.diffuse)

    def _diffuse(self, own: float, around: float) -> None:
        """``v <- own * v + around * neighbour_sum(v)``, in place (``_buf`` is scratch)."""
        v, nbsum = self._values, self._buf
        self._neighbour_sum(v, nbsum)
        v *= own
        nbsum *= around
        v += nbsum

    def _neighbour_sum(self, v: np.ndarray, out: np.ndarray) -> None:
        """``out[j, i]`` = sum of the four neighbours of node (j, i), boundary-filled.

        Written with slices into ``out`` (no padded copy): about three array passes.
        """
        periodic = self.grid.periodic
        ny, nx = v.shape[-2:]   # replicas' grids stacked ahead: each its own borders
        if nx == 1:
            np.multiply(v, 2.0, out=out)
        else:
            np.add(v[..., :-2], v[..., 2:], out=out[..., 1:-1])
            np.add(v[..., 1], v[..., -1] if periodic else v[..., 0], out=out[..., 0])
            np.add(v[..., -2], v[..., 0] if periodic else v[..., -1], out=out[..., -1])
        if ny == 1:
            out += 2.0 * v
        else:
            out[..., 1:-1, :] += v[..., :-2, :]
            out[..., 1:-1, :] += v[..., 2:, :]
            out[..., 0, :] += v[..., 1, :]
            out[..., 0, :] += v[..., -1, :] if periodic else v[..., 0, :]
            out[..., -1, :] += v[..., -2, :]
            out[..., -1, :] += v[..., 0, :] if periodic else v[..., -1, :]

    # -- agents write -----------------------------------------------------------------

    def deposit(self, pos, amount, radius: float = 0.0, replica=None) -> None:
        """Add ``amount`` (scalar or ``(M,)``) at each position ``(M, 2)`` (of replica
        ``replica (M,)`` for a field of replicas).

        ``radius == 0``: bilinear splat onto the 4 surrounding nodes, the exact adjoint of
        ``sample`` (so the field total grows by exactly ``sum(amount)``).
        ``radius > 0``: spread over the nodes closer than ``radius`` with cone weights
        ``1 - d / radius``, normalised per agent so the total is again ``amount``; nodes
        off a bounded grid are dropped before normalising. An agent with no node that
        close (radius below the node spacing) falls back to the bilinear splat.
        Several agents hitting one node accumulate (``np.add.at``), never overwrite, in
        the order of the points (so a replica's points, in its solo order, add as its
        solo run adds them).
        """
        pos = self.grid.check_positions(pos)
        amount = self._check_amount(amount, len(pos))
        radius = _check_finite_number("deposit radius", radius)
        if radius < 0:
            raise ValueError(f"deposit radius must not be negative, got {radius:g}")
        if len(pos) == 0:
            return
        off = self._offsets(replica, len(pos))
        if radius == 0.0:
            self._splat(pos, amount, off)
            return
        self._spread(pos, amount, radius, off)

    def _spread(self, pos: np.ndarray, amount: np.ndarray, radius: float, off) -> None:
        """The deposit of checked ``amount (M,)`` at checked ``pos (M, 2)`` within
        ``radius > 0`` (``off``: as `_splat`'s)."""
        flat = self._values.reshape(-1)  # view: values is C-contiguous
        idx, w = self.grid.bilinear(pos)  # (M, 4), (M, 4)
        disc_idx, disc_w = self._disc_weights(pos, radius)  # (M, K), (M, K)
        if off is not None:
            idx, disc_idx = idx + off[:, None], disc_idx + off[:, None]
        norm = disc_w.sum(axis=1)  # (M,)
        has_disc = norm > 0
        if has_disc.any():
            share = disc_w[has_disc] * (amount[has_disc] / norm[has_disc])[:, None]
            np.add.at(flat, disc_idx[has_disc].ravel(), share.ravel())
        if not has_disc.all():
            rest = ~has_disc
            np.add.at(flat, idx[rest].ravel(), (w[rest] * amount[rest, None]).ravel())

    def _offsets(self, replica, m: int) -> np.ndarray | None:
        return replica_starts(self, replica, m, self.grid.nx * self.grid.ny)

    def _splat(self, pos: np.ndarray, amount: np.ndarray, off=None) -> None:
        """Bilinear deposit of checked ``amount (M,)`` at checked ``pos (M, 2)``
        (``off``: each point's replica's first flat index, or None)."""
        idx, w = self.grid.bilinear(pos)  # (M, 4), (M, 4)
        if off is not None:
            idx = idx + off[:, None]
        np.add.at(self._values.reshape(-1), idx.ravel(), (w * amount[:, None]).ravel())

    def _check_amount(self, amount, m: int) -> np.ndarray:
        amount = np.asarray(amount, dtype=np.float64)
        if amount.ndim == 0:
            amount = np.full(m, float(amount))
        elif amount.shape != (m,):
            raise ValueError(
                f"deposit amount must be a number or have shape ({m},), got {amount.shape}"
            )
        if not np.isfinite(amount).all():
            raise ValueError("deposit amount must be finite")
        return amount

    def _disc_weights(self, pos: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
        """Candidate nodes ``(M, K)`` around each position and their cone weights."""
        g = self.grid
        s = g.spacing
        if not g.periodic:  # clamp like bilinear so off-grid deposits stay on the grid
            pos = np.stack(
                [np.clip(pos[:, 0], 0, g.grid_x[-1]), np.clip(pos[:, 1], 0, g.grid_y[-1])],
                axis=1,
            )
        reach = math.ceil(radius / s)
        offsets = np.arange(-reach, reach + 2)  # (L,) covers floor(p/s) +- radius/s
        base_i = np.floor(pos[:, 0] / s).astype(np.intp)  # (M,)
        base_j = np.floor(pos[:, 1] / s).astype(np.intp)
        ci = base_i[:, None, None] + offsets[None, None, :]  # (M, 1, L)
        cj = base_j[:, None, None] + offsets[None, :, None]  # (M, L, 1)
        dx = ci * s - pos[:, 0, None, None]  # (M, 1, L) unwrapped offsets
        dy = cj * s - pos[:, 1, None, None]  # (M, L, 1)
        dist = np.sqrt(dx * dx + dy * dy)  # (M, L, L)
        w = np.maximum(1.0 - dist / radius, 0.0)
        if g.periodic:
            ci, cj = ci % g.nx, cj % g.ny
        else:
            off = (ci < 0) | (ci >= g.nx) | (cj < 0) | (cj >= g.ny)
            w = np.where(off, 0.0, w)
            ci, cj = np.clip(ci, 0, g.nx - 1), np.clip(cj, 0, g.ny - 1)
        flat = np.broadcast_to(cj * g.nx + ci, w.shape)
        m = len(pos)
        return flat.reshape(m, -1), w.reshape(m, -1)

    def set_from_formula(self, fn: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> None:
        """Overwrite the field with ``fn(x (ny, nx), y (ny, nx))`` at the nodes.

        The caller builds ``fn`` (e.g. a compiled physical-twin expression with the tick's
        time bound in); nothing here evaluates text. Any result that broadcasts to
        ``(ny, nx)`` is accepted, so a constant formula may return a scalar.
        """
        x, y = self.grid.nodes()
        result = np.asarray(fn(x, y), dtype=np.float64)
        try:
            result = np.broadcast_to(result, self.grid.shape)
        except ValueError:
            raise ValueError(
                f"formula for field '{self.name}' returned shape {result.shape}, "
                f"expected {self.grid.shape} (ny, nx)"
            ) from None
        self.values = result

    # -- agents read ------------------------------------------------------------------

    def sample(self, pos, replica=None) -> np.ndarray:
        """Bilinear interpolation of the field at ``pos (M, 2)`` -> ``(M,)`` (each point
        on its replica's grid, ``replica (M,)``, for a field of replicas)."""
        idx, w = self.grid.bilinear(pos)
        off = self._offsets(replica, len(idx))
        if off is not None:
            idx = idx + off[:, None]
        return (self._values.reshape(-1)[idx] * w).sum(axis=1)

    def gradient(self, pos, replica=None) -> np.ndarray:
        """Spatial gradient ``(M, 2)`` (d/dx, d/dy per world unit) at ``pos (M, 2)``.

        Central differences at the four surrounding nodes (one-sided on a bounded grid's
        edge nodes, wrapped on a periodic grid), then bilinear interpolation. Only the
        nodes agents touch are differenced, so the cost is O(M), not O(grid).
        """
        g = self.grid
        idx, w = g.bilinear(pos)  # (M, 4)
        i, j = idx % g.nx, idx // g.nx
        flat = self._values.reshape(-1)
        off = self._offsets(replica, len(idx))
        base = 0 if off is None else off[:, None]   # the replica's grid in `flat`
        gx = self._central(flat, i, j * g.nx + base, g.nx, 1)
        gy = self._central(flat, j, i + base, g.ny, g.nx)
        return np.stack([(gx * w).sum(axis=1), (gy * w).sum(axis=1)], axis=1)

    def _central(self, flat, k, other, n, stride) -> np.ndarray:
        """Difference along one axis at node index ``k`` (the other axis' offset fixed)."""
        s = self.grid.spacing
        if self.grid.periodic:
            kp, km = (k + 1) % n, (k - 1) % n
            return (flat[other + kp * stride] - flat[other + km * stride]) / (2.0 * s)
        kp, km = np.minimum(k + 1, n - 1), np.maximum(k - 1, 0)
        span = np.maximum(kp - km, 1) * s  # 1 only when n == 1, where the diff is 0
        return (flat[other + kp * stride] - flat[other + km * stride]) / span

    def sample_ahead(self, pos, heading, distance, replica=None) -> np.ndarray:
        """Sample at ``distance`` (scalar or ``(M,)``) along ``heading (M,)`` radians."""
        pos = self.grid.check_positions(pos)
        heading = np.asarray(heading, dtype=np.float64)
        ahead = pos + np.asarray(distance, dtype=np.float64)[..., None] * np.stack(
            [portable.cos_array(heading), portable.sin_array(heading)], axis=-1
        )
        return self.sample(ahead) if replica is None else self.sample(ahead, replica)

    def sense_cone(self, pos, heading, distance, half_angle: float, samples: int = 5,
                   replica=None):
        """Mean of the field over ``samples`` points on an arc ahead of each agent.

        The points sit at ``distance`` from the agent at angles evenly spaced over
        ``heading +- half_angle`` (one point straight ahead when ``samples == 1``), a
        cheap stand-in for an antenna's reading that is smooth in the heading.
        """
        if int(samples) != samples or samples < 1:
            raise ValueError(f"cone samples must be a positive whole number, got {samples}")
        pos = self.grid.check_positions(pos)
        m = len(pos)
        heading = np.broadcast_to(np.asarray(heading, dtype=np.float64), (m,))
        dist = np.broadcast_to(np.asarray(distance, dtype=np.float64), (m,))
        spread = np.linspace(-half_angle, half_angle, int(samples)) if samples > 1 else [0.0]
        angles = heading[:, None] + np.asarray(spread)[None, :]  # (M, S)
        pts = pos[:, None, :] + dist[:, None, None] * np.stack(
            [portable.cos_array(angles), portable.sin_array(angles)], axis=-1
        )  # (M, S, 2)
        pts = pts.reshape(-1, 2)
        got = self.sample(pts) if replica is None else \
            self.sample(pts, np.repeat(np.asarray(replica), len(spread)))
        return got.reshape(m, len(spread)).mean(axis=1)

    def __repr__(self) -> str:
        return (
            f"Field({self.name!r}, {self.grid!r}, decay={self.decay:g}, "
            f"diffuse={self.diffuse:g})"
        )
