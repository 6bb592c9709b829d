"""Fused statements (`runtime/compiled/statements.py`) on the numba backend, ms per tick.

Run from the repository root:
``python -m benchmarks.bench_fused_statements [--models boids,vicsek] [--n 10000]``.

Compiles each model twice at the suite's sizes (`benchmarks/cases.py`), with its
`let`s and assignments fused and with them left to the numpy closures (everything else
compiled alike), and times `Simulation.step()` of the two alternately, tick by tick, in
one process, so a busy machine slows both alike. Prints the median tick of each, their
ratio, the time per tick spent in the fused statements themselves (with the aggregates
and draws they read) against the same statements on numpy, and the largest position
difference between the two after the timed ticks.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from benchmarks.cases import CASES, SwarmdslRun
from swarmdsl.runtime.compiled import statements


def _timed(fn, spent: dict, key: str):
    def run(f):
        t0 = time.perf_counter()
        try:
            return fn(f)
        finally:
            spent[key] += time.perf_counter() - t0
    return run


def _runs(case, n: int, spent: dict) -> dict:
    """The model built twice: the statements that have a plan fused, and left to the
    numpy closures; those statements of both builds timed into `spent`."""
    real_wrap = statements.wrap
    runs = {}
    try:
        for key in spent:
            def wrap(cg, st, reference, *args, _key=key, **kwargs):
                got = real_wrap(cg, st, reference, *args, **kwargs)
                if got is reference:   # no plan: the same closure in both builds
                    return got
                return _timed(got if _key == "fused" else reference, spent, _key)
            statements.wrap = wrap
            runs[key] = SwarmdslRun(case, n, 1, backend="numba")
    finally:
        statements.wrap = real_wrap
    return runs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default="boids,vicsek")
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--ticks", type=int, default=60)
    args = ap.parse_args()
    for model in args.models.split(","):
        spent = {"fused": 0.0, "numpy statements": 0.0}
        runs = _runs(CASES[model], args.n, spent)
        for run in runs.values():
            for _ in range(5):   # compile, then warm up
                run.step()
        spent.update({k: 0.0 for k in spent})
        times: dict[str, list[float]] = {k: [] for k in runs}
        for i in range(args.ticks):
            order = list(runs.items()) if i % 2 else list(reversed(runs.items()))
            for name, run in order:
                t0 = time.perf_counter()
                run.step()
                times[name].append(time.perf_counter() - t0)
        med = {k: statistics.median(v) * 1e3 for k, v in times.items()}
        pos = [r.state()["pos"] for r in runs.values()]
        alone = {k: v / args.ticks * 1e3 for k, v in spent.items()}
        print(f"{model} n={args.n}: fused {med['fused']:.2f} ms/tick, numpy statements "
              f"{med['numpy statements']:.2f} ms/tick, speed-up "
              f"{med['numpy statements'] / med['fused']:.3f}; the statements alone "
              f"{alone['fused']:.2f} against {alone['numpy statements']:.2f} ms/tick; "
              f"largest position difference {np.max(np.abs(pos[0] - pos[1])):.1e}")


if __name__ == "__main__":
    main()
