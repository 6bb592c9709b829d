"""`swarmdsl run --check` in whole ticks: ticks per second of a checked run whose
invariants the whole-tick kernel checks, against the same run checked tick by tick
(the only way a checked run ticked before) and the unchecked run, taking turns.

Run from the repository root (not part of CI):
``python -m benchmarks.bench_run_check [--steps 2000] [--rounds 3]``.

Models: boids as shipped (its two invariants) and Vicsek at 400 particles with an
invariant of our own on each particle's speed (`speed <= v0 * 1.000001`). Each round
runs three `Run`s of `--steps` ticks, no outputs (as `swarmdsl run --headless` without
`--out`: the metrics are sampled), kernels warm, in turns whose order alternates:
"whole" (checked, whole ticks allowed: this change), "stepped" (checked with
`SWARMDSL_WHOLE_TICKS=0`: every tick through `step()` and the monitor in Python, the
path every checked run took before) and "unchecked" (whole ticks, no check: the
bound). Printed per model: the median ticks per second of each (ticking time only, as
`run` reports it, and whole `execute()` wall time), the ratio whole / stepped, whether
the whole and stepped runs ended in the same state, and the load average before and
after.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _vicsek_text() -> str:
    text = (ROOT / "programs" / "vicsek.swarm").read_text()
    anchor = "  metric speed = mean(speed)\n"
    assert anchor in text
    return text.replace(anchor, anchor + "  invariant cruising: speed <= v0 * 1.000001\n")


def _program(model: str, checked: bool):
    from swarmdsl.compiler import compile_file, compile_source
    from swarmdsl.testing.monitor import enable_checks

    if model == "boids":
        prog = compile_file(ROOT / "programs" / "boids.swarm")
    else:
        prog = compile_source(_vicsek_text(), "vicsek_checked.swarm")
    if checked:
        enable_checks(prog)
    return prog


def _once(model: str, mode: str, steps: int, seed: int) -> tuple[float, float, bytes]:
    from swarmdsl.runtime.runner import Run

    os.environ["SWARMDSL_WHOLE_TICKS"] = "0" if mode == "stepped" else "1"
    run = Run(_program(model, mode != "unchecked"), seed=seed, steps=steps,
              backend="numba")
    run.show_progress = False
    t0 = time.perf_counter()
    outcome = run.execute()
    wall = time.perf_counter() - t0
    assert outcome == "completed", outcome
    state = b"".join(run.sim.agents.cols[c].tobytes() for c in ("pos", "vel"))
    return steps / run.tick_seconds, steps / wall, state


def measure(model: str, steps: int, rounds: int) -> dict:
    from swarmdsl.runtime.simulation import Simulation

    Simulation(_program(model, False), 0, backend="numba").advance(2)   # kernel at hand
    for mode in ("whole", "stepped", "unchecked"):      # warm: per-tick kernels too
        _once(model, mode, 50, 0)
    got: dict = {m: [] for m in ("whole", "stepped", "unchecked")}
    same = True
    for r in range(rounds):
        order = ["whole", "stepped", "unchecked"]
        if r % 2:
            order.reverse()
        states = {}
        for mode in order:
            rate, wall_rate, states[mode] = _once(model, mode, steps, seed=r + 1)
            got[mode].append((rate, wall_rate))
        same &= states["whole"] == states["stepped"] == states["unchecked"]
    med = {m: (float(np.median([a for a, _ in v])), float(np.median([b for _, b in v])))
           for m, v in got.items()}
    return {"median": med, "same": same}


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--models", default="boids,vicsek")
    p.add_argument("--steps", type=int, default=2000)
    p.add_argument("--rounds", type=int, default=3)
    args = p.parse_args(argv)
    print(f"load average before: {os.getloadavg()}")
    for model in args.models.split(","):
        got = measure(model, args.steps, args.rounds)
        med = got["median"]
        cells = ", ".join(f"{m} {t:,.0f} ticks/s ({w:,.0f} wall)" for m, (t, w) in
                          med.items())
        print(f"{model}: {cells}; whole / stepped {med['whole'][0] / med['stepped'][0]:.1f}x"
              f" (wall {med['whole'][1] / med['stepped'][1]:.1f}x); same state "
              f"{got['same']}")
    print(f"load average after: {os.getloadavg()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
