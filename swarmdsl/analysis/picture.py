"""A picture of a recorded run at one tick: its field as a heatmap, regions, agents.

Usage: ``python -m swarmdsl.analysis.picture RUN_DIR OUT.png [--tick T] [--field NAME]
[--px PX] [--window N]``.
Reads `run.json`, `fields.npz` and `agents.parquet` and draws them with the viewer's
frame renderer, so the picture looks like the live window. A folder that is not a run,
a tick it did not record or a field it does not have is one `error:` line naming the
option or file (exit 2), as `swarmdsl` reports its own.
"""

from __future__ import annotations

import argparse
import json
import zipfile
from pathlib import Path

import numpy as np

from swarmdsl.errors import SwarmOptionError, did_you_mean

_A_RUN = "give a folder written by `swarmdsl run --out`"
_FORMATS = (".png",)
_PX = (16, 16384)      # what `FrameRenderer` draws
_AGENT_COLUMNS = ("id", "kind", "status", "x", "y", "heading")


def snapshot_of_run(run_dir, tick: int | None = None, field: str | None = None,
                    window: int = 1):
    """The recorded Snapshot at `tick`; the last recorded one by default.

    With ``window > 1`` each field is the mean of the last ``window`` recorded frames,
    which shows where trails have lain rather than where they lie this tick.
    A tick that was not recorded is refused rather than replaced by a neighbour: the
    picture would be labelled with a tick the user did not ask for.
    """
    import pyarrow.parquet as pq

    from swarmdsl.runtime.snapshot import Snapshot
    from swarmdsl.runtime.spool import open_fields

    run_dir = Path(run_dir)
    if window < 1:
        raise SwarmOptionError(f"--window {window}: must be 1 or more")
    meta = _run_json(run_dir)
    try:
        with open_fields(run_dir) as data:   # fields.npz, or a killed run's frames
            ticks = np.asarray(data["ticks"])
            i = _tick_index(run_dir, ticks, tick)
            names = [k for k in data.files if k not in ("ticks", "grid_x", "grid_y")]
            if field is not None and field not in names:
                raise _unknown_field(run_dir, field, names)
            lo = max(i - int(window) + 1, 0)
            fields = {n: data[n][lo:i + 1].mean(axis=0) for n in names
                      if field is None or n == field}
            gx, gy = data["grid_x"], data["grid_y"]
            at = int(ticks[i])
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as exc:
        raise SwarmOptionError(f"RUN_DIR {run_dir}: its recorded fields (fields.npz) "
                               f"are unreadable ({_reason(exc)})") from None
    if not (run_dir / "agents.parquet").exists():
        raise SwarmOptionError(f"RUN_DIR {run_dir}: no agents.parquet; {_A_RUN}")
    try:
        table = pq.read_table(run_dir / "agents.parquet",
                              filters=[("tick", "==", at)]).to_pydict()
    except (OSError, ValueError) as exc:    # e.g. a damaged part file
        raise SwarmOptionError(f"RUN_DIR {run_dir}: agents.parquet is unreadable "
                               f"({_reason(exc)})") from None
    missing = [c for c in _AGENT_COLUMNS if c not in table]
    if missing:     # a run stopped before its first rows were flushed has no columns
        raise SwarmOptionError(f"RUN_DIR {run_dir}: agents.parquet has no column "
                               f"{', '.join(missing)}; {_A_RUN}")
    # run.json's order (the program's), then any status it does not list (a run.json
    # edited or from another run): a colour each, not a crash
    status_names = list(dict.fromkeys([*meta["status_counts"], *table["status"]]))
    codes = {s: k for k, s in enumerate(status_names)}
    kinds = sorted(set(table["kind"]))
    return Snapshot(
        tick=at, world_size=tuple(meta["world"]["size"]),
        pos=np.column_stack([table["x"], table["y"]]).reshape(-1, 2),
        heading=np.asarray(table["heading"], dtype=np.float64),
        status=np.asarray([codes[s] for s in table["status"]], dtype=np.int32),
        kind=np.asarray([kinds.index(k) for k in table["kind"]], dtype=np.int32),
        ids=np.asarray(table["id"], dtype=np.int64),
        status_names=status_names, kind_names=kinds,
        fields=fields, grid_x=gx, grid_y=gy, regions=meta["world"]["regions"],
        wraps=meta["world"].get("edges") == "wrap")


def _run_json(run_dir: Path) -> dict:
    """`run_dir`'s run.json, refused naming the folder when it is not a run's."""
    where = f"RUN_DIR {run_dir}"
    if not run_dir.exists():
        raise SwarmOptionError(f"{where}: no such folder; {_A_RUN}")
    if not run_dir.is_dir():
        raise SwarmOptionError(f"{where}: is a file, not a folder; {_A_RUN}")
    path = run_dir / "run.json"
    try:
        if not any(run_dir.iterdir()):
            raise SwarmOptionError(f"{where}: the folder is empty; {_A_RUN}")
        if not path.is_file():
            raise SwarmOptionError(f"{where}: no run.json, so not a run's folder; {_A_RUN}")
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise SwarmOptionError(f"{where}: run.json is unreadable ({_reason(exc)})") from None
    world = meta.get("world") if isinstance(meta, dict) else None
    size = world.get("size") if isinstance(world, dict) else None
    if (not isinstance(size, list) or len(size) != 2
            or not all(isinstance(v, int | float) for v in size)
            or not isinstance(world.get("regions", []), list)
            or not isinstance(meta.get("status_counts"), dict)):
        raise SwarmOptionError(f"{where}: run.json is not a run's record (no world size, "
                               f"regions or status counts); {_A_RUN}")
    world.setdefault("regions", [])
    return meta


def _tick_index(run_dir: Path, ticks: np.ndarray, tick: int | None) -> int:
    """The row of `tick` among the recorded ticks (the last row for None)."""
    if not len(ticks):
        raise SwarmOptionError(f"RUN_DIR {run_dir}: no tick was recorded (the run "
                               "stopped before its first record)")
    if tick is None:
        return len(ticks) - 1
    rows = np.flatnonzero(ticks == tick)
    if len(rows):
        return int(rows[0])
    j = int(np.searchsorted(ticks, tick))
    nearest = " and ".join(str(int(t)) for t in ticks[max(j - 1, 0):j + 1])
    raise SwarmOptionError(f"--tick {tick}: not recorded in {run_dir} ({len(ticks)} "
                           f"ticks from {int(ticks[0])} to {int(ticks[-1])}; nearest "
                           f"{nearest})")


def _unknown_field(run_dir: Path, field: str, names: list[str]) -> SwarmOptionError:
    if not names:
        return SwarmOptionError(f"--field {field}: the run in {run_dir} recorded no fields")
    return SwarmOptionError(f"--field {field}: not a field of the run in {run_dir} "
                            f"(fields: {', '.join(names)})", hint=did_you_mean(field, names))


def _reason(exc: BaseException) -> str:
    from swarmdsl.internal import describe

    return describe(exc)


def check_output(out_png, max_px: int) -> Path:
    """The picture's path and size, refused before the run is read (nothing created)."""
    from swarmdsl.runtime.outputs import check_file

    out = Path(out_png)
    if out.suffix.lower() not in _FORMATS:
        raise SwarmOptionError(f"OUT {out}: the picture must end in .png")
    check_file(out, "OUT")
    lo, hi = _PX
    if not lo <= max_px <= hi:
        raise SwarmOptionError(f"--px {max_px}: must be from {lo:,} to {hi:,}")
    return out


def save_picture(run_dir, out_png, tick: int | None = None, field: str | None = None,
                 max_px: int = 800, window: int = 1) -> Path:
    """Render the run at `tick` to a PNG (its folder made if missing); returns its path."""
    from swarmdsl.runtime.outputs import make_folder, replace_with
    from swarmdsl.viz import require_pygame
    from swarmdsl.viz.frames import FrameRenderer, fit_size

    out = check_output(out_png, max_px)
    snap = snapshot_of_run(run_dir, tick, field, window)
    w, h = fit_size(snap.world_size, max_px)
    renderer = FrameRenderer(w, h)
    surface = renderer.draw(snap)
    make_folder(out.parent, "OUT")
    pg = require_pygame()

    def write(tmp: Path) -> None:   # the PNG is whole at `out`, or the old one stays
        with open(tmp, "wb") as fh:
            pg.image.save(surface, fh, out.name)   # the name says PNG; `tmp`'s would not
    try:
        replace_with(out, write)
    except OSError as exc:      # a full disk, a folder gone read-only: not a bug
        reason = (exc.strerror or type(exc).__name__).lower()
        raise SwarmOptionError(f"OUT {out}: cannot write the picture ({reason})") from None
    return out


def main(argv=None) -> int:
    from swarmdsl.cli import path_arg, reported

    def command() -> int:
        ap = argparse.ArgumentParser(prog="python -m swarmdsl.analysis.picture",
                                     description=__doc__.splitlines()[0])
        ap.add_argument("run_dir", metavar="RUN_DIR",
                        type=path_arg("RUN_DIR", "a folder written by `swarmdsl run --out`"))
        ap.add_argument("out", metavar="OUT", type=path_arg("OUT", "a file name, e.g. out.png"),
                        help="the picture, a .png file (its folder is made if missing)")
        ap.add_argument("--tick", type=int, default=None,
                        help="a recorded tick (default: the last one)")
        ap.add_argument("--field", default=None, help="the field to draw (default: the first)")
        ap.add_argument("--px", type=int, default=800,
                        help="the picture's longer side in pixels (16 to 16384; default 800)")
        ap.add_argument("--window", type=int, default=1,
                        help="show the mean of the last N recorded frames of the field")
        args = ap.parse_args(argv)
        print(save_picture(args.run_dir, args.out, args.tick, args.field, args.px,
                           args.window))
        return 0

    return reported(command)


if __name__ == "__main__":
    raise SystemExit(main())
