"""Compiled loops of the portable math, for the arrays the runtime itself evaluates.

Draws (`normal`'s log and cosine), headings, field probes and sensing evaluate the
language's transcendental functions (`ops/portable.py`) over whole arrays. Their numpy
forms are exact but slow (30-40 array passes: 43-210 ns a value against numpy's own
SIMD ufuncs at 1-18 ns, whose bits depend on the CPU). A numba run installs these
loops of the scalar forms instead for large arrays: 9-53 ns a value, the same bits
(`tests/test_portable_math.py` holds the scalar and array forms to each other), each
compiled on first use and kept on disk (`disk_cache.py`).
"""

from __future__ import annotations

import numpy as np

from swarmdsl.ops import portable, portable_runtime

_LOOPS: dict = {}
# Functions the runtime evaluates that are no builtin of the language: their one-float
# forms, beside their array forms in `ops/portable_runtime.py`.
RUNTIME_ONLY = {"log1p": portable_runtime.log1p}


def install() -> None:
    """Let the portable math hand large arrays to these loops from now on."""
    portable.use_compiled(_loop)


def _loop(name: str, args: tuple) -> np.ndarray:
    """The function `name` over arrays `args` (broadcast), by a compiled loop."""
    fn = _LOOPS.get(name)
    if fn is None:
        fn = _LOOPS[name] = _build(name, len(args))
    first = args[0]
    if _plain(first) and all(_plain(a) and a.shape == first.shape for a in args[1:]):
        # already float and of one shape (most calls, on a few values each: the general
        # path's broadcast would cost as much as the loop; a strided one is copied flat)
        out = np.empty(first.shape)
        fn(*(a.reshape(-1) for a in args), out.reshape(-1))
        return out
    args = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in args))
    flat = [np.ascontiguousarray(a).ravel() for a in args]
    out = np.empty(flat[0].shape[0])
    fn(*flat, out)
    return out.reshape(args[0].shape)


def _plain(a) -> bool:
    return type(a) is np.ndarray and a.dtype == np.float64 and a.ndim > 0


def _build(name: str, arity: int):
    from swarmdsl.runtime.compiled.disk_cache import keep_on_disk
    from swarmdsl.runtime.compiled.jit import njit
    from swarmdsl.runtime.compiled.kernels import scalar_function

    if name in RUNTIME_ONLY:   # the runtime's own function, no row of the language's
        scalar_function("log")   # registers the helpers the one-float forms call
        f = njit(nogil=True, error_model="numpy", inline="always")(RUNTIME_ONLY[name])
    else:
        f = scalar_function(name)
    if arity == 1:
        @njit(nogil=True, error_model="numpy")
        def unary(x, out):
            for i in range(x.shape[0]):
                out[i] = f(x[i])
        return keep_on_disk(unary)

    @njit(nogil=True, error_model="numpy")
    def binary(x, y, out):
        for i in range(x.shape[0]):
            out[i] = f(x[i], y[i])
    return keep_on_disk(binary)
