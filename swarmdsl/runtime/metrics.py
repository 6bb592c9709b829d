"""The metric log of one run: values per recorded tick, `metrics.parquet`, summaries.

`metrics.parquet` is a Parquet dataset of part files flushed with `agents.parquet`'s
rows (`spool.PartFolder`), so a killed run keeps its flushed samples too.

Sweeps keep only the summaries (one row per run), so they are computed here, the same
way for `swarmdsl run` and for every run of a sweep: the last value, the mean over the
second half of the run (ticks at or after half the last tick: the stationary part an
order parameter is read from), the minimum and the maximum.

The swarm-level measures that need neighbours (`clusters(R)`, `largest_cluster(R)`,
`mean_nearest_distance()`) are computed here too, from positions alone, so a metric's
closure, a batch (one call per replica: replicas never see each other) and the tests'
independent scipy computation all measure the same thing. Clusters are the connected
components of the graph `neighbors(R)` draws: its pairs come from `spatial.build_pairs`,
the same search and arithmetic (distance <= R, the short way round a wrap-around world).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from swarmdsl.errors import SwarmError, SwarmRuntimeError
from swarmdsl.runtime import arrow
from swarmdsl.runtime.spatial import build_pairs
from swarmdsl.runtime.spool import PartFolder

SUMMARIES = ("last", "mean", "min", "max")
FILE = "metrics.parquet"
BOUNDS_KEY = "swarmdsl.metric_bounds"   # Parquet metadata: {metric: [low, high]}
_CHUNK = 1024       # samples gathered into one array


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


def swarm_frame(sim, segments=None) -> _SwarmFrame:
    """The frame metrics evaluate in. A batch (`runtime/batch.py`) gives `segments`:
    rows -> where each replica's start in them, so swarm aggregates reduce per replica."""
    frame = _SwarmFrame(sim)
    if segments is not None:
        frame.segments = segments
    return frame


def evaluate(metrics, sim) -> np.ndarray:
    """(k,) float64: every metric of `metrics` on `sim`'s current tick (a run's, or a
    replica's of a batch: `runtime/batch.py`)."""
    frame = swarm_frame(sim)
    row = np.empty(len(metrics))
    with np.errstate(all="ignore"):
        for j, m in enumerate(metrics):
            try:
                row[j] = float(np.asarray(m.value(frame), dtype=float))
            except SwarmError:
                raise
            except (ArithmeticError, ValueError, TypeError) as exc:
                raise SwarmRuntimeError(f"metric `{m.info.name}` failed at tick "
                                        f"{sim.tick}: {exc}", m.info.decl.span) from exc
    return row


def bounds_of(metrics) -> dict[str, list[float | None]]:
    """{metric: [low, high]}: the least and most each compiled metric can be, None
    where not known."""
    return {m.info.name: list(getattr(m.info, "bounds", (None, None))) for m in metrics}


def read_bounds(schema) -> dict[str, tuple[float | None, float | None]]:
    """The bounds a table's schema records (`BOUNDS_KEY`); {} for tables written
    before they were recorded, or damaged metadata."""
    raw = (schema.metadata or {}).get(BOUNDS_KEY.encode())
    try:
        got = json.loads(raw) if raw else {}
        return {str(k): (_bound(v[0]), _bound(v[1])) for k, v in got.items()}
    except (ValueError, TypeError, IndexError, AttributeError):
        return {}


def _bound(v) -> float | None:
    return None if v is None else float(v)


class MetricLog:
    """Metric samples of one run. With a folder (`attach`), samples are written to
    `metrics.parquet` as part files whenever the recorder flushes and then dropped, so
    a run's memory does not grow with its length and a killed run keeps every flushed
    sample; the summaries are read back from the parts at the end. Without one (a
    sweep's run that keeps no folder) they stay in memory, 8 bytes a value."""

    def __init__(self, program):
        self.metrics = program.metrics
        self.names = [m.info.name for m in self.metrics]
        self.count = 0                          # samples taken (kept or flushed)
        self.last_tick: int | None = None
        self._ticks: list[int] = []             # samples not yet gathered into a chunk
        self._rows: list[np.ndarray] = []
        self._chunks: list[tuple[np.ndarray, np.ndarray]] = []   # (ticks, values (n, k))
        self.parts: PartFolder | None = None
        self.pending_bytes = 0                  # what the pending samples take as rows
        self._row_bytes = sum(8 + 8 + 4 + len(n.encode()) for n in self.names)

    def __bool__(self) -> bool:
        return bool(self.metrics)

    def attach(self, out: Path) -> None:
        """Write the samples to OUT/metrics.parquet (part files) instead of keeping them."""
        if self.metrics:
            self.parts = PartFolder(Path(out) / FILE)

    def sample(self, sim) -> None:
        """Evaluate every metric on the simulation's current tick (once per tick)."""
        if not self.metrics or self.last_tick == sim.tick:
            return
        self.add_row(sim.tick, evaluate(self.metrics, sim))

    def add_row(self, tick: int, row: np.ndarray) -> None:
        """Take one tick's values computed elsewhere (a batch computes every replica's
        metrics at once, `BatchedSimulation.metric_rows`): the same log as `sample`'s,
        for one value per metric, once per tick."""
        if not self.metrics or self.last_tick == tick:
            return
        row = np.array(row, dtype=np.float64).reshape(len(self.metrics))
        self._ticks.append(int(tick))
        self._rows.append(row)
        self.count += 1
        self.last_tick = int(tick)
        self.pending_bytes += self._row_bytes
        if len(self._rows) >= _CHUNK:
            self._gather()

    @staticmethod
    def add_rows(logs: list[MetricLog], tick: int, rows: np.ndarray) -> None:
        """`logs[r].add_row(tick, rows[r])` for every replica of a batch at one tick,
        without a call and a copy per replica (a tenth of a 100-replica batch's time
        went to them): `rows` (R, k) float64 is the batch's fresh array, which the logs
        keep views of until they gather them."""
        tick = int(tick)
        for log, row in zip(logs, rows, strict=True):
            if not log.metrics or log.last_tick == tick:
                continue
            log._ticks.append(tick)
            log._rows.append(row)
            log.count += 1
            log.last_tick = tick
            log.pending_bytes += log._row_bytes
            if len(log._rows) >= _CHUNK:
                log._gather()

    @staticmethod
    def add_block(logs: list[MetricLog], ticks: np.ndarray, values: np.ndarray) -> None:
        """`add_rows(logs, ticks[t], values[t])` for every t, at once: `ticks` (T,)
        increasing, `values` (T, R, k) float64. A batch whose samples no recorder
        reads until it ends hands them over so (a call a tick cost ~1 us a replica)."""
        ticks = np.asarray(ticks, dtype=np.int64)
        for r, log in enumerate(logs):
            if not log.metrics:
                continue
            first = int(log.last_tick == ticks[0]) if ticks.size else 0   # as add_row
            if ticks.size <= first:
                continue
            log._gather()
            log._chunks.append((ticks[first:].copy(),
                                np.ascontiguousarray(values[first:, r, :])))
            kept = ticks.size - first
            log.count += kept
            log.last_tick = int(ticks[-1])
            log.pending_bytes += kept * log._row_bytes

    def _gather(self) -> None:
        if self._rows:
            self._chunks.append((np.asarray(self._ticks, dtype=np.int64),
                                 np.stack(self._rows)))
            self._ticks, self._rows = [], []

    def pending(self) -> tuple[np.ndarray, np.ndarray]:
        """(ticks, values (n, k)) of the samples held in memory, in order."""
        self._gather()
        if not self._chunks:
            return np.zeros(0, dtype=np.int64), np.zeros((0, len(self.names)))
        if len(self._chunks) > 1:
            self._chunks = [(np.concatenate([t for t, _ in self._chunks]),
                             np.concatenate([v for _, v in self._chunks]))]
        return self._chunks[0]

    def schema(self):
        """The columns, and in the schema's metadata (`BOUNDS_KEY`) the least and most
        each metric can be (`compiler/metric_ranges.py`), for plots' axes."""
        import pyarrow as pa

        return pa.schema([("tick", pa.int64()), ("name", pa.string()),
                          ("value", pa.float64())],
                         metadata={BOUNDS_KEY: json.dumps(bounds_of(self.metrics))})

    def _table(self, ticks: np.ndarray, values: np.ndarray):
        """One row per (tick, metric), long format."""
        import pyarrow as pa

        n, k = values.shape
        return pa.table({
            "tick": arrow.numbers(np.repeat(ticks, k), "int64"),
            "name": arrow.labels(self.names, np.tile(np.arange(k), n)),
            "value": arrow.numbers(values, "float64"),
        }, schema=self.schema())

    def flush(self) -> None:
        """Write the samples held in memory as the next part (when attached)."""
        if self.parts is None:
            return
        ticks, values = self.pending()
        if len(ticks):
            self.parts.write(self._table(ticks, values))
        self._chunks, self.pending_bytes = [], 0

    def finish(self) -> None:
        """Flush; a run that sampled nothing still gets a table with the columns."""
        if self.parts is None:
            return
        self.flush()
        if not self.parts.parts:
            self.parts.write(self.schema().empty_table())

    def _all_chunks(self):
        """(ticks, values (n, k)) chunks of every sample, in order: the flushed parts
        read back one at a time, then those in memory."""
        if self.parts is not None:
            import pyarrow.parquet as pq

            for path in self.parts.files():
                t = pq.ParquetFile(path).read()     # not read_table: no dataset module
                ticks = arrow.values(t["tick"], "int64")
                values = arrow.values(t["value"], "float64")
                k = len(self.names)
                # compared as Arrow columns: a string column to numpy imports pandas
                if len(ticks) % k or not t["name"].combine_chunks().equals(
                        arrow.labels(self.names, np.tile(np.arange(k), len(ticks) // k))):
                    raise SwarmRuntimeError(f"{path} holds other metrics than the program")
                yield ticks[::k], values.reshape(-1, k)
        self._gather()
        yield from self._chunks

    def summary(self) -> dict[str, dict[str, float | None]]:
        """{metric: {last, mean, min, max}}; None where nothing was sampled or all NaN."""
        k = len(self.names)
        if self.last_tick is None:
            return {name: dict.fromkeys(SUMMARIES) for name in self.names}
        half = self.last_tick / 2
        lo, hi = np.full(k, np.inf), np.full(k, -np.inf)
        seen = np.zeros(k, dtype=bool)
        last = np.full(k, np.nan)
        means = [_Mean() for _ in range(k)]
        for ticks, values in self._all_chunks():
            finite = np.isfinite(values)
            seen |= finite.any(axis=0)
            lo = np.minimum(lo, np.where(finite, values, np.inf).min(axis=0, initial=np.inf))
            hi = np.maximum(hi, np.where(finite, values, -np.inf).max(axis=0,
                                                                      initial=-np.inf))
            at_end = ticks == self.last_tick
            if at_end.any():
                last = values[np.flatnonzero(at_end)[-1]]
            second = values[ticks >= half]
            for j in range(k):
                means[j].add(second[:, j])
        return {name: {"last": _num(last[j]), "mean": means[j].value(),
                       "min": float(lo[j]) if seen[j] else None,
                       "max": float(hi[j]) if seen[j] else None}
                for j, name in enumerate(self.names)}

    def restore(self, ticks, names, values) -> None:
        """Continue a log read back from a checkpoint that kept the samples itself
        (checkpoints written before the samples were flushed to part files)."""
        if list(names) != self.names:
            raise SwarmRuntimeError("the checkpoint's metrics differ from the program's")
        ticks = np.asarray(ticks, dtype=np.int64)
        values = np.asarray(values, dtype=float).reshape(len(ticks), len(self.names))
        self._ticks, self._rows = [], []
        self._chunks = [(ticks, values)] if len(ticks) else []
        self.count = len(ticks)
        self.last_tick = int(ticks[-1]) if len(ticks) else None
        self.pending_bytes = self.count * self._row_bytes

    def resume(self, tick: int) -> None:
        """Continue the flushed parts of a run from its checkpoint at `tick`."""
        if self.parts is None:
            return
        kept = sorted(self.parts.keep_upto(tick, self.schema()))
        self._ticks, self._rows, self._chunks = [], [], []
        self.count = len(kept)
        self.last_tick = kept[-1] if kept else None
        self.pending_bytes = 0


# ---- swarm-level measures that need neighbours ----

# the metric functions below, by name (the batch runs them per replica: runtime/batch.py)
SWARM_MEASURES = ("clusters", "largest_cluster", "mean_nearest_distance")


def cluster_sizes(pos: np.ndarray, radius: float,
                  box: tuple[float, float] | None) -> np.ndarray:
    """(C,) int64: the number of agents in each cluster of the points `pos` (N, 2), two
    agents linked when at most `radius` apart (the pairs `neighbors(radius)` sees, the
    short way round when `box` makes the world wrap); a cluster is a connected
    component of those links, a lone agent a cluster of 1. Sizes in the order of each
    cluster's first row; no points, no clusters."""
    n = pos.shape[0]
    if n < 2:
        return np.ones(n, np.int64)
    from scipy.sparse import csr_matrix  # here: a run without these metrics never
    from scipy.sparse.csgraph import connected_components  # imports scipy.sparse

    table = build_pairs(pos, float(radius), box)
    links = csr_matrix((np.ones(table.j.size, np.int8), table.j, table.offsets),
                       shape=(n, n))
    _count, labels = connected_components(links, directed=False)
    return np.bincount(labels).astype(np.int64)


def cluster_count(pos: np.ndarray, radius: float, box) -> float:
    """How many clusters (`cluster_sizes`) the points form; 0 for none."""
    return float(cluster_sizes(pos, radius, box).size)


def largest_cluster(pos: np.ndarray, radius: float, box) -> float:
    """The number of agents in the largest cluster (`cluster_sizes`); 0 for none."""
    return float(cluster_sizes(pos, radius, box).max(initial=0))


def mean_nearest_distance(pos: np.ndarray, box: tuple[float, float] | None) -> float:
    """The mean over the points `pos` (N, 2) of the distance to the nearest other one
    (the short way round when `box` makes the world wrap); NaN for fewer than two
    points, where no agent has a neighbour to measure."""
    n = pos.shape[0]
    if n < 2:
        return math.nan
    from scipy.spatial import cKDTree

    # the quicker build (as `spatial`'s search): the distances do not depend on it
    fast = {"balanced_tree": False, "compact_nodes": False}
    if box is None:
        pts = pos
        tree = cKDTree(pts, **fast)
    else:
        pts = np.mod(pos, box)
        pts = np.where(pts >= box, 0.0, pts)    # mod can give `box` itself for -tiny
        tree = cKDTree(pts, boxsize=box, **fast)
    # the two nearest points of each: itself at 0 and its nearest neighbour (two
    # agents at one place: both at 0, which is then the right answer)
    dist, _ = tree.query(pts, k=2)
    return float(np.mean(dist[:, 1]))


class _Mean:
    """The mean of a stream of floats, the same however the stream is cut into
    chunks (parts on disk, or memory): sums of fixed blocks of values, each correctly
    rounded (`math.fsum`), so memory is one block whatever the length. NaN, or
    infinities of both signs, give None; one sign of infinity gives it."""

    _BLOCK = 4096

    def __init__(self):
        self.blocks: list[float] = []
        self.rest = np.zeros(0)
        self.n = 0
        self.nan = self.pos = self.neg = False

    def add(self, values: np.ndarray) -> None:
        if not values.size:
            return
        self.n += values.size
        finite = np.isfinite(values)
        if not finite.all():
            bad = values[~finite]
            self.nan |= bool(np.isnan(bad).any())
            self.pos |= bool((bad == np.inf).any())
            self.neg |= bool((bad == -np.inf).any())
            values = np.where(finite, values, 0.0)
        values = np.concatenate([self.rest, values])
        whole = len(values) - len(values) % self._BLOCK
        for start in range(0, whole, self._BLOCK):
            self.blocks.append(math.fsum(values[start:start + self._BLOCK].tolist()))
        self.rest = values[whole:].copy()

    def value(self) -> float | None:
        if not self.n or self.nan or (self.pos and self.neg):
            return None
        if self.pos or self.neg:
            return math.inf if self.pos else -math.inf
        return _num(math.fsum([*self.blocks, math.fsum(self.rest.tolist())]) / self.n)


def _num(x) -> float | None:
    x = float(x)
    return None if math.isnan(x) else x
