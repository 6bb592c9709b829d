"""The cost of the cluster metrics (`clusters`, `largest_cluster`,
`mean_nearest_distance`) per sample, against a tick of the program measured.

Run from the repository root: ``python -m benchmarks.bench_cluster_metrics
[--n 1000 10000 100000]``.

`programs/boids.swarm` at its density (the world grows with sqrt(n)), with three metrics
added: `clusters(radius / 4)`, `largest_cluster(radius / 4)` and
`mean_nearest_distance()`. After 20 ticks it times, alternately in one process, one tick
of the simulation and one evaluation of each metric (median of `--repeat`), so a busy
machine slows both alike.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from pathlib import Path

from swarmdsl.compiler import compile_source
from swarmdsl.runtime.metrics import evaluate
from swarmdsl.runtime.simulation import Simulation

PROGRAM = Path(__file__).resolve().parents[1] / "programs" / "boids.swarm"
METRICS = {"clusters": "clusters(radius / 4)", "largest": "largest_cluster(radius / 4)",
           "spacing": "mean_nearest_distance()"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[1_000, 10_000, 100_000])
    ap.add_argument("--repeat", type=int, default=15)
    ap.add_argument("--backend", default="numpy")
    args = ap.parse_args()
    text = PROGRAM.read_text() + "".join(f"\nmetric {k}_bench = {v}"
                                         for k, v in METRICS.items())
    print(f"{'n':>8} {'tick ms':>9} " + " ".join(f"{k + ' ms':>12}" for k in METRICS))
    for n in args.n:
        side = 600 * math.sqrt(n / 100)
        program = compile_source(text, "boids.swarm",
                                 {"n": str(n), "width": str(side), "height": str(side)})
        sim = Simulation(program, 1, backend=args.backend)
        sim.run(20)
        names = [m.info.name for m in program.metrics]
        chosen = [program.metrics[names.index(f"{k}_bench")] for k in METRICS]
        times: dict[str, list[float]] = {"tick": [], **{k: [] for k in METRICS}}
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            sim.step()
            times["tick"].append(time.perf_counter() - t0)
            for k, m in zip(METRICS, chosen, strict=True):
                t0 = time.perf_counter()
                evaluate([m], sim)
                times[k].append(time.perf_counter() - t0)
        med = {k: statistics.median(v) * 1e3 for k, v in times.items()}
        print(f"{n:>8} {med['tick']:>9.2f} " + " ".join(f"{med[k]:>12.2f}" for k in METRICS))


if __name__ == "__main__":
    main()
