"""Checkpointing a `Run` and resuming one: the simulation plus the run's own outputs.

A resumed run continues the same files: rows of `agents.parquet` and `metrics.parquet`,
frames of `fields.npz` (or of `fields.npy/`, when the run was killed before closing) up
to the checkpoint's tick are kept, later ones (written by the run after its last
checkpoint) are dropped, because the resumed run writes them again, bit for bit the
same. The recorder flushes before each checkpoint, so every row, sample and frame up
to a checkpoint is on disk whenever the checkpoint is.
"""

from __future__ import annotations

import shutil
import zipfile
from pathlib import Path

from swarmdsl.errors import SwarmOptionError
from swarmdsl.runtime import checkpoint


def save_run(run, outputs_upto: int | None = None) -> None:
    """Checkpoint `run` after its current tick into OUT/checkpoint.

    `outputs_upto`: the last tick of the outputs a resume keeps, when it is not the
    checkpoint's own (a run stopped off the `--every` grid records its stop tick, which
    the uninterrupted run does not; the resumed run must not keep it)."""
    run.recorder.flush()        # rows, samples and frames up to a checkpoint are on disk
    log = run.metrics           # before it exists, so it holds no metric samples itself
    ticks, values = log.pending()
    arrays = {"metric_ticks": ticks, "metric_values": values}
    extra = {"steps": run.steps, "every": run.every, "metric_names": log.names,
             **run_options(run),
             # ticking time up to here: a resumed run's run.json adds its own, so its
             # wall_seconds and rate cover the whole run
             "tick_seconds": run.tick_seconds_before + run.tick_seconds}
    history = run.recorder.extra_json.get(EVERY_HISTORY)
    if history:
        extra[EVERY_HISTORY] = history
    if outputs_upto is not None:
        extra["outputs_upto"] = int(outputs_upto)
    checkpoint.save(run.sim, Path(run.recorder.out) / checkpoint.FOLDER, extra=extra,
                    arrays_extra=arrays)


def save_at_stop(run) -> None:
    """A run with `checkpoint_every` stopped by a signal (a cluster preempting its job):
    a checkpoint at the stop tick, so resuming loses no tick (it lost up to K of them).
    The stop tick's row, recorded whatever `--every` says, is not kept by the resume
    unless the uninterrupted run records it too."""
    tick = run.sim.tick
    recorded = run.recorder.ticks
    upto = tick
    if tick % run.every != 0 and recorded and recorded[-1] == tick:
        upto = recorded[-2] if len(recorded) > 1 else -1
    if tick == run.steps or (tick % run.checkpoint_every == 0 and upto == tick):
        return   # the tick's own checkpoint is written already, keeping what it should
    # (a stop on a checkpoint's tick off the --every grid: that checkpoint kept the stop
    # tick's row, which the uninterrupted run does not record; written again without it)
    save_run(run, outputs_upto=upto)


# run.json's and the checkpoint's record of a resume with another `--every`: the
# segments of the run, `[[from_tick, every], ...]`, the first from tick 0.
EVERY_HISTORY = "every_history"


def run_options(run) -> dict:
    """What a resumed run must repeat, or take over, to continue the same files and
    checks: `swarmdsl run` compares these with the options given to `--resume`."""
    checked = [ext.checked() for ext in run.sim.extensions if hasattr(ext, "checked")]
    return {"backend": run.sim.backend.name,
            "checkpoint_every": run.checkpoint_every, "tree_leaf": run.tree_leaf,
            "tree_memory": run.tree_memory, "check": checked[0] if checked else None,
            "params": {k: _plain(v) for k, v in run.program.params.items()}}


def _plain(value):
    """A param value as JSON keeps it (params are booleans and numbers)."""
    return value if isinstance(value, bool | int | float) else repr(value)


def read(folder: Path) -> dict:
    """The checkpoint's meta (seed, steps, every, ...) before a Run is built."""
    return checkpoint.read_meta(Path(folder) / checkpoint.FOLDER)


def check_resume(run, folder: Path) -> None:
    """Refuse a resume that could not continue the checkpointed run, before `resume_run`
    cuts the folder's files back to the checkpoint: the checkpoint's random state would
    replace another `seed` (drawing seed S's numbers under another seed's name), a run
    shorter than the checkpoint's tick has nothing to run, and another `out` folder
    holds none of the record up to the checkpoint."""
    if run.executed is not None:
        raise SwarmOptionError(f"resume {folder}: this Run has already run; build a new "
                               "Run(program, ...) and resume that")
    if run.recorder is not None and run.recorder.out.resolve() != folder.resolve():
        raise SwarmOptionError(f"resume {folder}: the Run writes to {run.recorder.out}; "
                               f"resuming continues {folder}'s outputs, so build the Run "
                               f"with out={str(folder)!r}")
    meta = read(folder)
    try:
        seed, tick = int(meta["seed"]), int(meta["tick"])
    except (KeyError, TypeError, ValueError) as exc:
        raise SwarmOptionError(f"resume {folder}: the checkpoint is incomplete "
                               f"({exc!r})") from None
    if run.sim.seed != seed:
        raise SwarmOptionError(f"seed {run.sim.seed}: the checkpoint in {folder} is of a "
                               f"run with seed {seed}; build the Run with seed={seed}")
    if run.steps < tick:
        raise SwarmOptionError(f"steps {run.steps}: the checkpoint in {folder} is at tick "
                               f"{tick} already")
    for option in ("tree_leaf", "tree_memory"):     # the columns agents.parquet has
        saved = meta.get(option, getattr(run, option))  # older checkpoints: as given
        if bool(saved) != getattr(run, option):
            raise SwarmOptionError(f"{option}={getattr(run, option)}: the checkpoint in "
                                   f"{folder} is of a run with {option}={bool(saved)}; "
                                   f"build the Run with {option}={bool(saved)}")


def resume_run(run, folder: Path) -> int:
    """Load OUT/checkpoint into a freshly built `run`; returns the tick it resumes at."""
    meta, extra = checkpoint.load(run.sim, Path(folder) / checkpoint.FOLDER)
    tick = int(meta["tick"])
    upto = meta.get("outputs_upto", tick)     # the outputs it keeps: up to this tick
    upto = upto if isinstance(upto, int) and upto <= tick else tick
    seconds = meta.get("tick_seconds")
    if isinstance(seconds, int | float) and seconds >= 0:
        run.tick_seconds_before, run.timed_before = float(seconds), True
    if run.recorder is not None:
        _continue_outputs(run.recorder, Path(folder), upto)
        _note_every(run, meta, tick)
    if len(extra.get("metric_ticks", ())):
        # a checkpoint that kept the samples itself (before they went to part files):
        # they are the whole log up to its tick, whatever metrics.parquet holds
        if run.metrics.parts is not None:
            _remove(run.metrics.parts.folder)
            run.metrics.parts.parts = 0
        run.metrics.restore(extra["metric_ticks"], meta.get("metric_names", []),
                            extra["metric_values"])
    elif meta.get("metric_names", []) != run.metrics.names:
        raise SwarmOptionError(f"--resume {folder}: the checkpoint's metrics differ from "
                               "the program's")
    elif run.metrics.parts is not None:
        _require(run.metrics.parts.folder, folder, tick)
        _keep(run.metrics.parts, upto, run.metrics.schema(), folder)
        run.metrics.resume(upto)
    return tick


def _note_every(run, meta: dict, tick: int) -> None:
    """A resume with another `--every` records the ticks after the checkpoint on
    another grid: run.json keeps both (`every_history`), else it said only the new K
    of a table whose earlier ticks follow the old one."""
    history = meta.get(EVERY_HISTORY)
    if not (isinstance(history, list) and history):
        every = meta.get("every", run.every)
        history = [[0, every if isinstance(every, int) else run.every]]
    if history[-1][1] != run.every:
        history = [*history, [tick, run.every]]
    if len(history) > 1:
        run.recorder.extra_json[EVERY_HISTORY] = history


def _continue_outputs(rec, folder: Path, tick: int) -> None:
    """Keep the outputs of ticks <= `tick`: whole part files stay, a part that runs past
    the checkpoint is cut at it, later parts are removed; field frames likewise."""
    from swarmdsl.runtime.record import _field_values, _grid_nodes
    from swarmdsl.runtime.spool import NPZ

    _require(rec.agents.folder, folder, tick)
    rec.ticks = sorted(_keep(rec.agents, tick, rec.schema, folder))
    rec.last_recorded = rec.ticks[-1] if rec.ticks else -1
    frames_now = _field_values(rec.sim)
    fields = folder / NPZ
    if rec.fields.has_frames():         # the last run was killed before closing
        rec.fields.keep_upto(tick, frames_now)
    elif fields.exists():
        try:
            rec.fields.load_npz(fields, tick, _grid_nodes(rec.sim))
        except (OSError, ValueError, KeyError, zipfile.BadZipFile) as exc:
            raise SwarmOptionError(f"--resume {folder}: {NPZ} is unreadable ({exc})"
                                   ) from None
    else:
        _require(fields, folder, tick)


def _require(path: Path, folder: Path, tick: int) -> None:
    """Refuse to continue an output that is gone: the resumed run would write only the
    ticks after the checkpoint into it, a file that looks whole but starts mid-run (and
    metric summaries over those ticks alone), beside files that hold the whole run."""
    if not (path.exists() or path.is_symlink()):
        raise SwarmOptionError(f"--resume {folder}: {path.name} is missing, so the run's "
                               f"record up to the checkpoint (tick {tick}) is lost; run "
                               "the program again without --resume")


def _keep(parts, tick: int, schema, folder: Path) -> set[int]:
    """`parts.keep_upto`, its failures as option errors naming the run's folder."""
    try:
        return parts.keep_upto(tick, schema)
    except ValueError as exc:
        raise SwarmOptionError(f"--resume {folder}: {exc}") from None
    except OSError as exc:
        raise SwarmOptionError(f"--resume {folder}: {parts.folder.name} is unreadable "
                               f"({exc})") from None


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()
