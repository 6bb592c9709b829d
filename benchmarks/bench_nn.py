"""nn() speed: one batched forward vs one call per row, nn() inside a program, training.

Run: `python -m benchmarks.bench_nn [--rows 100000] [--single 1000] [--agents 100000]
[--no-train] [--rounding-only]`.
Why it matters: the runtime calls each `nn(...)` site once per tick over every agent
that reaches it; this shows what that buys over a per-agent loop, and what a call site
costs per tick inside a running program (against the same program with the rule written
out as arithmetic). And whether a row's output depends on how many rows share its pass
(`rounding`): a batch of replicas makes one pass where each solo run made its own, so
it must not, for the numpy pass the runtime uses; torch's own matrix product is
counted beside it, the reason the pass is not torch's (docs/nn.md#forward-pass).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

MODELS = Path(__file__).resolve().parents[1] / "programs" / "models"


def bench_forward(name: str, rows: int, single: int, threads: int) -> dict[str, float]:
    import torch

    from swarmdsl.runtime.nn import load_model
    from swarmdsl.train.data import TASKS

    torch.set_num_threads(threads)
    model = load_model(MODELS / f"{name}.pt")
    x, _ = TASKS[name].make(rows, np.random.default_rng(0))
    model.forward(x[:10])  # warm-up
    best = float("inf")
    for _ in range(5):
        t = time.perf_counter()
        model.forward(x)
        best = min(best, time.perf_counter() - t)
    t = time.perf_counter()
    for i in range(single):
        model.forward(x[i : i + 1])
    per_row = (time.perf_counter() - t) / single
    return {
        "batched_ms": best * 1e3,
        "single_us": per_row * 1e6,
        "single_scaled_ms": per_row * rows * 1e3,
        "ratio": per_row * rows / best,
    }


ROUNDING_ROWS = 4096
ROUNDING_SIZES = (1, 2, 3, 4, 5, 6, 7, 8, 9, 12, 16, 17, 24, 31, 32, 33, 48, 64, 100, 1000)


def rounding(name: str, threads: int) -> dict[str, dict[int, int]]:
    """Rows (of ROUNDING_ROWS random inputs, run in consecutive slices of M rows) whose
    output differs in any bit from the same row's in one pass over all of them, for
    every M in ROUNDING_SIZES: for the runtime's pass and for torch's module."""
    import torch

    from swarmdsl.runtime.nn import load_model

    torch.set_num_threads(threads)
    model = load_model(MODELS / f"{name}.pt")
    x = np.random.default_rng(0).uniform(-20, 220, size=(ROUNDING_ROWS, model.n_in))
    z = (x - model._in_shift) / model._in_scale
    if model._clip is not None:
        np.clip(z, *model._clip, out=z)

    def torch_pass(rows):
        with torch.no_grad():
            return model._module(torch.from_numpy(np.ascontiguousarray(rows))).numpy()

    out = {}
    for label, run in (("numpy", model._mlp), ("torch", torch_pass)):
        whole = run(z)
        out[label] = {}
        for m in ROUNDING_SIZES:
            parts = np.concatenate([run(z[i:i + m]) for i in range(0, ROUNDING_ROWS, m)])
            out[label][m] = int((parts != whole).any(axis=1).sum())
    return out


# One call site per program; `{rule}` is either the nn() call or the same rule written
# out, so the difference is the cost of the network inside a tick.
PROGRAM = """world {{ size 1000 x 1000 }}
agent a {{
  count {n}
  var t = {zero}
  status s {{ t = {rule} }}
}}
"""
RULES = {
    "spring1d": ("0", 'nn("models/spring1d.pt", pos.x - 20, pos.x + 20)',
                 "((pos.x - 20) + (pos.x + 20)) / 2"),
    "matrix2d": ("(0, 0)",
                 'nn("models/matrix2d.pt", pos + (0, 40), pos - (0, 40), pos - (40, 0), '
                 "pos + (40, 0))",
                 "((pos - (40, 0)).x + (pos + (40, 0)).x, (pos + (0, 40)).y + "
                 "(pos - (0, 40)).y) / 2"),
}


def bench_program(name: str, agents: int, ticks: int, threads: int) -> dict[str, float]:
    """Milliseconds per tick of a program with one nn() site vs the rule as arithmetic."""
    import torch

    from swarmdsl.compiler import compile_source
    from swarmdsl.runtime.simulation import Simulation

    torch.set_num_threads(threads)
    zero, nn_rule, plain_rule = RULES[name]
    out = {}
    for label, rule in (("nn", nn_rule), ("plain", plain_rule)):
        text = PROGRAM.format(n=agents, zero=zero, rule=rule)
        prog = compile_source(text, f"bench_{name}.swarm", program_dir=MODELS.parent)
        sim = Simulation(prog, 0)
        sim.step()  # warm-up
        best = float("inf")
        for _ in range(ticks):
            t = time.perf_counter()
            sim.step()
            best = min(best, time.perf_counter() - t)
        out[f"{label}_ms"] = best * 1e3
    return out


def bench_training(name: str) -> tuple[float, float]:
    from swarmdsl.train import TrainConfig, train

    result = train(TrainConfig.for_task(name, seed=0))
    return result.seconds, result.val_percentage_error


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=100_000)
    ap.add_argument("--single", type=int, default=1_000)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--agents", type=int, default=100_000)
    ap.add_argument("--ticks", type=int, default=10)
    ap.add_argument("--no-train", action="store_true")
    ap.add_argument("--rounding-only", action="store_true",
                    help="only whether a row's output depends on its pass's row count")
    args = ap.parse_args()
    print(f"rows of {ROUNDING_ROWS:,} differing from one pass, in slices of M rows")
    for name in ("spring1d", "matrix2d"):
        r = rounding(name, args.threads)
        for label, counts in r.items():
            print(f"  {name:9s} {label:5s} " + " ".join(f"{m}:{n}" for m, n in counts.items()))
    if args.rounding_only:
        return
    print(f"forward, {args.rows:,} rows, torch threads = {args.threads}")
    for name in ("spring1d", "matrix2d"):
        r = bench_forward(name, args.rows, args.single, args.threads)
        print(
            f"  {name:9s} batched {r['batched_ms']:8.2f} ms | one row per call "
            f"{r['single_us']:6.1f} us x {args.rows:,} = {r['single_scaled_ms']:9.0f} ms "
            f"| ratio {r['ratio']:,.0f}x"
        )
    print(f"nn() inside a program, {args.agents:,} agents, best of {args.ticks} ticks")
    for name in ("spring1d", "matrix2d"):
        r = bench_program(name, args.agents, args.ticks, args.threads)
        print(
            f"  {name:9s} {r['nn_ms']:8.2f} ms/tick with nn() | {r['plain_ms']:8.2f} ms/tick "
            f"with the rule as arithmetic | nn() site costs {r['nn_ms'] - r['plain_ms']:.2f} ms"
        )
    if not args.no_train:
        print("training (defaults, seed 0, 1 thread)")
        for name in ("spring1d", "matrix2d"):
            seconds, pe = bench_training(name)
            print(f"  {name:9s} {seconds:6.1f} s, held-out percentage error {pe:.4f} %")


if __name__ == "__main__":
    main()
