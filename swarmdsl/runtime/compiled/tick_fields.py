"""The environment's grids inside the whole-tick kernel: readings as steps, deposits kept
per agent and added once the agents' steps are done, decay and diffusion after the move.

A tick does what the reference does with its fields (`Simulation._step`): agents read
the grids as they were at the start of the tick; the deposits land after every status
has run, site by site in source order, each site's agents in row order, at the place
each agent stood when the tick began (`lang_fields._compile_deposit`'s effects); then,
after the move, every field decays and diffuses (`Environment.end_tick`). Each reading,
deposit and pass over the grid is the arithmetic of the compiled fields (`fields.py`:
its `sample_at`, `gradient_at`, `splat_at` and `_diffuse`), which is the numpy
reference's, so the bits are the same.

The kernel holds the grids as one `(K, nodes)` table `F`, one row per
`TickPlan.field_rows` (every field; a vector twin's two components), copied in from the
run's fields when a call starts and back when it returns (`load`, `store`). The steps
find it and its grid in `G[11:16]`. A twin whose formula reads `tick` is worked out at
every node after the move for the next tick, as the reference does at the end of a
tick: into a scratch table first, so that a value that is not finite stops the call
before the tick commits, and the tick runs again on the reference path, which raises.
"""

from __future__ import annotations

import math

import numpy as np

from swarmdsl.runtime.compiled.fields import _diffuse, gradient_at, sample_at, splat_at
from swarmdsl.runtime.compiled.jit import njit
from swarmdsl.runtime.compiled.kernels import node

_INLINE = {"nogil": True, "error_model": "numpy", "_nrt": False}
_FLAT = {**_INLINE, "inline": "always"}


def read_step(st, go: int, abort: int):
    """`("fread", what, row, x, y, out)`: row `row` of `F` at the point in S columns
    `x`, `y`, the bilinear reading (`what` 0) into `S[i, out]` or the gradient (1) into
    `out` and `out + 1`; a point that is not finite stops the kernel (the reference
    raises there)."""
    _f, what, row, x, y, out = st

    @njit(**_INLINE)
    def step(A, B, S, T, ids, G, W, keys, called, i):
        px, py = S[i, x], S[i, y]
        if not (math.isfinite(px) and math.isfinite(py)):
            return abort
        F, nx, ny, spacing, periodic = G[11], G[12], G[13], G[14], G[15]
        if what == 0:
            S[i, out] = sample_at(F[row], px, py, nx, ny, spacing, periodic, 0)
        else:
            S[i, out], S[i, out + 1] = gradient_at(F[row], px, py, nx, ny, spacing,
                                                   periodic, 0)
        return go
    return step


def deposit_step(st, go: int, abort: int):
    """`("deposit", on, amount)`: the agent deposits this tick (`S[i, on]`) the amount
    in `S[i, amount]`, added after the agents' steps (`deposits`); an amount that is
    not finite stops the kernel (the reference raises there)."""
    _d, on, amount = st

    @njit(**_INLINE)
    def step(A, B, S, T, ids, G, W, keys, called, i):
        if not math.isfinite(S[i, amount]):
            return abort
        S[i, on] = 1.0
        return go
    return step


@njit(**_FLAT)
def _no_deposits(A, S, F, n, nx, ny, spacing, periodic, P, ending):
    return None


def _deposit_site(row, on, amount, before):
    """`before`, then one deposit site: at the start of a tick (not `ending`) its
    agents' marks cleared; at its end the marked agents' amounts added to row `row`,
    in row order, at their start-of-tick positions (`A`'s), as `fields._splat`."""
    @njit(**_FLAT)
    def apply(A, S, F, n, nx, ny, spacing, periodic, P, ending):
        before(A, S, F, n, nx, ny, spacing, periodic, P, ending)
        if not ending:
            for i in range(n):
                S[i, on] = 0.0
            return
        v = F[row]
        for i in range(n):
            if S[i, on] != 0.0:
                splat_at(v, A[i, P], A[i, P + 1], S[i, amount], nx, ny, spacing,
                         periodic, 0)
    return apply


def deposits(plan):
    """The plan's deposit sites as one function, in the order the reference runs them."""
    apply = _no_deposits
    for row, on, amount in plan.deposits:
        apply = _deposit_site(row, on, amount, apply)
    return apply


@njit(**_FLAT)
def _no_twins(NP, TK, TW):
    return True


def _twin_row(row, tree, before):
    """`before`, then twin row `row` at every node into `TW`: scalar tree `tree` over
    the node's position (`NP`'s row, the tree's S columns) and the constants (`TK`'s
    row 0); False when a value is not finite (the reference raises there)."""
    fn = node(tree)

    @njit(**_FLAT)
    def update(NP, TK, TW):
        if not before(NP, TK, TW):
            return False
        for q in range(NP.shape[0]):
            v = fn(NP, TK, q, 0, 0.0, 0.0, 0.0)
            if not math.isfinite(v):
                return False
            TW[row, q] = v
        return True
    return update


def twins(plan):
    """The plan's twins that read `tick` as one function, each row worked out at every
    node for the next tick (`Environment._update_twins`)."""
    update = _no_twins
    for row, tree in plan.twins:
        update = _twin_row(row, tree, update)
    return update


@njit(cache=True, nogil=True, error_model="numpy")
def step_fields(F, FB, nx, ny, periodic, modes, own, around, keep):
    """Every row's `Field.step`: decay (mode 1: `values *= keep`) or decay and
    diffusion (mode 2: `_diffuse` with the scales `Field.step` works out); a twin's
    row (mode 0) stays."""
    for k in range(F.shape[0]):
        if modes[k] == 1:
            v = F[k]
            for q in range(v.shape[0]):
                v[q] *= keep[k]
        elif modes[k] == 2:
            _diffuse(F[k].reshape((ny, nx)), FB[k].reshape((ny, nx)), own[k], around[k],
                     periodic)


@njit(cache=True, nogil=True, error_model="numpy")
def copy_rows(F, TW, rows):
    """Rows `rows` of `TW` into `F` (the twins' values for the next tick)."""
    for r in rows:
        for q in range(F.shape[1]):
            F[r, q] = TW[r, q]


# what a call passes for a program without fields (one machine code serves both)
_NO_ROWS = np.zeros(0, np.int64)
_NONE = (np.zeros((0, 1)), np.zeros((0, 1)), 1, 1, 1.0, False, _NO_ROWS, np.zeros(0),
         np.zeros(0), np.zeros(0), np.zeros((0, 2)), np.zeros((1, 0)), np.zeros((0, 1)),
         _NO_ROWS, _NO_ROWS)


def _grids(sim, rows) -> list:
    """The run's fields behind `rows` (`TickPlan.field_rows`)."""
    env = sim.environment
    return [env.fields[r] if r in env.fields else getattr(env.vectors[r[:-2]], r[-1])
            for r in rows]


def load(sim, plan) -> tuple:
    """The kernel's `fields` argument: the grids' values copied into `F`, scratch,
    the grid, each row's decay and diffusion (as `Field.step` works them out), and for
    the twins that read `tick` the nodes' positions, their constants (`TK`, with the
    columns the next tick goes into) and their rows."""
    rows = plan.field_rows
    if not rows:
        return _NONE
    grids = _grids(sim, rows)
    F = np.stack([g.node_values() for g in grids])
    modes = np.zeros(len(grids), np.int64)
    own, around, keep = np.zeros(len(grids)), np.zeros(len(grids)), np.ones(len(grids))
    for k, g in enumerate(grids):
        keep[k] = 1.0 - g.decay
        if g.diffuse != 0.0:
            modes[k] = 2
            own[k] = keep[k] * (1.0 - 4.0 * g.diffuse)
            around[k] = keep[k] * g.diffuse
        elif g.decay != 0.0:
            modes[k] = 1
    grid = sim.environment.grid
    twin_rows = np.array(sorted({row for row, _tree in plan.twins}), np.int64)
    if plan.twins:
        nodes = np.ascontiguousarray(grid.node_positions())
        consts = np.array([[0.0 if v == "tick" else v for v in plan.twin_consts]])
        ticks = np.array([c for c, v in enumerate(plan.twin_consts) if v == "tick"],
                         np.int64)
        scratch = np.empty_like(F)
    else:
        nodes, consts, ticks, scratch = _NONE[10], _NONE[11], _NO_ROWS, _NONE[12]
    return (F, np.empty_like(F), int(grid.nx), int(grid.ny), float(grid.spacing),
            bool(grid.periodic), modes, own, around, keep, nodes, consts, scratch,
            twin_rows, ticks)


def store(sim, plan, fields: tuple) -> None:
    """The grids' values back from the kernel's `F` into the run's fields."""
    for g, values in zip(_grids(sim, plan.field_rows), fields[0], strict=True):
        g.node_values()[:] = values
