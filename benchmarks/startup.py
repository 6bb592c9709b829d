"""Start-up: `swarmdsl check` and `swarmdsl run --steps 1` against a bare numpy import.

Run from the repository root: ``python -m benchmarks.startup [--repeat 15]``.

Each command is a fresh interpreter, timed from launch to exit (wall clock). The
commands take turns, one of each per round, so the load of a shared machine hits all of
them alike; the table gives the median over the rounds and each command's ratio to
``python -c "import numpy"`` (every swarmdsl command needs numpy, so that is the floor).
`check` and `run` are timed with the grammar cache warm (the usual case) and with it
off (`SWARMDSL_CACHE_DIR=""`: a first run, or an unwritable cache folder); `run` also
with `--out` (writing Parquet: pyarrow's import and the files).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PROGRAM = str(ROOT / "programs" / "boids.swarm")


def commands(cache: str) -> dict[str, tuple[list[str], dict]]:
    """label -> (argv, environment overrides)."""
    py = sys.executable
    warm = {"SWARMDSL_CACHE_DIR": cache}
    cold = {"SWARMDSL_CACHE_DIR": ""}
    check = [py, "-m", "swarmdsl", "check", PROGRAM]
    run = [py, "-m", "swarmdsl", "run", PROGRAM, "--headless", "--steps", "1"]
    recorded = [*run, "--out", str(Path(cache) / "run")]    # the usual run: recorded
    return {
        'python -c "import numpy"': ([py, "-c", "import numpy"], {}),
        "swarmdsl check": (check, warm),
        "swarmdsl run --steps 1": (run, warm),
        "swarmdsl run --steps 1 --out DIR": (recorded, warm),
        "swarmdsl check (no grammar cache)": (check, cold),
        "swarmdsl run --steps 1 (no grammar cache)": (run, cold),
    }


def time_once(argv: list[str], env: dict) -> float:
    t0 = time.perf_counter()
    done = subprocess.run(argv, env={**os.environ, **env}, cwd=ROOT,
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    elapsed = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed:\n{done.stderr}")
    return elapsed


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=15, help="rounds (default 15)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="swarmdsl-bench-cache-") as cache:
        cmds = commands(cache)
        for argv_, env in cmds.values():  # warm the file cache and fill the grammar cache
            time_once(argv_, env)
        times: dict[str, list[float]] = {label: [] for label in cmds}
        for _ in range(args.repeat):
            for label, (argv_, env) in cmds.items():
                times[label].append(time_once(argv_, env))
    base = statistics.median(times['python -c "import numpy"'])
    print(f"{'command':<44} {'median s':>9} {'x numpy':>8}")
    for label, ts in times.items():
        med = statistics.median(ts)
        print(f"{label:<44} {med:>9.3f} {med / base:>8.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
