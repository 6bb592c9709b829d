"""Behaviour trees inside the whole-tick kernel: a `tree_plan` tree step composed into
jitted functions of one agent, each node one function that returns its result.

The reference (`runtime/trees.py`) ticks a node for a mask of rows and returns masks;
here one agent walks its tree, a node returning `RUN`, `SUCC` or `FAIL` (the
reference's codes) or `HALT_ALL` when a check failed (the kernel then stops before the
tick commits and the tick runs on the per-tick path, which raises the located error).
Each node does for its agent what the reference does for that agent's row, in the
same order: the same memory read (valid only when its stamp is the tick before and
the tree's is too), the same writes, the same halts. Leaves run their statement steps
(`tick_kernel`'s) when the walk reaches them, so they read the agent's own writes made
earlier in the tick, as the reference's frame does.

Memory lives in the state table (`tick_plan.TableLayout`: the tree columns, as
floats; stamps and counts are whole numbers far below 2**53).
"""

from __future__ import annotations

import math

import numpy as np

from swarmdsl.runtime.compiled.jit import njit

RUN, SUCC, FAIL, HALT_ALL = 0, 1, 2, 3
NEVER = -2.0   # `trees.NEVER`
_INLINE = {"nogil": True, "error_model": "numpy", "_nrt": False}
# The walks along a composite's children, and the small helpers, are inlined into
# their caller, as `tick_kernel` inlines its sequences of steps: each node is then one
# function of calls to its children's (fewer functions to compile and link again).
_FLAT = {**_INLINE, "inline": "always"}


def tree_step(st, steps_of, go: int, abort: int):
    """The kernel step of `("bt", ...)` step `st`; `steps_of(steps)` composes a leaf's
    statement steps, which return `go` or `abort`."""
    _bt, root, stamp, clocks, result, tick_col, flag, leaf_col, code_col = st
    node = _node(root, steps_of, abort, leaf_col)
    memory = stamp >= 0
    reset = _columns_to(clocks, -1.0)

    @njit(**_INLINE)
    def step(A, B, S, T, ids, G, W, keys, called, i):
        tick = A[i, tick_col]
        valid = memory and B[i, stamp] == tick - 1.0
        if not valid:
            reset(B, i)      # a cooldown's deadline of an earlier stay is void
        B[i, leaf_col] = 0.0   # no leaf yet: each leaf the walk reaches notes itself
        r = node(A, B, S, T, ids, G, W, keys, called, i, valid, tick)
        if r == HALT_ALL:
            return abort
        S[i, result] = float(r)
        B[i, code_col] = float(r + 1)
        if memory:
            B[i, stamp] = tick
        if flag >= 0:
            S[0, flag] = 1.0    # the statement ran this tick (`Tree._left`'s effect)
        return go
    return step


def _columns_to(cols: tuple, value: float):
    """A function setting the agent's state-table columns `cols` to `value`."""
    fn = _nothing_to_set
    for c in cols:
        fn = _set_then(fn, c, value)
    return fn


@njit(**_FLAT)
def _nothing_to_set(B, i):
    return None


def _set_then(before, col, value):
    @njit(**_FLAT)
    def fn(B, i):
        before(B, i)
        B[i, col] = value
    return fn


@njit(**_FLAT)
def _read(B, i, valid, tick, stamp, value, fill):
    """`Stateful.read`: the node's value kept from the tick before, else its fill."""
    if valid and B[i, stamp] == tick - 1.0:
        return B[i, value]
    return fill


@njit(**_FLAT)
def _keep(B, i, stamp, value, v, tick):
    """`Stateful.write`: the node keeps `v` until the next tick."""
    B[i, value] = v
    B[i, stamp] = tick


def _node(n, steps_of, abort, leaf_col):
    what = n[0]
    if what == "walk":
        return _walk(n, steps_of, abort, leaf_col)
    if what == "par":
        return _parallel(n, steps_of, abort, leaf_col)
    if what == "inv":
        return _invert(n[1], _node(n[2], steps_of, abort, leaf_col))
    if what == "rep":
        return _repeat(n, _node(n[5], steps_of, abort, leaf_col))
    if what == "timeout":
        return _timeout(n, _node(n[4], steps_of, abort, leaf_col))
    if what == "cool":
        return _cooldown(n, _node(n[3], steps_of, abort, leaf_col))
    # a leaf notes itself first as the agent's active leaf (`Leaf.tick`)
    noted = (leaf_col, float(n[-1]))
    if what in ("cond", "act"):
        return _leaf(steps_of(n[1]), _truth(n[2] if what == "cond" else -1), abort, noted)
    if what == "move":
        return _leaf(steps_of(n[1]), _move_to(n), abort, noted)
    if what == "wait":
        return _wait(*n[1:4], noted)
    raise ValueError(f"internal: no tree node `{what}`")


# ---- composites ----

@njit(**_FLAT)
def _walk_end(A, B, S, T, ids, G, W, keys, called, i, valid, tick, start):
    return -1     # every child went on: the composite's own end result


def _walk(n, steps_of, abort, leaf_col):
    """`Sequence.tick` for one agent: from the running child kept (memory form) or the
    first, on while children give `go_on`; a running child is kept."""
    _w, fallback, stateful, stamp, value, kids = n
    stop = SUCC if fallback else FAIL
    rest = _walk_end
    for k in range(len(kids) - 1, -1, -1):
        rest = _child(k, _node(kids[k][0], steps_of, abort, leaf_col), kids[k][1], stop,
                      stateful, stamp, value, rest)
    end = FAIL if fallback else SUCC

    @njit(**_INLINE)
    def walk(A, B, S, T, ids, G, W, keys, called, i, valid, tick):
        start = 0
        if stateful:
            start = int(_read(B, i, valid, tick, stamp, value, 0.0))
        r = rest(A, B, S, T, ids, G, W, keys, called, i, valid, tick, start)
        return end if r < 0 else r
    return walk


def _child(k, kid, can_run, stop, stateful, stamp, value, rest):
    @njit(**_FLAT)
    def child(A, B, S, T, ids, G, W, keys, called, i, valid, tick, start):
        if start <= k:
            r = kid(A, B, S, T, ids, G, W, keys, called, i, valid, tick)
            if r == HALT_ALL or r == stop:
                return r
            if can_run and r == RUN:
                if stateful:
                    _keep(B, i, stamp, value, float(k), tick)
                return RUN
        return rest(A, B, S, T, ids, G, W, keys, called, i, valid, tick, start)
    return child


@njit(**_FLAT)
def _par_end(A, B, S, T, ids, G, W, keys, called, i, valid, tick, bits, got, ns, nf):
    return got, ns, nf, True


def _parallel(n, steps_of, abort, leaf_col):
    """`Parallel.tick` for one agent: each child not finished before ticks; two bits a
    child keep its result (memory form); on completion every child is halted."""
    _p, k, reactive, stamp, value, kids, halts = n
    rest = _par_end
    for c in range(len(kids) - 1, -1, -1):
        rest = _par_child(c, _node(kids[c], steps_of, abort, leaf_col), rest)
    halt = _columns_to(halts, NEVER)
    total = len(kids)

    @njit(**_INLINE)
    def parallel(A, B, S, T, ids, G, W, keys, called, i, valid, tick):
        bits = 0
        if not reactive:
            bits = int(_read(B, i, valid, tick, stamp, value, 0.0))
        got, ns, nf, ok = rest(A, B, S, T, ids, G, W, keys, called, i, valid, tick, bits,
                               bits, 0, 0)
        if not ok:
            return HALT_ALL
        succ = ns >= k
        fail = not succ and nf > total - k
        if succ or fail:
            halt(B, i)
        elif not reactive:
            _keep(B, i, stamp, value, float(got), tick)
        return SUCC if succ else (FAIL if fail else RUN)
    return parallel


def _par_child(c, kid, rest):
    sb, fb = 1 << (2 * c), 1 << (2 * c + 1)

    @njit(**_FLAT)
    def child(A, B, S, T, ids, G, W, keys, called, i, valid, tick, bits, got, ns, nf):
        had_s = (bits & sb) != 0
        had_f = (bits & fb) != 0
        s = f = False
        if not had_s and not had_f:
            r = kid(A, B, S, T, ids, G, W, keys, called, i, valid, tick)
            if r == HALT_ALL:
                return got, ns, nf, False
            s, f = r == SUCC, r == FAIL
            if s:
                got |= sb
            if f:
                got |= fb
        if had_s or s:
            ns += 1
        if had_f or f:
            nf += 1
        return rest(A, B, S, T, ids, G, W, keys, called, i, valid, tick, bits, got, ns, nf)
    return child


# ---- decorators ----

def _invert(mode, kid):
    @njit(**_INLINE)
    def invert(A, B, S, T, ids, G, W, keys, called, i, valid, tick):
        r = kid(A, B, S, T, ids, G, W, keys, called, i, valid, tick)
        if r == RUN or r == HALT_ALL:
            return r
        if mode == 0:
            return FAIL if r == SUCC else SUCC
        return SUCC if mode == 1 else FAIL
    return invert


def _repeat(n, kid):
    """`Repeat.decorate` (`retry` its dual): the count read before the child runs."""
    _r, retry, stamp, value, count_col, _child = n
    again_on = FAIL if retry else SUCC
    other_on = SUCC if retry else FAIL

    @njit(**_INLINE)
    def repeat(A, B, S, T, ids, G, W, keys, called, i, valid, tick):
        limit = A[i, count_col]
        if not limit >= 1:
            return FAIL if retry else SUCC
        count = _read(B, i, valid, tick, stamp, value, 0.0)
        r = kid(A, B, S, T, ids, G, W, keys, called, i, valid, tick)
        if r == HALT_ALL:
            return r
        if r == again_on:
            count += 1.0
            if count >= limit:
                return FAIL if retry else SUCC
        elif r == other_on:
            return r
        _keep(B, i, stamp, value, count, tick)
        return RUN
    return repeat


def _timeout(n, kid):
    """`Timeout.decorate`: a child still running on the Nth tick is halted."""
    _t, stamp, value, count_col, _child, halts = n
    halt = _columns_to(halts, NEVER)

    @njit(**_INLINE)
    def timeout(A, B, S, T, ids, G, W, keys, called, i, valid, tick):
        elapsed = _read(B, i, valid, tick, stamp, value, 0.0) + 1.0
        limit = A[i, count_col]
        r = kid(A, B, S, T, ids, G, W, keys, called, i, valid, tick)
        if r != RUN:
            return r
        if elapsed >= limit:
            halt(B, i)
            return FAIL
        _keep(B, i, stamp, value, elapsed, tick)
        return RUN
    return timeout


def _cooldown(n, kid):
    """`Cooldown.decorate`: fails without ticking its child until its deadline."""
    _c, ready, count_col, _child = n

    @njit(**_INLINE)
    def cooldown(A, B, S, T, ids, G, W, keys, called, i, valid, tick):
        if tick < B[i, ready]:
            return FAIL
        wait = A[i, count_col]
        r = kid(A, B, S, T, ids, G, W, keys, called, i, valid, tick)
        if r == SUCC or r == FAIL:
            B[i, ready] = tick + 1.0 + math.floor(wait)
        return r
    return cooldown


# ---- leaves ----

def _leaf(steps, then, abort, noted):
    """A leaf with statement steps: noted as the agent's active leaf, its steps run
    (a check that fails stops the kernel), then `then` gives its result."""
    leaf_col, leaf_id = noted

    @njit(**_FLAT)
    def leaf(A, B, S, T, ids, G, W, keys, called, i, valid, tick):
        B[i, leaf_col] = leaf_id
        if steps(A, B, S, T, ids, G, W, keys, called, i) == abort:
            return HALT_ALL
        return then(A, B, S, i)
    return leaf


def _truth(col):
    """A condition's result: its value in scratch column `col`; -1: an instant action,
    which succeeds."""
    @njit(**_FLAT)
    def truth(A, B, S, i):
        return SUCC if col < 0 or S[i, col] != 0.0 else FAIL
    return truth


def _wait(stamp, value, count_col, noted):
    leaf_col, leaf_id = noted

    @njit(**_FLAT)
    def wait(A, B, S, T, ids, G, W, keys, called, i, valid, tick):
        B[i, leaf_col] = leaf_id
        elapsed = _read(B, i, valid, tick, stamp, value, 0.0) + 1.0
        if elapsed > A[i, count_col]:
            return SUCC
        _keep(B, i, stamp, value, elapsed, tick)
        return RUN
    return wait


def _move_to(n):
    """`MoveTo.act` after its steps: straight at the target (the short way round a
    wrap-around world), arriving exactly; velocity 0 once within `tol`."""
    _m, _steps, tx, ty, tol, speed, wrap, bw, bh, P, V, MS, _leaf_id = n
    given = speed >= 0

    @njit(**_FLAT)
    def move_to(A, B, S, i):
        dx = S[i, tx] - B[i, P]
        dy = S[i, ty] - B[i, P + 1]
        if wrap:
            dx = dx - bw * np.rint(dx / bw)
            dy = dy - bh * np.rint(dy / bh)
        dist = np.sqrt(dx * dx + dy * dy)
        arrived = dist <= S[i, tol]
        if given:
            sp = S[i, speed]
        else:
            sp = A[i, MS]          # the store's max_speed, as `_speed` reads it
            if not math.isfinite(sp):
                sp = 1.0
        step = sp if sp != sp or sp < dist else dist    # np.minimum: NaN stays
        if dist != dist:
            step = dist
        if arrived or dist == 0.0:
            vx = vy = 0.0
        else:
            vx = dx / dist * step
            vy = dy / dist * step
        if not (math.isfinite(vx) and math.isfinite(vy)):
            return HALT_ALL
        B[i, V] = vx
        B[i, V + 1] = vy
        return SUCC if arrived else RUN
    return move_to
