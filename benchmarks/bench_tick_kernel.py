"""Small swarms, kernels warm: ticks per second of `Simulation.advance` (the numba
backend's whole-tick kernel), of `Simulation.step()` one tick at a time, and of the
hand-written serial numba loop of the same model (`numba_refs.py`), taking turns.

Run from the repository root (not part of CI):
``python -m benchmarks.bench_tick_kernel [--models vicsek,boids] [--sizes 100,400]``
(`--models swarmalators` too: its agents' phases start alike as well).

Each model starts from its program's own agents at the suite's density
(`cases.CASES`); the reference starts from the same positions and velocities. After
warm-up (compiling, or loading the kernels from disk), the three take turns, a block of
`--block` ticks each, for `--rounds` rounds, each round from a fresh start (seed + round)
so the three are timed at the same density; a block of `advance` is one call of
`--block` ticks. Printed: the median microseconds per tick of each, the ratios advance /
reference and step / reference in ticks per second (1.0: as fast as the hand-written
loop), the mean neighbours within the radius after the block (swarmdsl / reference),
and the load average before and after.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from benchmarks import cases


def _median_us(samples: list[float], ticks: int) -> float:
    return float(np.median(samples)) / ticks * 1e6


def measure(model: str, n: int, rounds: int, block: int, seed: int = 1) -> dict:
    """Each round starts the three afresh from the same agents (a flock tightens
    over the ticks, and the program and the hand-written loop draw their noise from
    different generators, so over hundreds of ticks their densities part), runs one
    untimed tick each, then times `block` ticks of each in turn."""
    from swarmdsl import load_program
    from swarmdsl.runtime.compiled import tick_run
    from swarmdsl.runtime.simulation import Simulation

    case = cases.CASES[model]
    params = case.params_at(n, None)
    text = {k: str(v) for k, v in params.items()}
    program = load_program(case.program, text)
    t0 = time.perf_counter()
    Simulation(program, seed, backend="numba").advance(1)   # compiles or loads
    compile_s = time.perf_counter() - t0
    times: dict = {"advance": [], "step": [], "reference": []}
    neighbours: dict = {"swarmdsl": [], "reference": []}
    same = True
    line = ""
    for r in range(rounds):
        fused = Simulation(program, seed + r, backend="numba")
        stepped = Simulation(program, seed + r, backend="numba")
        cols = fused.agents.cols   # positions, velocities and the model's own columns
        start = {k: v.copy() for k, v in cols.items()
                 if k in ("pos", "vel") or k in program.var_specs}
        ref = cases.reference(case, "numba", start, params, seed + r)
        fused.advance(1)
        stepped.step()
        ref.step()
        t = time.perf_counter()
        fused.advance(block)
        times["advance"].append(time.perf_counter() - t)
        t = time.perf_counter()
        for _ in range(block):
            stepped.step()
        times["step"].append(time.perf_counter() - t)
        t = time.perf_counter()
        for _ in range(block):
            ref.step()
        times["reference"].append(time.perf_counter() - t)
        same = same and (fused.agents.cols["pos"].tobytes()
                         == stepped.agents.cols["pos"].tobytes())
        mine = {k: fused.agents.cols[k] for k in start}
        neighbours["swarmdsl"].append(cases.statistics(case, params, mine)["neighbours"])
        neighbours["reference"].append(
            cases.statistics(case, params, ref.state())["neighbours"])
        line = tick_run.summary(fused.backend)[0]
    us = {k: _median_us(v, block) for k, v in times.items()}
    return {"model": model, "n": n, "us": us, "compile_s": compile_s, "whole": line,
            "same": same, "neighbours": {k: float(np.mean(v)) for k, v in
                                         neighbours.items()}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default="vicsek,boids")
    ap.add_argument("--sizes", default="100,400")
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--block", type=int, default=100)
    args = ap.parse_args(argv)
    print(f"load average before: {os.getloadavg()[0]:.2f}")
    print("model   N     advance us/tick  step us/tick  reference us/tick  "
          "advance/ref  step/ref  (ticks/s ratios)")
    for model in args.models.split(","):
        for n in (int(s) for s in args.sizes.split(",")):
            r = measure(model, n, args.rounds, args.block)
            us = r["us"]
            print(f"{model:7} {n:<5} {us['advance']:15.1f} {us['step']:13.1f} "
                  f"{us['reference']:18.1f} {us['reference'] / us['advance']:12.2f} "
                  f"{us['reference'] / us['step']:9.2f}   neighbours after: "
                  f"{r['neighbours']['swarmdsl']:.1f} / {r['neighbours']['reference']:.1f}; "
                  f"first advance {r['compile_s']:.2f} s; bits "
                  f"{'same' if r['same'] else 'DIFFER'} as step(); {r['whole']}")
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
