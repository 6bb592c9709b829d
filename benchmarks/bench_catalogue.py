"""The catalogue of buggy programs (`tests/data/catalogue/`): for each, the first
failure of a plain checked run, the time `swarmdsl test` takes to find it and to
shrink it with its default budget, the case it shrinks to, and the hunt of the fixed
version.

Run from the repository root: ``python -m benchmarks.bench_catalogue [--backend numpy]
[--only NAME ...]``. Prints a Markdown table (`docs/benchmarks.md`). Every hunt is
seeded (`--hypothesis-seed 0`) and uses the defaults of `swarmdsl test` (100 drawn
runs, a 60 s time budget, 3 runs of the program as written); the hunt is made again
with drawn runs only (`--seeds 0`), to show what the draws reach by themselves.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

CATALOGUE = Path(__file__).resolve().parent.parent / "tests" / "data" / "catalogue"


def buggy_programs() -> list[Path]:
    """Every buggy program of the catalogue (each has a `NAME_fixed.swarm` twin)."""
    return sorted(p for p in CATALOGUE.glob("*.swarm") if not p.stem.endswith("_fixed"))


def measure(path: Path) -> dict:
    from swarmdsl.testing import run_program, search
    from swarmdsl.testing.search import horizon
    from swarmdsl.testing.runner import load

    prog = load(path)
    steps, _ = horizon(prog, None, 0)
    plain = run_program(prog, steps, seed=0)
    t0 = time.perf_counter()
    report = search(path, hypothesis_seed_value=0)
    hunt = time.perf_counter() - t0
    ce = report.counterexample
    t0 = time.perf_counter()
    drawn = search(path, hypothesis_seed_value=0, seeds=0).counterexample
    drawn_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    fixed = search(path.with_name(f"{path.stem}_fixed.swarm"), hypothesis_seed_value=0)
    return {
        "name": path.stem, "plain_tick": plain.first_tick(), "hunt": hunt,
        "found_runs": ce.found_after if ce else None,
        "found_s": ce.found_seconds if ce else None,
        "origin": ce.origin if ce else None,
        "shrink_runs": ce.shrink_runs if ce else None,
        "shrink_s": ce.shrink_seconds if ce else None,
        "agents": ce.agents if ce else None, "ticks": ce.tick if ce else None,
        "minimal": ce.minimal if ce else None,
        "drawn": (f"{_n(drawn.found_after, 'run')}, {drawn.found_seconds:.1f} s; "
                  f"{_n(drawn.agents, 'agent')}, "
                  f"{'1-minimal' if drawn.minimal else 'NOT minimal'}"
                  if drawn else f"not found ({drawn_s:.0f} s)"),
        "fixed_ok": fixed.counterexample is None, "fixed_runs": fixed.examples,
        "fixed_s": time.perf_counter() - t0,
    }


def _n(count, word: str) -> str:
    return f"{count} {word}{'s' * (count != 1)}"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--backend", default=os.environ.get("SWARMDSL_BACKEND", "numpy"))
    ap.add_argument("--only", nargs="*", default=None)
    args = ap.parse_args(argv)
    os.environ["SWARMDSL_BACKEND"] = args.backend
    print("| program | plain run fails at tick | found after | found in | shrunk in | "
          "to | 1-minimal | drawn runs only (`--seeds 0`) | fixed version |")
    print("|---|---|---|---|---|---|---|---|---|")
    for path in buggy_programs():
        if args.only and path.stem not in args.only:
            continue
        m = measure(path)
        where = "as written" if m["origin"] and "as written" in m["origin"] else "drawn"
        print(f"| `{m['name']}` | {m['plain_tick']} | {_n(m['found_runs'], 'run')} "
              f"({where}) | {m['found_s']:.1f} s | {_n(m['shrink_runs'], 'run')}, "
              f"{m['shrink_s']:.1f} s | {_n(m['agents'], 'agent')}, "
              f"{_n(m['ticks'], 'tick')} | "
              f"{'yes' if m['minimal'] else 'NO'} | {m['drawn']} | "
              f"{'passes' if m['fixed_ok'] else 'FAILS'}: {_n(m['fixed_runs'], 'run')}, "
              f"{m['fixed_s']:.1f} s |", flush=True)


if __name__ == "__main__":
    main()
