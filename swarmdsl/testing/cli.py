"""`swarmdsl test FILE`: hunt for a counterexample to a program's properties.

Exit 1 when one is found (printed shrunk, with the command that replays it), 0 when
none is, 2 when the program or the options are bad, 4 (`--strict`) when none is but a
property was never exercised: a pass that put it to no test is no pass.
"""

from __future__ import annotations

import hashlib
import math
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from swarmdsl.command_args import path_arg
from swarmdsl.errors import SwarmError, SwarmOptionError


def register(sub) -> None:
    p = sub.add_parser(
        "test", help="search for runs that break a program's invariants",
        description="Run the program's `invariant`, `eventually` and `always` properties "
        "under hypothesis-drawn swarms (agent by agent: ids, start positions, drawn initial "
        "values; a kind runs with 1 up to its count of agents unless --fixed-counts), "
        "ticks, seeds and param values (within their declared ranges); shrink a "
        "failure to the fewest agents and ticks, print it with every agent's initial state "
        "and save it for `swarmdsl run --example`. Says how many runs exercised each property "
        "(could have broken it) and warns about one none did. Exit 1 on a counterexample, "
        "0 when none was found, 2 on a bad program, 4 with --strict when a property was "
        "never exercised.")
    p.add_argument("file", type=path_arg("file", "a .swarm program file", text=True),
                   help="the .swarm program")
    p.add_argument("--examples", type=int, default=100, metavar="N",
                   help="how many runs to try (default 100)")
    p.add_argument("--time-budget", type=float, default=60.0, metavar="SECONDS",
                   help="stop drawing new runs after this long; shrinking gets as long "
                   "again (default 60)")
    p.add_argument("--steps", type=int, metavar="N",
                   help="ticks per run (default: the program's `world { steps N }`; "
                   "without it 100, or the largest `within` if larger)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="fix a param instead of drawing it; repeatable")
    p.add_argument("--property", action="append", dest="properties", metavar="NAME",
                   help="check only this property; repeatable")
    p.add_argument("--fixed-counts", action="store_true",
                   help="keep every kind's program count (default: a kind not counted by "
                   "a size param of its own, as in `count 12`, runs with 1 up to its count "
                   "of its agents, shrunk toward the fewest; a kind placed by `index` or "
                   "`id` keeps its count)")
    p.add_argument("--fixed-count", action="append", default=[], dest="fixed_kinds",
                   metavar="KIND", help="keep this kind's program count; repeatable")
    p.add_argument("--hypothesis-seed", type=int, metavar="N",
                   help="seed the search itself, for a repeatable hunt")
    p.add_argument("--save-example", metavar="FILE.json",
                   type=path_arg("--save-example", "a file name, e.g. example.json"),
                   help="write the counterexample here (default: a file in the user "
                   "cache folder); `swarmdsl run FILE --example FILE.json` replays it")
    p.add_argument("--strict", action="store_true",
                   help="fail (exit 4) when no run exercised a property: an `always` "
                   "whose trigger never held, an `eventually` whose deadline no run "
                   "reached, a per-agent invariant of a kind no run had")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    p.set_defaults(func=cmd_test)


def cmd_test(args) -> int:
    from swarmdsl.command_args import parse_sets
    from swarmdsl.runtime.backends import environment_backend
    from swarmdsl.testing.search import search

    environment_backend()     # else every run fails, reported as a counterexample
    if args.examples < 1:
        raise SwarmOptionError(f"--examples {args.examples}: must be 1 or more")
    if not math.isfinite(args.time_budget) or args.time_budget <= 0:   # nan <= 0 is False
        raise SwarmOptionError(f"--time-budget {args.time_budget}: must be a positive "
                               "number of seconds")
    if args.steps is not None and args.steps < 1:
        raise SwarmOptionError(f"--steps {args.steps}: must be 1 or more")
    if args.save_example is not None:    # found unwritable before the search, not after
        from swarmdsl.runtime.outputs import check_file

        check_file(args.save_example, "--save-example", example="example.json")
    progress = _Progress(args.examples, quiet=args.quiet)
    try:
        with _hypothesis_home():
            report = search(args.file, max_examples=args.examples,
                            time_budget=args.time_budget, steps=args.steps,
                            fixed=parse_sets(args.set), properties=args.properties,
                            hypothesis_seed_value=args.hypothesis_seed,
                            progress=progress.update,
                            fixed_counts=args.fixed_counts or args.fixed_kinds)
    finally:
        progress.close()
    if not report.properties:
        print(f"{args.file}: no properties to test (declare `invariant`, `eventually` or "
              "`always`)")
        return 0
    ce = report.counterexample
    what = f"{len(report.properties)} propert{'ies' if len(report.properties) != 1 else 'y'}"
    if ce is None:
        runs = report.examples
        print(f"{args.file}: no counterexample to {what} in {runs} run{'s' * (runs != 1)} "
              f"of up to {report.steps} ticks ({report.seconds:.1f} s)")
        return _exercised(args, report)
    found = report.found_after
    # printed before it is saved, so a failed save never loses it
    print(f"{args.file}: counterexample found after {found} run{'s' * (found != 1)} "
          f"({report.found_seconds:.1f} s), shrunk in {report.shrink_runs} more "
          f"({report.seconds - report.found_seconds:.1f} s) to:")
    print(ce.describe(args.file))
    print(_horizon(report), flush=True)
    if args.save_example is not None:
        saved = args.save_example
        ce.save(saved)          # creates missing folders, as `run --out` does
    else:
        saved = _cache_path(args.file, ce)
        try:
            ce.save(saved, option=None)
        except SwarmError as err:   # the user asked for no file: say so, keep exit 1
            print(f"warning: the example was not saved: {err.message}", file=sys.stderr)
            return 1
    print(f"  reproduce: {ce.command(args.file, saved)}")
    return 1


def _exercised(args, report) -> int:
    """Print how many runs exercised each property and which horizon they ran; warn
    about each property none exercised (exit 4 with --strict, else 0)."""
    from swarmdsl.testing.monitor import never_exercised

    runs = report.examples
    print(_horizon(report))
    declared = report.infos
    for name in report.properties:
        print(f"  {declared[name].keyword} `{name}`: exercised by "
              f"{report.exercised.get(name, 0)} of {runs} run{'s' * (runs != 1)}")
    for name in report.unexercised():
        info = declared[name]
        print(f"{info.decl.name_span}: warning: {info.keyword} `{name}` was never "
              f"exercised: {never_exercised(info, report.steps)}, so its pass says "
              "nothing; try longer runs (--steps N) or other params (--set)"
              f"{'' if args.strict else '; --strict makes this a failure'}",
              file=sys.stderr)
    return 4 if args.strict and report.unexercised() else 0


def _horizon(report) -> str:
    """Which horizon the hunt ran, and why: a pass is only as good as its runs' length."""
    return f"  horizon: up to {report.steps} ticks per run ({report.horizon})"


def _cache_path(filename: str, ce) -> Path:
    from swarmdsl.testing.example import cache_folder

    data = repr(ce.replay()).encode("utf-8")
    return cache_folder() / f"{Path(filename).stem}-{hashlib.sha256(data).hexdigest()[:12]}.json"


@contextmanager
def _hypothesis_home():
    """Hypothesis keeps its files (few: the hunt uses no example database) in the user
    cache folder while the hunt runs, never in the current folder."""
    from hypothesis import configuration

    from swarmdsl.testing.example import cache_folder

    before = getattr(configuration, "__hypothesis_home_directory", None)
    configuration.set_hypothesis_home_dir(cache_folder().parent / "hypothesis")
    try:
        yield
    finally:
        configuration.set_hypothesis_home_dir(before)


class _Progress:
    """A rich spinner line on a terminal; a line per 10% of the examples otherwise."""

    def __init__(self, total: int, quiet: bool = False):
        self.total = total
        self.bar = None
        self.next = max(total // 10, 1)
        self.quiet = quiet
        self.start = time.perf_counter()
        if not quiet and sys.stderr.isatty():
            from rich.console import Console
            from rich.progress import Progress

            self.bar = Progress(console=Console(stderr=True), transient=True)
            self.task = self.bar.add_task("searching", total=total)
            self.bar.start()

    def update(self, runs: int, elapsed: float, shrinking: bool) -> None:
        if self.quiet:
            return
        if self.bar is not None:
            self.bar.update(self.task, completed=min(runs, self.total),
                            description="shrinking" if shrinking else "searching")
            return
        if runs >= self.next:
            phase = "shrinking" if shrinking else "searching"
            print(f"{phase}: {runs} runs, {elapsed:.1f} s", file=sys.stderr)
            self.next += max(self.total // 10, 1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()
