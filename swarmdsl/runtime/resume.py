"""Checkpointing a `Run` and resuming one: the simulation plus the run's own outputs.

A resumed run continues the same files: rows of `agents.parquet`, frames of `fields.npz`
(or of the field spool, when the run was killed before closing) and metric samples up to
the checkpoint's tick are kept, later ones (written by the run after its last
checkpoint) are dropped, because the resumed run writes them again, bit for bit the
same. The recorder writes its rows out before each checkpoint, so every row up to a
checkpoint is on disk whenever the checkpoint is.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from swarmdsl.compiler.errors import SwarmOptionError
from swarmdsl.runtime import checkpoint
from swarmdsl.runtime.outputs import replace_with


def save_run(run) -> None:
    """Checkpoint `run` after its current tick into OUT/checkpoint."""
    run.recorder.flush()        # rows up to a checkpoint are on disk before it exists
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
    """Keep the outputs of ticks <= `tick`: whole part files stay, a part that runs past
    the checkpoint is cut at it, later parts are removed; field frames likewise."""
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    from swarmdsl.runtime.record import AGENTS, PART, part_files

    agents = folder / AGENTS
    if agents.is_file():                # one file, as runs before part files wrote it
        table = _read(pq, agents, folder)
        agents.unlink()
        agents.mkdir()
        pq.write_table(table, agents / PART.format(0), compression="zstd")
    ticks: set[int] = set()
    parts = 0
    for path in part_files(folder):
        table = _read(pq, path, folder)
        if table.schema != rec.schema:
            raise SwarmOptionError(f"--resume {folder}: agents.parquet has other columns")
        kept = table.filter(pc.less_equal(table["tick"], tick))
        if kept.num_rows == 0:
            path.unlink()
            continue
        if kept.num_rows < table.num_rows:
            replace_with(path, lambda tmp, t=kept: pq.write_table(t, tmp, compression="zstd"))
        ticks.update(pc.unique(kept["tick"]).to_pylist())
        target = agents / PART.format(parts)      # renumber: parts stay consecutive
        if path != target:
            path.rename(target)
        parts += 1
    rec.parts = parts
    rec.ticks = sorted(ticks)
    rec.last_recorded = rec.ticks[-1] if rec.ticks else -1
    from swarmdsl.runtime.record import _field_values

    frames_now = _field_values(rec.sim)
    fields = folder / "fields.npz"
    if rec.fields.has_frames():         # the last run was killed before closing
        rec.fields.keep_upto(tick, frames_now)
    elif fields.exists():
        try:
            rec.fields.load_npz(fields, tick)
        except (OSError, ValueError, KeyError) as exc:
            raise SwarmOptionError(f"--resume {folder}: fields.npz is unreadable ({exc})"
                                   ) from None
    else:
        rec.fields.reset()


def _read(pq, path: Path, folder: Path):
    try:
        return pq.read_table(path)
    except (OSError, ValueError) as exc:
        raise SwarmOptionError(f"--resume {folder}: {path.name} is unreadable ({exc})"
                               ) from None
