"""The benchmark suite: every model against its hand-written references, in one run.

Run from the repository root (not part of CI):
``python -m benchmarks [--models boids,vicsek] [--sizes 1000,10000,100000,1000000]``.

Each model runs at its own density unless ``--neighbours K`` is given: then every
model's world is sized so that a uniform layout has a mean of K other agents within the
model's radius (`cases.Case.params_at`), and every column, the same-work check and the
memory probes get those params.

For each model (`cases.py`) and size N, every implementation column is built from the
same initial agents: the compiled program on each runtime backend (`SWARMDSL_BACKENDS`,
plus `--backend NAME`), a hand-written numpy program, a hand-written serial numba
program (skipped when numba is not installed) and, for boids up to N = 1,000, Mesa's
boid flockers (skipped when Mesa is not installed). After untimed warm-up ticks (the
numba kernels compile in the first; the compile time is reported once per model) the
columns take turns tick by tick, so the load of a shared machine hits all alike, until
the tick count or the time cap per size is reached. Agent-steps/s = N / median tick time.
`dsl ÷ this` is the swarmdsl column's agent-steps/s over this column's (0.5: swarmdsl
at half this column's speed).

Same work: before timing, each model runs 10 ticks at N = 1,000 with its noise off from
one start in every column, and the largest position difference from the swarmdsl column
is printed (rounding level: the same rules in the same order). After the timed ticks
each column's polarisation and mean neighbours within the model's radius are printed:
with noise on they agree in size, not in bits.

Peak memory: each (model, column, N) runs again in a fresh process (`--probe`): the
resident-set high-water mark while building the agents and running 3 ticks, minus the
process's size after its imports and warm-up, per agent.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks import cases
from benchmarks.cases import (CASES, SwarmdslRun, reference, statistics,
                              uniform_neighbours)

ROOT = Path(__file__).resolve().parents[1]
CHECK_N = 1000
CHECK_TICKS = 10


def available(module: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(module) is not None


def columns(case, n: int, backends: dict) -> list[str]:
    """The implementation columns for `case` at size n, in table order."""
    cols = list(backends)
    cols += [c for c in case.references if c != "numba" or available("numba")]
    if n <= case.mesa_max and available("mesa"):
        cols.append("mesa")
    return cols


def build(case, column: str, n: int, seed: int, backends: dict, start=None, params=None,
          overrides=None, neighbours=None):
    """One implementation of `case` at size n (a reference needs `start` and `params`;
    the swarmdsl columns size their world from `neighbours`, see `Case.params_at`)."""
    if column in backends:
        return SwarmdslRun(case, n, seed, backends[column], overrides, neighbours)
    if column == "mesa":
        from benchmarks.mesa_boids import MesaBoids
        return MesaBoids(start, params, seed)
    return reference(case, column, start, params, seed)


def same_work(case, backends: dict, seed: int, n: int = CHECK_N,
              ticks: int = CHECK_TICKS, neighbours: float | None = None) -> dict[str, float]:
    """Largest position gap from the swarmdsl column after noise-free ticks."""
    base = SwarmdslRun(case, n, seed, None, case.quiet, neighbours)
    start = {k: v.copy() for k, v in base.state().items()}
    impls = {c: build(case, c, n, seed, backends, start, base.params, case.quiet,
                      neighbours)
             for c in columns(case, n, backends) if c != "mesa"}
    for _ in range(ticks):
        base.step()
        for impl in impls.values():
            impl.step()
    want = base.state()["pos"]
    return {c: float(np.abs(impl.state()["pos"] - want).max()) for c, impl in impls.items()}


def runtime_compile_seconds(case, seed: int) -> float | None:
    """The numba backend's kernel compilation for this model (its first tick, 100 agents;
    0 when an earlier model already compiled kernels of the same shapes)."""
    if not available("numba"):
        return None
    run = SwarmdslRun(case, 100, seed, "numba")
    run.step()
    return run.sim.backend.compile_seconds


def compile_seconds(case, seed: int) -> float | None:
    """First tick of the numba reference at 100 agents: its compile time (or cache load)."""
    if "numba" not in case.references or not available("numba"):
        return None
    run = SwarmdslRun(case, 100, seed)
    ref = reference(case, "numba", run.state(), run.params, seed)
    t0 = time.perf_counter()
    ref.step()
    return time.perf_counter() - t0


def ticks_for(n: int, steps: int) -> int:
    return max(3, steps if n <= 10_000 else steps // 5 if n <= 100_000 else steps // 20)


def time_size(case, n: int, args, backends: dict) -> list[dict]:
    """Interleaved ticks of every column at size n; one result row per column."""
    main = SwarmdslRun(case, n, args.seed, backends[next(iter(backends))],
                       neighbours=args.neighbours)
    start = {k: v.copy() for k, v in main.state().items()}
    impls = {}
    for c in columns(case, n, backends):
        try:
            impls[c] = main if c == next(iter(backends)) else build(
                case, c, n, args.seed, backends, start, main.params,
                neighbours=args.neighbours)
        except LookupError as exc:
            print(f"  {c}: skipped ({exc})", flush=True)
    for _ in range(args.warmup):
        for impl in impls.values():
            impl.step()
    times = {c: [] for c in impls}
    began = time.perf_counter()
    for _ in range(ticks_for(n, args.steps)):
        for c, impl in impls.items():
            t0 = time.perf_counter()
            impl.step()
            times[c].append(time.perf_counter() - t0)
        if time.perf_counter() - began > args.cap and len(times[c]) >= 3:
            break
    rows = []
    for c, impl in impls.items():
        med = float(np.median(times[c]))
        rows.append({"model": case.name, "n": n, "column": c, "ticks": len(times[c]),
                     "agent_steps": n / med, "seconds_per_tick": med,
                     "density": uniform_neighbours(case, main.params),
                     **statistics(case, main.params, impl.state())})
    dsl = rows[0]["agent_steps"]
    for row in rows:
        row["dsl_ratio"] = dsl / row["agent_steps"]
    return rows, start, main.params


# ---- peak memory, one fresh process per (model, column, n) ----

def _rss_mb() -> tuple[float, float]:
    """(current, peak) resident set in MB, from /proc/self/status."""
    got = {}
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(("VmRSS:", "VmHWM:")):
                got[line.split(":")[0]] = int(line.split()[1]) / 1024
    return got["VmRSS"], got["VmHWM"]


def probe(model: str, column: str, n: int, seed: int, backends: dict,
          start_file: str | None, neighbours: float | None = None) -> dict:
    """In this process: build one column at size n, run 3 ticks, report memory and the
    params it ran with (so the caller can check they are the timed ones)."""
    import gc

    case = CASES[model]
    tiny = SwarmdslRun(case, 100, seed, neighbours=neighbours)
    warm = build(case, column, 100, seed, backends, tiny.state(), tiny.params,
                 neighbours=neighbours)
    for _ in range(2):  # imports, compiled kernels, caches: part of the baseline
        warm.step()
    del warm, tiny
    start = params = None
    if column not in backends:  # the start state, read before the baseline is taken
        with np.load(start_file) as data:
            start = {k: data[k] for k in data.files if k != "params"}
            params = json.loads(str(data["params"]))
    gc.collect()
    base, _ = _rss_mb()
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # reset the high-water mark to the current resident set
    impl = build(case, column, n, seed, backends, start, params, neighbours=neighbours)
    for _ in range(3):
        impl.step()
    _, peak = _rss_mb()
    return {"base_mb": base, "peak_mb": peak, "bytes_per_agent": (peak - base) * 2**20 / n,
            "params": params if params is not None else impl.params}


def probe_command(model: str, column: str, n: int, seed: int, backend_args: list[str],
                  start_file: Path, neighbours: float | None) -> list[str]:
    """The fresh process that measures one column: the suite's own options passed on."""
    density = ["--neighbours", repr(neighbours)] if neighbours is not None else []
    return [sys.executable, "-m", "benchmarks", "--probe", model, column, str(n),
            "--start", str(start_file), "--seed", str(seed), *backend_args, *density]


def memory(model: str, column: str, n: int, seed: int, backend_args: list[str],
           start: dict, params: dict, neighbours: float | None = None) -> dict:
    """Peak memory of one column at size n, measured in a fresh process ({} if not Linux,
    or if the probe ran with other params than `params`: then it measured another run)."""
    import tempfile

    if not Path("/proc/self/clear_refs").exists():
        return {}
    with tempfile.TemporaryDirectory() as tmp:
        start_file = Path(tmp) / "start.npz"
        np.savez(start_file, params=json.dumps(params), **start)
        cmd = probe_command(model, column, n, seed, backend_args, start_file, neighbours)
        done = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT,
                              env={**os.environ, "PYTHONPATH": str(ROOT)})
    if done.returncode != 0:
        print(f"  memory probe {model}/{column}/{n} failed: {done.stderr.strip()[-300:]}")
        return {}
    got = json.loads(done.stdout.strip().splitlines()[-1])
    if got.pop("params") != json.loads(json.dumps(params)):
        print(f"  memory probe {model}/{column}/{n} ran with other params; not reported")
        return {}
    return got


# ---- report ----

def fmt_row(r: dict) -> str:
    mem = (f"{r['peak_mb']:>8.0f} {r['bytes_per_agent']:>8.0f}" if "peak_mb" in r
           else f"{'-':>8} {'-':>8}")
    return (f"| {r['n']:>9,} | {r['column']:<14} | {r['ticks']:>5} | {r['agent_steps']:>9.3g} "
            f"| {r['dsl_ratio']:>6.3g} | {mem.split()[0]:>7} | {mem.split()[1]:>7} "
            f"| {r['polarisation']:>5.3f} | {r['neighbours']:>6.2f} |")


def neighbours_option(text: str) -> float:
    """`--neighbours K`: a positive, finite mean number of neighbours."""
    value = float(text)
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"K must be a positive number, got {text}")
    return value


def density_line(case, n: int, neighbours: float | None) -> str:
    """What density the model runs at: the option's, or its own (at size n)."""
    params = case.params_at(n, neighbours)
    source = (f"--neighbours {neighbours:g}" if neighbours is not None
              else "the model's own; --neighbours K sets it")
    return (f"density: {uniform_neighbours(case, params):.2f} other agents within "
            f"r = {case.radius(params):g} of each for a uniform layout ({source})")


HEADER = ("|         N | column         | ticks | agent-st/s | dsl ÷ this | peak MB | B/agent "
          "| polar | neighb |\n|---:|---|---:|---:|---:|---:|---:|---:|---:|")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", default=",".join(CASES), help="comma-separated models")
    parser.add_argument("--sizes", default="1000,10000,100000,1000000")
    parser.add_argument("--steps", type=int, default=100,
                        help="timed ticks at N <= 10,000 (a fifth at 10^5, a twentieth above)")
    parser.add_argument("--cap", type=float, default=60.0,
                        help="seconds of timed ticks per size, at least 3 ticks each")
    parser.add_argument("--warmup", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--backend", action="append", default=[], metavar="NAME",
                        help="also time the runtime on backend NAME (repeatable)")
    parser.add_argument("--neighbours", type=neighbours_option, metavar="K",
                        help="size every model's world for a mean of K other agents within "
                             "its radius (uniform layout); default: each model's own density")
    parser.add_argument("--no-memory", action="store_true", help="skip the memory probes")
    parser.add_argument("--json", type=Path, help="also write every row to this file")
    parser.add_argument("--probe", nargs=3, metavar=("MODEL", "COLUMN", "N"),
                        help=argparse.SUPPRESS)
    parser.add_argument("--start", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    backends = dict(cases.SWARMDSL_BACKENDS)
    for name in args.backend:
        backends[f"swarmdsl-{name}"] = name
    backend_args = [a for name in args.backend for a in ("--backend", name)]
    if args.probe:
        model, column, n = args.probe
        print(json.dumps(probe(model, column, int(n), args.seed, backends, args.start,
                               args.neighbours)))
        return 0
    sizes = [int(s.replace("_", "")) for s in args.sizes.split(",") if s.strip()]
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else math.nan
    print(f"# python -m benchmarks {' '.join(argv if argv is not None else sys.argv[1:])}")
    print(f"# load average at start {load:.1f}; numba "
          f"{'yes' if available('numba') else 'no'}; mesa {'yes' if available('mesa') else 'no'}")
    all_rows = []
    for model in args.models.split(","):
        case = CASES[model]
        print(f"\n## {model}  ({case.program.relative_to(ROOT)})\n", flush=True)
        print(density_line(case, sizes[0], args.neighbours))
        seconds = compile_seconds(case, args.seed)  # first: nothing compiled yet
        if seconds is not None:
            print(f"numba reference: first tick {seconds:.2f} s (its compile time, or the "
                  "load from numba's cache in benchmarks/__pycache__)")
        seconds = runtime_compile_seconds(case, args.seed)
        if seconds is not None:
            print(f"swarmdsl numba backend: kernels compiled in {seconds:.2f} s "
                  "(or loaded from disk if an earlier process compiled them; see "
                  "docs/backends.md)")
        gaps = same_work(case, backends, args.seed, neighbours=args.neighbours)
        print("same work, 10 noise-free ticks at N = 1,000, largest |pos - swarmdsl pos|: "
              + ", ".join(f"{c} {g:.1e}" for c, g in gaps.items()))
        print(f"\n{HEADER}", flush=True)
        for n in sizes:
            rows, start, params = time_size(case, n, args, backends)
            for row in rows:
                if not args.no_memory:
                    row.update(memory(model, row["column"], n, args.seed, backend_args,
                                      start, params, args.neighbours))
                print(fmt_row(row), flush=True)
                all_rows.append(row)
    print(f"\n# load average at end {os.getloadavg()[0]:.1f}")
    if args.json:
        args.json.write_text(json.dumps(all_rows, indent=1))
    return 0
