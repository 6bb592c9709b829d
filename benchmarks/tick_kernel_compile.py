"""Seconds to compile a program's whole-tick kernel the first time.

Run from the repository root (not part of CI):
``python -m benchmarks.tick_kernel_compile [--programs programs/patrol.swarm,...]
[--rounds 3] [--against OTHER_CHECKOUT]``.

Each measurement is a fresh process with swarmdsl's kernel cache turned off
(`SWARMDSL_KERNEL_CACHE=0`): it compiles the program, steps one tick (the per-tick
kernels), then times the first `Simulation.advance(1)`, which composes and compiles the
whole-tick kernel and runs one tick. numba's own cache of the shared functions stays
as it is, so the figure is the program's kernel. `--against` times another checkout's
code the same way, the two taking turns, and gives the ratio of the medians (this /
other).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ("programs/patrol.swarm", "programs/boids.swarm", "programs/vicsek.swarm")
CHILD = """
import sys, time
from swarmdsl import load_program
from swarmdsl.runtime.simulation import Simulation
sim = Simulation(load_program(sys.argv[1]), 0, backend="numba")
sim.step()
t = time.perf_counter()
assert sim.advance(1) == 1
print(time.perf_counter() - t)
"""


def once(checkout: Path, program: str) -> float:
    env = {**os.environ, "SWARMDSL_KERNEL_CACHE": "0", "PYTHONPATH": str(checkout)}
    got = subprocess.run([sys.executable, "-c", CHILD, str(ROOT / program)], env=env,
                         capture_output=True, text=True, cwd=checkout, check=True)
    return float(got.stdout.strip().splitlines()[-1])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--programs", default=",".join(DEFAULT))
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--against", type=Path, default=None)
    args = ap.parse_args(argv)
    checkouts = [ROOT] + ([args.against.resolve()] if args.against else [])
    print(f"load before: {os.getloadavg()[0]:.1f}")
    head = "| program | this: s (each) |" + (" other: s (each) | this / other |"
                                            if args.against else "")
    print(head)
    print("|---|---:|" + ("---:|---:|" if args.against else ""))
    for program in args.programs.split(","):
        times: list[list[float]] = [[] for _ in checkouts]
        for r in range(args.rounds):
            order = range(len(checkouts)) if r % 2 == 0 else reversed(range(len(checkouts)))
            for k in order:
                times[k].append(once(checkouts[k], program))
        cells = [f"{statistics.median(t):.1f} ({', '.join(f'{x:.1f}' for x in t)})"
                 for t in times]
        line = f"| {Path(program).stem} | " + " | ".join(cells) + " |"
        if args.against:
            ratio = statistics.median(times[0]) / statistics.median(times[1])
            line += f" {ratio:.2f} |"
        print(line)
    print(f"load after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
