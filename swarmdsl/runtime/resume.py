"""Checkpointing a `Run` and resuming one: the simulation plus the run's own outputs.

A resumed run continues the same files: rows of `agents.parquet`, frames of `fields.npz`
and metric samples up to the checkpoint's tick are kept, later ones (written by the run
after its last checkpoint) are dropped, because the resumed run writes them again, bit
for bit the same.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from swarmdsl.compiler.errors import SwarmOptionError
from swarmdsl.runtime import checkpoint


def save_run(run) -> None:
    """Checkpoint `run` after its current tick into OUT/checkpoint."""
    log = run.metrics
    arrays = {"metric_ticks": np.asarray(log.ticks, dtype=np.int64),
              "metric_values": np.asarray(log.values, dtype=float).reshape(
                  len(log.ticks), len(log.names))}
    checkpoint.save(run.sim, Path(run.recorder.out) / checkpoint.FOLDER,
                    extra={"steps": run.steps, "every": run.every,
                           "metric_names": log.names}, arrays_extra=arrays)


def read(folder: Path) -> dict:
    """The checkpoint's meta (seed, steps, every, ...) before a Run is built."""
    return checkpoint.read_meta(Path(folder) / checkpoint.FOLDER)


def resume_run(run, folder: Path) -> int:
    """Load OUT/checkpoint into a freshly built `run`; returns the tick it resumes at."""
    meta, extra = checkpoint.load(run.sim, Path(folder) / checkpoint.FOLDER)
    tick = int(meta["tick"])
    run.metrics.restore(extra["metric_ticks"], meta.get("metric_names", []),
                        extra["metric_values"])
    if run.recorder is not None:
        _continue_outputs(run.recorder, Path(folder), tick)
    return tick


def _continue_outputs(rec, folder: Path, tick: int) -> None:
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    path = folder / "agents.parquet"
    if path.exists():
        try:
            table = pq.read_table(path)
        except (OSError, ValueError) as exc:
            raise SwarmOptionError(f"--resume {folder}: agents.parquet is unreadable ({exc})"
                                   ) from None
        if table.schema != rec.schema:
            raise SwarmOptionError(f"--resume {folder}: agents.parquet has other columns")
        table = table.filter(pc.less_equal(table["tick"], tick))
        if table.num_rows:
            rec.pending.append(table)
            rec.pending_rows += table.num_rows
        rec.ticks = sorted(set(table["tick"].to_pylist()))
    fields = folder / "fields.npz"
    if fields.exists() and rec.ticks:
        with np.load(fields, allow_pickle=False) as data:
            ticks = data["ticks"]
            keep = ticks <= tick
            for name in data.files:
                if name not in ("ticks", "grid_x", "grid_y"):
                    rec.field_frames[name] = [f for f in data[name][keep]]
    rec.last_recorded = rec.ticks[-1] if rec.ticks else -1
