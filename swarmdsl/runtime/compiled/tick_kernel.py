"""Whole ticks in one compiled call: a `tick_plan.TickPlan` composed into one jitted loop.

For a small swarm most of a tick is Python's fixed cost (frames, tables, calls into a
dozen kernels), not arithmetic. When nothing outside the kernels needs the state
between ticks, `advance(backend, sim, k)` runs up to k ticks in one call of a function
composed from the plan's steps, each a closure of `@njit(inline="always")` functions
(the expression nodes of `kernels.node`, the cell list of `cells.py`, the motion of
`motion.py`, the draws' mixer of `random.py`): never from generated text.

A tick, as `Simulation._step` does it: sort the agents into the cell list; every agent,
in row order, runs its status's steps, reading the start-of-tick state of its
neighbours and its own writes; the writes and next statuses commit together; edge
push, speed clamp, move, edges and heading (`motion._move_range`). Each agent's result
depends only on the start-of-tick state and its own earlier steps, so running the
agents one after another instead of statement by statement over all of them changes
no bit; sums add their terms in the cell list's order, as the reference does, and
`min`/`max`/`nearest` meet the pairs in that order too.

The state is one (N, C) float64 table (`tick_plan.TableLayout`), packed from the agent
columns when `advance` starts and unpacked when it returns. A check that fails (a `let`
that is NaN, an assignment that is not finite, a draw's arguments, a position that is
not finite) stops the kernel before that tick commits; the tick then runs on the
per-tick path, which raises the located error (or, if the check was only cautious,
simply runs it).
"""

from __future__ import annotations

import math

import numpy as np

from swarmdsl.runtime import randomness, spatial
from swarmdsl.runtime.compiled.cells import (
    _delta,
    _gather_range,
    _sort_by_cell,
    cell_ranges,
    reach2,
)
from swarmdsl.runtime.compiled.disk_cache import keep_on_disk
from swarmdsl.runtime.compiled.jit import njit
from swarmdsl.runtime.compiled.kernels import FALSE, TRUE, ZERO, node, scalar_function
from swarmdsl.runtime.compiled.motion import _move_range
from swarmdsl.runtime.compiled.plan import Unsupported
from swarmdsl.runtime.compiled.random import _mix
from swarmdsl.runtime.compiled.tick_checks import CheckPlan, no_observer, observer
from swarmdsl.runtime.compiled.tick_fields import (
    _no_deposits,
    _no_twins,
    copy_rows,
    deposit_step,
    deposits,
    read_step,
    step_fields,
    twins,
)
from swarmdsl.runtime.compiled.tick_plan import RECORDED, SUMS, TickPlan
from swarmdsl.runtime.compiled.tree_kernel import NEVER, tree_step

_JIT = {"nogil": True, "error_model": "numpy"}
# Each step is a function of its own, called (LLVM inlines the small ones); the
# sequences of steps are inlined into their caller, so a body is one function of calls.
# Measured on Vicsek (load 6 on 2 cores): 26 s to compile so, 34 s with every sequence
# a function (each links its callees again), 47 s with every step inlined too.
# Steps and the loop over agents run without numba's reference counting (`_nrt`: off):
# they allocate nothing, and with it every call of a step increfs and decrefs each
# array it is handed (the tables, the grid's and the pairs' arrays: about fifty atomic
# calls per agent and step). Profiled on boids at 100 agents (perf, samples by
# function), those calls were 47 % of the kernel's time; the agents' loop moved out of
# `run` into `_agents` so that it too runs without them.
_INLINE = {**_JIT, "_nrt": False}
_FLAT = {**_JIT, "inline": "always"}   # sequences: their steps' calls, in one function
GO, STOPPED, ABORT = 0, 1, 2   # what a step returns: go on, the agent stopped, stop all

_U_ID = np.uint64(randomness._C_ID)
_U_GOLDEN = np.uint64(randomness._GOLDEN)
_U_TICK = np.uint64(randomness._C_TICK)
_S11 = np.uint64(11)
_TO_UNIT = randomness._TO_UNIT
_TWO_PI = 2.0 * np.pi
_KERNELS: dict = {}   # the plan's shape -> its jitted loop


# ---- steps: f(A, B, S, T, ids, G, W, keys, called, i) -> GO, STOPPED or ABORT ----
@njit(**_INLINE)
def _nothing(A, B, S, T, ids, G, W, keys, called, i):
    return GO


def _seq(a, b):
    @njit(**_FLAT)
    def step(A, B, S, T, ids, G, W, keys, called, i):
        r = a(A, B, S, T, ids, G, W, keys, called, i)
        if r != GO:
            return r
        return b(A, B, S, T, ids, G, W, keys, called, i)
    return step


def _tree(col, tree):
    fn = node(tree)

    @njit(**_INLINE)
    def step(A, B, S, T, ids, G, W, keys, called, i):
        S[i, col] = fn(S, B, i, i, 0.0, 0.0, 0.0)   # `o` leaves: the agent's row
        return GO
    return step



def _nan(col):
    @njit(**_INLINE)
    def step(A, B, S, T, ids, G, W, keys, called, i):
        v = S[i, col]
        return ABORT if v != v else GO
    return step


@njit(**_INLINE)
def _set(cur, v):
    return v


@njit(**_INLINE)
def _add(cur, v):
    return cur + v


@njit(**_INLINE)
def _sub(cur, v):
    return cur - v


@njit(**_INLINE)
def _mul(cur, v):
    return cur * v


@njit(**_INLINE)
def _div(cur, v):
    return cur / v


_APPLY = {"=": _set, "+=": _add, "-=": _sub, "*=": _mul, "/=": _div}


def _write(tcol, width, op, cols):
    apply = _APPLY[op]
    c0 = cols[0]
    c1 = cols[1] if len(cols) == 2 else cols[0]
    two = width == 2

    @njit(**_INLINE)
    def step(A, B, S, T, ids, G, W, keys, called, i):
        x = apply(B[i, tcol], S[i, c0])
        y = x
        if two:
            y = apply(B[i, tcol + 1], S[i, c1])
        if not math.isfinite(x) or not math.isfinite(y):
            return ABORT
        B[i, tcol] = x
        if two:
            B[i, tcol + 1] = y
        return GO
    return step


def _when(col, code, body):
    next_status = float(code)

    @njit(**_INLINE)
    def step(A, B, S, T, ids, G, W, keys, called, i):
        if S[i, col] == 0.0:
            return GO
        S[i, 0] = next_status
        if body(A, B, S, T, ids, G, W, keys, called, i) == ABORT:
            return ABORT
        return STOPPED
    return step


_DRAW_KINDS = {"random": 0, "uniform": 1, "normal": 2, "chance": 3, "random_direction": 4}


@njit(**_INLINE)
def _unit(h, lane, low):
    """Lane `lane` of an agent's draw (`randomness.AgentRandom._unit`'s bits)."""
    z = _mix(h + np.uint64(lane) * _U_GOLDEN)
    return (float(z >> _S11) + low) * _TO_UNIT


def _draw(name, site, args, out):
    kind = _DRAW_KINDS[name]
    a0 = args[0] if args else 0
    a1 = args[1] if len(args) > 1 else a0
    log, cos, sin = scalar_function("log"), scalar_function("cos"), scalar_function("sin")

    @njit(**_INLINE)
    def step(A, B, S, T, ids, G, W, keys, called, i):
        called[site] = 1
        h = _mix(ids[i] * _U_ID + keys[site])
        if kind == 2:   # normal(mean, sd): Box-Muller over two lanes, open below
            mu, sd = S[i, a0], S[i, a1]
            if mu != mu or sd != sd or sd < 0 or math.isinf(mu) or math.isinf(sd):
                return ABORT
            u0 = _unit(h, 0, 1.0)
            u1 = _unit(h, 1, 1.0)
            S[i, out] = np.sqrt(-2.0 * log(u0)) * cos(_TWO_PI * u1) * sd + mu
            return GO
        u = _unit(h, 0, 0.0)
        if kind == 0:
            S[i, out] = u
        elif kind == 1:   # uniform(lo, hi)
            lo, hi = S[i, a0], S[i, a1]
            if lo != lo or hi != hi or lo > hi or math.isinf(lo) or math.isinf(hi):
                return ABORT
            S[i, out] = u * (hi - lo) + lo
        elif kind == 3:   # chance(p)
            p = S[i, a0]
            if p != p or p < 0 or p > 1:
                return ABORT
            S[i, out] = 1.0 if u < p else 0.0
        else:             # random_direction(): unit(uniform(0, 2 pi))
            a = 0.0 + u * (_TWO_PI - 0.0)
            S[i, out] = cos(a)
            S[i, out + 1] = sin(a)
        return GO
    return step


@njit(**_FLAT)
def _written(i, G, W):
    """How many of agent i's candidates (in `W`'s arrays) are within the table's
    radius: written by the first sum of the agent this tick, then reused."""
    sp, scell, start, nx, ny, wrap, bw, bh, within2, rank = G[:10]   # (then the fields)
    near, near_dist, near_delta, lo, hi, memo = W
    if memo[0] == i:
        return memo[1]
    s = rank[i]
    _c, k, wx, wy = cell_ranges(s, -1, 0, wrap, wrap, scell, nx, ny, wrap, start, lo, hi)
    # `cells.write_owner`'s pairs, in its order, with its `delta` and `dist`; but only
    # the kept ones written, and their root only taken (a small swarm's branch is
    # cheaper than a root of every candidate).
    ax, ay = sp[s, 0], sp[s, 1]
    p = 0
    for q in range(k):
        for t in range(lo[q], hi[q]):
            dx, dy = _delta(ax, ay, sp[t, 0], sp[t, 1], wx, wy, bw, bh)
            d2 = dx * dx + dy * dy
            if d2 <= within2 and t != s:
                near[p] = t
                near_dist[p] = np.sqrt(d2)
                near_delta[p, 0] = dx
                near_delta[p, 1] = dy
                p += 1
    memo[0] = i
    memo[1] = p
    return p


def _finisher(name, two, out, default):
    """`S[i, out...]` from one sum's (sx, sy, count), as `FusedAggregate._finish`."""
    kind = SUMS.index(name)
    d0 = default[0] if default else 0
    d1 = default[1] if default and len(default) == 2 else d0

    @njit(**_FLAT)
    def finish(S, i, sx, sy, c):
        if kind == 0:     # count
            S[i, out] = float(c)
        elif kind == 1:   # sum
            S[i, out] = sx
            if two:
                S[i, out + 1] = sy
        elif kind == 2:   # mean, or the default without neighbours
            if c > 0:
                S[i, out] = sx / float(c)
                if two:
                    S[i, out + 1] = sy / float(c)
            else:
                S[i, out] = S[i, d0]
                if two:
                    S[i, out + 1] = S[i, d1]
        elif kind == 3:   # any
            S[i, out] = 1.0 if sx > 0 else 0.0
        else:             # all
            S[i, out] = 1.0 if sx == float(c) else 0.0
    return finish


@njit(**_FLAT)
def _no_finish(S, i, sx, sy, c):
    return None


_NO = ("not", ("true",))


def _shared_test(conds: list) -> tuple:
    """(the set's test every member's pair test starts with, each member's own test):
    sums over one `let` set test its filters and its robot's view (`("if", set, own,
    no)`, tick_plan.py) once per pair for them all; (None, `conds`) when they differ."""
    first = conds[0]
    if all(c[0] == "if" and c[3] == _NO and c[1] == first[1] for c in conds):
        return first[1], [c[2] for c in conds]
    return None, conds


def _aggs(members):
    """One to four neighbour sums in one loop over the agent's pairs (`_written`: the
    candidates in the cells around it, in the cell list's order), each slot's terms
    tested and added in the order its own loop would add them, as
    `kernels._direct_body` does (so each has its own loop's bits). The slots are
    written out, each sum in local variables, for the reason `kernels._sums_body`
    gives; unused slots test `FALSE` and compile away."""
    shared, conds = _shared_test([m[2] for m in members])
    ts = node(shared) if shared is not None else TRUE
    slots = []
    for (name, two, _cond, each, out, default), cond in zip(members, conds, strict=True):
        slots += [node(cond), node(each[0]) if each else ZERO,
                  node(each[1]) if len(each) == 2 else ZERO,
                  _finisher(name, two, out, default)]
    slots += [FALSE, ZERO, ZERO, _no_finish] * (4 - len(members))
    (t0, fx0, fy0, f0, t1, fx1, fy1, f1, t2, fx2, fy2, f2, t3, fx3, fy3, f3) = slots

    @njit(**_INLINE)
    def step(A, B, S, T, ids, G, W, keys, called, i):
        p = _written(i, G, W)
        near, near_dist, near_delta = W[0], W[1], W[2]
        x0 = y0 = x1 = y1 = x2 = y2 = x3 = y3 = 0.0
        c0 = c1 = c2 = c3 = 0
        for e in range(p):
            j = near[e]
            d = near_dist[e]
            dx = near_delta[e, 0]
            dy = near_delta[e, 1]
            if not ts(S, T, i, j, d, dx, dy):
                continue
            if t0(S, T, i, j, d, dx, dy):
                c0 += 1
                x0 += fx0(S, T, i, j, d, dx, dy)
                y0 += fy0(S, T, i, j, d, dx, dy)
            if t1(S, T, i, j, d, dx, dy):
                c1 += 1
                x1 += fx1(S, T, i, j, d, dx, dy)
                y1 += fy1(S, T, i, j, d, dx, dy)
            if t2(S, T, i, j, d, dx, dy):
                c2 += 1
                x2 += fx2(S, T, i, j, d, dx, dy)
                y2 += fy2(S, T, i, j, d, dx, dy)
            if t3(S, T, i, j, d, dx, dy):
                c3 += 1
                x3 += fx3(S, T, i, j, d, dx, dy)
                y3 += fy3(S, T, i, j, d, dx, dy)
        f0(S, i, x0, y0, c0)
        f1(S, i, x1, y1, c1)
        f2(S, i, x2, y2, c2)
        f3(S, i, x3, y3, c3)
        return GO
    return step


@njit(**_FLAT)
def _less(a, b):
    return a < b


@njit(**_FLAT)
def _greater(a, b):
    return a > b


def _pick(name, two, cond, each, out, default):
    """`min`, `max` or `nearest` over the agent's pairs (`_written`, in the cell list's
    order) into `S[i, out...]`, or its `else` (`default`'s columns) when no pair counts:
    `kernels._extreme_body` and `_nearest_body` with their rows' finishing forms
    (`aggregate_forms.extreme_finish`, `nearest_finish`), so the same bits. The
    nearest's ties go to the lowest row of the agent table (`G`'s `order`: sorted
    position -> row), as the reference's `segment_argmin` breaks them."""
    t = node(cond)
    fx = node(each[0])
    fy = node(each[1]) if two else ZERO
    nearest = name == "nearest"
    better = _less if name == "min" else _greater
    d0 = default[0]
    d1 = default[1] if len(default) == 2 else d0

    @njit(**_INLINE)
    def step(A, B, S, T, ids, G, W, keys, called, i):
        p = _written(i, G, W)
        near, near_dist, near_delta = W[0], W[1], W[2]
        order = G[10]
        c = 0
        best = 0.0
        at = -1
        bd = math.inf
        bt = -1
        for e in range(p):
            j = near[e]
            d = near_dist[e]
            dx = near_delta[e, 0]
            dy = near_delta[e, 1]
            if not t(S, T, i, j, d, dx, dy):
                continue
            c += 1
            if nearest:
                tie = order[j]
                if at < 0 or d < bd or (d == bd and tie < bt):   # ties: the lowest row
                    at, bd, bt = e, d, tie
            else:
                v = fx(S, T, i, j, d, dx, dy)
                if c == 1 or (best == best and (v != v or better(v, best))):
                    best = v     # np.minimum.reduceat: a NaN stays
        if c == 0:
            S[i, out] = S[i, d0]
            if two:
                S[i, out + 1] = S[i, d1]
        elif nearest:
            j = near[at]
            dx = near_delta[at, 0]
            dy = near_delta[at, 1]
            S[i, out] = float(fx(S, T, i, j, bd, dx, dy))
            if two:
                S[i, out + 1] = float(fy(S, T, i, j, bd, dx, dy))
        else:
            S[i, out] = best
        return GO
    return step


def _steps(steps) -> object:
    """The steps of a body composed into one step."""
    return _balanced([_step(st) for st in steps])


def _balanced(fns):
    """`fns` in order as one step: halves composed, so no call is nested deeper than
    log2 of their number (numba compiles and links each level's callees again)."""
    if not fns:
        return _nothing
    if len(fns) == 1:
        return fns[0]
    half = len(fns) // 2
    return _seq(_balanced(fns[:half]), _balanced(fns[half:]))


def _step(st):
    what = st[0]
    if what == "tree":
        return _tree(st[1], st[2])
    if what == "nan":
        return _balanced([_nan(col) for col in st[1]])
    if what == "write":
        return _write(*st[1:])
    if what == "when":
        return _when(st[1], st[2], _steps(st[3]))
    if what == "draw":
        return _draw(*st[1:])
    if what == "agg":
        return _aggs((st[1:],)) if st[1] in SUMS else _pick(*st[1:])
    if what == "aggs":
        return _aggs(st[1])
    if what == "bt":
        return tree_step(st, _steps, GO, ABORT)
    if what == "fread":
        return read_step(st, GO, ABORT)
    if what == "deposit":
        return deposit_step(st, GO, ABORT)
    raise Unsupported(f"internal: no step `{what}`")


def _case(code, body, rest):
    @njit(**_FLAT)
    def dispatch(c, A, B, S, T, ids, G, W, keys, called, i):
        if c == code:
            return body(A, B, S, T, ids, G, W, keys, called, i)
        return rest(c, A, B, S, T, ids, G, W, keys, called, i)
    return dispatch


@njit(**_INLINE)
def _no_status(c, A, B, S, T, ids, G, W, keys, called, i):
    return GO


@njit(**_JIT)
def _cells_along(extent, radius):
    """`spatial._cells_along_one`."""
    if not extent > 0:
        return 1
    fit = extent / (radius * spatial._MARGIN)
    if fit < 2.0 ** 31:
        return int(min(max(math.floor(fit), 1.0), 2.0 ** 31))
    return 2 ** 31


@njit(**_JIT)
def _grid(pos, radius, wrap, bw, bh):
    """`spatial.cell_grid`: (x0, y0, nx, ny, cell width, cell height)."""
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
    cap = max(spatial._CELLS_PER_AGENT * n, spatial._MIN_CELLS)
    while nx * ny > cap:
        nx, ny = max(1, nx // 2), max(1, ny // 2)
    wx = ex / nx if ex > 0 else radius
    wy = ey / ny if ey > 0 else radius
    return x0, y0, nx, ny, wx, wy


@njit(**_FLAT)
def _no_derived(S, T, n):
    return None


def _derived(col, tree, before):
    """`before`, then column `col` of the sorted table: scalar tree `tree` over each
    agent's own columns, by the functions a pair loop would use (`kernels.
    derived_kernel`: the same bits as working it out pair by pair)."""
    fn = node(tree)

    @njit(**_FLAT)
    def derive(S, T, n):
        before(S, T, n)
        for s in range(n):
            T[s, col] = fn(S, T, 0, s, 0.0, 0.0, 0.0)
    return derive


@njit(**_FLAT)
def _no_settle(A, B, S, n, ending):
    return None


def _settle(flag, left, code, stamp, ST, before):
    """`before`, then one tree's `Tree._left` after the agents' steps (`ending`): the
    agents of status `code` that took a transition forget the tree's stamp, when its
    statement ran this tick (`S[0, flag]`); at the start of a tick (not `ending`), the
    flag is cleared."""
    status = float(code)

    @njit(**_FLAT)
    def settle(A, B, S, n, ending):
        before(A, B, S, n, ending)
        if not ending:
            S[0, flag] = 0.0
            return
        if S[0, flag] == 0.0:
            return
        for i in range(n):
            if A[i, ST] == status and S[i, left] != 0.0:
                B[i, stamp] = NEVER
    return settle


def _zeroed(col, before):
    """`before`, then at the start of a tick column `col` of every agent set to 0 (a
    tree's active leaf and result: `TreeMemory.begin_tick`)."""
    @njit(**_FLAT)
    def settle(A, B, S, n, ending):
        before(A, B, S, n, ending)
        if not ending:
            for i in range(n):
                B[i, col] = 0.0
    return settle


def _agents(dispatch, ST):
    """Every agent's status body, in row order; False when a check stopped one."""
    @njit(**_INLINE)
    def agents(A, B, S, T, ids, G, W, keys, called, n):
        for i in range(n):
            code = int(A[i, ST])
            S[i, 0] = float(code)
            if dispatch(code, A, B, S, T, ids, G, W, keys, called, i) == ABORT:
                return False
            B[i, ST] = S[i, 0]
        return True
    return agents


def _loop(dispatch, cols, has_pairs, derive, observe=no_observer, settle=_no_settle,
          deposit=_no_deposits, twin=_no_twins):
    """The jitted loop of up to `ticks` ticks; returns how many it ran. With `watch`'s
    first item true, `observe` sees each tick once it commits (`tick_checks.py`:
    properties checked, metrics sampled) and a failing check ends the call after
    that tick. `fields` holds the environment's grids (`tick_fields.py`): read by the
    steps, `deposit`ed into after them, decayed and diffused after the move."""
    P, V, H, ST, MS, SPD, NAME = cols
    agents = _agents(dispatch, ST)
    atan2 = scalar_function("atan2")

    @njit(**_JIT)
    def run(A, B, S, T, ids, ticks, tick0, seed_key, site_keys, keys, called,
            tick_cols, names, radius, wrap, bw, bh, motion, sp, scell, rank, W, pos, vel,
            limit, new_pos, new_vel, fields, watch):
        repel, width, height, grid, weight, reach, corners = motion
        (F, FB, fnx, fny, fsp, fper, fmodes, fown, faround, fkeep, NP, TK, TW, trows,
         tticks) = fields
        watching = watch[0]
        n, C = A.shape
        within2 = reach2(radius)
        for t in range(ticks):
            tick = tick0 + t
            for i in range(n):
                vx, vy = A[i, V], A[i, V + 1]
                A[i, SPD] = np.sqrt(vx * vx + vy * vy)
                A[i, NAME] = names[int(A[i, ST])]
                pos[i, 0], pos[i, 1] = A[i, P], A[i, P + 1]
            for c in tick_cols:
                for i in range(n):
                    A[i, c] = float(tick)
            tk = np.uint64(tick) * _U_TICK
            for c in range(site_keys.size):
                keys[c] = _mix(seed_key ^ _mix(tk ^ site_keys[c]))
                called[c] = 0
            start = np.zeros(1, np.int64)
            order = rank   # (no pairs: no pick reads it)
            nx, ny = 1, 1
            if has_pairs:
                x0, y0, nx, ny, wx, wy = _grid(pos, radius, wrap, bw, bh)
                order, start, cell = _sort_by_cell(pos, wrap, bw, bh, x0, y0, nx, ny, wx,
                                                   wy)
                _gather_range(0, n, pos, wrap, bw, bh, order, cell, scell, sp)
                for s in range(n):
                    a = order[s]
                    rank[a] = s
                    for c in range(C):
                        T[s, c] = A[a, c]
                derive(S, T, n)
            for i in range(n):
                for c in range(C):
                    B[i, c] = A[i, c]
            W[5][0] = -1   # no agent's pairs written yet this tick
            G = (sp, scell, start, nx, ny, wrap, bw, bh, within2, rank, order, F, fnx, fny,
                 fsp, fper)
            settle(A, B, S, n, False)
            deposit(A, S, F, n, fnx, fny, fsp, fper, P, False)
            if not agents(A, B, S, T, ids, G, W, keys, called, n):
                return t
            settle(A, B, S, n, True)
            for i in range(n):
                pos[i, 0], pos[i, 1] = B[i, P], B[i, P + 1]
                vel[i, 0], vel[i, 1] = B[i, V], B[i, V + 1]
                limit[i] = B[i, MS]
            _move_range(0, n, pos, vel, limit, repel, width, height, grid, weight, reach,
                        corners, wrap, new_pos, new_vel)
            for i in range(n):
                if not (math.isfinite(new_pos[i, 0]) and math.isfinite(new_pos[i, 1])):
                    return t
            for c in tticks:   # the twins that read `tick`, for the next one
                TK[0, c] = float(tick + 1)
            if not twin(NP, TK, TW):
                return t
            # the tick commits: deposits at the start-of-tick positions (A's), then
            # every field's decay and diffusion and the twins, as `Environment.end_tick`
            deposit(A, S, F, n, fnx, fny, fsp, fper, P, True)
            step_fields(F, FB, fnx, fny, fper, fmodes, fown, faround, fkeep)
            copy_rows(F, TW, trows)
            for i in range(n):
                B[i, P], B[i, P + 1] = new_pos[i, 0], new_pos[i, 1]
                vx, vy = new_vel[i, 0], new_vel[i, 1]
                B[i, V], B[i, V + 1] = vx, vy
                if vx != 0.0 or vy != 0.0:
                    B[i, H] = atan2(vy, vx)
            for i in range(n):
                for c in range(C):
                    A[i, c] = B[i, c]
            if watching and observe(A, S, n, tick + 1, names, watch):
                return t + 1
        return ticks
    return run


def _frozen(x):
    if isinstance(x, list | tuple):
        return tuple(_frozen(v) for v in x)
    if isinstance(x, dict):
        return tuple(sorted((k, _frozen(v)) for k, v in x.items()))
    return x


def kernel(plan: TickPlan, checks: CheckPlan | None = None):
    """The jitted loop of `plan` with the program's compiled `checks` (memoised by
    their shape: params are constants, not part of it), and whether it is new."""
    lay = plan.layout
    cols = tuple(lay.at(c) for c in ("pos", "vel", "heading", "status", "max_speed",
                                     "speed", "status_name"))
    has_pairs = plan.radius > 0
    derived = tuple((lay.width + c, v[1]) for c, v in enumerate(plan.consts)
                    if isinstance(v, tuple))
    key = (_frozen(plan.bodies), cols, has_pairs, derived, _frozen(plan.settles),
           _frozen(plan.deposits), _frozen(plan.twins),
           checks.key if checks is not None and not checks.empty else None)
    got = _KERNELS.get(key)
    if got is not None:
        return got, False
    dispatch = _no_status
    for code, steps in sorted(plan.bodies.items(), reverse=True):
        dispatch = _case(code, _steps(steps), dispatch)
    derive = _no_derived
    for col, tree in derived:
        derive = _derived(col, tree, derive)
    settle = _no_settle
    for flag, left, code, stamp in plan.settles:
        settle = _settle(flag, left, code, stamp, cols[3], settle)
    for name in RECORDED:
        if name in lay.cols:
            settle = _zeroed(lay.at(name), settle)
    observe = observer(checks, lay.at("status"), lay.at("status_name"), lay.at("kind"))
    got = _KERNELS[key] = keep_on_disk(_loop(dispatch, cols, has_pairs, derive, observe,
                                             settle, deposits(plan), twins(plan)))
    return got, True
