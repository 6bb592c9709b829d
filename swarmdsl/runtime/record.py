"""Run outputs: agents.parquet, fields.npz and run.json, as DESIGN.md fixes them.

Rows reach the Parquet file in row groups while the run goes on, so a run stopped by
Ctrl-C or a fault still leaves a valid file holding every tick recorded so far.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from swarmdsl import __version__
from swarmdsl.runtime.jsonsafe import standard_json
from swarmdsl.runtime.randomness import RNG_NAME

_FLUSH_ROWS = 1_000_000


class Recorder:
    def __init__(self, out_dir: Path, sim, every: int = 1):
        import pyarrow as pa

        self.pa = pa
        self.out = Path(out_dir)
        self.out.mkdir(parents=True, exist_ok=True)
        self.sim = sim
        self.every = max(int(every), 1)
        self.program = sim.program
        self.kind_names = np.array([k.name for k in self.program.kinds], dtype=object)
        self.status_names = np.array(self.program.status_display, dtype=object)
        self.var_names = list(self.program.var_specs)
        self.schema = self._schema()
        self.writer = None
        self.pending: list = []
        self.pending_rows = 0
        self.ticks: list[int] = []
        self.field_frames: dict[str, list[np.ndarray]] = {}
        self.last_recorded = -1
        self.wall_seconds = 0.0
        self.closed = False
        self.extra_json: dict = {}      # more run.json keys from the run (metric summaries)

    def _schema(self):
        pa = self.pa
        cols = [("tick", pa.int64()), ("id", pa.int64()), ("kind", pa.string()),
                ("status", pa.string()), ("x", pa.float64()), ("y", pa.float64()),
                ("heading", pa.float64()), ("vx", pa.float64()), ("vy", pa.float64())]
        for name in self.var_names:
            t = self.program.var_types[name]
            if t == "vec":
                cols += [(f"{name}_x", pa.float64()), (f"{name}_y", pa.float64())]
            elif t == "bool":
                cols.append((name, pa.bool_()))
            else:
                cols.append((name, pa.float64()))
        return pa.schema(cols)

    def wants(self, tick: int) -> bool:
        return tick % self.every == 0

    def record(self) -> None:
        """Record the simulation's current tick (once per tick)."""
        sim = self.sim
        if sim.tick == self.last_recorded:
            return
        self.last_recorded = sim.tick
        pa = self.pa
        # Copies: pyarrow wraps contiguous arrays without copying, and a column the
        # program later changes in place (`msg_tick`) would rewrite rows already recorded.
        cols = {k: np.array(sim.agents.cols[k]) for k in (
            "id", "kind", "status", "pos", "heading", "vel", *self.var_names)}
        n = sim.agents.n
        data = {
            "tick": pa.array(np.full(n, sim.tick, dtype=np.int64)),
            "id": pa.array(cols["id"]),
            "kind": pa.array(self.kind_names[cols["kind"]], type=pa.string()),
            "status": pa.array(self.status_names[cols["status"]], type=pa.string()),
            "x": pa.array(cols["pos"][:, 0]), "y": pa.array(cols["pos"][:, 1]),
            "heading": pa.array(cols["heading"]),
            "vx": pa.array(cols["vel"][:, 0]), "vy": pa.array(cols["vel"][:, 1]),
        }
        for name in self.var_names:
            values = cols[name]
            mask = ~sim.agents.declared[name]
            if values.ndim == 2:
                data[f"{name}_x"] = pa.array(values[:, 0], mask=mask)
                data[f"{name}_y"] = pa.array(values[:, 1], mask=mask)
            else:
                data[name] = pa.array(values, mask=mask)
        self.pending.append(pa.table(data, schema=self.schema))
        self.pending_rows += n
        self.ticks.append(sim.tick)
        for name, values in _field_values(sim).items():
            self.field_frames.setdefault(name, []).append(values.copy())
        if self.pending_rows >= _FLUSH_ROWS:
            self._flush()

    def _flush(self) -> None:
        import pyarrow.parquet as pq

        if not self.pending:
            return
        if self.writer is None:
            self.writer = pq.ParquetWriter(self.out / "agents.parquet", self.schema,
                                           compression="zstd")
        self.writer.write_table(self.pa.concat_tables(self.pending))
        self.pending, self.pending_rows = [], 0

    def close(self, steps: int, status: str = "completed") -> None:
        """Write everything recorded so far; safe to call after an interruption."""
        if self.closed:
            return
        self.closed = True
        self._flush()
        if self.writer is None:
            import pyarrow.parquet as pq

            pq.write_table(self.schema.empty_table(), self.out / "agents.parquet")
        else:
            self.writer.close()
        self._write_fields()
        self._write_json(steps, status)

    def _write_fields(self) -> None:
        arrays = {"ticks": np.asarray(self.ticks, dtype=np.int64)}
        grid = _grid_nodes(self.sim)
        arrays["grid_x"], arrays["grid_y"] = grid
        for name, frames in self.field_frames.items():
            arrays[name] = np.stack(frames) if frames else np.zeros((0, 0, 0))
        np.savez_compressed(self.out / "fields.npz", **arrays)

    def _write_json(self, steps: int, status: str) -> None:
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
            "steps_per_second": round(steps / self.wall_seconds, 3)
            if self.wall_seconds > 0 else None,
            "status_counts": sim.status_counts(),
            "version": __version__,
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
        text = json.dumps(standard_json(data), indent=2, allow_nan=False)
        (self.out / "run.json").write_text(text + "\n")


def _field_values(sim) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for ext in sim.extensions:
        fields = getattr(ext, "field_values", None)
        if fields is not None:
            out.update(fields(sim))
    return out


def _grid_nodes(sim):
    for ext in sim.extensions:
        nodes = getattr(ext, "grid_nodes", None)
        if nodes is not None:
            return nodes(sim)
    w = sim.world
    nx = int(np.floor(w.width / w.grid + 1e-9)) + 1
    ny = int(np.floor(w.height / w.grid + 1e-9)) + 1
    return np.arange(nx) * w.grid, np.arange(ny) * w.grid


def _regions(sim) -> list[dict]:
    out: list[dict] = []
    for ext in sim.extensions:
        regions = getattr(ext, "regions_json", None)
        if regions is not None:
            out.extend(regions(sim))
    return out
