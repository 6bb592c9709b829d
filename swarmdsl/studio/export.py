"""Export what the studio shows as `swarmdsl run --out` writes it, with a GIF or MP4.

The run on screen is replayed from tick 0 to its current tick with the same program
text, params and seed: runs are reproducible, so the replay is the run shown, written
by the same `Run` as the command (agents.parquet, metrics.parquet, fields, run.json).
A param changed mid-run is the exception: the replay uses the values shown from tick 0,
and the result says so. Every file goes into a new folder under the session's outputs
folder, named here, never by the page.
"""

from __future__ import annotations

import re
from pathlib import Path

from swarmdsl.errors import SwarmError, SwarmOptionError

VIDEOS = ("gif", "mp4")


def export(session, video: str | None) -> dict:
    """Replay the session's run into a new folder; returns what was written."""
    from swarmdsl.runtime.runner import Run

    if video is not None and video not in VIDEOS:
        raise SwarmOptionError(f"video {video!r}: choose gif or mp4")
    with session.lock:
        if session.program is None or session.sim is None:
            raise SwarmOptionError("nothing to export: the program has not run")
        text, overrides = session.text, dict(session.overrides)
        seed, tick, changed_at = session.seed, session.sim.tick, session.changed_at
        line = session.reproduce()
    program = session.compile(text, overrides)      # its own: the live run keeps going
    folder = _new_folder(session.out, f"{session.file.stem}-seed{seed}-tick{tick}")
    record = folder / f"run.{video}" if video else None
    run = Run(program, seed=seed, steps=tick, out=folder, record=record,
              backend=session.backend)
    run.show_progress = False
    outcome = run.execute(headless=True)
    result = {"folder": str(folder), "outcome": outcome, "ticks": tick,
              "files": sorted(p.name for p in folder.iterdir() if not p.name.startswith("."))}
    notes = []
    if line.exact:
        result["command"] = f"{line.line} --steps {tick} --out {folder.name}"
    else:       # the text running is not the file's: no command makes this export
        notes.append(line.line)
    if changed_at is not None:
        notes.append(f"a param changed at tick {changed_at}: the export replays the "
                     "values shown from tick 0")
    if notes:
        result["note"] = "\n".join(notes)
    if outcome == "fault" and run.fault is not None:
        result["fault"] = run.fault.render()
    if video and not run.video_complete:
        result["video_error"] = run.video_error or "the encoder did not finish the video"
    return result


def _new_folder(root: Path, name: str) -> Path:
    """`root/name`, or `root/name-2`, ... : an export never writes over another."""
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", name)
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SwarmOptionError(f"outputs folder {root}: cannot create it ({exc.strerror})"
                               ) from None
    for i in range(1, 10_000):
        folder = root / (name if i == 1 else f"{name}-{i}")
        if not folder.exists():
            return folder
    raise SwarmError(f"outputs folder {root}: too many exports named {name}")
