"""Cost of one field tick (decay + diffusion), against one memory-bound numpy pass.

Run from the repository root: ``python -m benchmarks.bench_fields [--repeat N]``.
For each grid it prints the median milliseconds per ``Field.step()`` and the ratio to
one ``np.add(a, b, out=a)`` over an array of the same shape, which is roughly how many
full-array passes a tick costs; that ratio is the number to compare across machines.
It also times a bilinear deposit and sample for a batch of 10,000 agents.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from swarmdsl.runtime.fields import Field, Grid


def _median_ms(fn, repeat: int) -> float:
    fn()  # warm caches and page in the buffers
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def bench_grid(n_nodes_side: int, repeat: int, periodic: bool = False) -> dict:
    """Time decay+diffusion on an ``n x n`` node grid and the one-pass baseline."""
    side = n_nodes_side if periodic else n_nodes_side - 1
    grid = Grid(side, side, 1.0, periodic=periodic)
    rng = np.random.default_rng(0)
    field = Field("pheromone", grid, decay=0.05, diffuse=0.2, init=rng.random(grid.shape))
    a = rng.random(grid.shape)  # (ny, nx)
    b = rng.random(grid.shape)
    step_ms = _median_ms(field.step, repeat)
    add_ms = _median_ms(lambda: np.add(a, b, out=a), repeat)
    pos = rng.uniform(0, side, size=(10_000, 2))  # (M, 2)
    deposit_ms = _median_ms(lambda: field.deposit(pos, 1.0), repeat)
    sample_ms = _median_ms(lambda: field.sample(pos), repeat)
    return {
        "grid": f"{grid.ny}x{grid.nx}" + (" periodic" if periodic else ""),
        "step_ms": step_ms,
        "add_ms": add_ms,
        "ratio": step_ms / add_ms,
        "deposit_ms": deposit_ms,
        "sample_ms": sample_ms,
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=0,
                        help="timed repetitions per figure (default: 200 small, 20 large)")
    args = parser.parse_args(argv)
    print(f"{'grid':>18} {'step ms':>9} {'np.add ms':>10} {'ratio':>6} "
          f"{'deposit 10k ms':>15} {'sample 10k ms':>14}")
    for side, periodic in [(201, False), (201, True), (2001, False), (2001, True)]:
        repeat = args.repeat or (200 if side < 1000 else 20)
        r = bench_grid(side, repeat, periodic)
        print(f"{r['grid']:>18} {r['step_ms']:9.3f} {r['add_ms']:10.3f} {r['ratio']:6.2f} "
              f"{r['deposit_ms']:15.3f} {r['sample_ms']:14.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
