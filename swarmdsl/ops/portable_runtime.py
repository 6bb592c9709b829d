"""The runtime's own functions built on the portable math (`portable.py`): no builtin of
the language, but evaluated by the runtime with the same bits on every machine and
backend. `tanh` is a network's activation (`runtime/nn.py`), `log1p` the direction
choice's weights (`runtime/environment.py`, `choose`).

Each has its array form; `log1p` also its one-float form beside it, which the numba
backend compiles into a loop (`compiled/math_loops.py`, `RUNTIME_ONLY`) and hands the
arrays to that the portable math hands to its loops (`portable.by_loop`).
"""

from __future__ import annotations

import fractions

import numpy as np

from swarmdsl.ops.portable import INF, by_loop, exp_array, log, log_array

_TANH_SERIES = tuple(float(c) for c in (  # tanh x = x (1 + c1 x^2 + c2 x^4 + ...), |x| < 1/16
    fractions.Fraction(-1, 3), fractions.Fraction(2, 15), fractions.Fraction(-17, 315),
    fractions.Fraction(62, 2835), fractions.Fraction(-1382, 155925),
    fractions.Fraction(21844, 6081075)))


def tanh_array(x):
    """tanh, within 5 ulp: an odd series near 0, (e^2x - 1) / (e^2x + 1) beyond."""
    x = np.asarray(x, dtype=np.float64)
    ax = np.abs(x)
    z = x * x
    c1, c2, c3, c4, c5, c6 = _TANH_SERIES
    small = x + x * (z * (c1 + z * (c2 + z * (c3 + z * (c4 + z * (c5 + z * c6))))))
    t = exp_array(2.0 * np.minimum(ax, 22.0))
    with np.errstate(all="ignore"):
        big = np.copysign((t - 1.0) / (t + 1.0), x)
    return np.where(ax < 0.0625, small, np.where(ax > 22.0, np.copysign(1.0, x), big))


def log1p(x):
    """`log1p_array` of one float (the numba backend's loop of it)."""
    u = 1.0 + x
    if u == 1.0 or x != x:
        return x
    if x == INF:
        return INF
    return log(u) * (x / (u - 1.0))


def log1p_array(x):
    """log(1 + x), accurate for small x too (the log of the rounded 1 + x, corrected by
    how much rounding moved it)."""
    out = by_loop("log1p", (x,))
    if out is not None:
        return out
    x = np.asarray(x, dtype=np.float64)
    u = 1.0 + x
    with np.errstate(all="ignore"):
        corrected = log_array(u) * (x / (u - 1.0))
    return np.where((u == 1.0) | (x != x), x, np.where(x == INF, INF, corrected))
