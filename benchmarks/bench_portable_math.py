"""The cost of computing the transcendental functions ourselves (`ops/portable.py`).

Run from the repository root: ``python -m benchmarks.bench_portable_math [--n 100000]``.

Per function, nanoseconds per value: numpy's own ufunc (SIMD where the CPU has it, the
bits of which depend on the CPU) against our array form, and numba's call of the C
library against our scalar form compiled by numba, each over the same `n` arguments,
timed alternately in one process (best of several rounds), so a busy machine slows both
alike; and the arrays a numba run hands to those compiled loops (`compiled/math_loops.py`).
"""

from __future__ import annotations

import argparse
import timeit

import numpy as np

from swarmdsl.ops import portable

ROWS = {  # name: (numpy's ufunc, our array form, arity)
    "exp": (np.exp, portable.exp_array, 1),
    "log": (np.log, portable.log_array, 1),
    "sin": (np.sin, portable.sin_array, 1),
    "cos": (np.cos, portable.cos_array, 1),
    "tan": (np.tan, portable.tan_array, 1),
    "atan2": (np.arctan2, portable.atan2_array, 2),
    "hypot": (np.hypot, portable.hypot_array, 2),
    "pow": (np.power, portable.pow_array, 2),
}


def _arguments(name: str, n: int, rng) -> list[np.ndarray]:
    if name == "log":
        return [rng.uniform(1e-3, 1e3, n)]
    if name == "pow":
        return [rng.uniform(0.1, 10, n), rng.uniform(-5, 5, n)]
    return [rng.uniform(-10, 10, n) for _ in range(ROWS[name][2])]


def _best(fn, rounds: int) -> float:
    return min(timeit.repeat(fn, number=1, repeat=rounds))


def _numba_pair(name: str):
    """(libm loop, our loop), both jitted loops over the arguments."""
    import math

    import numba

    from swarmdsl.runtime.compiled.kernels import scalar_function

    ours = scalar_function(name)
    libm = {"exp": math.exp, "log": math.log, "sin": math.sin, "cos": math.cos,
            "tan": math.tan, "atan2": math.atan2, "hypot": math.hypot,
            "pow": math.pow}[name]
    if ROWS[name][2] == 1:
        def make(f):
            @numba.njit
            def loop(x, out):
                for i in range(x.shape[0]):
                    out[i] = f(x[i])
            return loop
    else:
        def make(f):
            @numba.njit
            def loop(x, y, out):
                for i in range(x.shape[0]):
                    out[i] = f(x[i], y[i])
            return loop
    return make(numba.njit(lambda *a: libm(*a))), make(ours)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100_000)
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    print(f"n = {args.n:,}; ns per value, best of {args.rounds}")
    print("| function | numpy ufunc | ours, numpy | ratio | numba libm | ours, numba | ratio "
          "| ours, numba run's arrays |")
    print("|---|---|---|---|---|---|---|---|")
    for name, (ufunc, ours, _) in ROWS.items():
        print(_row(name, ufunc, ours, _arguments(name, args.n, rng), args.rounds))


def _row(name, ufunc, ours, xs, rounds) -> str:
    """One table row: ns per value of each way of computing `name` over `xs`."""
    from swarmdsl.runtime.compiled import math_loops

    out = np.empty(xs[0].shape[0])
    with np.errstate(all="ignore"):
        t_np = _best(lambda: ufunc(*xs), rounds)
        t_ours = _best(lambda: ours(*xs), rounds)
    libm_loop, our_loop = _numba_pair(name)
    libm_loop(*xs, out)
    our_loop(*xs, out)
    t_nb = _best(lambda: libm_loop(*xs, out), rounds)
    t_nb_ours = _best(lambda: our_loop(*xs, out), rounds)
    math_loops.install()        # what a numba run does: large arrays go to the loops
    try:
        ours(*xs)
        t_run = _best(lambda: ours(*xs), rounds)
    finally:
        portable.use_compiled(None)
    per = 1e9 / xs[0].shape[0]
    return (f"| {name} | {t_np * per:.1f} | {t_ours * per:.1f} | {t_ours / t_np:.1f}x "
            f"| {t_nb * per:.1f} | {t_nb_ours * per:.1f} | {t_nb_ours / t_nb:.1f}x "
            f"| {t_run * per:.1f} |")

if __name__ == "__main__":
    main()
