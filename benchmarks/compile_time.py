"""First-run kernel compilation of the shipped programs on the numba backend.

Run from the repository root: ``python -m benchmarks.compile_time [--rounds 3]
[--programs boids,vicsek] [--agents 10000] [--against OTHER_CHECKOUT]``.

What a user waits for the first time they run a program, and what the test suite pays
for every program shape it runs: each round runs every program for one tick
(`swarmdsl run --steps 1 --backend numba -v`) in a fresh process whose kernel cache
holds only the kernels every program shares (the cell list, motion: compiled into it
once beforehand), so the time is that of the program's own kernels. It is read from
the run's `-v` line (`kernel compilation X s`), with the process's CPU seconds beside
it. `--against` runs another checkout's code the same way, taking turns with this one
program by program, and gives the ratio of the medians (this checkout / the other).
`--agents 10000` runs each program at 10^4 agents (its count param set, its world grown
to keep its density: `first_tick.sets_for`), where the kernels split their agents over
threads (`threads.MIN_PARALLEL`).
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = ("boids", "vicsek", "aco", "matrix2d", "patrol", "spring1d")
# Shares the cell list, the sums' search and the motion with every program, and
# compiles nothing of its own worth counting: run once into the warm cache.
WARM = """
world { size 40 x 40; edges wrap }
agent a {
  count 10
  velocity random_direction()
  status go { velocity = normalize(vel + sum(neighbors(5) : other.vel)) }
}
"""


def _env(tree: Path, cache: str) -> dict:
    return {**os.environ, "PYTHONPATH": str(tree), "NUMBA_CACHE_DIR": cache,
            "SWARMDSL_CACHE_DIR": cache}


def _run(tree: Path, cache: str, program: Path, sets=()) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "swarmdsl", "run", str(program),
                           "--headless", "--steps", "1", "--seed", "1", "--backend",
                           "numba", "-v", *sets], env=_env(tree, cache), cwd=tree,
                          capture_output=True, text=True, check=True)


def warm_cache(tree: Path, folder: Path) -> str:
    """A kernel cache holding what every program shares, compiled by `tree`'s code."""
    folder.mkdir(parents=True)
    program = folder / "warm.swarm"
    program.write_text(WARM)
    _run(tree, str(folder), program)
    program.unlink()
    return str(folder)


def first_run(tree: Path, warm: str, program: Path, sets=()) -> tuple[float, float]:
    """(kernel compilation seconds, process CPU seconds) of `program`'s first run."""
    with tempfile.TemporaryDirectory() as cache:
        shutil.copytree(warm, cache, dirs_exist_ok=True)
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        done = _run(tree, cache, program, sets)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    found = re.search(r"kernel compilation ([0-9.]+) s", done.stdout + done.stderr)
    if found is None:
        raise SystemExit(f"{program.name}: no `kernel compilation` in its -v output")
    return float(found.group(1)), cpu


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--programs", default=",".join(PROGRAMS))
    p.add_argument("--agents", default="own", help="own (each program's size) or 10000")
    p.add_argument("--against", type=Path, metavar="CHECKOUT",
                   help="another checkout of swarmdsl, timed the same way in turns")
    args = p.parse_args(argv)
    trees = {"this": ROOT}
    if args.against is not None:
        trees["other"] = args.against.resolve()
    with tempfile.TemporaryDirectory() as tmp:
        warm = {name: warm_cache(tree, Path(tmp) / name) for name, tree in trees.items()}
        print(f"| program | {' | '.join(f'{n}: compile s (CPU s)' for n in trees)} |"
              + (" this / other |" if len(trees) == 2 else ""))
        print("|---|" + "---:|" * (len(trees) + (len(trees) == 2)))
        for name in args.programs.split(","):
            program = ROOT / "programs" / f"{name}.swarm"
            from benchmarks.first_tick import sets_for

            sets = [a for k, v in sets_for(name, args.agents).items()
                    for a in ("--set", f"{k}={v}")]
            got = {n: [] for n in trees}
            for _ in range(args.rounds):
                for n, tree in trees.items():
                    got[n].append(first_run(tree, warm[n], program, sets))
            med = {n: (statistics.median(c for c, _ in rows),
                       statistics.median(u for _, u in rows)) for n, rows in got.items()}
            cells = " | ".join(f"{c:.2f} ({u:.1f})" for c, u in med.values())
            ratio = (f" {med['this'][0] / med['other'][0]:.2f} |"
                     if len(trees) == 2 and med["other"][0] > 0 else "")
            print(f"| {name} | {cells} |{ratio}", flush=True)


if __name__ == "__main__":
    main()
