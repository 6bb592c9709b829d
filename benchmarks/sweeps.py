"""Batched sweeps against solo sweeps, back to back, as ratios; and single small runs.

Run from the repository root (not part of CI): ``python -m benchmarks.sweeps`` (half an
hour on two busy cores, most of it the solo sweeps), ``--quick`` for a small version a
test runs, ``--only NAME,...`` for some cases (names in ``SWEEPS``, plus ``rss`` and
``ticks``).

Sweeps: each case is timed twice, one command right after the other, as a user types
them: ``swarmdsl sweep FILE ... --workers 2 --no-batch`` and the same command without
``--no-batch`` (batched by the default rule, docs/scaling.md), each a fresh process, wall
time from launch to exit: start-up, compiling the program and the kernels, the runs and
the table included; also each command's CPU time with its workers' (user + system: on a
shared machine it moves less with the others' load than the wall time does) and the
load average as each starts and ends. Both run on ``$SWARMDSL_BACKEND`` (numba unless
set: what a long sweep's runs take), so the two tables must be identical but for
`wall_seconds`, which is checked. A program the batch refuses is reported with the
refusal and not timed.

Memory: one ``Batch`` of 1,000 vicsek runs (n = 100, 300 ticks) in a fresh process, its
peak resident set size (``ru_maxrss``) and its time.

Ticks/s of single runs: each program once, as ``swarmdsl run`` runs it, after a first
untimed run of as many ticks (every kernel compiled) and five untimed ticks, on each
backend (only ``$SWARMDSL_BACKEND`` when it is set): the per-tick fixed cost that
batching amortises. Each in wall time and per second of the process's own CPU time (on a
shared machine the second moves less with the others' load).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@dataclass
class SweepCase:
    name: str
    program: str
    sets: list[str]
    seeds: int
    steps: int | None           # None: the program's own
    target: float | None        # the speed-up asked for (None: none asked)
    quick_sets: list[str]
    quick_seeds: int
    quick_steps: int


SWEEPS = {
    "vicsek100": SweepCase("vicsek n=100: 10 eta x 100 seeds, 300 ticks", "vicsek.swarm",
                           ["n=100", "eta=0.5:5:0.5"], 100, 300, 10,
                           ["n=100", "eta=1,3"], 4, 20),
    "vicsek400": SweepCase("vicsek n=400: 12 eta x 20 seeds, 300 ticks", "vicsek.swarm",
                           ["eta=0:5.5:0.5"], 20, 300, 4, ["eta=1,3"], 3, 10),
    "matrix2d": SweepCase("matrix2d: 256 seeds, 400 ticks", "matrix2d.swarm", [], 256,
                          None, 10, [], 4, 10),
    "spring1d": SweepCase("spring1d: 256 seeds, 600 ticks", "spring1d.swarm", [], 256,
                          None, 10, [], 4, 10),
    # nn(): the network's forward pass once a tick for the whole batch
    "matrix2d_nn": SweepCase("matrix2d_nn: 64 seeds, 400 ticks", "matrix2d_nn.swarm",
                             [], 64, None, 10, [], 4, 10),
    # fields: 7 ants laying pheromone on a 41 x 31 grid, one grid per replica batched
    "aco": SweepCase("aco: 64 seeds, 1000 ticks", "aco.swarm", [], 64, 1000, None,
                     [], 4, 10),
}

SINGLE = [("spring1d", "spring1d.swarm", {}), ("matrix2d", "matrix2d.swarm", {}),
          ("aco", "aco.swarm", {}), ("boids n=100", "boids.swarm", {"n": 100}),
          ("vicsek n=100", "vicsek.swarm", {"n": 100}), ("vicsek n=400", "vicsek.swarm", {})]


def _environment() -> dict:
    env = dict(os.environ)
    env.setdefault("SWARMDSL_BACKEND", "numba")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    return env


def _first_params(sets: list[str]) -> dict:
    """The first value of every axis: the program the refusal is asked about."""
    from swarmdsl.sweep.grid import parse_axis

    return {name: values[0] for name, values in (parse_axis(s) for s in sets)}


def refusal(case: SweepCase, sets: list[str]) -> str | None:
    from swarmdsl.compiler import compile_file
    from swarmdsl.runtime.batch_runner import batch_refusal_of

    return batch_refusal_of(compile_file(ROOT / "programs" / case.program,
                                         _first_params(sets)))


def _sweep(case: SweepCase, out: Path, sets, seeds, steps, batched: bool) -> float:
    argv = [sys.executable, "-m", "swarmdsl", "sweep", str(ROOT / "programs" / case.program),
            "--seeds", str(seeds), "--workers", "2", "--out", str(out)]
    for s in sets:
        argv += ["--set", s]
    if steps is not None:
        argv += ["--steps", str(steps)]
    if not batched:
        argv.append("--no-batch")
    load = os.getloadavg()[0]
    t0, c0 = time.perf_counter(), _children_cpu()
    done = subprocess.run(argv, env=_environment(), cwd=ROOT, capture_output=True,
                          text=True)
    elapsed, cpu = time.perf_counter() - t0, _children_cpu() - c0
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({done.returncode}):\n{done.stderr}")
    return elapsed, cpu, (load, os.getloadavg()[0])


def _children_cpu() -> float:
    """CPU seconds (user + system) of this process's finished children: a sweep's
    command and its worker processes, which it waits for."""
    import resource

    got = resource.getrusage(resource.RUSAGE_CHILDREN)
    return got.ru_utime + got.ru_stime


def _same_table(a: Path, b: Path) -> bool:
    import pyarrow.parquet as pq

    def read(folder):
        return pq.read_table(folder / "sweep.parquet").drop(["wall_seconds"])
    return read(a).equals(read(b))


def time_sweeps(names: list[str], quick: bool, work: Path) -> list[dict]:
    rows = []
    for name in names:
        case = SWEEPS[name]
        sets = case.quick_sets if quick else case.sets
        seeds = case.quick_seeds if quick else case.seeds
        steps = case.quick_steps if quick else case.steps
        why = refusal(case, sets)
        row = {"case": case.name, "target": case.target, "refused": why}
        if why is None:
            solo, solo_cpu, solo_load = _sweep(case, work / f"{name}-solo", sets, seeds,
                                               steps, False)
            batched, batched_cpu, batched_load = _sweep(case, work / f"{name}-batched",
                                                        sets, seeds, steps, True)
            row.update(solo=solo, batched=batched, ratio=solo / batched,
                       solo_cpu=solo_cpu, batched_cpu=batched_cpu,
                       cpu_ratio=solo_cpu / batched_cpu,
                       load=[*solo_load, *batched_load],
                       same=_same_table(work / f"{name}-solo", work / f"{name}-batched"))
        rows.append(row)
        print(json.dumps(row), file=sys.stderr, flush=True)
    return rows


_RSS = """
import json, resource, sys, time
import swarmdsl
program = swarmdsl.load_program(sys.argv[1], {"n": 100})
runs, steps = int(sys.argv[2]), int(sys.argv[3])
t0 = time.perf_counter()
results = swarmdsl.Batch(program, range(runs), steps=steps, size=runs).execute()
print(json.dumps({"seconds": time.perf_counter() - t0,
                  "replicas": max(r.replicas for r in results),
                  "completed": sum(r.outcome == "completed" for r in results),
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def peak_rss(quick: bool) -> dict:
    runs, steps = (20, 10) if quick else (1000, 300)
    done = subprocess.run([sys.executable, "-c", _RSS, str(ROOT / "programs" / "vicsek.swarm"),
                           str(runs), str(steps)], env=_environment(), cwd=ROOT,
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"the batch of {runs} runs failed:\n{done.stderr}")
    result = json.loads(done.stdout.splitlines()[-1])
    result.update(runs=runs, steps=steps)
    print(json.dumps(result), file=sys.stderr, flush=True)
    return result


def _backends() -> tuple[str, ...]:
    """`$SWARMDSL_BACKEND` alone when set (a test's quick run), else both."""
    name = os.environ.get("SWARMDSL_BACKEND", "").strip()
    return (name,) if name else ("numba", "numpy")


BACKENDS = _backends()


def ticks_per_second(quick: bool) -> list[dict]:
    from swarmdsl.compiler import compile_file
    from swarmdsl.runtime.simulation import Simulation

    rows = []
    ticks = 10 if quick else 300
    for label, file, params in SINGLE:
        program = compile_file(ROOT / "programs" / file,
                               {k: str(v) for k, v in params.items()})
        row = {"program": label, "agents": sum(k.count for k in program.kinds)}
        for backend in BACKENDS:
            # A first run of as many ticks compiles (or loads) every kernel the timed
            # run reaches, also those of statuses entered late (five ticks left
            # matrix2d compiling inside the timed ticks: 36 ticks/s instead of ~500).
            Simulation(program, 0, backend=backend).run(ticks + 5)
            sim = Simulation(program, 0, backend=backend)
            sim.run(5)          # caches warm
            t0, c0 = time.perf_counter(), time.process_time()
            sim.run(ticks)
            row[backend] = ticks / (time.perf_counter() - t0)
            row[f"{backend} cpu"] = ticks / (time.process_time() - c0)
        rows.append(row)
        print(json.dumps(row), file=sys.stderr, flush=True)
    return rows


def report(sweeps, rss, single) -> str:
    lines = []
    if sweeps:
        lines += ["| sweep (`--workers 2`) | solo runs | batched | speed-up | CPU: solo, "
                  "batched, speed-up | target | same table | load (1 min) |",
                  "|---|---:|---:|---:|---:|---:|---|---|"]
        for r in sweeps:
            target = "-" if r["target"] is None else f"{r['target']:g}x"
            if r["refused"]:
                lines.append(f"| {r['case']} | refused: {r['refused']} | | | | {target} | "
                             "| |")
            else:
                load = " -> ".join(f"{x:.1f}" for x in r["load"])
                lines.append(f"| {r['case']} | {r['solo']:.1f} s | {r['batched']:.1f} s | "
                             f"{r['ratio']:.1f}x | {r['solo_cpu']:.1f} s, "
                             f"{r['batched_cpu']:.1f} s, {r['cpu_ratio']:.1f}x | {target} | "
                             f"{'yes' if r['same'] else 'NO'} | {load} |")
    if rss:
        lines += ["", f"Batch of {rss['runs']:,} vicsek runs (n = 100, {rss['steps']} "
                  f"ticks, {rss['replicas']:,} replicas a batch): {rss['seconds']:.1f} s, "
                  f"peak RSS {rss['peak_mb']:.0f} MB, {rss['completed']:,} completed"]
    if single:
        lines += ["", "| single run | agents | " + " | ".join(
            f"ticks/s {b} (per CPU second)" for b in BACKENDS) + " |",
            "|---|---:|" + "---:|" * len(BACKENDS)]
        for r in single:
            lines.append(f"| {r['program']} | {r['agents']} | " + " | ".join(
                f"{r[b]:,.0f} ({r[f'{b} cpu']:,.0f})" for b in BACKENDS) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="small sizes (a few runs, a few ticks): a smoke test")
    parser.add_argument("--only", metavar="NAME,...",
                        help=f"some of {', '.join([*SWEEPS, 'rss', 'ticks'])}")
    args = parser.parse_args(argv)
    names = [*SWEEPS, "rss", "ticks"]
    if args.only:
        names = [n.strip() for n in args.only.split(",") if n.strip()]
        bad = [n for n in names if n not in [*SWEEPS, "rss", "ticks"]]
        if bad:
            parser.error(f"--only {bad[0]}: the cases are "
                         f"{', '.join([*SWEEPS, 'rss', 'ticks'])}")
    with tempfile.TemporaryDirectory(prefix="swarmdsl-bench-sweeps-") as work:
        sweeps = time_sweeps([n for n in names if n in SWEEPS], args.quick, Path(work))
    rss = peak_rss(args.quick) if "rss" in names else None
    single = ticks_per_second(args.quick) if "ticks" in names else []
    print(report(sweeps, rss, single))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
