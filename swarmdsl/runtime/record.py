"""Run outputs: agents.parquet, metrics.parquet, fields.npz and run.json.

`agents.parquet` and `metrics.parquet` are Parquet datasets: folders of finished part
files (`part-000000.parquet`, ...), read as one table by `pyarrow.parquet.read_table`
and `pandas.read_parquet`. Rows are kept in memory only until 32 MiB of them or 10
seconds have gathered, then written as the next part of each (`spool.PartFolder`), and
the field frames appended since are counted in `fields.npy/` (`spool.FieldSpool`). A
Parquet file is readable only once its footer is written, so one growing file would
lose everything to a kill; finished parts lose at most what was recorded since the last
flush, even to SIGKILL, and memory stays bounded however long the run. `fields.npz` is
streamed from `fields.npy/` when the run closes.

`run.json` is written first, saying `"finished": "running"`, again after each flush
(still `running`, counting the ticks flushed), and last, saying how the run ended;
every file is put in place whole (`outputs.replace_with`). A new run into a folder
first removes the outputs of the run before it, `run.json` first, so nothing stale
ever claims to describe it.
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import numpy as np

from swarmdsl.runtime import arrow
from swarmdsl.runtime.columns import FIXED_COLUMNS, vector_columns
from swarmdsl.runtime.metrics import FILE as METRICS
from swarmdsl.runtime.outputs import check_folder, make_folder, replace_with
from swarmdsl.runtime.spool import FOLDER as FIELD_FOLDER
from swarmdsl.runtime.spool import NPZ as FIELDS
from swarmdsl.runtime.spool import FieldSpool, PartFolder
from swarmdsl.version import __version__, libraries

AGENTS = "agents.parquet"
# Files of a run's folder that a new run replaces (the checkpoint belongs to the old
# run; `.fields.spool` is where runs before `fields.npy/` kept their frames).
OUTPUTS = ("run.json", AGENTS, FIELDS, FIELD_FOLDER, METRICS, "checkpoint", ".fields.spool")
class Recorder:
    flush_bytes = 32 * 2**20    # rows gathered before they are written as a part
    flush_seconds = 10.0        # ... or after this long, whichever comes first

    def __init__(self, out_dir: Path, sim, every: int = 1, metrics=None):
        import pyarrow as pa

        self.pa = pa
        self.out = check_folder(out_dir, "--out")    # made when the run begins
        self.sim = sim
        self.every = max(int(every), 1)
        self.program = sim.program
        self.kind_names = [k.name for k in self.program.kinds]
        self.status_names = list(self.program.status_display)
        self.var_names = list(self.program.var_specs)
        # columns asked for by the run (`--tree-leaf`, `--tree-memory`): name ->
        # (arrow type name, fn(sim) -> one value per agent; for "string" columns
        # (names, one code into names per agent), a None name recorded as null)
        self.extra_columns = dict(sim.record_columns)
        self.extra_names: dict[str, list] = {}
        self.schema = self._schema()
        self.pending: list = []
        self.pending_rows = 0
        self.pending_bytes = 0
        self.last_flush = time.monotonic()
        self.agents = PartFolder(self.out / AGENTS)
        self.metrics = None             # the run's MetricLog, flushed with the rows
        if metrics:
            metrics.attach(self.out)
            self.metrics = metrics
        self.ticks: list[int] = []
        self.fields = FieldSpool(self.out)
        self.last_recorded = -1
        self.wall_seconds = 0.0
        self.ticks_timed: int | None = None     # the ticks wall_seconds covers (resumed)
        self.closed = False
        self.extra_json: dict = {}      # more run.json keys from the run (metric summaries)

    def begin(self, resumed: bool = False) -> None:
        """Before the first tick: clear the previous run's outputs (unless resuming)
        and write a `run.json` that says the run is under way."""
        make_folder(self.out, "--out")
        if not resumed:
            for name in OUTPUTS:
                path = self.out / name
                if path.is_dir() and not path.is_symlink():
                    shutil.rmtree(path)
                elif path.exists() or path.is_symlink():
                    path.unlink()
            self.fields.reset(_grid_nodes(self.sim))
        (self.out / AGENTS).mkdir(exist_ok=True)
        if self.metrics is not None and self.metrics.parts is not None:
            self.metrics.parts.folder.mkdir(exist_ok=True)
        self._write_json(self.sim.tick, "running")

    def _schema(self):
        pa = self.pa
        cols = [(name, getattr(pa, t)()) for name, (t, _what) in FIXED_COLUMNS.items()]
        for name in self.var_names:
            t = self.program.var_types[name]
            if t == "vec":
                cols += [(column, pa.float64()) for column in vector_columns(name)]
            elif t == "bool":
                cols.append((name, pa.bool_()))
            else:
                cols.append((name, pa.float64()))
        cols += [(name, getattr(pa, kind)()) for name, (kind, _fn) in self.extra_columns.items()]
        return pa.schema(cols)

    def wants(self, tick: int) -> bool:
        return tick % self.every == 0

    def record(self) -> None:
        """Record the simulation's current tick (once per tick)."""
        sim = self.sim
        if sim.tick == self.last_recorded:
            return
        self.last_recorded = sim.tick
        # Copies: a column the program later changes in place (`msg_tick`) would
        # otherwise rewrite rows already recorded. Plain arrays, not one Arrow table per
        # tick: an Arrow table costs some 10 kB of bookkeeping however few its rows.
        cols = {k: np.array(sim.agents.cols[k]) for k in (
            "id", "kind", "status", "pos", "heading", "vel", *self.var_names)}
        for name, (kind, column) in self.extra_columns.items():
            values = column(sim)
            if kind == "string":
                self.extra_names[name], values = values
            cols["@" + name] = np.array(values)
        masks = {name: ~sim.agents.declared[name] for name in self.var_names}
        self.pending.append((sim.tick, cols, masks))
        self.pending_rows += sim.agents.n
        self.pending_bytes += sum(v.nbytes + 256 for v in (*cols.values(), *masks.values()))
        self.ticks.append(sim.tick)
        if not self.fields.shapes:      # recording without `begin` (tests, tools)
            self.fields.reset(_grid_nodes(sim))
        self.fields.add(sim.tick, _field_values(sim))
        metric_bytes = self.metrics.pending_bytes if self.metrics is not None else 0
        if (self.pending_bytes + metric_bytes + self.fields.pending_bytes >= self.flush_bytes
                or time.monotonic() - self.last_flush >= self.flush_seconds):
            self.flush()

    def _table(self, pending):
        """One Arrow table from the gathered ticks (columns from buffers: `arrow.py`)."""
        def cat(key, part=None):
            arrays = [c[key] if part is None else c[key][:, part] for _, c, _ in pending]
            return np.concatenate(arrays) if arrays else np.zeros(0)

        counts = [len(c["id"]) for _, c, _ in pending]
        ticks = np.repeat(np.array([t for t, _, _ in pending], dtype=np.int64), counts)
        data = {
            "tick": arrow.numbers(ticks, "int64"),
            "id": arrow.numbers(cat("id"), "int64"),
            "kind": arrow.labels(self.kind_names, cat("kind")),
            "status": arrow.labels(self.status_names, cat("status")),
            "x": arrow.numbers(cat("pos", 0), "float64"),
            "y": arrow.numbers(cat("pos", 1), "float64"),
            "heading": arrow.numbers(cat("heading"), "float64"),
            "vx": arrow.numbers(cat("vel", 0), "float64"),
            "vy": arrow.numbers(cat("vel", 1), "float64"),
        }
        for name in self.var_names:
            declared = ~np.concatenate([m[name] for _, _, m in pending])
            kind = "bool_" if self.program.var_types[name] == "bool" else "float64"
            if pending[0][1][name].ndim == 2:
                for part, column in enumerate(vector_columns(name)):
                    data[column] = arrow.numbers(cat(name, part), kind, valid=declared)
            else:
                data[name] = arrow.numbers(cat(name), kind, valid=declared)
        for name, (kind, _fn) in self.extra_columns.items():
            data[name] = (arrow.labels(self.extra_names[name], cat("@" + name))
                          if kind == "string" else arrow.numbers(cat("@" + name), kind))
        return self.pa.table(data, schema=self.schema)

    def flush(self) -> None:
        """Put everything recorded so far on disk: the rows as the next part of
        `agents.parquet`, the metric samples as the next part of `metrics.parquet`, the
        field frames counted in `fields.npy/`, then `run.json` (still `running`) with
        the ticks they hold, so a run killed later says what its files have."""
        from swarmdsl import stopping

        self.last_flush = time.monotonic()
        with stopping.uncut():
            if self.pending:
                self.agents.write(self._table(self.pending))
                self.pending, self.pending_rows, self.pending_bytes = [], 0, 0
            if self.metrics is not None:
                self.metrics.flush()
            self.fields.flush()
            if not self.closed:     # a killed run's run.json counts what it kept
                self._write_json(self.sim.tick, "running")

    @property
    def parts(self) -> int:
        """Part files of `agents.parquet` written."""
        return self.agents.parts

    def close(self, steps: int, status: str = "completed") -> None:
        """Write everything recorded so far; safe to call after an interruption."""
        if self.closed:
            return
        self.closed = True
        self.flush()
        if not self.agents.parts:   # no rows at all: one empty part keeps the columns
            self.agents.write(self.schema.empty_table())
        if self.metrics is not None:
            self.metrics.finish()
        replace_with(self.out / FIELDS, self.fields.write_npz)
        self.fields.remove()
        self._write_json(steps, status)

    def _write_json(self, steps: int, status: str) -> None:
        from swarmdsl.runtime.jsonsafe import standard_json
        from swarmdsl.runtime.randomness import RNG_NAME

        sim = self.sim
        w = sim.world
        data = {
            "program": str(self.program.filename),
            "sha256": self.program.sha256,
            "seed": sim.seed,
            "rng": RNG_NAME,
            "params": {k: v for k, v in self.program.params.items()},
            "steps": int(steps),
            "wall_seconds": round(self.wall_seconds, 6),
            "steps_per_second": round((steps if self.ticks_timed is None
                                       else self.ticks_timed) / self.wall_seconds, 3)
            if self.wall_seconds > 0 else None,
            "status_counts": sim.status_counts(),
            "version": __version__,
            "libraries": libraries(),
            "world": {"size": [w.width, w.height], "grid_spacing": w.grid,
                      "edges": w.edges, "regions": _regions(sim)},
            "agents": int(sim.agents.n),
            "every": self.every,
            "recorded_ticks": len(self.ticks),
            "last_tick": int(sim.tick),
            "finished": status,
            "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        }
        data.update(self.extra_json)
        text = json.dumps(standard_json(data), indent=2, allow_nan=False) + "\n"
        replace_with(self.out / "run.json", lambda tmp: tmp.write_text(text))


def _field_values(sim) -> dict[str, np.ndarray]:
    """The frames of one recorded tick: each field on the base grid, and on a refined
    grid also on every node (`NAME.nodes`)."""
    out: dict[str, np.ndarray] = {}
    for ext in sim.extensions:
        for hook in ("field_values", "field_node_values"):
            fields = getattr(ext, hook, None)
            if fields is not None:
                out.update(fields(sim))
    return out


def _grid_nodes(sim) -> dict[str, np.ndarray]:
    """The grid files of `fields.npz`: `grid_x`, `grid_y`, and a refined grid's
    `nodes_x`, `nodes_y`, `nodes_level`."""
    static: dict[str, np.ndarray] = {}
    for ext in sim.extensions:
        nodes = getattr(ext, "grid_nodes", None)
        if nodes is not None and not static:
            static["grid_x"], static["grid_y"] = nodes(sim)
        refined = getattr(ext, "refined_nodes", None)
        if refined is not None:
            static.update(refined(sim))
    if "grid_x" not in static:
        w = sim.world
        nx = int(np.floor(w.width / w.grid + 1e-9)) + 1
        ny = int(np.floor(w.height / w.grid + 1e-9)) + 1
        static["grid_x"], static["grid_y"] = np.arange(nx) * w.grid, np.arange(ny) * w.grid
    return {name: static[name] for name in ("grid_x", "grid_y", *sorted(
        set(static) - {"grid_x", "grid_y"}))}


def _regions(sim) -> list[dict]:
    out: list[dict] = []
    for ext in sim.extensions:
        regions = getattr(ext, "regions_json", None)
        if regions is not None:
            out.extend(regions(sim))
    return out
