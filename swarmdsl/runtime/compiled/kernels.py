"""Fused aggregate kernels: a plan's expression trees composed into jitted functions.

Every expression tree becomes one small `@njit(inline="always")` function of one pair
`(S, O, r, j, d, dx, dy)` (`tree_functions.py`: built as a Python syntax tree from the
plan's tree, never from text). One kernel per aggregate loops over each owner's pairs,
tests the filters, evaluates the value and accumulates: no array as long as the pair
list is made. Sums may instead search the cell list themselves (`direct_kernel`), so
the pairs are not even written.

Scalar semantics follow the reference (numpy) closures: each operation is the
`scalar` of its row in `ops/` (the operator and function tables), IEEE division
(`error_model="numpy"`: x/0 is inf or NaN, never an exception), NaN propagating
through `min`/`max`, `round` half to even, `%` floored as numpy's. Kernels are
memoised by the plan's shape for the life of the process, and on disk across processes
under a fingerprint of what they are made of
(`disk_cache.py`); the time compiling or loading took is reported
(`Backend.compile_seconds`).
"""

from __future__ import annotations

import math

import numpy as np

from swarmdsl.compiler.builtins import AGGREGATES
from swarmdsl.ops import portable
from swarmdsl.ops.scalars import scalar
from swarmdsl.runtime.compiled import tree_functions
from swarmdsl.runtime.compiled.cells import reach2, solo_ranges, split_work, write_owner
from swarmdsl.runtime.compiled.disk_cache import keep_on_disk
from swarmdsl.runtime.compiled.jit import njit, prange
from swarmdsl.runtime.compiled.replica_cells import batch_ranges

_JIT = {"nogil": True, "error_model": "numpy"}
_INLINE = {**_JIT, "inline": "always"}
_NODES: dict = {}      # tree -> jitted node function
_NO_INDEX = np.zeros(0, np.int64)   # `_pair` without a row index: entries in order
_KERNELS: dict = {}    # plan key -> (kernel, compiled?)


# ---- the constant trees' functions, shared by every kernel (slots left empty) ----
@njit(**_INLINE)
def ZERO(S, O, r, j, d, dx, dy):
    return 0.0


@njit(**_INLINE)
def TRUE(S, O, r, j, d, dx, dy):
    return True


@njit(**_INLINE)
def FALSE(S, O, r, j, d, dx, dy):
    return False


# ---- scalar operations: each row's `scalar` (ops/), compiled on first use ----
def scalar_function(op: str):
    """The jitted scalar function of tree node `op` (a row's `scalar`, ops/)."""
    got = _SCALAR_FNS.get(op)
    if got is None:
        _register_helpers()
        got = _SCALAR_FNS[op] = njit(**_INLINE)(scalar(op))
    return got


def _register_helpers() -> None:
    """Let jitted code call the plain functions the portable math is built from
    (`ops/portable.py`), which imports no numba."""
    global _HELPERS_REGISTERED
    if not _HELPERS_REGISTERED:
        from numba.extending import register_jitable

        for helper in portable.SCALAR_HELPERS:
            register_jitable(**_JIT)(helper)
        _HELPERS_REGISTERED = True


_HELPERS_REGISTERED = False


_SCALAR_FNS: dict = {}   # node name -> its jitted scalar function


def node(tree: tuple):
    """The jitted function of one expression tree (memoised: equal trees share it)."""
    got = _NODES.get(tree)
    if got is None:
        got = _NODES[tree] = _build(tree)
    return got


def _build(tree: tuple):
    return njit(**_INLINE)(tree_functions.build(tree, scalar_function, _both))


@njit(**_INLINE)
def _and(x, y):
    return x and y


@njit(**_INLINE)
def _or(x, y):
    return x or y


def _both(op: str):
    """`and`/`or` of two values both evaluated (as arguments), as the reference does."""
    return _and if op == "and" else _or


# ---- the per-owner loops ----
class Kernel:
    """A plan's loop, serial and on the thread pool (compiled on first use of each).

    Call: `k(groups, off, rows, J, D, DL, K, S, O, ranks, out, cnt, W, chunks)`. Owner k of
    the loop has the pairs of group `groups[k]` (k itself when `groups` is empty): pairs
    `off[q]:off[q+1]`, through `rows` when it is not empty, skipping pair p when `K` is
    not empty and `K[p]` is false (a filtered set's mask). Its owner-only values are row
    k of `S` and its results go to row `W[k]` (k when `W` is empty) of `out` (M, 2: the
    sum, extreme, hit count or nearest pair's value; for a filter, (P,) booleans: the
    pairs it keeps) and `cnt` (M,: the pairs kept): owner-side values are read in loop
    order, and results land in the frame's row order with no permutation afterwards.
    `J` indexes `O`; `ranks[J[p]]` (or `J[p]`) is the neighbour's row, which breaks `nearest` ties. `chunks` > 1 splits the owners into
    that many runs on numba's threads. Serially the body itself is called: a jitted
    wrapper around it compiled the whole loop a second time (about a fifth of each
    kernel's compile time, for no speed).
    """

    def __init__(self, body):
        self.body = keep_on_disk(body)
        self._parallel = None

    def __call__(self, *args):
        if args[-1] > 1 and self._parallel is not False:
            try:
                if self._parallel is None:
                    self._parallel = _parallel(self.body)
                return self._parallel(*args)
            except Exception:   # numba could not thread it: the serial loop, same bits
                self._parallel = False
        groups, off = args[0], args[1]
        self.body(0, groups.size if groups.size else off.size - 1, *args[:-1])


@njit(**_INLINE)
def _owners(groups, off):
    """How many owners the loop visits (see `_group`)."""
    return groups.size if groups.size else off.size - 1


def _parallel(body):
    @njit(**_JIT, parallel=True)
    def run(groups, off, rows, J, D, DL, K, S, O, ranks, out, cnt, W, chunks):
        n = _owners(groups, off)
        if groups.size:   # a frame's share of the owners: equal numbers of them
            bounds = np.arange(chunks + 1) * n // chunks
        else:             # every owner: equal numbers of pairs
            bounds = split_work(off, n, chunks)
        for c in prange(chunks):
            body(bounds[c], bounds[c + 1], groups, off, rows, J, D, DL, K, S, O, ranks, out,
                 cnt, W)
    return keep_on_disk(run)


def kernel(plan):
    """The `Kernel` of `plan`, and whether it is new (numba compiles it on first call)."""
    got = _KERNELS.get(plan.key)
    if got is not None:
        return got, False
    cond = node(plan.cond)
    fx = node(plan.each[0]) if plan.each else ZERO
    fy = node(plan.each[1]) if len(plan.each) == 2 else ZERO
    family = "filter" if plan.name == "filter" else AGGREGATES[plan.name].kernel
    make = {"sum": _sum_body, "min": _min_body, "max": _max_body,
            "nearest": _nearest_body, "filter": _filter_body}[family]
    k = _KERNELS[plan.key] = Kernel(make(cond, fx, fy, plan.width))
    return k, True


_NO_OWNER = np.zeros((1, 1))   # the owner table of a derived column: none is read


def derived_kernel(tree):
    """The kernel of a derived neighbour column (plan.py): `k(B, out, chunks)` sets
    `out[j]` to `tree` over row j of the neighbours' table B, with the functions the
    pair kernels use (so the same bits as evaluating it pair by pair); and whether
    it is new."""
    key = ("derived", tree)
    got = _KERNELS.get(key)
    if got is not None:
        return got, False
    fn = node(tree)

    @njit(**_INLINE)
    def rows(a, b, B, out):
        for j in range(a, b):
            out[j] = fn(_NO_OWNER, B, 0, j, 0.0, 0.0, 0.0)

    @njit(**_JIT)
    def serial(B, out, chunks):
        rows(0, out.size, B, out)

    @njit(**_JIT, parallel=True)
    def parallel(B, out, chunks):
        n = out.size
        for c in prange(chunks):
            rows(c * n // chunks, (c + 1) * n // chunks, B, out)

    serial, parallel = keep_on_disk(serial), keep_on_disk(parallel)

    def run(B, out, chunks):
        (parallel if chunks > 1 else serial)(B, out, chunks)
    _KERNELS[key] = run
    return run, True


MAX_SIBLINGS = 4   # sums one shared loop adds up (each keeps its sums in registers)


def sums_kernel(plan):
    """The `Kernel` of siblings' sums (`plan`: ("siblings", ((width, cond, each), ...)),
    at most MAX_SIBLINGS of them), and whether it is new. `out` and `cnt` are tuples of
    one (M, 2) and one (M,) array per sibling (one block for all of them would be a
    fresh mapping, paid in page faults, every tick): sibling g's sums and count, added
    in the order its own `_sum_body` adds them."""
    got = _KERNELS.get(plan)
    if got is not None:
        return got, False
    k = _KERNELS[plan] = Kernel(_sums_body(*_slots(plan)))
    return k, True


def direct_kernel(plan, keep=None, batch=False):
    """The `DirectKernel` of siblings' sums (`plan` as for `sums_kernel`; one sum is
    a plan of one) over the pairs filter condition `keep` keeps (None: all), searching
    a solo run's cell list or (`batch`) a batch's, and whether it is new."""
    key = ("direct", keep, plan, batch)
    got = _KERNELS.get(key)
    if got is not None:
        return got, False
    n, *slots = _slots(plan)
    k = _KERNELS[key] = DirectKernel(_direct_body(
        n, node(keep) if keep else TRUE, batch_ranges if batch else solo_ranges, *slots))
    return k, True


def _slots(plan):
    """(n, then condition, x and y functions of each of the MAX_SIBLINGS slots)."""
    fns = []
    for width, cond, each in plan[1]:
        fx = node(each[0]) if each else ZERO
        fy = node(each[1]) if len(each) == 2 else ZERO
        fns += [node(cond), fx, fy]
    n = len(plan[1])
    return (n, *fns, *[FALSE, ZERO, ZERO] * (MAX_SIBLINGS - n))


def _putter(n):
    @njit(**_INLINE)
    def put(out, cnt, g, w, sx, sy, c):
        if g < n:
            o = out[g]
            o[w, 0] = sx
            o[w, 1] = sy
            cnt[g][w] = c
    return put


def _sums_body(n, t0, fx0, fy0, t1, fx1, fy1, t2, fx2, fy2, t3, fx3, fy3):
    """Four slots written out, each sibling's sums in local variables: kept in an
    array, or passed through inlined steps as tuples, the same loop ran 2-4x slower
    than the siblings' own loops (stores and reloads on every pair). Unused slots test
    `FALSE` and compile away."""
    put = _putter(n)

    @njit(**_JIT)
    def body(r0, r1, groups, off, rows, J, D, DL, K, S, O, ranks, out, cnt, W):
        for r in range(r0, r1):
            a, b = _group(r, groups, off)
            x0 = y0 = x1 = y1 = x2 = y2 = x3 = y3 = 0.0
            c0 = c1 = c2 = c3 = 0
            for e in range(a, b):
                if _dropped(e, rows, K):
                    continue
                _p, j, d, dx, dy = _pair(e, rows, J, D, DL)
                if t0(S, O, r, j, d, dx, dy):
                    c0 += 1
                    x0 += fx0(S, O, r, j, d, dx, dy)
                    y0 += fy0(S, O, r, j, d, dx, dy)
                if t1(S, O, r, j, d, dx, dy):
                    c1 += 1
                    x1 += fx1(S, O, r, j, d, dx, dy)
                    y1 += fy1(S, O, r, j, d, dx, dy)
                if t2(S, O, r, j, d, dx, dy):
                    c2 += 1
                    x2 += fx2(S, O, r, j, d, dx, dy)
                    y2 += fy2(S, O, r, j, d, dx, dy)
                if t3(S, O, r, j, d, dx, dy):
                    c3 += 1
                    x3 += fx3(S, O, r, j, d, dx, dy)
                    y3 += fy3(S, O, r, j, d, dx, dy)
            w = _dest(r, W)
            put(out, cnt, 0, w, x0, y0, c0)
            put(out, cnt, 1, w, x1, y1, c1)
            put(out, cnt, 2, w, x2, y2, c2)
            put(out, cnt, 3, w, x3, y3, c3)
    return body


def _direct_body(n, keep, ranges, t0, fx0, fy0, t1, fx1, fy1, t2, fx2, fy2, t3, fx3, fy3):
    """`_sums_body` searching the cell list itself: each owner's candidates in the
    cells around it (`ranges` of the grid G: a solo run's or a batch's, whose owners
    each search their own replica's cells), in the order `cells._fill_once` writes
    them (a batch: `replica_cells._fill_range`), each kept pair's
    `dist` and `delta` computed as it computes them (so the sums have the same bits as
    over the written pairs), and no pair written anywhere; a pair counts if the
    filter `keep` (of tables S2, O2) keeps it. The slots are written out again for
    the reason `_sums_body` gives. `seen[s]` (if given) gets owner s's
    number of pairs: next tick's estimate of where the work is."""
    put = _putter(n)

    @njit(**_JIT)
    def body(r0, r1, groups, sp, G, radius, wrap, bw, bh, S, O, S2, O2, out, cnt, W, seen,
             room):
        lo = np.empty(6, np.int64)
        hi = np.empty(6, np.int64)
        # A tile of owners' pairs, written as write_owner writes them (every candidate at
        # the next free slot, kept only if the pair is), then summed owner by owner.
        # Summing each owner right after its search was 2-3x slower at 10^6 agents: the
        # search's unpredictable branches between owners stall the loads of `O` that a
        # plain loop over a tile's pairs overlaps.
        near = np.empty(room, np.int64)
        near_dist = np.empty(room)
        near_delta = np.empty((room, 2))
        ends = np.empty(room + 1, np.int64)
        within2 = reach2(radius)
        cell, k, wx, wy = -1, 0, wrap, wrap
        r = r0
        while r < r1:
            first, p = r, 0
            while r < r1:
                s = groups[r] if groups.size else r
                cell, k, wx, wy = ranges(s, cell, k, wx, wy, G, wrap, lo, hi)
                most = 0
                for q in range(k):
                    most += hi[q] - lo[q]
                if p + most > room and p > 0:
                    break    # the tile is full: this owner starts the next one
                p = write_owner(s, p, room, k, lo, hi, sp, within2, wx, wy, bw, bh, near,
                                near_dist, near_delta)
                ends[r - first] = p
                r += 1
            a = 0
            for t in range(first, r):
                b = ends[t - first]
                x0 = y0 = x1 = y1 = x2 = y2 = x3 = y3 = 0.0
                c0 = c1 = c2 = c3 = 0
                for e in range(a, b):
                    _p, j, d, dx, dy = _pair(e, _NO_INDEX, near, near_dist, near_delta)
                    if not keep(S2, O2, t, j, d, dx, dy):
                        continue
                    if t0(S, O, t, j, d, dx, dy):
                        c0 += 1
                        x0 += fx0(S, O, t, j, d, dx, dy)
                        y0 += fy0(S, O, t, j, d, dx, dy)
                    if t1(S, O, t, j, d, dx, dy):
                        c1 += 1
                        x1 += fx1(S, O, t, j, d, dx, dy)
                        y1 += fy1(S, O, t, j, d, dx, dy)
                    if t2(S, O, t, j, d, dx, dy):
                        c2 += 1
                        x2 += fx2(S, O, t, j, d, dx, dy)
                        y2 += fy2(S, O, t, j, d, dx, dy)
                    if t3(S, O, t, j, d, dx, dy):
                        c3 += 1
                        x3 += fx3(S, O, t, j, d, dx, dy)
                        y3 += fy3(S, O, t, j, d, dx, dy)
                if seen.size:
                    seen[groups[t] if groups.size else t] = b - a
                w = _dest(t, W)
                put(out, cnt, 0, w, x0, y0, c0)
                put(out, cnt, 1, w, x1, y1, c1)
                put(out, cnt, 2, w, x2, y2, c2)
                put(out, cnt, 3, w, x3, y3, c3)
                a = b
    return body


class DirectKernel:
    """A `_direct_body` run over all its owners, or split at `bounds` (more than one
    run: on numba's threads). Called as (groups, *grid, S, O, S2, O2, out, cnt, W,
    seen, room, bounds), `grid` as `CellPairs.grid` (sorted positions, G, radius,
    wrap, box width and height), (S2, O2) the filter's tables and
    `room` the candidates a tile holds, at least the most any owner has. Serially the
    body itself is called, as in `Kernel`."""

    def __init__(self, body):
        self.body = keep_on_disk(body)
        self._parallel = None

    def __call__(self, *args):
        if args[-1].size > 2 and self._parallel is not False:
            try:
                if self._parallel is None:
                    self._parallel = _direct_parallel(self.body)
                return self._parallel(*args)
            except Exception:   # numba could not thread it: the serial loop, same bits
                self._parallel = False
        groups, sp = args[0], args[1]
        self.body(0, groups.size if groups.size else sp.shape[0], *args[:-1])


def _direct_parallel(body):
    @njit(**_JIT, parallel=True)
    def run(groups, sp, G, radius, wrap, bw, bh, S, O, S2, O2, out, cnt, W, seen, room,
            bounds):
        for c in prange(bounds.size - 1):
            body(bounds[c], bounds[c + 1], groups, sp, G, radius, wrap, bw, bh, S, O, S2,
                 O2, out, cnt, W, seen, room)
    return keep_on_disk(run)


@njit(**_INLINE)
def _group(r, groups, off):
    """(first pair, end) of owner r's group."""
    q = groups[r] if groups.size else r
    return off[q], off[q + 1]


@njit(**_INLINE)
def _pair(q, rows, J, D, DL):
    """(pair row, neighbour, dist, dx, dy) of the q-th entry of a group."""
    p = rows[q] if rows.size else q
    return p, J[p], D[p], DL[p, 0], DL[p, 1]


@njit(**_INLINE)
def _dest(r, W):
    """The row of `out` and `cnt` owner r's results go to."""
    return W[r] if W.size else r


@njit(**_INLINE)
def _dropped(q, rows, K):
    """Whether the q-th entry of a group is outside the set's mask `K`."""
    return K.size > 0 and not K[rows[q] if rows.size else q]


def _sum_body(cond, fx, fy, width):
    two = width == 2

    @njit(**_JIT)
    def body(r0, r1, groups, off, rows, J, D, DL, K, S, O, ranks, out, cnt, W):
        for r in range(r0, r1):
            a, b = _group(r, groups, off)
            sx = 0.0
            sy = 0.0
            c = 0
            for e in range(a, b):
                if _dropped(e, rows, K):
                    continue
                _p, j, d, dx, dy = _pair(e, rows, J, D, DL)
                if not cond(S, O, r, j, d, dx, dy):
                    continue
                c += 1
                sx += fx(S, O, r, j, d, dx, dy)
                if two:
                    sy += fy(S, O, r, j, d, dx, dy)
            w = _dest(r, W)
            out[w, 0] = sx
            out[w, 1] = sy
            cnt[w] = c
    return body


def _extreme_body(cond, fx, better):
    @njit(**_JIT)
    def body(r0, r1, groups, off, rows, J, D, DL, K, S, O, ranks, out, cnt, W):
        for r in range(r0, r1):
            a, b = _group(r, groups, off)
            best = 0.0
            c = 0
            for e in range(a, b):
                if _dropped(e, rows, K):
                    continue
                _p, j, d, dx, dy = _pair(e, rows, J, D, DL)
                if not cond(S, O, r, j, d, dx, dy):
                    continue
                v = fx(S, O, r, j, d, dx, dy)
                c += 1
                if c == 1 or (best == best and (v != v or better(v, best))):
                    best = v     # np.minimum.reduceat: a NaN stays
            w = _dest(r, W)
            out[w, 0] = best
            out[w, 1] = 0.0
            cnt[w] = c
    return body


@njit(**_INLINE)
def _less(a, b):
    return a < b


@njit(**_INLINE)
def _greater(a, b):
    return a > b


def _min_body(cond, fx, fy, width):
    return _extreme_body(cond, fx, _less)


def _max_body(cond, fx, fy, width):
    return _extreme_body(cond, fx, _greater)


def _nearest_body(cond, fx, fy, width):
    @njit(**_JIT)
    def body(r0, r1, groups, off, rows, J, D, DL, K, S, O, ranks, out, cnt, W):
        for r in range(r0, r1):
            a, b = _group(r, groups, off)
            c = 0
            best = -1
            bd = math.inf
            bj = -1
            bt = -1
            for e in range(a, b):
                if _dropped(e, rows, K):
                    continue
                p, j, d, dx, dy = _pair(e, rows, J, D, DL)
                if not cond(S, O, r, j, d, dx, dy):
                    continue
                c += 1
                tie = ranks[j] if ranks.size else j
                if best < 0 or d < bd or (d == bd and tie < bt):   # ties: the lowest row
                    best, bd, bj, bt = p, d, j, tie
            w = _dest(r, W)
            out[w, 0] = 0.0
            out[w, 1] = 0.0
            if best >= 0:
                bx = DL[best, 0]
                by = DL[best, 1]
                out[w, 0] = fx(S, O, r, bj, bd, bx, by)
                out[w, 1] = fy(S, O, r, bj, bd, bx, by)
            cnt[w] = c
    return body


def _filter_body(cond, fx, fy, width):
    @njit(**_JIT)
    def body(r0, r1, groups, off, rows, J, D, DL, K, S, O, ranks, out, cnt, W):
        for r in range(r0, r1):
            a, b = _group(r, groups, off)
            c = 0
            for e in range(a, b):
                if _dropped(e, rows, K):
                    continue
                p, j, d, dx, dy = _pair(e, rows, J, D, DL)
                if cond(S, O, r, j, d, dx, dy):
                    out[p] = True
                    c += 1
            cnt[_dest(r, W)] = c
    return body
