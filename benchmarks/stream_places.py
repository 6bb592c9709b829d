"""What naming every draw by its place costs a compile: the shipped programs' place
tables against their whole compile.

Run from the repository root: ``python -m benchmarks.stream_places [--repeat 20]``.

The table (`compiler/stream_places.py`) is one walk over the checked program, made
once per compile by the first draw compiled; this times that walk alone (best of
`--repeat`) beside `compile_file` of the same program (parse, check, reference
closures; best of `--repeat`), in this process, CPU time.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _best(fn, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def main(argv=None) -> None:
    from swarmdsl.compiler import compile_file
    from swarmdsl.compiler.stream_places import _expanded_trees, places

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=20)
    args = parser.parse_args(argv)
    print("| program | AST nodes | place table | compile | share |")
    print("|---|---:|---:|---:|---:|")
    for path in sorted((ROOT / "programs").glob("*.swarm")):
        program = compile_file(path)
        info = program.info
        table = places(info.tree, _expanded_trees(info))
        walk = _best(lambda info=info: places(info.tree, _expanded_trees(info)),
                     args.repeat)
        whole = _best(lambda path=path: compile_file(path), args.repeat)
        print(f"| {path.stem} | {len(table)} | {walk * 1e3:.2f} ms | {whole * 1e3:.1f} ms "
              f"| {walk / whole:.1%} |")


if __name__ == "__main__":
    main()
