"""Fused statement kernels: one loop over a frame's agents per `let` or assignment.

The value trees are composed into jitted functions by `kernels.node`, as an aggregate's
are: each node reads one agent `r` of `(S, K, r, 0, 0.0, 0.0, 0.0)` (the pair arguments
stay unused; `K` is the statement's constants as the one row of a neighbour table). One
loop per statement stores the plan's shared subtrees in their columns of `S`, evaluates
the trees, applies the assignment's operator to the current value, finds the first
running agent whose result is not finite (assignment) or is NaN (`let`), and writes the
result, keeping the current value of agents that are not running. Memoised by the
plan's shape for the life of the process, like the aggregate kernels.

The loop costs tens of nanoseconds an agent (boids' two statements: 1.1 ms at 10^5
agents), but a statement of the portable transcendental functions costs more (Vicsek's
`velocity = unit(angle(...) + uniform(...)) * v0`: some 90 ns an agent, a fifth of a
tick at 10^6 agents), so from `THREADS_FROM` agents it is split over numba's threads
(the call that compiles the threaded form counts as compiling, `Backend.compile_seconds`).
Beside another busy process on two cores threads made it slower (10^5: 7 ms on two
threads against 1.1 ms serial; 3 * 10^5: 6.9 against 3.3 ms): a run's ticks then go
serial as a whole (`threads.Pace`).
"""

from __future__ import annotations

import math
import time

import numpy as np

from swarmdsl.runtime.compiled import threads
from swarmdsl.runtime.compiled.disk_cache import keep_on_disk
from swarmdsl.runtime.compiled.jit import njit, prange
from swarmdsl.runtime.compiled.kernels import node

_JIT = {"nogil": True, "error_model": "numpy"}
_INLINE = {**_JIT, "inline": "always"}
_KERNELS: dict = {}    # plan key -> its `Loop`
# Threaded from this many agents (`Loop`); below it the thread pool's start and join
# cost more than they save. At most the tiered start's warm-up swarm (`warmup.AGENTS`),
# so a first big run finds the threaded loops compiled on disk with the rest.
THREADS_FROM = 20_000


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


def kernel(plan):
    """The jitted loop of `plan` (numba compiles it on its first call).

    Call: `k(S, K, cur, active, out)` -> the first agent row whose result fails the
    check among the `active` ones, or -1. `S` (M, columns) and `cur` (M, width: an
    assignment's current values) are read and `out` (M, width) written in agent order.
    """
    got = _KERNELS.get(plan.key)
    if got is not None:
        return got
    fx = node(plan.value[0])
    fy = node(plan.value[1]) if len(plan.value) == 2 else fx
    first = _nothing
    for col, tree in plan.stages:
        first = _then(first, node(tree), col)
    k = _KERNELS[plan.key] = _body(first, fx, fy, plan.width == 2, len(plan.value) == 2,
                                   _APPLY[plan.op], plan.what == "assign")
    return k


@njit(**_INLINE)
def _nothing(S, K, r):
    return None


def _then(before, fn, col):
    """`before`, then a shared subtree's value stored in its column of agent r's row."""
    @njit(**_INLINE)
    def stage(S, K, r):
        before(S, K, r)
        S[r, col] = fn(S, K, r, 0, 0.0, 0.0, 0.0)
    return stage


def _body(first, fx, fy, two, pair, apply, assign):
    """`first` stores the shared subtrees; `two`: the result is a vector; `pair`: so is
    the value (else a number applied to both components); `assign`: apply to `cur`,
    check finiteness, keep idle agents' values (a `let` checks for NaN only and writes
    every agent)."""
    @njit(**_INLINE)
    def rows(r0, r1, S, K, cur, active, out):
        bad = -1
        for r in range(r0, r1):
            first(S, K, r)
            x = fx(S, K, r, 0, 0.0, 0.0, 0.0)
            y = x
            if pair:
                y = fy(S, K, r, 0, 0.0, 0.0, 0.0)
            if assign:
                x = apply(cur[r, 0], x)
                if two:
                    y = apply(cur[r, 1], y)
                if bad < 0 and active[r]:
                    if not math.isfinite(x) or (two and not math.isfinite(y)):
                        bad = r
                if active[r]:
                    out[r, 0] = x
                    if two:
                        out[r, 1] = y
                else:
                    out[r, 0] = cur[r, 0]
                    if two:
                        out[r, 1] = cur[r, 1]
            else:
                if bad < 0 and active[r] and (x != x or (two and y != y)):
                    bad = r
                out[r, 0] = x
                if two:
                    out[r, 1] = y
        return bad

    @njit(**_JIT)
    def body(S, K, cur, active, out):
        return rows(0, out.shape[0], S, K, cur, active, out)

    @njit(**_JIT, parallel=True)
    def parallel(S, K, cur, active, out, chunks):
        n = out.shape[0]
        bads = np.empty(chunks, np.int64)
        for c in prange(chunks):
            bads[c] = rows(c * n // chunks, (c + 1) * n // chunks, S, K, cur, active, out)
        for c in range(chunks):   # the first failing agent, as the serial loop finds
            if bads[c] >= 0:
                return bads[c]
        return -1
    return Loop(keep_on_disk(body), parallel)


class Loop:
    """A statement's loop: `loop(S, K, cur, active, out)` -> the first failing row or
    -1, serial, or over `THREADS_FROM` agents split into runs on numba's threads (each
    agent's result is its own, so the bits do not depend on the split; its threaded
    form is compiled on first use)."""

    def __init__(self, body, parallel):
        self.body = body
        self._make = parallel
        self._parallel = None
        self.compile_seconds = 0.0   # the threaded form's compiling (or loading) call

    def __call__(self, S, K, cur, active, out):
        m = out.shape[0]
        chunks = threads.chunks(m) if m >= THREADS_FROM else 1
        if chunks > 1 and self._parallel is not False:
            try:
                if self._parallel is None:
                    t0 = time.perf_counter()
                    self._parallel = keep_on_disk(self._make)
                    bad = self._parallel(S, K, cur, active, out, chunks)
                    self.compile_seconds += time.perf_counter() - t0
                    return bad
                return self._parallel(S, K, cur, active, out, chunks)
            except Exception:   # numba could not thread it: the serial loop, same bits
                self._parallel = False
        return self.body(S, K, cur, active, out)
