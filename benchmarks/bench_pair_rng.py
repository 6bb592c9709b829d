"""Per-pair random keys made eagerly (as before) or on first use, one process, alternating.

Run from the repository root: ``python -m benchmarks.bench_pair_rng [--n 10000]``.
Boids on the numpy backend; prints the median ms per tick of each and whether the two
runs' positions are bit-identical (they must be: only when the keys are made changes).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks.cases import CASES, SwarmdslRun
from swarmdsl.runtime import frame


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=10_000)
    parser.add_argument("--ticks", type=int, default=40)
    args = parser.parse_args(argv)
    lazy = frame.PairFrame.__init__

    def eager(self, pairs):
        lazy(self, pairs)
        self.rng  # noqa: B018  (key every pair at once, as before)

    runs = {m: SwarmdslRun(CASES["boids"], args.n, 0, "numpy") for m in ("eager", "lazy")}
    times = {m: [] for m in runs}
    try:
        for _ in range(args.ticks):
            for m, run in runs.items():
                frame.PairFrame.__init__ = eager if m == "eager" else lazy
                t0 = time.perf_counter()
                run.step()
                times[m].append(time.perf_counter() - t0)
    finally:
        frame.PairFrame.__init__ = lazy
    same = np.array_equal(runs["eager"].state()["pos"], runs["lazy"].state()["pos"])
    for m, ts in times.items():
        print(f"{m:>5}: {1e3 * float(np.median(ts[5:])):.1f} ms/tick")
    print(f"positions bit-identical: {same}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
