"""A picture of a recorded run at one tick: its field as a heatmap, regions, agents.

Usage: ``python -m swarmdsl.analysis.picture RUN_DIR OUT.png [--tick T] [--field NAME]
[--window N]``.
Reads `run.json`, `fields.npz` and `agents.parquet` and draws them with the viewer's
frame renderer, so the picture looks like the live window.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def snapshot_of_run(run_dir, tick: int | None = None, field: str | None = None,
                    window: int = 1):
    """The recorded Snapshot nearest (at or before) `tick`; the last one by default.

    With ``window > 1`` each field is the mean of the last ``window`` recorded frames,
    which shows where trails have lain rather than where they lie this tick.
    """
    import pyarrow.parquet as pq

    from swarmdsl.runtime.snapshot import Snapshot
    from swarmdsl.runtime.spool import open_fields

    run_dir = Path(run_dir)
    meta = json.loads((run_dir / "run.json").read_text())
    with open_fields(run_dir) as data:   # fields.npz, or a killed run's frames
        ticks = data["ticks"]
        i = len(ticks) - 1 if tick is None else int(np.searchsorted(ticks, tick, "right")) - 1
        i = max(i, 0)
        names = [k for k in data.files if k not in ("ticks", "grid_x", "grid_y")]
        lo = max(i - max(int(window), 1) + 1, 0)
        fields = {n: data[n][lo:i + 1].mean(axis=0) for n in names
                  if field is None or n == field}
        gx, gy = data["grid_x"], data["grid_y"]
        at = int(ticks[i])
    table = pq.read_table(run_dir / "agents.parquet",
                          filters=[("tick", "==", at)]).to_pydict()
    status_names = sorted(meta["status_counts"], key=list(meta["status_counts"]).index)
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


def save_picture(run_dir, out_png, tick: int | None = None, field: str | None = None,
                 max_px: int = 800, window: int = 1) -> Path:
    """Render the run at `tick` to a PNG; returns its path."""
    from swarmdsl.viz import require_pygame
    from swarmdsl.viz.frames import FrameRenderer, fit_size

    snap = snapshot_of_run(run_dir, tick, field, window)
    w, h = fit_size(snap.world_size, max_px)
    renderer = FrameRenderer(w, h)
    surface = renderer.draw(snap)
    out = Path(out_png)
    out.parent.mkdir(parents=True, exist_ok=True)
    require_pygame().image.save(surface, str(out))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir")
    ap.add_argument("out")
    ap.add_argument("--tick", type=int, default=None)
    ap.add_argument("--field", default=None)
    ap.add_argument("--px", type=int, default=800)
    ap.add_argument("--window", type=int, default=1,
                    help="show the mean of the last N recorded frames of the field")
    args = ap.parse_args(argv)
    print(save_picture(args.run_dir, args.out, args.tick, args.field, args.px,
                       args.window))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
