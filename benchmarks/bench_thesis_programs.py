"""Ticks per second of the thesis programs at their own sizes, on both backends.

Run from the repository root: ``python -m benchmarks.bench_thesis_programs [--rounds 3]
[--ticks 1000] [--programs aco,patrol,benchmarks/models/beeclust.swarm]
[--backends numba,numpy] [--set n=10000 ...] [--against OTHER_CHECKOUT]``.

The thesis programs are small swarms (6-60 agents) whose ticks mostly run an extension
in Python (fields, trees, messages, robots), so the whole-tick kernel refuses most of
them and their speed is the fixed cost of a tick, not a cost per agent (boids_leader,
whose robots only see through a field of view, takes whole ticks). `--set` changes a
param of every program measured (boids_leader at `n=10000`: a dense swarm, ~2,000
candidates each); the table then gives each process's peak memory too. Each measurement is a
fresh process that compiles the program (a name under `programs/`, or a path ending
in `.swarm`), advances `--warm` ticks (kernels, the
whole-tick one included, compiled or loaded from the disk cache, the first deposits
made) and then times `--ticks` more with `Simulation.run`: no recording, no progress
line. `--against` times another checkout's
code the same way, taking turns with this one measurement by measurement, and gives the
ratio of the medians (this checkout / the other). Each checkout keeps its own kernel
cache folder for the whole benchmark, filled by a first untimed pass.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = ("aco", "aco_bt", "boids_leader", "mas_environment", "matrix2d", "patrol",
            "spring1d")
# Run inside the measured checkout's process: only the API every checkout has.
CHILD = """
import json, sys, time
from swarmdsl.compiler import compile_file
from swarmdsl.runtime.simulation import Simulation
import resource
path, backend, warm, ticks = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
sets = dict(a.split("=", 1) for a in sys.argv[5:])
sim = Simulation(compile_file(path, sets), 1, backend=backend)
sim.advance(warm)   # whole ticks where the program takes them: their kernel made or loaded
t0 = time.perf_counter()
sim.run(ticks)
wall = time.perf_counter() - t0
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps({"agents": int(sim.agents.n), "ticks_per_s": ticks / wall, "mb": peak}))
"""


def measure(tree: Path, cache: str, program: Path, backend: str, warm: int,
            ticks: int, sets=()) -> dict:
    """One fresh process of checkout `tree`: {agents, ticks_per_s, mb}."""
    env = {**os.environ, "PYTHONPATH": str(tree), "NUMBA_CACHE_DIR": cache,
           "SWARMDSL_CACHE_DIR": cache}
    done = subprocess.run([sys.executable, "-c", CHILD, str(program), backend, str(warm),
                           str(ticks), *sets], env=env, capture_output=True, text=True,
                          check=False, cwd=str(tree))
    if done.returncode:
        raise SystemExit(f"{program.name} ({backend}) failed in {tree}:\n{done.stderr}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--ticks", type=int, default=1000)
    p.add_argument("--warm", type=int, default=100)
    p.add_argument("--programs", default=",".join(PROGRAMS))
    p.add_argument("--backends", default="numba,numpy")
    p.add_argument("--against", type=Path, metavar="CHECKOUT",
                   help="another checkout of swarmdsl, timed the same way in turns")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="a param of the programs measured (repeatable)")
    args = p.parse_args(argv)
    trees = {"this": ROOT}
    if args.against is not None:
        trees["other"] = args.against.resolve()
    two = len(trees) == 2
    with tempfile.TemporaryDirectory() as tmp:
        caches = {n: tempfile.mkdtemp(dir=tmp, prefix=n) for n in trees}
        mem = " " + " | ".join(f"{n}: peak MB" for n in trees) + " |" if args.set else ""
        print(f"| program | agents | backend | {' | '.join(f'{n}: ticks/s' for n in trees)} |"
              + (" this / other |" if two else "") + mem)
        print("|---|---:|---|" + "---:|" * (len(trees) + two + len(trees) * bool(mem)))
        for name in args.programs.split(","):
            program = Path(name).resolve() if name.endswith(".swarm") else \
                ROOT / "programs" / f"{name}.swarm"
            for backend in args.backends.split(","):
                for n, tree in trees.items():      # fill each cache, untimed
                    measure(tree, caches[n], program, backend, args.warm, 10, args.set)
                got = {n: [] for n in trees}
                peak = {n: [] for n in trees}
                agents = 0
                for _ in range(args.rounds):
                    for n, tree in trees.items():
                        r = measure(tree, caches[n], program, backend, args.warm,
                                    args.ticks, args.set)
                        got[n].append(r["ticks_per_s"])
                        peak[n].append(r["mb"])
                        agents = r["agents"]
                med = {n: statistics.median(v) for n, v in got.items()}
                cells = " | ".join(f"{v:,.2f}" if v < 10 else f"{v:,.0f}"
                                   for v in med.values())
                ratio = f" {med['this'] / med['other']:.2f} |" if two else ""
                mb = (" " + " | ".join(f"{max(v):,.0f}" for v in peak.values()) + " |"
                      if mem else "")
                print(f"| {name} | {agents} | {backend} | {cells} |{ratio}{mb}", flush=True)


if __name__ == "__main__":
    main()
