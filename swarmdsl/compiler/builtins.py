"""The one table of built-in functions: signature, result type and vectorised kernel.

A kernel receives the evaluation frame (for `n`, the number of agents or pairs being
evaluated, and `rng`) and its argument arrays, and returns an array over the frame.
Scalars are `(M,)` float64, vectors `(M, 2)` float64, booleans `(M,)` bool; constants may
arrive as Python floats or `(2,)` arrays and broadcast.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from swarmdsl.runtime.values import BOOL, NUM, VEC

STR = "str"
SET, STATUS, KIND, FIELD, REGION, MEMORY, OTHER = (
    "set", "status", "kind", "field", "region", "memory", "other")
VALUE_TYPES = (NUM, BOOL, VEC)

TYPE_TEXT = {
    NUM: "a number", BOOL: "a boolean", VEC: "a vector", STR: "a string",
    SET: "a neighbour set", STATUS: "a status", KIND: "an agent kind", FIELD: "a field",
    REGION: "a region", MEMORY: "a path memory", OTHER: "`other`",
}


@dataclass(frozen=True)
class Builtin:
    name: str
    params: tuple[str, ...]
    result: str
    kernel: Callable
    doc: str
    random: bool = False


def vec_length(v):
    # Two explicit squares add in the same order as np.sum over the last axis (same
    # bits) and avoid its reduction machinery, which is ~30x slower on (P, 2) arrays.
    return np.sqrt(np.square(v[..., 0]) + np.square(v[..., 1]))


def _dot(a, b):
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def _normalize(f, v):
    n = vec_length(v)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = v / np.asarray(n)[..., None]
    return np.where(np.asarray(n)[..., None] > 0, out, 0.0)


def _rotate(f, v, a):
    c, s = np.cos(a), np.sin(a)
    x, y = v[..., 0], v[..., 1]
    return np.stack(np.broadcast_arrays(c * x - s * y, s * x + c * y), axis=-1)


def _vec(f, x, y):
    x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
    return np.stack([x, y], axis=-1)


def _unit(f, a):
    return _vec(f, np.cos(a), np.sin(a))


def _angle_between(f, a, b):
    return np.arctan2(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0], _dot(a, b))


def _random_direction(f):
    return _unit(f, f.rng.uniform(0.0, 2 * np.pi, f.n))


def _sizeof(f, *args):
    return np.broadcast_shapes(*(np.shape(a) for a in args), (f.n,))


def _m1(fn):
    """Wrap a numpy ufunc of one number as a kernel."""
    return lambda f, a: fn(a)


def _m2(fn):
    return lambda f, a, b: fn(a, b)


_ENTRIES = [
    Builtin("abs", (NUM,), NUM, _m1(np.abs), "absolute value"),
    Builtin("sqrt", (NUM,), NUM, _m1(np.sqrt), "square root"),
    Builtin("exp", (NUM,), NUM, _m1(np.exp), "e to the power x"),
    Builtin("log", (NUM,), NUM, _m1(np.log), "natural logarithm"),
    Builtin("sin", (NUM,), NUM, _m1(np.sin), "sine (radians)"),
    Builtin("cos", (NUM,), NUM, _m1(np.cos), "cosine (radians)"),
    Builtin("tan", (NUM,), NUM, _m1(np.tan), "tangent (radians)"),
    Builtin("floor", (NUM,), NUM, _m1(np.floor), "round down"),
    Builtin("ceil", (NUM,), NUM, _m1(np.ceil), "round up"),
    Builtin("round", (NUM,), NUM, _m1(np.round), "round to nearest (half to even)"),
    Builtin("sign", (NUM,), NUM, _m1(np.sign), "-1, 0 or 1"),
    Builtin("atan2", (NUM, NUM), NUM, _m2(np.arctan2), "angle of (x, y) given y, x"),
    Builtin("min", (NUM, NUM), NUM, _m2(np.minimum), "smaller of two numbers"),
    Builtin("max", (NUM, NUM), NUM, _m2(np.maximum), "larger of two numbers"),
    Builtin("clamp", (NUM, NUM, NUM), NUM, lambda f, x, lo, hi: np.clip(x, lo, hi),
            "x limited to [lo, hi]"),
    Builtin("vec", (NUM, NUM), VEC, _vec, "the vector (x, y)"),
    Builtin("length", (VEC,), NUM, lambda f, v: vec_length(v), "Euclidean length"),
    Builtin("normalize", (VEC,), VEC, _normalize, "unit vector; the zero vector stays zero"),
    Builtin("normalise", (VEC,), VEC, _normalize, "British spelling of normalize"),
    Builtin("dot", (VEC, VEC), NUM, lambda f, a, b: _dot(a, b), "dot product"),
    Builtin("cross", (VEC, VEC), NUM,
            lambda f, a, b: a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
            "z component of the 3-D cross product"),
    Builtin("angle", (VEC,), NUM, lambda f, v: np.arctan2(v[..., 1], v[..., 0]),
            "direction of a vector in radians, 0 = +x, counter-clockwise"),
    Builtin("angle_between", (VEC, VEC), NUM, _angle_between,
            "signed angle from a to b in (-pi, pi]"),
    Builtin("unit", (NUM,), VEC, _unit, "unit vector pointing at angle a"),
    Builtin("rotate", (VEC, NUM), VEC, _rotate, "vector rotated counter-clockwise by a"),
    Builtin("distance", (VEC, VEC), NUM, lambda f, a, b: vec_length(a - b),
            "Euclidean distance between two points"),
    Builtin("random", (), NUM, lambda f: f.rng.random(f.n), "uniform draw in [0, 1)",
            random=True),
    Builtin("uniform", (NUM, NUM), NUM,
            lambda f, lo, hi: f.rng.uniform(0.0, 1.0, f.n) * (np.asarray(hi) - lo) + lo,
            "uniform draw in [lo, hi)", random=True),
    Builtin("normal", (NUM, NUM), NUM,
            lambda f, mu, sd: f.rng.standard_normal(f.n) * sd + mu,
            "normal draw with mean and standard deviation", random=True),
    Builtin("chance", (NUM,), BOOL, lambda f, p: f.rng.random(f.n) < p,
            "true with probability p", random=True),
    Builtin("random_direction", (), VEC, lambda f: _random_direction(f),
            "uniformly random unit vector", random=True),
]

FUNCTIONS: dict[str, Builtin] = {b.name: b for b in _ENTRIES}

# Aggregates over a neighbour set: name -> (needs `: each`, allowed each types, result rule)
AGGREGATES = {
    "count": (False, ()),
    "sum": (True, (NUM, VEC)),
    "mean": (True, (NUM, VEC)),
    "min": (True, (NUM,)),
    "max": (True, (NUM,)),
    "nearest": (True, (NUM, VEC, BOOL, STATUS)),
    "any": (True, (BOOL,)),
    "all": (True, (BOOL,)),
}

CONSTANTS = {"pi": float(np.pi), "tau": float(2 * np.pi), "inf": float("inf")}
