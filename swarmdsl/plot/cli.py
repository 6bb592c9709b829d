"""`swarmdsl plot`: `time` for metrics over ticks, `sweep` for a metric against a param."""

from __future__ import annotations

import argparse

from swarmdsl.command_args import path_arg

_FIGURE = "a file name, e.g. figure.png"


def register(sub) -> None:
    p = sub.add_parser("plot", help="plot metrics of runs or of a sweep (PNG, SVG, PDF)",
                       description="Plot a metric over time from run folders (overlaid), or "
                       "a metric against a swept param from a sweep table.")
    what = p.add_subparsers(dest="plot_kind", metavar="WHAT", required=True)
    t = what.add_parser("time", help="metrics over ticks from one or more run folders")
    t.add_argument("runs", nargs="+", metavar="RUN_DIR",
                   type=path_arg("RUN_DIR", "a folder written by `swarmdsl run --out`"),
                   help="folders written by `swarmdsl run --out`")
    t.add_argument("--metric", action="append", metavar="NAME",
                   help="a metric to draw (repeatable; default: all)")
    t.add_argument("--band", default="quantiles", choices=("quantiles", "minmax", "sd"),
                   help="runs of the same program and params (seeds) drawn as one line "
                   "and band: median and 25-75 %% of runs (default), median and min-max, "
                   "or mean ± 1 sd")
    t.add_argument("--each", action="store_true",
                   help="also draw every run of a group as a thin line")
    t.add_argument("-o", "--output", type=path_arg("-o", _FIGURE), required=True,
                   metavar="FILE.png|svg|pdf")
    t.set_defaults(func=_cmd_time)
    s = what.add_parser("sweep", help="a metric summary against a swept param")
    s.add_argument("table", type=path_arg("table", "a sweep folder or its sweep.parquet"),
                   help="a sweep folder or its sweep.parquet")
    s.add_argument("--x", required=True, metavar="PARAM", help="the swept param")
    s.add_argument("--metric", required=True, metavar="NAME")
    s.add_argument("--summary", default="mean", choices=("last", "mean", "min", "max"),
                   help="which per-run summary (default: mean over the second half)")
    s.add_argument("--band", default="quantiles", choices=("quantiles", "minmax", "sd"),
                   help="replicate spread: the median with bands of 25-75 %% and 5-95 %% "
                   "of runs (default), the median with 25-75 %% and min-max, or the mean "
                   "± 1 standard deviation; always within what the metric can take")
    s.add_argument("--points", action=argparse.BooleanOptionalAction, default=True,
                   help="draw every run as a point (default; --no-points: bands only)")
    s.add_argument("-o", "--output", type=path_arg("-o", _FIGURE), required=True,
                   metavar="FILE.png|svg|pdf")
    s.set_defaults(func=_cmd_sweep)


def _cmd_time(args) -> int:
    from swarmdsl.plot.figures import over_time
    from swarmdsl.runtime.outputs import check_file

    check_file(args.output, "-o")
    print(f"wrote {over_time(args.runs, args.metric, args.output, args.band, args.each)}")
    return 0


def _cmd_sweep(args) -> int:
    from swarmdsl.plot.figures import against_param
    from swarmdsl.runtime.outputs import check_file

    check_file(args.output, "-o")
    table = args.table / "sweep.parquet" if args.table.is_dir() else args.table
    path = against_param(table, args.x, args.metric, args.summary, args.output, args.band,
                         args.points)
    print(f"wrote {path}")
    return 0
