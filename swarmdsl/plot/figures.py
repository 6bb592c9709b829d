"""The two figures researchers draw: a metric over time, a metric against a parameter.

matplotlib is imported only here and in `draw.py` (how spreads are drawn), with the
non-interactive Agg backend, so plotting works on a machine without a display and the
rest of swarmdsl never pays for it.
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


def over_time(run_dirs: list[Path], metrics: list[str] | None, output: Path,
              band: str = "quantiles", each: bool = False) -> Path:
    """Each metric over ticks, one panel per metric. Runs of the same program and
    params (replicates: seeds) are one group, drawn as a line and a band (`band`:
    `draw.TIME_BANDS`), with its runs as thin lines too when `each`; a group of one
    run is its line. One legend entry per group."""
    _check_output(output)
    fig = time_figure(run_dirs, metrics, band, each)
    return _save(_pyplot(), fig, output)


def time_figure(run_dirs: list[Path], metrics: list[str] | None, band: str = "quantiles",
                each: bool = False):
    """The figure `over_time` saves (tests read its lines, bands and legend)."""
    from swarmdsl.plot import draw

    if band not in draw.TIME_BANDS:
        raise SwarmOptionError(f"--band {band}: choose {', '.join(draw.TIME_BANDS)}")
    series, available, bounds = _read_runs(run_dirs)
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
    groups = _groups([d for d, _ in series])
    pers = [per for _, per in series]
    plt = _pyplot()
    fig, axes = plt.subplots(len(wanted), 1, figsize=(7, 2.6 * len(wanted) + 0.6),
                             squeeze=False, sharex=True)
    palette = draw.colours(len(groups))
    replicated = any(len(members) > 1 for _, members in groups)
    for ax, m in zip(axes[:, 0], wanted, strict=True):
        drawn = []
        for (label, members), colour in zip(groups, palette, strict=True):
            runs = [pers[i][m] for i in members if m in pers[i]]
            if not runs:
                continue
            ticks = np.unique(np.concatenate([t for t, _ in runs]))
            values = np.full((len(runs), ticks.size), np.nan)
            for r, (t, v) in enumerate(runs):
                values[r, np.searchsorted(ticks, t)] = v
            drawn.append(values)
            if len(runs) == 1:
                ax.plot(ticks, values[0], color=colour, linewidth=1.2, label=label)
                continue
            if each:
                for row in values:
                    ax.plot(ticks, row, color=colour, linewidth=0.5, alpha=0.3,
                            label="_nolegend_")
            centre, bands = draw.spread(values, band, outer=False)
            bounds_m = bounds.get(m, (None, None))
            for lo, hi in bands:
                ax.fill_between(ticks, draw.clip(lo, bounds_m), draw.clip(hi, bounds_m),
                                color=colour, alpha=0.25, linewidth=0, label="_nolegend_")
            ax.plot(ticks, draw.clip(centre, bounds_m), color=colour, linewidth=1.4,
                    label=f"{label} ({len(runs)} runs)" if label else f"{len(runs)} runs")
        lims = draw.limits(drawn, bounds.get(m, (None, None)))
        if lims is not None:
            ax.set_ylim(*lims)
        ax.set_ylabel(m)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("tick")
    title = _program_title(run_dirs)
    if replicated:
        title = f"{title}: {draw.TIME_BANDS[band]}" if title else draw.TIME_BANDS[band]
    axes[0, 0].set_title(title, fontsize="medium")
    if len(groups) > 1 or replicated:
        draw.place_legend(fig, axes[0, 0], len(groups))
    return fig


def _read_runs(run_dirs: list[Path]):
    """[(folder, {metric: (ticks, values)})], the metrics in first-seen order, and
    {metric: (low, high)} from the first run that records them."""
    import pyarrow.parquet as pq

    from swarmdsl.runtime.metrics import read_bounds

    series: list[tuple[Path, dict[str, tuple[np.ndarray, np.ndarray]]]] = []
    available: list[str] = []
    bounds: dict = {}
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
            table = pq.read_table(path)
        except (OSError, ValueError) as exc:    # e.g. a damaged part file
            raise SwarmOptionError(f"{d}: metrics.parquet is unreadable ({exc})") from None
        t = table.to_pydict()
        # a run killed before its first flush leaves the folder without parts: pyarrow
        # reads it as a table without columns, i.e. no samples
        names = list(dict.fromkeys(t.get("name", [])))
        if not names:       # e.g. a run that faulted before its first sample
            raise SwarmOptionError(f"no metric samples in {d}{_why_no_samples(Path(d))}")
        for name, b in read_bounds(table.schema).items():
            bounds.setdefault(name, b)
        available += [n for n in names if n not in available]
        tick, name, value = (np.asarray(t[c]) for c in ("tick", "name", "value"))
        per = {n: (tick[name == n], value[name == n].astype(float)) for n in names}
        series.append((Path(d), per))
    return series, available, bounds


def _groups(dirs: list[Path]) -> list[tuple[str, list[int]]]:
    """The runs grouped by program and params (all but the seed), in first-seen order:
    [(label, [indexes of its runs])]. A label names what sets its group apart; with
    every run in a group of its own, the runs' labels (`_run_labels`: the seed
    too). Without run.json files, every folder is its own group."""
    metas = _metas(dirs)
    if metas is None:
        return [(Path(d).name, [i]) for i, d in enumerate(dirs)]
    keyed: dict[str, list[int]] = {}
    for i, m in enumerate(metas):
        key = json.dumps({str(k) if k is not _PROGRAM else "": v for k, v in m.items()
                          if k != "seed"}, sort_keys=True, default=str)
        keyed.setdefault(key, []).append(i)
    members = list(keyed.values())
    if all(len(g) == 1 for g in members):
        return [(label, [i]) for i, label in enumerate(_run_labels(dirs))]
    reps = [metas[g[0]] for g in members]
    keys = [k for k in dict.fromkeys(k for m in reps for k in m) if k != "seed"
            and len({json.dumps(m.get(k), default=str) for m in reps}) > 1]
    labels = [", ".join(m[k] if k is _PROGRAM else f"{k} = {m[k]}" for k in keys if k in m)
              for m in reps]
    return list(zip(labels, members, strict=True))


def _metas(dirs: list[Path]) -> list[dict] | None:
    metas = []
    for d in dirs:
        try:
            meta = json.loads((Path(d) / "run.json").read_text())
        except (OSError, ValueError):
            return None
        metas.append({_PROGRAM: Path(str(meta.get("program"))).name,
                      **(meta.get("params") or {}), "seed": meta.get("seed")})
    return metas


def against_param(table: Path, param: str, metric: str, summary: str,
                  output: Path, band: str = "quantiles", points: bool = True) -> Path:
    """One metric summary against a swept param: per line of the other params, the
    centre and bands of its runs at each value, and each run as a point."""
    _check_output(output)
    fig = sweep_figure(table, param, metric, summary, band, points)
    return _save(_pyplot(), fig, output)


def sweep_figure(table: Path, param: str, metric: str, summary: str,
                 band: str = "quantiles", points: bool = True):
    """The figure `against_param` saves (tests read its points, bands and limits)."""
    import pandas as pd
    import pyarrow.parquet as pq

    from swarmdsl.plot import draw
    from swarmdsl.runtime.metrics import read_bounds

    if band not in draw.BANDS:
        raise SwarmOptionError(f"--band {band}: choose {', '.join(draw.BANDS)}")
    if not Path(table).is_file():
        run = Path(table).parent
        if (run / "run.json").is_file():       # the other plot's input
            raise SwarmOptionError(f"{run}: a run's folder, not a sweep's; draw its "
                                   f"metrics with: swarmdsl plot time {run} -o FILE.png")
        raise SwarmOptionError(f"{table}: no such sweep table")
    try:
        arrow = pq.read_table(table)
        t = arrow.to_pandas()
    except (OSError, ValueError) as exc:    # not Parquet (runs.jsonl, a picture...)
        raise SwarmOptionError(f"{table}: not a sweep table ({exc})") from None
    if "outcome" not in t.columns:          # Parquet, but e.g. a run's agents.parquet
        raise SwarmOptionError(f"{table}: not a sweep table (no `outcome` column; give "
                               "the folder `swarmdsl sweep` wrote or its sweep.parquet)")
    column = f"{metric}.{summary}"
    if param not in t.columns:
        params = [c for c in t.columns if c != "seed" and "." not in c
                  and c not in _NOT_PARAMS]
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
    bounds = read_bounds(arrow.schema).get(metric, (None, None))
    others = [c for c in t.columns if c not in (param, "seed", *_NOT_PARAMS)
              and "." not in c]
    # a text param (`true`/`false`, a mode name) is drawn at evenly spaced places
    # labelled with its values, in the order the sweep ran them
    categories = None if pd.api.types.is_numeric_dtype(t[param]) else list(
        dict.fromkeys(ok[param].astype(str)))

    def x_of(values) -> np.ndarray:
        if categories is None:
            return np.asarray(values, dtype=float)
        return np.array([categories.index(str(c)) for c in values], dtype=float)

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2))
    groups = list(ok.groupby(others, dropna=False, sort=False)) if others else [((), ok)]
    palette = draw.colours(len(groups))
    width = draw.jitter_width(x_of(ok[param]))
    drawn = []
    for g_index, ((key, g), colour) in enumerate(zip(groups, palette, strict=True)):
        xs = x_of(g[param])
        order = np.unique(xs)
        runs = [g[column].to_numpy(dtype=float)[xs == x] for x in order]
        most = max(len(r) for r in runs)
        values = np.full((most, order.size), np.nan)
        for j, r in enumerate(runs):
            values[:len(r), j] = r
        centre, bands = draw.spread(values, band)
        for (lo, hi), alpha in zip(bands, (0.35, 0.15), strict=False):
            ax.fill_between(order, draw.clip(lo, bounds), draw.clip(hi, bounds),
                            color=colour, alpha=alpha, linewidth=0, label="_nolegend_")
        key = key if isinstance(key, tuple) else (key,)
        label = ", ".join(f"{c} = {v:g}" if isinstance(v, float) else f"{c} = {v}"
                          for c, v in zip(others, key, strict=True)) or None
        ax.plot(order, draw.clip(centre, bounds), marker="o", markersize=3.5,
                color=colour, label=label)
        raw = g[column].to_numpy(dtype=float)
        drawn += [raw, *(b for pair in bands for b in pair)]
        if points:
            ax.scatter(draw.jitter(xs, width, seed=g_index), raw, s=9, color=colour,
                       alpha=0.45, linewidths=0, clip_on=False, zorder=3,
                       label="_nolegend_")
    seeds = replicates_per_point(ok, param, others)
    if categories is not None:
        ax.set_xticks(range(len(categories)), categories)
    lims = draw.limits(drawn, bounds)
    if lims is not None:
        ax.set_ylim(*lims)
    ax.set_xlabel(param)
    ax.set_ylabel(f"{metric} ({summary})")
    runs_as = ", runs as points" if points else ""
    ax.set_title(f"{metric} against {param}, {seeds} seeds\n{draw.BANDS[band]}{runs_as}",
                 fontsize="medium")
    ax.grid(alpha=0.3)
    if others:
        draw.place_legend(fig, ax, len(groups))
    return fig


# the sweep table's bookkeeping columns (sweep/table.py), not params: a line per
# value of one of them would split a sweep by, say, the library versions
_NOT_PARAMS = ("outcome", "error", "ticks", "wall_seconds", "sha256", "version",
               "libraries", "key")


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
    metas = _metas(dirs)
    if metas is None:
        return [Path(d).name for d in dirs]
    # every run's keys, not only the first's: runs of different programs (or of one
    # program before and after a param was added) differ in params the first lacks
    names = list(dict.fromkeys(k for m in metas for k in m))
    keys = [k for k in names if len({json.dumps(m.get(k)) for m in metas}) > 1]
    if not keys:
        return [Path(d).name for d in dirs]
    return [", ".join(m[k] if k is _PROGRAM else f"{k} = {m[k]}"
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
