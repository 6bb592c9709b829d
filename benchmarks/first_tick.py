"""How soon a first run from a cold kernel cache ticks, and what its first run costs.

Run from the repository root: ``python -m benchmarks.first_tick [--programs boids,vicsek]
[--sizes own,10000] [--ratio-rounds 3] [--ratio-steps 200]``.

First tick: each shipped program, at its own size and at 10^4 agents (its count param
set to 10,000 and, where the program has them, its world's params grown with the square
root of the count, so the density stays its own), in a fresh process with fresh,
empty cache folders (numba's and swarmdsl's): the wall time from starting the process
to the end of its first tick, with the backend the default gives a run of the
program's own length (`world { steps }`, else 1,000 ticks).

Cold first run: `swarmdsl run programs/boids.swarm --headless --steps 200` at 10^4 agents
in a 6,000 x 6,000 world (boids' own density), whole process, with fresh cache folders
against a second run with the folders the first one filled (warm), taking turns; the
ratio of the medians, and where the cold run switched to numba (`-v`).
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = ("boids", "boids_leader", "vicsek", "aco", "aco_bt", "mas_environment",
            "patrol", "matrix2d", "spring1d")
# The params that make 10^4 agents, and the world params grown with sqrt(count).
BIG = {
    "boids": ({"n": 10_000}, {"width": 600, "height": 600}, 100),
    "boids_leader": ({"n": 10_000}, {}, 40),
    "vicsek": ({"n": 10_000}, {"size": 10}, 400),
    "aco": ({"ants": 10_000}, {}, 7),          # the ants meet on their trails, not in
    "aco_bt": ({"ants": 10_000}, {}, 7),       # the open: the same arena
    "mas_environment": ({"n": 10_000}, {}, 60),
    "patrol": ({"robots": 10_000}, {}, 8),
    "matrix2d": ({"cols": 100, "rows": 100}, {}, 12),
    "spring1d": ({"extensions": 10_000}, {}, 6),
}

CHILD = r"""
import sys, time
launched = float(sys.argv[1])
from swarmdsl.compiler import compile_file
from swarmdsl.runtime.simulation import Simulation
sets = dict(a.split("=", 1) for a in sys.argv[3:])
program = compile_file(sys.argv[2], sets)
steps = program.world.steps or 1000
sim = Simulation(program, 0, work=steps * sum(k.count for k in program.kinds))
sim.step()
took = time.time() - launched
choice = sim.backend.choice
print(f"{took:.3f}\t{sim.agents.n}\t{choice.line if choice else sim.backend.name}")
"""


def _env(cache: str) -> dict:
    env = {**os.environ, "NUMBA_CACHE_DIR": f"{cache}/numba",
           "SWARMDSL_CACHE_DIR": f"{cache}/sw", "PYTHONPATH": str(ROOT)}
    env.pop("SWARMDSL_BACKEND", None)
    return env


def sets_for(name: str, size: str) -> dict:
    if size == "own":
        return {}
    counts, world, own = BIG[name]
    scale = (int(size) / own) ** 0.5
    return {**counts, **{k: round(v * scale) for k, v in world.items()}}


def first_tick(name: str, size: str) -> tuple[float, int, str]:
    """(seconds from launch to the first tick's end, agents, the backend's line)."""
    sets = [f"{k}={v}" for k, v in sets_for(name, size).items()]
    with tempfile.TemporaryDirectory() as cache:
        done = subprocess.run([sys.executable, "-c", CHILD, repr(time.time()),
                               str(ROOT / "programs" / f"{name}.swarm"), *sets],
                              env=_env(cache), capture_output=True, text=True, cwd=ROOT)
    if done.returncode != 0:
        raise SystemExit(f"{name} {size}: {done.stderr.strip().splitlines()[-1:]}")
    took, agents, line = done.stdout.strip().split("\t")
    return float(took), int(agents), line


BOIDS = ["-m", "swarmdsl", "run", "programs/boids.swarm", "--headless", "--set", "n=10000",
         "--set", "width=6000", "--set", "height=6000", "-v"]


def _timed(cache: str, steps: int) -> tuple[float, str]:
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, *BOIDS, "--steps", str(steps)], env=_env(cache),
                          capture_output=True, text=True, cwd=ROOT, check=True)
    took = time.perf_counter() - t0
    found = re.search(r"ticks 0-(\d+) on numpy while its kernels compiled in another "
                      r"process \(([0-9.]+) s\)", done.stderr)
    how = (f"numba from tick {int(found.group(1)) + 1} (compiled in {found.group(2)} s)"
           if found else done.stderr.strip().splitlines()[-1] if "numpy (" in done.stderr
           else "numba throughout")
    return took, how


def ratio(rounds: int, steps: int) -> None:
    with tempfile.TemporaryDirectory() as warm:
        _timed(warm, steps)           # fills `warm`
        cold, hot, hows = [], [], []
        for _ in range(rounds):
            with tempfile.TemporaryDirectory() as fresh:
                took, how = _timed(fresh, steps)
            cold.append(took)
            hows.append(how)
            hot.append(_timed(warm, steps)[0])
    c, w = statistics.median(cold), statistics.median(hot)
    print(f"\nboids, 10^4 agents, {steps} ticks, whole process (load "
          f"{os.getloadavg()[0]:.1f}): cold {c:.1f} s "
          f"({', '.join(f'{x:.1f}' for x in cold)}), warm {w:.1f} s "
          f"({', '.join(f'{x:.1f}' for x in hot)}), ratio {c / w:.2f}")
    for how in hows:
        print(f"  cold run: {how}")


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--programs", default=",".join(PROGRAMS))
    p.add_argument("--sizes", default="own,10000")
    p.add_argument("--ratio-rounds", type=int, default=3, help="0: no cold/warm ratio")
    p.add_argument("--ratio-steps", type=int, default=200)
    args = p.parse_args(argv)
    print(f"load average {os.getloadavg()[0]:.1f}")
    print("| program | agents | first tick, cold | backend |\n|---|---:|---:|---|")
    for name in args.programs.split(","):
        for size in args.sizes.split(","):
            took, agents, line = first_tick(name, size)
            print(f"| {name} | {agents:,} | {took:.2f} s | {line} |", flush=True)
    if args.ratio_rounds:
        ratio(args.ratio_rounds, args.ratio_steps)


if __name__ == "__main__":
    main()
