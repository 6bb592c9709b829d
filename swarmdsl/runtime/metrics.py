"""The metric log of one run: values per recorded tick, `metrics.parquet`, summaries.

Sweeps keep only the summaries (one row per run), so they are computed here, the same
way for `swarmdsl run` and for every run of a sweep: the last value, the mean over the
second half of the run (ticks at or after half the last tick: the stationary part an
order parameter is read from), the minimum and the maximum.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from swarmdsl.compiler.errors import SwarmError, SwarmRuntimeError

SUMMARIES = ("last", "mean", "min", "max")


class _SwarmFrame:
    """The frame a metric evaluates in: one row, no agent of its own."""

    def __init__(self, sim):
        self.sim, self.tick, self.rng = sim, sim.tick, sim.rng
        self.n = 1
        self.kind = None
        self.status_name = None
        self.locals: dict = {}
        self.overlay: dict = {}

    def state(self, col: str):  # pragma: no cover - the checker forbids it
        raise SwarmRuntimeError(f"internal: a metric read per-agent `{col}`")


class MetricLog:
    def __init__(self, program):
        from swarmdsl.compiler.lang_metrics import metrics_of

        self.metrics = metrics_of(program)
        self.names = [m.info.name for m in self.metrics]
        self.ticks: list[int] = []
        self.values: list[list[float]] = []     # one row per sample, one column per metric

    def __bool__(self) -> bool:
        return bool(self.metrics)

    def sample(self, sim) -> None:
        """Evaluate every metric on the simulation's current tick (once per tick)."""
        if not self.metrics or (self.ticks and self.ticks[-1] == sim.tick):
            return
        frame = _SwarmFrame(sim)
        row = []
        with np.errstate(all="ignore"):
            for m in self.metrics:
                try:
                    row.append(float(np.asarray(m.value(frame), dtype=float)))
                except SwarmError:
                    raise
                except (ArithmeticError, ValueError, TypeError) as exc:
                    raise SwarmRuntimeError(f"metric `{m.info.name}` failed at tick "
                                            f"{sim.tick}: {exc}", m.info.decl.span) from exc
        self.ticks.append(int(sim.tick))
        self.values.append(row)

    def series(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(ticks, values) of one metric."""
        j = self.names.index(name)
        vals = np.array([r[j] for r in self.values], dtype=float)
        return np.asarray(self.ticks, dtype=np.int64), vals

    def summary(self) -> dict[str, dict[str, float | None]]:
        """{metric: {last, mean, min, max}}; None where nothing was sampled or all NaN."""
        out = {}
        ticks = np.asarray(self.ticks, dtype=np.int64)
        for name in self.names:
            _t, v = self.series(name)
            if v.size == 0:
                out[name] = dict.fromkeys(SUMMARIES)
                continue
            half = v[ticks >= ticks[-1] / 2]
            finite = v[np.isfinite(v)]
            out[name] = {
                "last": _num(v[-1]),
                "mean": _num(np.mean(half)) if half.size else None,
                "min": _num(finite.min()) if finite.size else None,
                "max": _num(finite.max()) if finite.size else None,
            }
        return out

    def restore(self, ticks, names, values) -> None:
        """Continue a log read back from a checkpoint (same metrics, same order)."""
        if list(names) != self.names:
            raise SwarmRuntimeError("the checkpoint's metrics differ from the program's")
        self.ticks = [int(t) for t in ticks]
        self.values = [list(map(float, r)) for r in np.asarray(values, dtype=float)]

    def write(self, out: Path) -> None:
        """`metrics.parquet`: one row per (tick, metric), long format."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        n = len(self.ticks)
        k = len(self.names)
        vals = np.asarray(self.values, dtype=float).reshape(n, k)
        table = pa.table({
            "tick": pa.array(np.repeat(np.asarray(self.ticks, dtype=np.int64), k)),
            "name": pa.array(np.tile(np.asarray(self.names, dtype=object), n),
                             type=pa.string()),
            "value": pa.array(vals.reshape(-1)),
        })
        tmp = Path(out) / "metrics.parquet.tmp"
        pq.write_table(table, tmp)
        tmp.replace(Path(out) / "metrics.parquet")


def _num(x) -> float | None:
    x = float(x)
    return None if math.isnan(x) else x
