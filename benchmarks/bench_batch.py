"""Replicas batched against solo runs: ticks/s and agent-steps/s of one program's run
alone and of R replicas stepped as one `BatchedSimulation`, on one backend, measured
back to back in one process (kernels compiled and warmed first).

Run from the repository root: ``python -m benchmarks.bench_batch [--program vicsek]
[--set n=100] [--replicas 100] [--ticks 200] [--backend numba]``. Each gain column is
what batching gains: R solo runs' time (one timed, times R) over the batch's, metrics
sampled every tick in both (as `swarmdsl sweep` does by default), kernels compiled
before either is timed; in wall time and in this process's CPU time (on a shared
machine the second moves less with the others' load).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from swarmdsl import load_program
from swarmdsl.runtime.batch import BatchedSimulation
from swarmdsl.runtime.metrics import MetricLog
from swarmdsl.runtime.simulation import Simulation

PROGRAMS = Path(__file__).resolve().parents[1] / "programs"


def _timed(step, ticks: int) -> tuple[float, float]:
    """(wall seconds, CPU seconds of this process) of `ticks` calls of `step`."""
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(ticks):
        step()
    return time.perf_counter() - t0, time.process_time() - c0


def bench(program, replicas: int, ticks: int, backend: str) -> dict:
    # A first solo run of as many ticks compiles (or loads) every kernel the run
    # reaches, also those of statuses entered late; the runs timed after it compile none.
    Simulation(program, 0, backend=backend).run(ticks)
    solo = Simulation(program, 1, backend=backend)
    log = MetricLog(program)

    def solo_tick():
        solo.step()
        log.sample(solo)
    solo_s, solo_cpu = _timed(solo_tick, ticks)
    batch = BatchedSimulation(program, list(range(replicas)), backend=backend)

    def batch_tick():
        batch.step()
        batch.metric_rows()
    _timed(batch_tick, 3)
    batch_s, batch_cpu = _timed(batch_tick, ticks)
    n = solo.agents.n
    return {"agents": n, "replicas": replicas,
            "solo_ticks": ticks / solo_s, "solo_steps": n * ticks / solo_s,
            "batch_ticks": ticks / batch_s, "batch_steps": replicas * n * ticks / batch_s,
            "gain": replicas * solo_s / batch_s,
            "solo_cpu_ms": 1e3 * solo_cpu / ticks,
            "batch_cpu_ms": 1e3 * batch_cpu / (ticks * replicas),
            "gain_cpu": replicas * solo_cpu / max(batch_cpu, 1e-9)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--program", default="vicsek")
    ap.add_argument("--set", action="append", default=["n=100"], metavar="NAME=VALUE")
    ap.add_argument("--replicas", type=int, default=100)
    ap.add_argument("--ticks", type=int, default=200)
    ap.add_argument("--backend", choices=("numba", "numpy"), action="append")
    args = ap.parse_args(argv)
    overrides = dict(s.split("=", 1) for s in args.set) if args.set else None
    if args.program != "vicsek" and args.set == ["n=100"]:
        overrides = None
    program = load_program(PROGRAMS / f"{args.program}.swarm", overrides)
    print(f"{args.program} {overrides or ''}: {args.replicas} replicas, {args.ticks} ticks")
    print(f"{'backend':>8} {'agents':>6} {'solo ticks/s':>13} {'solo steps/s':>13} "
          f"{'batch ticks/s':>14} {'batch steps/s':>14} {'gain':>6} "
          f"{'CPU ms: solo tick':>18} {'replica-tick':>13} {'gain':>6}")
    for backend in args.backend or ("numba", "numpy"):
        r = bench(program, args.replicas, args.ticks, backend)
        print(f"{backend:>8} {r['agents']:>6} {r['solo_ticks']:>13,.0f} "
              f"{r['solo_steps']:>13.3g} {r['batch_ticks']:>14,.1f} "
              f"{r['batch_steps']:>14.3g} {r['gain']:>5.1f}x "
              f"{r['solo_cpu_ms']:>18.4f} {r['batch_cpu_ms']:>13.4f} "
              f"{r['gain_cpu']:>5.1f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
