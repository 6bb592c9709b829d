"""The transcendental functions, with the same bits on every machine and in every evaluator.

numpy picks a SIMD loop for `exp`, `log`, `tan`, `arctan2`, `power`... by what the CPU
offers (on AVX-512 machines Intel's SVML), and those round differently from the C
library that Python's `math` and numba call: one ulp apart in about one value in twenty
(`2.5 ^ 2.5` gave ...186 folded and ...185 per agent). A run would then depend on the
CPU it ran on, and the two backends would disagree. So the language computes each of
them here, from IEEE-754 operations that every machine rounds alike (`+ - * /`, `sqrt`,
comparisons, `frexp`, `ldexp`, `fmod`), with no fused multiply-add (numba's default
leaves none, numpy never fuses two ufuncs, CPython neither).

Each function's arithmetic is written once (the `_..._core` functions: operators only,
so one body serves a float and an array alike), and wrapped twice: `name(x)` over one
float picks its special cases with `if` (constant folding calls it; the numba kernels
compile it, with the helpers in `SCALAR_HELPERS`), `name_array(x)` over numpy arrays
picks them with `where` (the reference closures). `tests/test_portable_math.py` holds the
two to each other bit for bit and to the C library within an ulp; `docs/backends.md`
says what this guarantees.

The methods are the classic ones of Sun's freely distributable fdlibm (Cody-Waite
argument reduction, its minimax polynomials); `pow` is `exp(y log x)` carried in
double-double, with a table of `log(c)` made at import with `decimal` (exact to the
last bit on every machine). Accuracy, measured against glibc over millions of
arguments: `exp`, `log`, `sin`, `cos`, `atan2`, `hypot`, `pow` within 1 ulp, `tan`
within 2; `sin`, `cos`, `tan` reduce exactly for |x| < 2^20 pi/2 (1.6e6 radians),
beyond which the argument is first taken modulo the double nearest 2 pi (absolute error
about 4e-17 |x|).
"""

from __future__ import annotations

import decimal
import math

import numpy as np

NAN = math.nan
INF = math.inf
_RNE = 6755399441055744.0          # 1.5 * 2^52: (x + _RNE) - _RNE rounds |x| < 2^51 to even
_sqrt = np.sqrt                    # correctly rounded on every machine (IEEE 754)
_SPLIT = 134217729.0               # 2^27 + 1: Veltkamp's split into two 26-bit halves

# ---- ln 2 in two parts: k * _LN2_HI is exact for |k| < 2^21 ----
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_INV_LN2 = 1.44269504088896338700e+00

# ---- exp: fdlibm's rational approximation on |r| <= ln(2) / 2 ----
_E1 = 1.66666666666666019037e-01
_E2 = -2.77777777770155933842e-03
_E3 = 6.61375632143793436117e-05
_E4 = -1.65339022054652515390e-06
_E5 = 4.13813679705723846039e-08
_EXP_MAX = 7.09782712893383973096e+02     # above: overflow
_EXP_MIN = -7.45133219101941108420e+02    # below: underflow to 0

# ---- log: fdlibm's polynomial in s = f / (2 + f) ----
_LG1 = 6.666666666666735130e-01
_LG2 = 3.999999999940941908e-01
_LG3 = 2.857142874366239149e-01
_LG4 = 2.222219843214978396e-01
_LG5 = 1.818357216161805012e-01
_LG6 = 1.531383769920937332e-01
_LG7 = 1.479819860511658591e-01
_SQRT_HALF = 0.7071067811865476

# ---- sin, cos: pi / 2 in 33-bit parts (n * part exact for |n| < 2^20) ----
_INV_PIO2 = 6.36619772367581382433e-01
_PIO2_1 = 1.57079632673412561417e+00
_PIO2_2 = 6.07710050630396597660e-11
_PIO2_3 = 2.02226624871116645580e-21
_PIO2_3T = 8.47842766036889956997e-32
_REDUCE_MAX = 1647099.0            # about 2^20 pi / 2: beyond, taken modulo 2 pi first
_TWO_PI = 6.283185307179586
_S1 = -1.66666666666666324348e-01
_S2 = 8.33333333332248946124e-03
_S3 = -1.98412698298579493134e-04
_S4 = 2.75573137070700676789e-06
_S5 = -2.50507602534068634195e-08
_S6 = 1.58969099521155010221e-10
_C1 = 4.16666666666666019037e-02
_C2 = -1.38888888888741095749e-03
_C3 = 2.48015872894767294178e-05
_C4 = -2.75573143513906633035e-07
_C5 = 2.08757232129817482790e-09
_C6 = -1.13596475577881948265e-11
_TINY_ANGLE = 2.0 ** -27           # sin x = tan x = x, cos x = 1 to the last bit below it

# ---- atan: fdlibm's reduction points and polynomial ----
# atan at the reduction points (0 for the interval below 0.4375, where t is x itself)
_ATAN_HI = np.array([0.0, 4.63647609000806093515e-01, 7.85398163397448278999e-01,
                     9.82793723247329054082e-01, 1.57079632679489655800e+00])
_ATAN_LO = np.array([0.0, 2.26987774529616870924e-17, 3.06161699786838301793e-17,
                     1.39033110312309984516e-17, 6.12323399573676603587e-17])
_AT0 = 3.33333333333329318027e-01
_AT1 = -1.99999999998764832476e-01
_AT2 = 1.42857142725034663711e-01
_AT3 = -1.11111104054623557880e-01
_AT4 = 9.09088713343650656196e-02
_AT5 = -7.69187620504482999495e-02
_AT6 = 6.66107313738753120669e-02
_AT7 = -5.83357013379057348645e-02
_AT8 = 4.97687799461593236017e-02
_AT9 = -3.65315727442169155270e-02
_AT10 = 1.62858201153657823623e-02
# atan's argument reduced in interval j = ident + 1 as (A x - B) / (C + D x): x itself,
# (2x - 1) / (2 + x), (x - 1) / (1 + x), (x - 1.5) / (1 + 1.5x), -1 / x (each product by
# 1 or 0 and each sum with 0 is exact, so these are those formulas to the bit)
_RED_A = np.array([1.0, 2.0, 1.0, 1.0, 0.0])
_RED_B = np.array([0.0, 1.0, 1.0, 1.5, 1.0])
_RED_C = np.array([1.0, 2.0, 1.0, 1.0, 0.0])
_RED_D = np.array([0.0, 1.0, 1.0, 1.5, 1.0])
_PI = 3.1415926535897931160e+00
_PI_LO = 1.2246467991473531772e-16
_PIO2 = 1.57079632679489655800e+00
_PIO4 = 7.8539816339744827900e-01
_ATAN_BOUNDS = np.array([0.4375, 0.6875, 1.1875, 2.4375])
_ATAN_HUGE = 7.378697629483821e19   # 2^66

# ---- pow: log(c) for c = i / 64 around 1, as double-doubles exact to the last bit ----
_TABLE_FIRST = 45                  # 45/64 <= sqrt(1/2) and 91/64 >= sqrt(2)
_TABLE_LAST = 91


def _log_table():
    ctx = decimal.Context(prec=60)
    hi, lo = [], []
    for i in range(_TABLE_FIRST, _TABLE_LAST + 1):
        exact = ctx.ln(ctx.divide(decimal.Decimal(i), decimal.Decimal(64)))
        h = float(exact)
        hi.append(h)
        lo.append(float(ctx.subtract(exact, decimal.Decimal(h))))
    return np.array(hi), np.array(lo)


_LOGC_HI, _LOGC_LO = _log_table()
# 2 atanh(s) = 2 s + s^3 (2/3 + 2/5 s^2 + 2/7 s^4 + ...): |s| < 1/180, three terms reach 2^-80
_AH3 = 2.0 / 3.0
_AH5 = 2.0 / 5.0
_AH7 = 2.0 / 7.0
_AH9 = 2.0 / 9.0


# ======================================================================================
# the arithmetic, once: operators only, so floats and numpy arrays run the same body
# ======================================================================================
def _two_sum(a, b):
    """(s, e): s = a + b rounded and its error e, exactly (Knuth; any order of sizes)."""
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


def _two_prod_err(a, b, p):
    """The rounding error of p = a * b, exactly (Dekker, no fused multiply-add)."""
    t = _SPLIT * a
    ah = t - (t - a)
    al = a - ah
    t = _SPLIT * b
    bh = t - (t - b)
    bl = b - bh
    return ((ah * bh - p) + ah * bl + al * bh) + al * bl


def _exp_core(x, xl):
    """(y, k): exp(x + xl) == y 2^k, for x in exp's range (xl a small correction)."""
    k = (x * _INV_LN2 + _RNE) - _RNE
    hi = x - k * _LN2_HI
    lo = k * _LN2_LO - xl
    r = hi - lo
    t = r * r
    c = r - t * (_E1 + t * (_E2 + t * (_E3 + t * (_E4 + t * _E5))))
    return 1.0 - ((lo - (r * c) / (2.0 - c)) - hi), k


def _log_core(m, k):
    """log(m 2^k) for m in [sqrt(1/2), sqrt(2))."""
    f = m - 1.0
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    t1 = w * (_LG2 + w * (_LG4 + w * _LG6))
    t2 = z * (_LG1 + w * (_LG3 + w * (_LG5 + w * _LG7)))
    hfsq = 0.5 * f * f
    return k * _LN2_HI - ((hfsq - (s * (hfsq + (t2 + t1)) + k * _LN2_LO)) - f)


def _log_dd_core(m, k, c, chi, clo):
    """log(m 2^k) as (hi, lo) to about 2^-100, given c = i/64 near m and log(c) as
    chi + clo: k ln 2 + log(c) + 2 atanh((m - c) / (m + c))."""
    f = m - c                       # exact: m and c within a factor 2
    u, ul = _two_sum(m, c)
    s = f / u
    p = s * u
    sl = (((f - p) - _two_prod_err(s, u, p)) - s * ul) / u
    z = s * s
    tail = s * z * (_AH3 + z * (_AH5 + z * (_AH7 + z * _AH9)))
    hi, lo = _two_sum(k * _LN2_HI, chi)          # k * _LN2_HI is exact
    h2, e2 = _two_sum(hi, 2.0 * s)
    lo = (lo + e2) + (k * _LN2_LO + clo + 2.0 * sl + tail)
    hi = h2 + lo
    return hi, lo - (hi - h2)


def _pow_exponent(y, lh, ll):
    """(ph, h, l): y (lh + ll) as ph = y lh rounded and, normalised, h + l."""
    ph = y * lh
    pl = _two_prod_err(y, lh, ph) + y * ll
    h = ph + pl
    return ph, h, pl - (h - ph)


def _reduce(x):
    """(n, hi, lo): x - n pi/2 == hi + lo to about 2^-100, |hi| <= pi/4 (|x| < 2^20 pi/2)."""
    n = (x * _INV_PIO2 + _RNE) - _RNE
    r1 = x - n * _PIO2_1
    s1, e1 = _two_sum(r1, -(n * _PIO2_2))
    s2, e2 = _two_sum(s1, -(n * _PIO2_3))
    lo = (e1 + e2) - n * _PIO2_3T
    hi = s2 + lo
    return n, hi, lo - (hi - s2)


def _sin_kernel(x, y):
    z = x * x
    v = z * x
    r = _S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))
    return x - ((z * (0.5 * y - v * r) - y) - v * _S1)


def _cos_kernel(x, y):
    z = x * x
    r = z * (_C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6)))))
    hz = 0.5 * z
    w = 1.0 - hz
    return w + (((1.0 - w) - hz) + (z * r - x * y))


def _atan_core(x, a, b, c, d, hi, lo):
    """atan(x) for x >= 0 reduced in its interval as t = (a x - b) / (c + d x), plus
    atan at the interval's point, hi + lo (each product by 1 or 0 and each sum with 0
    is exact, so t is exactly x, (2x - 1) / (2 + x), (x - 1) / (1 + x),
    (x - 1.5) / (1 + 1.5x) or -1 / x)."""
    t = (a * x - b) / (c + d * x)
    z = t * t
    w = z * z
    s1 = z * (_AT0 + w * (_AT2 + w * (_AT4 + w * (_AT6 + w * (_AT8 + w * _AT10)))))
    s2 = w * (_AT1 + w * (_AT3 + w * (_AT5 + w * (_AT7 + w * _AT9))))
    return hi - ((t * (s1 + s2) - lo) - t)


def _hypot_core(b, s):
    """sqrt(b^2 + s^2) for b in [1/2, 1), s <= b: the sum carried in double-double,
    the root corrected by one Newton step on it."""
    bb = b * b
    ss = s * s
    total, lo = _two_sum(bb, ss)
    lo = lo + (_two_prod_err(b, b, bb) + _two_prod_err(s, s, ss))
    h = _sqrt(total)
    hh = h * h
    return h + (((total - hh) - _two_prod_err(h, h, hh)) + lo) / (2.0 * h)



# ======================================================================================
# one float at a time: special cases by `if` (numba compiles these with SCALAR_HELPERS)
# ======================================================================================
def _scale(y, k):
    """y * 2^k with a single rounding (k a whole float in [-1100, 1100])."""
    ki = int(k)
    if ki > 1000:                  # ldexp overflowing raises in Python: let `*` give inf
        return math.ldexp(y, ki - 1) * 2.0
    return math.ldexp(y, ki)


def _exp_dd(x, xl):
    """exp(x + xl), xl a small correction (0 for plain exp)."""
    if x != x:
        return x
    if x > _EXP_MAX:
        return INF
    if x < _EXP_MIN:
        return 0.0
    y, k = _exp_core(x, xl)
    return _scale(y, k)


def exp(x):
    return _exp_dd(x, 0.0)


def _frexp(x):
    """(m, k): x == m 2^k, m in [sqrt(1/2), sqrt(2)), k a float (x finite, > 0)."""
    m, e = math.frexp(x)
    if m < _SQRT_HALF:
        return m * 2.0, float(e) - 1.0
    return m, float(e)


def log(x):
    if x != x or x < 0.0:
        return NAN
    if x == 0.0:
        return -INF
    if x == INF:
        return INF
    m, k = _frexp(x)
    return _log_core(m, k)


def _log_dd(x):
    """log(x) of a finite x > 0 as (hi, lo)."""
    m, k = _frexp(x)
    i = int((m * 64.0 + _RNE) - _RNE)
    j = i - _TABLE_FIRST
    return _log_dd_core(m, k, i / 64.0, float(_LOGC_HI[j]), float(_LOGC_LO[j]))


def _odd_whole(y):
    """Whether y is an odd whole number (every |y| >= 2^53 is even)."""
    return abs(y) < 9007199254740992.0 and np.fmod(y, 2.0) != 0.0 and y == np.floor(y)


def pow(x, y):
    if y == 0.0 or x == 1.0:
        return 1.0
    if x != x or y != y:
        return NAN
    ax = abs(x)
    odd = _odd_whole(y)
    if y == INF or y == -INF:
        if ax == 1.0:
            return 1.0
        return INF if (ax > 1.0) == (y > 0.0) else 0.0
    if x == 0.0:
        r = INF if y < 0.0 else 0.0
        return math.copysign(r, x) if odd else r
    if ax == INF:
        r = INF if y > 0.0 else 0.0
        return -r if (x < 0.0 and odd) else r
    if x < 0.0 and y != np.floor(y):
        return NAN
    if y == 2.0:
        return x * x
    if y == 1.0:
        return x
    lh, ll = _log_dd(ax)
    ph, h, pl = _pow_exponent(y, lh, ll)
    if ph > 710.0:
        r = INF
    elif ph < -746.0:
        r = 0.0
    else:
        r = _exp_dd(h, pl)
    return -r if (x < 0.0 and odd) else r


def _quadrant(x):
    """(quadrant 0..3, hi, lo) of a finite x."""
    if abs(x) > _REDUCE_MAX:
        x = float(np.fmod(x, _TWO_PI))
    n, hi, lo = _reduce(x)
    return int(n) & 3, hi, lo


def sin(x):
    if x != x or x == INF or x == -INF:
        return NAN
    if abs(x) < _TINY_ANGLE:
        return x
    q, hi, lo = _quadrant(x)
    r = _sin_kernel(hi, lo) if q % 2 == 0 else _cos_kernel(hi, lo)
    return -r if q >= 2 else r


def cos(x):
    if x != x or x == INF or x == -INF:
        return NAN
    if abs(x) < _TINY_ANGLE:
        return 1.0
    q, hi, lo = _quadrant(x)
    r = _cos_kernel(hi, lo) if q % 2 == 0 else _sin_kernel(hi, lo)
    return -r if (q == 1 or q == 2) else r


def tan(x):
    if x != x or x == INF or x == -INF:
        return NAN
    if abs(x) < _TINY_ANGLE:
        return x
    q, hi, lo = _quadrant(x)
    s = _sin_kernel(hi, lo)
    c = _cos_kernel(hi, lo)
    return s / c if q % 2 == 0 else -c / s


def _atan_interval(x):
    """Which of atan's reduction intervals x >= 0 lies in, 0 (below 0.4375) .. 4."""
    if x < 0.4375:
        return 0
    if x < 0.6875:
        return 1
    if x < 1.1875:
        return 2
    return 3 if x < 2.4375 else 4


def _atan_pos(x):
    """atan of x >= 0 (finite or inf)."""
    if x >= _ATAN_HUGE:
        return float(_ATAN_HI[4]) + float(_ATAN_LO[4])
    if x < _TINY_ANGLE:
        return x
    j = _atan_interval(x)
    return _atan_core(x, float(_RED_A[j]), float(_RED_B[j]), float(_RED_C[j]),
                      float(_RED_D[j]), float(_ATAN_HI[j]), float(_ATAN_LO[j]))


def atan2(y, x):
    if x != x or y != y:
        return NAN
    neg = y < 0.0 or (y == 0.0 and math.copysign(1.0, y) < 0.0)
    left = x < 0.0 or (x == 0.0 and math.copysign(1.0, x) < 0.0)
    if y == 0.0:
        r = _PI if left else 0.0
    elif x == 0.0:
        r = _PIO2
    elif x == INF or x == -INF:
        if y == INF or y == -INF:
            r = 3.0 * _PIO4 if left else _PIO4
        else:
            r = _PI if left else 0.0
    elif y == INF or y == -INF:
        r = _PIO2
    else:
        z = _atan_pos(abs(y / x))
        r = _PI - (z - _PI_LO) if left else z
    return -r if neg else r


def hypot(x, y):
    ax = abs(x)
    ay = abs(y)
    if ax == INF or ay == INF:
        return INF
    if ax != ax or ay != ay:
        return NAN
    big = ax if ax >= ay else ay
    small = ay if ax >= ay else ax
    if big == 0.0:
        return 0.0
    e = math.frexp(big)[1]
    return math.ldexp(_hypot_core(math.ldexp(big, -e), math.ldexp(small, -e)), e)


SCALAR_HELPERS = (_two_sum, _two_prod_err, _exp_core, _log_core, _log_dd_core, _pow_exponent,
                  _reduce, _sin_kernel, _cos_kernel, _atan_core, _hypot_core, _scale, _exp_dd,
                  _frexp, _log_dd, _odd_whole, _quadrant, _atan_interval, _atan_pos, log)
"""Functions the one-float forms call: the numba backend compiles them with those forms."""


# ======================================================================================
# over numpy arrays: special cases by `where`, skipped when every value is ordinary
# ======================================================================================
COMPILED_MIN = 4096      # values from which an installed compiled loop takes an array
_compiled = None         # (name, args) -> array: loops of the one-float forms, same bits


def use_compiled(loop) -> None:
    """Evaluate arrays of `COMPILED_MIN` values or more with `loop(name, args)`, compiled
    loops of the one-float forms (the numba backend's `compiled/math_loops.py`); None goes
    back to the array forms. The bits are the same either way."""
    global _compiled
    _compiled = loop


class _EverySize:
    """Inside this block an installed compiled loop takes arrays of every size, not only
    from `COMPILED_MIN` values. A numba run's tick is such a block (its backend's
    `ticking`): a small swarm's extensions evaluate these functions over a few values at
    a time, where the array forms' 30-40 numpy calls cost 25-160 us and the loop 5 us.
    Outside it, a numpy run's small arrays keep the array forms, the reference, even in
    a process that ran a numba simulation before. The bits are the same either way."""

    __slots__ = ()

    def __enter__(self):
        global _every_size
        _every_size += 1

    def __exit__(self, *exc):
        global _every_size
        _every_size -= 1


_every_size = 0          # depth of `_EverySize` blocks entered
EVERY_SIZE = _EverySize()


def at_every_size() -> bool:
    """Whether compiled loops are installed and take arrays of every size here: inside
    a numba tick (`_EverySize`)."""
    return _compiled is not None and _every_size > 0


def by_loop(name: str, args: tuple):
    """`name` over `args` by the installed compiled loop when it takes them (see
    `_big`), else None: for functions built on these outside this module."""
    return _compiled(name, args) if _big(*args) else None


def _big(*args) -> bool:
    if _compiled is None:
        return False
    return _every_size > 0 or max(np.size(a) for a in args) >= COMPILED_MIN


def _f(x):
    return np.asarray(x, dtype=np.float64)


def _usual(*absolutes) -> bool:
    """Whether every value is finite and non-zero (numpy's min and max carry NaN)."""
    return all(a.size and a.min() > 0.0 and a.max() < INF for a in absolutes)


def _scale_array(y, k):
    ki = np.where(np.abs(k) <= 1100.0, k, 0.0).astype(np.int64)
    return np.ldexp(y, ki)


def _exp_dd_array(x, xl):
    with np.errstate(all="ignore"):
        out = _scale_array(*_exp_core(x, xl))
    if x.size and _EXP_MIN <= x.min() and x.max() <= _EXP_MAX:    # no NaN either
        return out
    out = np.where(x < _EXP_MIN, 0.0, out)
    out = np.where(x > _EXP_MAX, INF, out)
    return np.where(x != x, x, out)


def exp_array(x):
    if _big(x):
        return _compiled("exp", (x,))
    x = _f(x)
    return _exp_dd_array(x, np.zeros_like(x))


def _frexp_array(x):
    m, e = np.frexp(x)
    k = e.astype(np.float64)
    low = m < _SQRT_HALF
    return np.where(low, m * 2.0, m), np.where(low, k - 1.0, k)


def log_array(x):
    if _big(x):
        return _compiled("log", (x,))
    x = _f(x)
    with np.errstate(all="ignore"):
        out = _log_core(*_frexp_array(x))
    if x.size and 0.0 < x.min() and x.max() < INF:
        return out
    out = np.where(x == INF, INF, out)
    out = np.where(x == 0.0, -INF, out)
    return np.where((x != x) | (x < 0.0), NAN, out)


def _log_dd_array(x):
    m, k = _frexp_array(x)
    i = (m * 64.0 + _RNE) - _RNE
    i = np.where((i >= _TABLE_FIRST) & (i <= _TABLE_LAST), i, 64.0)   # lanes not used
    j = i.astype(np.int64) - _TABLE_FIRST
    return _log_dd_core(m, k, i / 64.0, _LOGC_HI[j], _LOGC_LO[j])


def _odd_whole_array(y):
    with np.errstate(all="ignore"):
        return (np.abs(y) < 9007199254740992.0) & (np.fmod(y, 2.0) != 0.0) & (y == np.floor(y))


def pow_array(x, y):
    if _big(x, y):
        return _compiled("pow", (x, y))
    x, y = np.broadcast_arrays(_f(x), _f(y))
    with np.errstate(all="ignore"):
        ax = np.abs(x)
        odd = _odd_whole_array(y)
        finite = (ax > 0.0) & (ax < INF)
        ph, h, pl = _pow_exponent(y, *_log_dd_array(np.where(finite, ax, 1.0)))
        r = _exp_dd_array(h, pl)
        r = np.where(ph > 710.0, INF, np.where(ph < -746.0, 0.0, r))
        r = np.where(y == 1.0, x, np.where(y == 2.0, x * x, r))
        r = np.where((x < 0.0) & odd & (y != 1.0) & (y != 2.0), -r, r)
        r = np.where((x < 0.0) & (y != np.floor(y)), NAN, r)
        # infinities and zeros of x, then of y, NaN, then the cases that are 1 even with NaN
        big = np.where(y > 0.0, INF, 0.0)
        r = np.where(ax == INF, np.where((x < 0.0) & odd, -big, big), r)
        tiny = np.where(y < 0.0, INF, 0.0)
        r = np.where(x == 0.0, np.where(odd, np.copysign(tiny, x), tiny), r)
        r = np.where(np.abs(y) == INF,
                     np.where(ax == 1.0, 1.0, np.where((ax > 1.0) == (y > 0.0), INF, 0.0)), r)
        r = np.where((x != x) | (y != y), NAN, r)
        return np.where((y == 0.0) | (x == 1.0), 1.0, r)


def _quadrant_array(x, usual):
    if not usual:
        x = np.where(np.abs(x) > _REDUCE_MAX, np.fmod(x, _TWO_PI), x)
        x = np.where(np.isfinite(x), x, 0.0)
    n, hi, lo = _reduce(x)
    return n.astype(np.int64) & 3, hi, lo


def _angle_array(x, fn, tiny):
    x = _f(x)
    ax = np.abs(x)
    usual = bool(x.size) and _TINY_ANGLE <= ax.min() and ax.max() <= _REDUCE_MAX
    with np.errstate(all="ignore"):
        out = fn(*_quadrant_array(x, usual))
    if usual:
        return out
    out = np.where(ax < _TINY_ANGLE, x if tiny is None else tiny, out)
    return np.where(np.isfinite(x), out, NAN)


def _sin_of(q, hi, lo):
    r = np.where(q % 2 == 0, _sin_kernel(hi, lo), _cos_kernel(hi, lo))
    return np.where(q >= 2, -r, r)


def _cos_of(q, hi, lo):
    r = np.where(q % 2 == 0, _cos_kernel(hi, lo), _sin_kernel(hi, lo))
    return np.where((q == 1) | (q == 2), -r, r)


def _tan_of(q, hi, lo):
    s = _sin_kernel(hi, lo)
    c = _cos_kernel(hi, lo)
    return np.where(q % 2 == 0, s / c, -c / s)


def sin_array(x):
    if _big(x):
        return _compiled("sin", (x,))
    return _angle_array(x, _sin_of, None)


def cos_array(x):
    if _big(x):
        return _compiled("cos", (x,))
    return _angle_array(x, _cos_of, 1.0)


def tan_array(x):
    if _big(x):
        return _compiled("tan", (x,))
    return _angle_array(x, _tan_of, None)


def _atan_pos_array(x):
    with np.errstate(all="ignore"):
        j = np.searchsorted(_ATAN_BOUNDS, x, side="right")
        out = _atan_core(x, _RED_A[j], _RED_B[j], _RED_C[j], _RED_D[j], _ATAN_HI[j],
                         _ATAN_LO[j])
    if not (x.size and _TINY_ANGLE <= x.min() and x.max() < _ATAN_HUGE):   # NaN too
        out = np.where(x < _TINY_ANGLE, x, out)
        out = np.where(x >= _ATAN_HUGE, _ATAN_HI[4] + _ATAN_LO[4], out)
    return out


def atan2_array(y, x):
    if _big(y, x):
        return _compiled("atan2", (y, x))
    y, x = np.broadcast_arrays(_f(y), _f(x))
    left = np.signbit(x)
    with np.errstate(all="ignore"):
        z = _atan_pos_array(np.abs(y / x))
        r = np.where(left, _PI - (z - _PI_LO), z)
    ax, ay = np.abs(x), np.abs(y)
    if not _usual(ax, ay):
        yinf, xinf = ay == INF, ax == INF
        r = np.where(yinf, _PIO2, r)
        r = np.where(xinf, np.where(yinf, np.where(left, 3.0 * _PIO4, _PIO4),
                                    np.where(left, _PI, 0.0)), r)
        r = np.where(x == 0.0, _PIO2, r)
        r = np.where(y == 0.0, np.where(left, _PI, 0.0), r)
        r = np.where((x != x) | (y != y), NAN, r)
    return np.where(np.signbit(y), -r, r)


def hypot_array(x, y):
    if _big(x, y):
        return _compiled("hypot", (x, y))
    x, y = np.broadcast_arrays(_f(x), _f(y))
    ax, ay = np.abs(x), np.abs(y)
    with np.errstate(all="ignore"):
        big = np.where(ax >= ay, ax, ay)
        small = np.where(ax >= ay, ay, ax)
        e = np.frexp(np.where(np.isfinite(big), big, 1.0))[1]
        out = np.ldexp(_hypot_core(np.ldexp(big, -e), np.ldexp(small, -e)), e)
    if _usual(ax, ay):
        return out
    out = np.where(big == 0.0, 0.0, out)
    out = np.where((ax != ax) | (ay != ay), NAN, out)
    return np.where((ax == INF) | (ay == INF), INF, out)
