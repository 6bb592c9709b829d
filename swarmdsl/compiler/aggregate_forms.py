"""What each aggregate computes, in both of its array forms: from the neighbour pairs
(the reference, numpy) and from a compiled kernel's per-owner accumulators (the numba
backend's fused loops). Each aggregate's row (`builtins.AGGREGATES`) names its two forms
here and the kernel family whose loop accumulates for it (`sum`: a running sum and a
count; `min`, `max`; `nearest`: the value at the least distance), so a new aggregate
whose accumulation is one of these is its row and its two forms, nothing in the
backends.

Reference forms take `(pairs, m, values, fallback, vtype)`: the owner frame's
neighbour set, its number of rows, and two thunks (EACH per pair, the `else` per row),
called only where the answer needs them. Finishing forms take `(value, cnt, fallback,
vtype)`: the kernel's accumulator per owner (a column, or two for a vector) and its
count. Both give the same bits (`tests/test_compiled.py` runs them side by side).
"""

from __future__ import annotations

import numpy as np

from swarmdsl.ops.types import VEC
from swarmdsl.runtime import spatial


def _col(a):
    a = np.asarray(a)
    return a[..., None] if a.ndim >= 1 else a


def _where(test, a, b, vtype):
    return np.where(_col(test), a, b) if vtype == VEC else np.where(test, a, b)


# ---- from the pairs (the reference) ----
def count_pairs(pairs, m, values, fallback, vtype):
    return spatial.segment_count(pairs.seg, m)


def sum_pairs(pairs, m, values, fallback, vtype):
    return spatial.segment_sum(np.asarray(values(), float), pairs.seg, m)


def mean_pairs(pairs, m, values, fallback, vtype):
    seg = pairs.seg
    counts = spatial.segment_count(seg, m)
    total = spatial.segment_sum(np.asarray(values(), float), seg, m)
    c = _col(counts) if vtype == VEC else counts
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = total / np.maximum(c, 1)
    return _where(counts > 0, mean, fallback(), vtype)


def _extreme_pairs(ufunc):
    def extreme(pairs, m, values, fallback, vtype):
        seg = pairs.seg
        counts = spatial.segment_count(seg, m)
        out = spatial.segment_extreme(ufunc, np.asarray(values()), seg, m, 0.0)
        return np.where(counts > 0, out, fallback())
    return extreme


min_pairs = _extreme_pairs(np.minimum)
max_pairs = _extreme_pairs(np.maximum)


def nearest_pairs(pairs, m, values, fallback, vtype):
    """Equally near neighbours: the lowest row, whatever the pair order."""
    segs, rows = spatial.segment_argmin(pairs.dist, pairs.seg, m, tie=pairs.j)
    out = np.array(fallback(), copy=True)
    out[segs] = np.asarray(values())[rows]
    return out


def _hits(pairs, m, values):
    seg = pairs.seg
    hits = np.bincount(seg, weights=np.asarray(values(), float), minlength=m)
    return hits, spatial.segment_count(seg, m)


def any_pairs(pairs, m, values, fallback, vtype):
    hits, _counts = _hits(pairs, m, values)
    return hits > 0


def all_pairs(pairs, m, values, fallback, vtype):
    hits, counts = _hits(pairs, m, values)
    return hits == counts


# ---- from a kernel's accumulators ----
def count_finish(value, cnt, fallback, vtype):
    return cnt.astype(np.float64)


def sum_finish(value, cnt, fallback, vtype):
    return value


def mean_finish(value, cnt, fallback, vtype):
    vec = value.ndim == 2
    mean = value / np.maximum(cnt[:, None] if vec else cnt, 1)
    keep = cnt > 0
    return np.where(keep[:, None] if vec else keep, mean, fallback())


def extreme_finish(value, cnt, fallback, vtype):
    return np.where(cnt > 0, value, fallback())


def nearest_finish(value, cnt, fallback, vtype):
    result = np.array(fallback(), copy=True)
    has = cnt > 0
    result[has] = value[has]
    return result


def any_finish(value, cnt, fallback, vtype):
    return value > 0


def all_finish(value, cnt, fallback, vtype):
    return value == cnt
