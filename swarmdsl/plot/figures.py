"""The two figures researchers draw: a metric over time, a metric against a parameter.

matplotlib is imported here only, with the non-interactive Agg backend, so plotting
works on a machine without a display and the rest of swarmdsl never pays for it.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from swarmdsl.errors import SwarmOptionError, did_you_mean

FORMATS = (".png", ".svg", ".pdf")


def _pyplot():
    try:
        import matplotlib
    except ImportError:
        raise SwarmOptionError("plots need matplotlib: pip install 'swarmdsl[plot]'") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _check_output(path: Path) -> None:
    if path.suffix.lower() not in FORMATS:
        raise SwarmOptionError(f"--output {path}: the file must end in .png, .svg or .pdf")


def _column_hint(metric: str, column: str, cols: list[str]) -> str | None:
    """A column's whole name given as the metric (`--metric polarisation.mean`) gets the
    two options it stands for; "did you mean 'polarisation.mean'?", the very text given,
    told the user nothing."""
    if metric in cols:
        name, _, kept = metric.rpartition(".")
        return f"give the summary on its own: --metric {name} --summary {kept}"
    return did_you_mean(column, cols)


def over_time(run_dirs: list[Path], metrics: list[str] | None, output: Path) -> Path:
    """Each metric over ticks, one line per run folder (overlaid), one panel per metric."""
    import pyarrow.parquet as pq

    _check_output(output)
    series: list[tuple[str, dict[str, tuple[np.ndarray, np.ndarray]]]] = []
    available: list[str] = []
    for d in run_dirs:
        path = Path(d) / "metrics.parquet"     # a folder of parts (a file before them)
        if not Path(d).is_dir():
            # a mistyped folder: "no metrics.parquet" sent the user to fix the program
            what = "is a file, not a folder" if Path(d).exists() else "no such folder"
            raise SwarmOptionError(f"RUN_DIR {d}: {what}; give a folder written by "
                                   "`swarmdsl run --out`")
        if not path.exists():
            if (Path(d) / "sweep.parquet").exists():     # the other plot's input
                raise SwarmOptionError(f"RUN_DIR {d}: a sweep's folder, not a run's; draw "
                                       f"it with: swarmdsl plot sweep {d} --x PARAM "
                                       "--metric NAME -o FILE.png")
            raise SwarmOptionError(f"{d}: no metrics.parquet (run a program that declares a "
                                   "`metric` with --out)")
        try:
            t = pq.read_table(path).to_pydict()
        except (OSError, ValueError) as exc:    # e.g. a damaged part file
            raise SwarmOptionError(f"{d}: metrics.parquet is unreadable ({exc})") from None
        # a run killed before its first flush leaves the folder without parts: pyarrow
        # reads it as a table without columns, i.e. no samples
        names = list(dict.fromkeys(t.get("name", [])))
        if not names:       # e.g. a run that faulted before its first sample
            raise SwarmOptionError(f"no metric samples in {d}{_why_no_samples(Path(d))}")
        available += [n for n in names if n not in available]
        tick, name, value = (np.asarray(t[c]) for c in ("tick", "name", "value"))
        per = {n: (tick[name == n], value[name == n].astype(float)) for n in names}
        series.append((Path(d), per))
    wanted = metrics or available
    for m in wanted:
        if m not in available:
            where = "the run" if len(series) == 1 else f"any of the {len(series)} runs"
            raise SwarmOptionError(f"--metric {m}: not in {where} (metrics: "
                                   f"{', '.join(available)})", hint=did_you_mean(m, available))
    for d, per in series:   # overlaid runs are compared: say which ones a panel lacks
        for m in wanted:
            if m not in per:
                print(f"warning: {d}: no metric `{m}`; left out of its panel",
                      file=sys.stderr)
    labels = _run_labels([d for d, _ in series])
    series = [(labels[i], per) for i, (_d, per) in enumerate(series)]
    plt = _pyplot()
    fig, axes = plt.subplots(len(wanted), 1, figsize=(7, 2.6 * len(wanted) + 0.6),
                             squeeze=False, sharex=True)
    for ax, m in zip(axes[:, 0], wanted, strict=True):
        for label, per in series:
            if m in per:
                ax.plot(*per[m], label=label, linewidth=1.2)
        ax.set_ylabel(m)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("tick")
    if len(series) > 1:
        axes[0, 0].legend(fontsize="small", frameon=False)
    axes[0, 0].set_title(_program_title(run_dirs))
    return _save(plt, fig, output)


def against_param(table: Path, param: str, metric: str, summary: str,
                  output: Path, band: str = "sd") -> Path:
    """Mean over replicate seeds of one metric summary per param value, with a band."""
    import pandas as pd
    import pyarrow.parquet as pq

    _check_output(output)
    if not Path(table).is_file():
        run = Path(table).parent
        if (run / "run.json").is_file():       # the other plot's input
            raise SwarmOptionError(f"{run}: a run's folder, not a sweep's; draw its "
                                   f"metrics with: swarmdsl plot time {run} -o FILE.png")
        raise SwarmOptionError(f"{table}: no such sweep table")
    try:
        t = pq.read_table(table).to_pandas()
    except (OSError, ValueError) as exc:    # not Parquet (runs.jsonl, a picture...)
        raise SwarmOptionError(f"{table}: not a sweep table ({exc})") from None
    if "outcome" not in t.columns:          # Parquet, but e.g. a run's agents.parquet
        raise SwarmOptionError(f"{table}: not a sweep table (no `outcome` column; give "
                               "the folder `swarmdsl sweep` wrote or its sweep.parquet)")
    column = f"{metric}.{summary}"
    if param not in t.columns:
        params = [c for c in t.columns if c != "seed" and "." not in c
                  and c not in ("outcome", "error", "ticks", "wall_seconds", "sha256",
                                "version", "key")]
        raise SwarmOptionError(f"--x {param}: not a swept param (params: "
                               f"{', '.join(params) or 'none'})", hint=did_you_mean(param,
                                                                                    params))
    if column not in t.columns:
        cols = [c for c in t.columns if "." in c]
        raise SwarmOptionError(f"--metric {metric} --summary {summary}: no column `{column}`"
                               f" (columns: {', '.join(cols) or 'none'})",
                               hint=_column_hint(metric, column, cols))
    ok = t[(t.outcome == "completed") & t[column].notna()]
    if ok.empty:
        raise SwarmOptionError(f"{table}: no completed run has `{column}`")
    others = [c for c in t.columns if c not in (param, "seed", "outcome", "error", "ticks",
                                                "wall_seconds", "sha256", "version", "key")
              and "." not in c]
    # a text param (`true`/`false`, a mode name) is drawn at evenly spaced places
    # labelled with its values, in the order the sweep ran them
    categories = None if pd.api.types.is_numeric_dtype(t[param]) else list(
        dict.fromkeys(ok[param].astype(str)))
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2))
    groups = ok.groupby(others, dropna=False) if others else [((), ok)]
    for key, g in groups:
        stats = g.groupby(param)[column].agg(["mean", "std", "count",
                                              lambda s: s.quantile(0.1),
                                              lambda s: s.quantile(0.9)])
        stats.columns = ["mean", "std", "count", "q10", "q90"]
        if categories is not None:
            stats.index = stats.index.astype(str)
            stats = stats.reindex([c for c in categories if c in stats.index])
            x = np.array([categories.index(c) for c in stats.index], dtype=float)
        else:
            x = stats.index.to_numpy(dtype=float)
        mean = stats["mean"].to_numpy()
        if band == "sd":
            sd = np.nan_to_num(stats["std"].to_numpy())
            lo, hi = mean - sd, mean + sd
        else:
            lo, hi = stats["q10"].to_numpy(), stats["q90"].to_numpy()
        key = key if isinstance(key, tuple) else (key,)
        label = ", ".join(f"{c} = {v:g}" if isinstance(v, float) else f"{c} = {v}"
                          for c, v in zip(others, key, strict=True)) or None
        line, = ax.plot(x, mean, marker="o", markersize=3.5, label=label)
        ax.fill_between(x, lo, hi, color=line.get_color(), alpha=0.25, linewidth=0)
    seeds = replicates_per_point(ok, param, others)
    if categories is not None:
        ax.set_xticks(range(len(categories)), categories)
    ax.set_xlabel(param)
    ax.set_ylabel(f"{metric} ({summary})")
    what = "± 1 sd" if band == "sd" else "10-90 % of runs"
    ax.set_title(f"{metric} against {param}: mean of {seeds} seeds, "
                 f"band {what}", fontsize="medium")
    ax.grid(alpha=0.3)
    if others:
        ax.legend(fontsize="small", frameon=False)
    return _save(plt, fig, output)


def replicates_per_point(ok, param: str, others: list[str]) -> str:
    """How many seeds each plotted point averages ("5", or "3-5" when runs failed).

    Counted per line and param value: counting per param value alone would add up the
    seeds of every line drawn (two values of `n` at 5 seeds each is not 10 seeds).
    """
    per_point = ok.groupby([*others, param], dropna=False).size()
    fewest, most = int(per_point.min()), int(per_point.max())
    return f"{most}" if fewest == most else f"{fewest}-{most}"


def _run_labels(dirs: list[Path]) -> list[str]:
    """Name each run by what sets it apart (params that differ, then the seed), from
    its run.json; the folder name when nothing does or run.json is missing."""
    metas = []
    for d in dirs:
        try:
            meta = json.loads((Path(d) / "run.json").read_text())
        except (OSError, ValueError):
            return [Path(d).name for d in dirs]
        metas.append({_PROGRAM: Path(str(meta.get("program"))).name,
                      **(meta.get("params") or {}), "seed": meta.get("seed")})
    # every run's keys, not only the first's: runs of different programs (or of one
    # program before and after a param was added) differ in params the first lacks
    names = list(dict.fromkeys(k for m in metas for k in m))
    keys = [k for k in names if len({json.dumps(m.get(k)) for m in metas}) > 1]
    if not keys:
        return [Path(d).name for d in dirs]
    return [", ".join(m[k] if k == _PROGRAM else f"{k} = {m[k]}"
                      for k in keys if k in m) for m in metas]


_PROGRAM = object()     # the program's key among the params (no param can be named so)


def _why_no_samples(d: Path) -> str:
    """How the run ended, from its run.json, when that explains an empty metric log."""
    try:
        meta = json.loads((d / "run.json").read_text())
        finished, tick = str(meta["finished"]), int(meta["last_tick"])
    except (OSError, ValueError, KeyError, TypeError):
        return ""
    if finished == "completed":
        return ""
    return f" (the run ended at tick {tick}: its run.json says \"finished\": \"{finished}\")"


def _program_title(dirs: list[Path]) -> str:
    """The program's file name when every run is of it; else empty (each run's label
    then names its program)."""
    names = set()
    for d in dirs:
        try:
            meta = json.loads((Path(d) / "run.json").read_text())
            names.add(Path(meta["program"]).name)
        except (OSError, ValueError, KeyError, TypeError):
            return ""
    return names.pop() if len(names) == 1 else ""


def _save(plt, fig, output: Path) -> Path:
    output = Path(output)
    output.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    tmp = output.with_name(output.stem + ".tmp" + output.suffix)
    fig.savefig(tmp, dpi=120)
    plt.close(fig)
    tmp.replace(output)
    return output
