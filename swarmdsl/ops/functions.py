"""The built-in functions: one row each, holding its type rule and every evaluator.

- `params`, `result`: its type rule (the checker's `typing_rules.call`).
- `numpy(frame, *args)`: the reference kernel over whole arrays. Scalars arrive as `(M,)`
  float64, vectors `(M, 2)`, booleans `(M,)` bool; constants may arrive as Python floats
  or `(2,)` arrays and broadcast. The frame gives `n` (agents or pairs evaluated) and
  `rng` to the draws.
- `scalar`: one float at a time, a plain function numba compiles when a kernel first
  uses it (so neither `check` nor a numpy run imports numba); the kernels' scalar tree
  of a call is `(name, *argument trees)`.
- `lower`: for the others (vectors, compositions), the argument trees (`(x,)` for a
  number, `(x, y)` for a vector) to the result's trees. Neither: the call has no
  compiled form and its aggregate or statement keeps the reference closure.
- `fold`: its value on constants, on Python numbers. None: numpy's value as a float
  (so folding and running agree to the bit); the folder refuses non-finite results of
  finite arguments with a message in the language's words.
- `kilobot`: the C function the exported program calls (`kb_*` helpers are in the
  exported preamble, `export/kilobot_csrc.py`; a vector is a `kb_vec_t`), or a C
  template of the arguments' C (`{0}`, `{1}`) when no helper is needed, or a
  `Refused` saying why the Kilobot has none (a located error where it is used);
  `kilobot_helper`, the C function a new form needs, added to the exported preamble.
- `batch`: whether R replicas in one store run it bit-identical to their solo runs
  (`runtime/batch.py`): every function here works row by row, and a draw takes each
  row's own replica's stream, so all say True; a `Refused` sends such programs solo.

Adding a builtin is one row of `_ENTRIES`: `tests/test_ops_rows.py` cross-checks every
row's evaluators on edge values (negatives, zero, NaN, infinities, huge, tiny),
`tests/test_export_kilobot_ops.py` its C on the same values, and
`tests/test_rows_complete.py` that it has a form or a declared refusal on every target.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from swarmdsl.ops import portable
from swarmdsl.ops.targets import Refused
from swarmdsl.ops.types import BOOL, NUM, VEC


@dataclass(frozen=True)
class Builtin:
    name: str
    params: tuple[str, ...]
    result: str
    numpy: Callable
    doc: str
    scalar: Callable | None = None
    lower: Callable | None = None
    fold: Callable | None = None
    random: bool = False
    kilobot: str | Refused | None = None
    batch: bool | Refused = True
    kilobot_helper: str = ""     # C the form needs in the exported preamble, if any

    @property
    def compiled(self) -> bool:
        """Whether the kernels' scalar trees compute it (draws never: their streams)."""
        return not self.random and (self.scalar is not None or self.lower is not None)

    @property
    def foldable(self) -> bool:
        """Whether constant folding computes it: numbers in, a number out, no draw."""
        return not self.random and self.result == NUM and all(p == NUM for p in self.params)

    def trees(self, *args: tuple) -> tuple:
        """The scalar trees of a call given its arguments' trees."""
        if self.lower is not None:
            return self.lower(*args)
        return ((self.name, *(a[0] for a in args)),)

    def folded(self, *args):
        """The value on constants (Python numbers); NaN and infinities as numpy gives them."""
        if self.fold is not None:
            return self.fold(*args)
        with np.errstate(all="ignore"):
            return float(self.numpy(None, *(np.float64(a) for a in args)))


def vec_length(v):
    # Two explicit squares add in the same order as np.sum over the last axis (same
    # bits) and avoid its reduction machinery, which is ~30x slower on (P, 2) arrays.
    return np.sqrt(np.square(v[..., 0]) + np.square(v[..., 1]))


def _dot(a, b):
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def _normalize(f, v):
    n = vec_length(v)
    if np.ndim(v) >= 2:
        # Per agent: each component divided on its own (the same quotients as the
        # broadcast below, which steps two numbers at a time: 3x slower on (N, 2)),
        # and zero where the length is not positive (zero or NaN), as `np.where` does.
        out = np.empty(np.shape(v), dtype=np.result_type(v, n, 0.0))
        with np.errstate(invalid="ignore", divide="ignore"):
            np.divide(v[..., 0], n, out=out[..., 0])
            np.divide(v[..., 1], n, out=out[..., 1])
        out[~(n > 0)] = 0.0
        return out
    with np.errstate(invalid="ignore", divide="ignore"):
        out = v / np.asarray(n)[..., None]
    return np.where(np.asarray(n)[..., None] > 0, out, 0.0)


def _rotate(f, v, a):
    c, s = portable.cos_array(a), portable.sin_array(a)
    x, y = v[..., 0], v[..., 1]
    return np.stack(np.broadcast_arrays(c * x - s * y, s * x + c * y), axis=-1)


def _vec(f, x, y):
    x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
    return np.stack([x, y], axis=-1)


def _unit(f, a):
    return _vec(f, portable.cos_array(a), portable.sin_array(a))


def _angle_between(f, a, b):
    return portable.atan2_array(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0], _dot(a, b))


def _random_direction(f):
    return _unit(f, f.rng.uniform(0.0, 2 * np.pi, f.n))


def _m1(fn):
    """Wrap a numpy ufunc of one number as a kernel."""
    return lambda f, a: fn(a)


def _m2(fn):
    return lambda f, a, b: fn(a, b)


# ---- scalar forms shared by several rows (plain functions: numba compiles them) ----
def _min(a, b):
    return a if (a < b or a != a) else b     # np.minimum: NaN wins, equal: the second


def _max(a, b):
    return a if (a > b or a != a) else b


def _nz(x, n):
    return x / n if n > 0 else 0.0           # normalize: the zero vector stays zero


# Scalar-tree operations no row names (the parts of a row's lowering).
PRIMITIVES = {"nz": _nz}


# ---- constants folded as Python numbers (whole numbers stay ints: counts, sizes) ----
def _whole(ufunc):
    """floor, ceil, round of a constant: numpy's value, an int when it is a finite whole
    number (-0.0, NaN and infinities stay floats, as numpy has them)."""
    def fold(x):
        if isinstance(x, int):
            return x
        with np.errstate(all="ignore"):
            r = float(ufunc(x))
        if math.isfinite(r) and not (r == 0 and math.copysign(1.0, r) < 0):
            return int(r)
        return r
    return fold


def _fold_sign(x):
    if x != x or x == 0:
        return x + 0                          # NaN stays NaN, -0.0 is 0.0: np.sign's
    return 1 if x > 0 else -1


def _sign(x):
    return np.sign(x) + 0.0                   # numba's np.sign(-0.0) is -0.0, numpy's 0.0


# ---- lowerings of the vector functions into scalar trees ----
def _length(v):
    return ("sqrt", ("add", ("mul", v[0], v[0]), ("mul", v[1], v[1])))


def _lower_normalize(v):
    n = _length(v)
    return (("nz", v[0], n), ("nz", v[1], n))


def _lower_rotate(v, a):
    c, s = ("cos", a[0]), ("sin", a[0])
    return (("sub", ("mul", c, v[0]), ("mul", s, v[1])),
            ("add", ("mul", s, v[0]), ("mul", c, v[1])))


def _tree_dot(a, b):
    return ("add", ("mul", a[0], b[0]), ("mul", a[1], b[1]))


def _tree_cross(a, b):
    return ("sub", ("mul", a[0], b[1]), ("mul", a[1], b[0]))


_ENTRIES = [
    Builtin("abs", (NUM,), NUM, _m1(np.abs), "absolute value",
            scalar=lambda x: np.abs(x), fold=abs, kilobot="fabsf"),
    Builtin("sqrt", (NUM,), NUM, _m1(np.sqrt), "square root", scalar=lambda x: np.sqrt(x),
            kilobot="sqrtf"),
    Builtin("exp", (NUM,), NUM, _m1(portable.exp_array), "e to the power x",
            scalar=portable.exp, fold=portable.exp, kilobot="expf"),
    Builtin("log", (NUM,), NUM, _m1(portable.log_array), "natural logarithm",
            scalar=portable.log, fold=portable.log, kilobot="logf"),
    Builtin("sin", (NUM,), NUM, _m1(portable.sin_array), "sine (radians)",
            scalar=portable.sin, fold=portable.sin, kilobot="sinf"),
    Builtin("cos", (NUM,), NUM, _m1(portable.cos_array), "cosine (radians)",
            scalar=portable.cos, fold=portable.cos, kilobot="cosf"),
    Builtin("tan", (NUM,), NUM, _m1(portable.tan_array), "tangent (radians)",
            scalar=portable.tan, fold=portable.tan, kilobot="tanf"),
    Builtin("floor", (NUM,), NUM, _m1(np.floor), "round down",
            scalar=lambda x: np.floor(x), fold=_whole(np.floor), kilobot="floorf"),
    Builtin("ceil", (NUM,), NUM, _m1(np.ceil), "round up",
            scalar=lambda x: np.ceil(x), fold=_whole(np.ceil), kilobot="ceilf"),
    Builtin("round", (NUM,), NUM, _m1(np.round), "round to nearest (half to even)",
            scalar=lambda x: np.rint(x), fold=_whole(np.round), kilobot="kb_round"),
    Builtin("sign", (NUM,), NUM, _m1(np.sign), "-1, 0 or 1",
            scalar=_sign, fold=_fold_sign, kilobot="kb_sign"),
    Builtin("atan2", (NUM, NUM), NUM, _m2(portable.atan2_array), "angle of (x, y) given y, x",
            scalar=portable.atan2, fold=portable.atan2, kilobot="atan2f"),
    Builtin("hypot", (NUM, NUM), NUM, _m2(portable.hypot_array),
            "length of (x, y), never overflowing", scalar=portable.hypot, fold=portable.hypot,
            kilobot="hypotf"),
    Builtin("min", (NUM, NUM), NUM, _m2(np.minimum), "smaller of two numbers",
            scalar=_min, fold=_min, kilobot="kb_min"),
    Builtin("max", (NUM, NUM), NUM, _m2(np.maximum), "larger of two numbers",
            scalar=_max, fold=_max, kilobot="kb_max"),
    Builtin("clamp", (NUM, NUM, NUM), NUM, lambda f, x, lo, hi: np.clip(x, lo, hi),
            "x limited to [lo, hi]",
            lower=lambda x, lo, hi: (("min", ("max", x[0], lo[0]), hi[0]),),
            fold=lambda x, lo, hi: _min(_max(x, lo), hi), kilobot="kb_clamp"),
    Builtin("vec", (NUM, NUM), VEC, _vec, "the vector (x, y)",
            lower=lambda x, y: (x[0], y[0]), kilobot="kb_v"),
    Builtin("length", (VEC,), NUM, lambda f, v: vec_length(v), "Euclidean length",
            lower=lambda v: (_length(v),), kilobot="kb_vlen"),
    Builtin("normalize", (VEC,), VEC, _normalize, "unit vector; the zero vector stays zero",
            lower=_lower_normalize, kilobot="kb_vnorm"),
    Builtin("normalise", (VEC,), VEC, _normalize, "British spelling of normalize",
            lower=_lower_normalize, kilobot="kb_vnorm"),
    Builtin("dot", (VEC, VEC), NUM, lambda f, a, b: _dot(a, b), "dot product",
            lower=lambda a, b: (_tree_dot(a, b),), kilobot="kb_vdot"),
    Builtin("cross", (VEC, VEC), NUM,
            lambda f, a, b: a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
            "z component of the 3-D cross product", lower=lambda a, b: (_tree_cross(a, b),),
            kilobot="kb_vcross"),
    Builtin("angle", (VEC,), NUM, lambda f, v: portable.atan2_array(v[..., 1], v[..., 0]),
            "direction of a vector in radians, 0 = +x, counter-clockwise",
            lower=lambda v: (("atan2", v[1], v[0]),), kilobot="kb_vangle"),
    Builtin("angle_between", (VEC, VEC), NUM, _angle_between,
            "signed angle from a to b in (-pi, pi]",
            lower=lambda a, b: (("atan2", _tree_cross(a, b), _tree_dot(a, b)),),
            kilobot=Refused("not translated to C yet: write `atan2(cross(a, b), dot(a, b))`")),
    Builtin("unit", (NUM,), VEC, _unit, "unit vector pointing at angle a",
            lower=lambda a: (("cos", a[0]), ("sin", a[0])), kilobot="kb_unit"),
    Builtin("rotate", (VEC, NUM), VEC, _rotate, "vector rotated counter-clockwise by a",
            lower=_lower_rotate, kilobot="kb_vrot"),
    Builtin("distance", (VEC, VEC), NUM, lambda f, a, b: vec_length(a - b),
            "Euclidean distance between two points",
            lower=lambda a, b: (_length((("sub", a[0], b[0]), ("sub", a[1], b[1]))),),
            kilobot="kb_vdist"),
    Builtin("random", (), NUM, lambda f: f.rng.random(f.n), "uniform draw in [0, 1)",
            random=True, kilobot="kb_random"),
    Builtin("uniform", (NUM, NUM), NUM,
            lambda f, lo, hi: f.rng.uniform(0.0, 1.0, f.n) * (np.asarray(hi) - lo) + lo,
            "uniform draw in [lo, hi)", random=True, kilobot="kb_uniform"),
    Builtin("normal", (NUM, NUM), NUM,
            lambda f, mu, sd: f.rng.standard_normal(f.n) * sd + mu,
            "normal draw with mean and standard deviation", random=True,
            kilobot=Refused("a Kilobot draws uniform bytes; a normal draw is not translated")),
    Builtin("chance", (NUM,), BOOL, lambda f, p: f.rng.random(f.n) < p,
            "true with probability p", random=True, kilobot="kb_chance"),
    Builtin("random_direction", (), VEC, lambda f: _random_direction(f),
            "uniformly random unit vector", random=True,
            kilobot=Refused("not translated to C yet: write `unit(uniform(0, tau))`")),
]

FUNCTIONS: dict[str, Builtin] = {b.name: b for b in _ENTRIES}
