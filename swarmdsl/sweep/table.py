"""A sweep's results: the append-only log of finished runs and the tidy Parquet table.

Each finished run is one JSON line appended and flushed to `runs.jsonl` as soon as it
arrives, so killing the sweep (even with SIGKILL) loses only the runs in progress; a torn
last line is dropped on restart (the log is rewritten without it, so readers of JSON
lines such as `pandas.read_json(lines=True)` read it again). `sweep.parquet` is rebuilt from the log whenever the
sweep stops, written to a temporary name and renamed, so it is always a whole table.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

LOG = "runs.jsonl"
TABLE = "sweep.parquet"


class ResultLog:
    def __init__(self, out: Path):
        self.out = Path(out)
        self.out.mkdir(parents=True, exist_ok=True)
        self.rows: dict[str, dict] = {}
        path = self.out / LOG
        if path.exists():
            text = _read(path, self.out)
            whole = []
            for line in text.splitlines():
                try:
                    row = json.loads(line)
                except json.JSONDecodeError:
                    continue          # the torn end of a killed sweep
                whole.append(line)
                if isinstance(row, dict) and "key" in row:
                    self.rows[row["key"]] = row
            if len(whole) != len(text.splitlines()) or (text and text[-1] != "\n"):
                _rewrite(path, whole)
        self._file = None

    def __contains__(self, key: str) -> bool:
        return key in self.rows

    def failed(self, key: str) -> bool:
        """Whether the log's last entry for `key` is a failed run (`--retry-failed`)."""
        return self.rows[key].get("outcome") != "completed"

    def add(self, row: dict) -> None:
        self.add_all([row])

    def add_all(self, rows: list[dict]) -> None:
        """Append `rows` (one task's: a batch's runs end together) and flush them to
        disk at once: one `fsync` a batch rather than one a run (a thousand of them
        took seconds of a sweep's wall time)."""
        from swarmdsl import stopping

        if not rows:
            return
        with stopping.uncut():      # a row in the log is a row in the table
            if self._file is None:
                self._file = open(self.out / LOG, "a", encoding="utf-8")  # noqa: SIM115
            self._file.write("".join(json.dumps(_plain(row), allow_nan=False) + "\n"
                                     for row in rows))
            self._file.flush()
            os.fsync(self._file.fileno())
            for row in rows:
                self.rows[row["key"]] = row

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


def _rewrite(path: Path, lines: list[str]) -> None:
    """The log again with only its whole lines, under a temporary name then renamed, so a
    kill now leaves either the old log or the new one."""
    from swarmdsl import stopping

    tmp = path.with_name(LOG + ".tmp")
    with stopping.uncut():
        with open(tmp, "w", encoding="utf-8") as f:
            f.write("".join(line + "\n" for line in lines))
            f.flush()
            os.fsync(f.fileno())
        tmp.replace(path)


def _read(path: Path, out: Path) -> str:
    """The log's text; one that cannot be read (a folder in its place, not UTF-8) is
    refused naming the sweep's folder, not reported as an internal error."""
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        from swarmdsl.errors import SwarmOptionError

        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        raise SwarmOptionError(f"--out {out}: its {LOG} is unreadable ({reason}); give "
                               "the sweep another folder") from None


def _plain(x):
    """NaN and infinities as null: the log and the table stay standard JSON."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_plain(v) for v in x]
    return x


def write_table(out: Path, rows: list[dict], param_names: list[str], keep: list[str],
                metric_names: list[str], bounds: dict | None = None) -> Path:
    """One row per run, in the sweep's order: params, seed, metric summaries, outcome.
    `bounds` ({metric: [low, high]}, `runtime.metrics.bounds_of`) goes into the
    table's metadata, where `swarmdsl plot sweep` reads what a metric can take."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    cols: dict[str, list] = {name: [] for name in param_names}
    cols["seed"] = []
    summary_cols = [f"{m}.{s}" for m in metric_names for s in keep]
    for c in summary_cols:
        cols[c] = []
    for c in ("outcome", "error", "ticks", "wall_seconds", "sha256", "version", "libraries",
              "key"):
        cols[c] = []
    typed: dict[str, list] = {name: [] for name in param_names}
    for row in rows:
        params = dict(row["params"])
        for name in param_names:
            typed[name].append(params.get(name))
            cols[name].append(_number(params.get(name)))
        cols["seed"].append(row["seed"])
        for m in metric_names:
            summary = (row.get("metrics") or {}).get(m) or {}
            for s in keep:
                v = summary.get(s)
                cols[f"{m}.{s}"].append(float(v) if v is not None else None)
        for c in ("outcome", "error", "ticks", "wall_seconds", "sha256", "version",
                  "libraries", "key"):
            cols[c].append(row.get(c))
    types = {c: pa.float64() for c in summary_cols}
    types.update(seed=pa.int64(), ticks=pa.int64(), wall_seconds=pa.float64(),
                 outcome=pa.string(), error=pa.string(), sha256=pa.string(),
                 version=pa.string(), libraries=pa.string(), key=pa.string())
    for name in param_names:      # a column of numbers, or all of it as text as typed
        if any(isinstance(v, str) for v in cols[name]):   # (`10`, not `10.0` from float)
            cols[name] = [None if v is None else str(v) for v in typed[name]]
    arrays = {}
    for c, values in cols.items():
        arrays[c] = pa.array(values, type=types.get(c))
    table = pa.table(arrays)
    if bounds:
        import json

        from swarmdsl.runtime.metrics import BOUNDS_KEY

        table = table.replace_schema_metadata({BOUNDS_KEY: json.dumps(bounds)})
    path = Path(out) / TABLE
    tmp = path.with_name(TABLE + ".tmp")
    pq.write_table(table, tmp)
    tmp.replace(path)
    return path


def _number(text):
    """A param value as a number when it reads as one, else the text (a bool stays text)."""
    if text is None:
        return None
    try:
        v = float(text)
    except ValueError:
        return text
    return v
