"""Boids: the compiled `programs/boids.swarm` against hand-written numpy, agent-steps/s.

Run from the repository root:
``python -m benchmarks.bench_boids [--steps 300] [--sizes 1000,10000,100000]``.

For each n the world grows with sqrt(n) so the density stays the program's own (100
agents on 600 x 600), and both models get the same parameters (`--set n=... --set
width=... --set height=...` for the program). Only the tick loop is timed: for the
compiled program, `Simulation.step()` called directly (what `run.json`'s
`steps_per_second` measures, without recording); for the reference,
`ReferenceBoids.step()`. The two alternate tick by tick in one process, so a busy
shared machine slows both alike. Agent-steps/s come from the median tick time (robust
to the other load of a shared machine); `mean ratio` is the same ratio from total times.
Compare ratios, not absolute figures. Sizes above 10,000 run a fifth of the steps.

Both start from the same placement and velocities (the same seeded draws), so `gap`, the
largest position difference after the untimed warm-up ticks, shows that they compute the
same model: it stays at rounding level (~1e-12) until the chaos of flocking amplifies it.
After the timed ticks it prints how each has flocked: global polarisation, mean
neighbours within the radius, and local alignment (the mean, over agents, of the length
of the mean heading of the agent and its neighbours). The two models draw random numbers
in a different order, so the figures agree in size, not in bits.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from benchmarks.reference_boids import ReferenceBoids, polarisation

PROGRAM = Path(__file__).resolve().parents[1] / "programs" / "boids.swarm"
RADIUS = 80.0  # the program's default `radius`


def world_side(n: int) -> int:
    """Side of a square world holding n agents at the program's density (100 on 600^2)."""
    return round(600 * math.sqrt(n / 100))


def local_order(pos: np.ndarray, vel: np.ndarray, radius: float) -> tuple[float, float]:
    """(mean neighbours within `radius`, mean local alignment) of a swarm state."""
    n = pos.shape[0]
    unit = vel / np.maximum(np.linalg.norm(vel, axis=1), 1e-12)[:, None]  # (N, 2)
    pairs = cKDTree(pos).query_pairs(radius, output_type="ndarray")
    a, b = pairs[:, 0], pairs[:, 1]
    total = unit.copy()
    for c in range(2):
        total[:, c] += (np.bincount(a, unit[b, c], minlength=n)
                        + np.bincount(b, unit[a, c], minlength=n))
    count = np.bincount(a, minlength=n) + np.bincount(b, minlength=n)
    return 2 * len(pairs) / n, float(np.mean(np.linalg.norm(total, axis=1) / (count + 1)))


def bench_size(n: int, steps: int, warmup: int, seed: int) -> dict:
    from swarmdsl import load_program
    from swarmdsl.runtime.simulation import Simulation

    side = world_side(n)
    program = load_program(PROGRAM, {"n": str(n), "width": str(side), "height": str(side)})
    sim = Simulation(program, seed)
    ref = ReferenceBoids(n, side, side, radius=RADIUS, seed=seed)
    for _ in range(warmup):
        ref.step()
        sim.step()
    gap = float(np.abs(sim.agents.cols["pos"] - ref.pos).max())
    t_ref = np.empty(steps)
    t_sim = np.empty(steps)
    for k in range(steps):
        t0 = time.perf_counter()
        ref.step()
        t1 = time.perf_counter()
        sim.step()
        t_sim[k] = time.perf_counter() - t1
        t_ref[k] = t1 - t0
    cols = sim.agents.cols
    ref_nb, ref_local = local_order(ref.pos, ref.vel, RADIUS)
    sim_nb, sim_local = local_order(cols["pos"], cols["vel"], RADIUS)
    return {
        "n": n, "side": side, "steps": steps,
        "ref": n / np.median(t_ref), "sim": n / np.median(t_sim),
        "ratio": np.median(t_ref) / np.median(t_sim), "mean_ratio": t_ref.sum() / t_sim.sum(),
        "gap": gap,
        "ref_pol": polarisation(ref.vel), "sim_pol": polarisation(cols["vel"]),
        "ref_nb": ref_nb, "sim_nb": sim_nb, "ref_local": ref_local, "sim_local": sim_local,
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=300,
                        help="timed ticks per size (a fifth above 10,000 agents)")
    parser.add_argument("--sizes", default="1000,10000,100000",
                        help="comma-separated agent counts")
    parser.add_argument("--warmup", type=int, default=10, help="untimed ticks first")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    sizes = [int(s.replace("_", "")) for s in args.sizes.split(",") if s.strip()]
    print(f"{'n':>8} {'world':>11} {'steps':>5} {'reference':>10} {'swarmdsl':>10} "
          f"{'ratio':>5} {'mean':>5} {'gap':>7}  {'polarisation':>11} {'neighbours':>11} "
          f"{'alignment':>9}")
    print(f"{'':>8} {'':>11} {'':>5} {'agent-st/s':>10} {'agent-st/s':>10} {'':>5} "
          f"{'ratio':>5} {'':>7}  {'ref/dsl':>11} {'ref/dsl':>11} {'ref/dsl':>9}")
    for n in sizes:
        steps = args.steps if n <= 10_000 else max(args.steps // 5, 1)
        r = bench_size(n, steps, args.warmup, args.seed)
        print(f"{n:>8,} {r['side']:>5}x{r['side']:<5} {steps:>5} {r['ref']:>10.3g} "
              f"{r['sim']:>10.3g} {r['ratio']:>5.2f} {r['mean_ratio']:>5.2f} "
              f"{r['gap']:>7.0e}  {r['ref_pol']:>5.2f}/{r['sim_pol']:<5.2f} "
              f"{r['ref_nb']:>5.1f}/{r['sim_nb']:<5.1f} "
              f"{r['ref_local']:>4.2f}/{r['sim_local']:<4.2f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
