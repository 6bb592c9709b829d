"""The cost of the NaN guards (`compiler/nan_guard.py`) on boids, ms per tick.

Run from the repository root: ``python -m benchmarks.bench_nan_guard [--n 10000]``.

Compiles `programs/boids.swarm` twice, with the guards and with them replaced by the
bare closures, at the program's density (the world grows with sqrt(n)), and times
`Simulation.step()` of the two alternately, tick by tick, in one process, so a busy
machine slows both alike. Both must end at bit-identical positions: the guards only
read. It also times one guard on an (n, 2) array directly.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
import timeit
from pathlib import Path

import numpy as np

from swarmdsl.compiler import compile_file, nan_guard
from swarmdsl.runtime.simulation import Simulation

PROGRAM = Path(__file__).resolve().parents[1] / "programs" / "boids.swarm"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--ticks", type=int, default=300)
    args = ap.parse_args()
    side = 600 * math.sqrt(args.n / 100)
    over = {"n": str(args.n), "width": str(side), "height": str(side)}
    guarded = compile_file(PROGRAM, over)
    real_guard = nan_guard.guard
    nan_guard.guard = lambda fn, *a, **k: fn
    try:
        plain = compile_file(PROGRAM, over)
    finally:
        nan_guard.guard = real_guard
    sims = {"guarded": Simulation(guarded, 1), "plain": Simulation(plain, 1)}
    for sim in sims.values():
        for _ in range(5):
            sim.step()
    times: dict[str, list[float]] = {k: [] for k in sims}
    for i in range(args.ticks):
        order = list(sims.items()) if i % 2 else list(reversed(sims.items()))
        for name, sim in order:
            t0 = time.perf_counter()
            sim.step()
            times[name].append(time.perf_counter() - t0)
    for name, ts in times.items():
        print(f"{name:8} median {statistics.median(ts) * 1e3:7.2f} ms/tick")
    same = np.array_equal(sims["guarded"].agents.cols["pos"], sims["plain"].agents.cols["pos"])
    print(f"bit-identical positions: {same}")

    class _Frame:
        active = np.ones(args.n, dtype=bool)

    values = np.random.default_rng(0).random((args.n, 2))
    per = timeit.timeit(lambda: nan_guard.nan_rows(values, _Frame), number=2000) / 2000
    print(f"one guard on ({args.n}, 2): {per * 1e6:.1f} us")


if __name__ == "__main__":
    main()
