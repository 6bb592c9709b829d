"""`swarmdsl test` runs per second: whole processes, ticks whole (the properties
checked inside the whole-tick kernel) against ticks one by one, taking turns.

Run from the repository root (not part of CI):
``python -m benchmarks.bench_tester [--programs boids,vicsek,...] [--pairs 3]``
(a name under `programs/`, or a path ending in `.swarm`).

Each pair runs `swarmdsl test PROGRAM --examples 15 --seeds 1 --hypothesis-seed 0
--quiet` twice back to back, once with `SWARMDSL_WHOLE_TICKS=0` (every tick through
`step()`, the monitor checking it in Python: the path every run took before) and once
with it on, alternating which goes first; kernels warm (the whole-tick kernel compiled
in a process of its own, then one untimed run of each, which compiles or loads the
others). Printed per program: the CPU seconds (user + system) of each whole process,
median over the pairs, and their ratio (runs per second, on / off), with the load
average before and after. The hunt is seeded, so
both make the same runs: the report lines must agree, and do (checked).
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import subprocess
import sys

import numpy as np

ARGS = ["--examples", "15", "--seeds", "1", "--hypothesis-seed", "0", "--quiet"]


def _once(path: str, whole: bool, extra: list[str]) -> tuple[float, str]:
    """CPU seconds of one `swarmdsl test` process, and its report."""
    env = {**os.environ, "SWARMDSL_WHOLE_TICKS": "1" if whole else "0"}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    got = subprocess.run([sys.executable, "-m", "swarmdsl", "test", path, *ARGS, *extra],
                         env=env, capture_output=True, text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    # the report without its timings ("(5.0 s)"), which differ run to run
    report = re.sub(r" \(\d+(\.\d+)? s\)$", "", got.stdout, flags=re.MULTILINE)
    return cpu, report


# Compiles (or loads) the program's whole-tick kernel in a process of its own: a hunt
# shorter than the kernel's compile never gets it, its background compile ending with it.
_COMPILE = """
import sys
from swarmdsl import load_program
from swarmdsl.runtime.simulation import Simulation
Simulation(load_program(sys.argv[1]), 0, backend="numba").advance(2)
"""


def measure(path: str, pairs: int, extra: list[str]) -> dict:
    subprocess.run([sys.executable, "-c", _COMPILE, path], check=True)
    _once(path, True, extra)       # the other kernels compiled or loaded
    _once(path, False, extra)
    on, off = [], []
    reports = set()
    for k in range(pairs):
        for whole in ((True, False) if k % 2 == 0 else (False, True)):
            cpu, report = _once(path, whole, extra)
            (on if whole else off).append(cpu)
            reports.add(report)
    return {"on": float(np.median(on)), "off": float(np.median(off)),
            "ratios": [b / a for a, b in zip(on, off, strict=True)],
            "same": len(reports) == 1}


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--programs", default="boids,patrol,vicsek")
    p.add_argument("--pairs", type=int, default=3)
    p.add_argument("--steps", type=int, default=None)
    args = p.parse_args(argv)
    extra = ["--steps", str(args.steps)] if args.steps else []
    print(f"load before: {os.getloadavg()[0]:.1f}")
    print("| program | off CPU s | on CPU s | runs/s on ÷ off (median; each pair) | same report |")
    print("|---|---:|---:|---:|---|")
    for name in args.programs.split(","):
        got = measure(name if name.endswith(".swarm") else f"programs/{name}.swarm",
                      args.pairs, extra)
        ratios = ", ".join(f"{r:.2f}" for r in got["ratios"])
        print(f"| {name} | {got['off']:.2f} | {got['on']:.2f} | "
              f"**{got['off'] / got['on']:.2f}** ({ratios}) | {got['same']} |", flush=True)
    print(f"load after: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
