"""The ant colony at scale: steps per second and the share of each tick spent in field
updates (decay, and decay + diffusion), for 1,000 ants on a 2,000 x 2,000 world with a
10-unit and a 1-unit grid.

Run from the repository root: ``python -m benchmarks.bench_aco [--ticks N] [--ants N]``.
It runs ``programs/aco.swarm`` with its params overridden (`ants`, `width`, `height`,
`spacing`) and times ``Field.step`` inside the run, so the field share is measured in the
real tick, not in isolation.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from swarmdsl.compiler import compile_file
from swarmdsl.runtime import fields as fields_mod
from swarmdsl.runtime.simulation import Simulation

ACO = Path(__file__).resolve().parents[1] / "programs" / "aco.swarm"


def bench(ants: int, size: int, spacing: float, ticks: int, seed: int = 0,
          diffusion: float = 0.0) -> dict:
    overrides = {"ants": str(ants), "width": str(size), "height": str(size),
                 "spacing": str(spacing), "diffusion": str(diffusion)}
    sim = Simulation(compile_file(ACO, overrides), seed)
    sim.run(5)  # warm up: first deposits, page in the grid
    field_seconds = 0.0
    step = fields_mod.Field.step

    def timed_step(self):
        nonlocal field_seconds
        t0 = time.perf_counter()
        step(self)
        field_seconds += time.perf_counter() - t0

    fields_mod.Field.step = timed_step
    try:
        t0 = time.perf_counter()
        sim.run(ticks)
        wall = time.perf_counter() - t0
    finally:
        fields_mod.Field.step = step
    nodes = sim.environment.grid.nx * sim.environment.grid.ny
    return {"ants": ants, "world": f"{size}x{size}", "spacing": spacing, "nodes": nodes,
            "diffusion": diffusion,
            "steps_per_s": ticks / wall, "ms_per_tick": 1e3 * wall / ticks,
            "field_ms": 1e3 * field_seconds / ticks, "field_share": field_seconds / wall}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ticks", type=int, default=200)
    ap.add_argument("--ants", type=int, default=1000)
    ap.add_argument("--size", type=int, default=2000)
    args = ap.parse_args(argv)
    print(f"{'ants':>6} {'world':>10} {'grid':>5} {'diffuse':>7} {'nodes':>10} {'steps/s':>8} "
          f"{'ms/tick':>8} {'field ms':>9} {'field share':>11}")
    for spacing, diffusion in ((10, 0.0), (1, 0.0), (10, 0.1), (1, 0.1)):
        r = bench(args.ants, args.size, spacing, args.ticks, diffusion=diffusion)
        print(f"{r['ants']:>6} {r['world']:>10} {r['spacing']:>5g} {r['diffusion']:>7g} "
              f"{r['nodes']:>10,} "
              f"{r['steps_per_s']:>8.1f} {r['ms_per_tick']:>8.2f} {r['field_ms']:>9.2f} "
              f"{r['field_share']:>10.0%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
