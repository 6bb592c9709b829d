"""`choose(K, persistence, attraction...)` in two compiled loops, the same bits as the
reference's array forms (`runtime/choice.py`, `Environment.choose`).

An ant's choice is a few dozen numpy calls on (M, K) arrays: distances to the regions,
their bearings' cosines, the attractions' `log1p`, the row maxima, `exp`, the base
weights, the cumulative sums and the draw's pick. In a small swarm each call costs its
fixed few microseconds, not its values: a quarter of aco's tick on numba. Here the
bearing scores of a region kind (all circles) are one loop, and the logits, weights
and pick of every agent another; field samples stay the field's own compiled loop.

Each value is computed by the operations the array forms apply, in their order, with
the portable math's one-float forms (`kernels.scalar_function`), so a numba tick picks
the same direction as a numpy tick: `tests/test_direction_choice.py` holds them to
each other.
"""

from __future__ import annotations

import math

import numpy as np

from swarmdsl.ops import portable_runtime
from swarmdsl.runtime.compiled.disk_cache import keep_on_disk
from swarmdsl.runtime.compiled.jit import njit
from swarmdsl.runtime.compiled.kernels import scalar_function

_LOOPS: list = []   # (scores, pick), compiled on first use


def loops():
    """(scores, pick): the jitted loops, made once per process."""
    if not _LOOPS:
        _LOOPS.extend(_build())
    return _LOOPS


def _build():
    hypot, atan2, cos, exp = (scalar_function(n) for n in ("hypot", "atan2", "cos", "exp"))
    log1p = njit(nogil=True, error_model="numpy", inline="always")(portable_runtime.log1p)

    @njit(nogil=True, error_model="numpy", inline="always")
    def short_way(d, period):
        return d - period * np.rint(d / period)

    @njit(nogil=True, error_model="numpy")
    def scores(pos, look, cx, cy, rad, bits, known, centers, angles, box, wrap, out):
        """`Environment._bearing_scores` over circles: each agent's (K,) closeness of
        the directions to the nearest region it sees (`known`: one row of label bits
        an agent, or none)."""
        m, k, n = pos.shape[0], angles.shape[0], cx.shape[0]
        for i in range(m):
            x, y = pos[i, 0], pos[i, 1]
            best, nearest, any_seen = math.inf, 0, False   # argmin's: the first least
            for j in range(n):
                dx, dy = x - cx[j], y - cy[j]
                if box[0] > 0.0:
                    dx, dy = short_way(dx, box[0]), short_way(dy, box[1])
                d = hypot(dx, dy) - rad[j]
                if not d >= 0.0 and d == d:   # np.maximum(d, 0): NaN stays NaN
                    d = 0.0
                seen = d > 0.0 and d <= look[i]
                if seen and known.shape[0] > 0:
                    seen = (known[i] & bits[j]) == 0
                any_seen = any_seen or seen
                if seen and d < best:
                    best, nearest = d, j
            if not any_seen:
                for a in range(k):
                    out[i, a] = 0.0
                continue
            tx, ty = centers[nearest, 0] - x, centers[nearest, 1] - y
            if wrap[0] > 0.0:
                tx, ty = short_way(tx, wrap[0]), short_way(ty, wrap[1])
            bearing = atan2(ty, tx)
            for a in range(k):
                c = cos(angles[a] - bearing)
                out[i, a] = c if c > 0.0 or c != c else 0.0

    @njit(nogil=True, error_model="numpy")
    def pick(S, G, table, heading, to_index, draws, out):
        """`weighted_direction_choice` of each agent with `exp(logits - max)` as its
        extra weights, the logits summed over the attractions in order (`S` (A, M, K)
        scores, `G` (A, M) gains). Returns 0, or 1 when an extra weight is NaN (the
        reference's `weights_extra` error)."""
        a_n, m, k = S.shape[0], S.shape[1], S.shape[2]
        logits = np.empty(k)
        w = np.empty(k)
        for i in range(m):
            current = np.int64(np.rint(heading[i] * to_index)) % k
            for a in range(k):
                logits[a] = 0.0
            for t in range(a_n):
                g = G[t, i]
                for a in range(k):
                    s = S[t, i, a]
                    if not s >= 0.0 and s == s:
                        s = 0.0
                    logits[a] += g * log1p(s)
            top = logits[0]
            for a in range(1, k):
                v = logits[a]
                if v > top or v != v:
                    top = v
            for a in range(k):
                e = exp(logits[a] - top)
                if e != e:
                    return 1
                w[a] = table[current, a] * e
            last = k - 1   # the last direction of positive weight (none: the last)
            for a in range(k - 1, -1, -1):
                if w[a] > 0.0:
                    last = a
                    break
            total = w[0]   # the cumulative sums, in order, as numpy's cumsum
            for a in range(1, k):
                total += w[a]
            u = draws[i] * total
            chosen, cum = 0, 0.0
            for a in range(k):
                cum = w[a] if a == 0 else cum + w[a]
                if cum <= u:
                    chosen += 1
            out[i] = min(chosen, last) if total > 0.0 else current
        return 0

    return keep_on_disk(scores), keep_on_disk(pick)
