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
        description="Hunt for runs that break the program's `invariant`, `eventually` "
        "and `always` properties: first the program as written (its counts, params and "
        "ticks, as `swarmdsl run --check` runs it, at --seeds seeds), then "
        "hypothesis-drawn runs (swarms agent by agent, 1 up to each kind's count, "
        "weighted to both ends, unless --fixed-counts; ticks, seeds and param values "
        "within their declared ranges). Every failing property gets its own "
        "counterexample, shrunk to a checked 1-minimal case (or said to be possibly not "
        "minimal), printed with every agent's initial state and saved for `swarmdsl run "
        "--example`. A pass says what was tried and, per property, the runs and "
        "agent-ticks that exercised it, and warns about one none did. Exit 1 on a "
        "counterexample, 0 when none was found, 2 on a bad program, 4 with --strict "
        "when a property was never exercised.")
    p.add_argument("file", type=path_arg("file", "a .swarm program file", text=True),
                   help="the .swarm program")
    p.add_argument("--examples", type=int, default=100, metavar="N",
                   help="how many drawn runs to try (default 100)")
    p.add_argument("--time-budget", type=float, default=60.0, metavar="SECONDS",
                   help="stop drawing new runs after this long (the runs of the program "
                   "as written are always made; default 60)")
    p.add_argument("--shrink-budget", type=float, metavar="SECONDS",
                   help="shrink each counterexample for up to this long (default: the "
                   "time budget); a case cut short says it may not be minimal")
    p.add_argument("--seeds", type=int, default=3, metavar="N",
                   help="first run the program as written (its counts, params and "
                   "horizon) at seeds 0..N-1, as `swarmdsl run --check` would (default "
                   "3; 0: drawn runs only)")
    p.add_argument("--steps", type=int, metavar="N",
                   help="ticks per run (default: the program's `world { steps N }`; "
                   "without it 100, or the largest `within` if larger)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="fix a param in every run instead of drawing it (a kind counted "
                   "by it keeps that count); repeatable")
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
    p.add_argument("-v", "--verbose", action="store_true",
                   help="say how the runs ticked: how many ran whole ticks with the "
                   "properties checked in the compiled kernel, and why the others did not")
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
    if args.seeds < 0:
        raise SwarmOptionError(f"--seeds {args.seeds}: must be 0 or more")
    if args.shrink_budget is not None and (not math.isfinite(args.shrink_budget)
                                           or args.shrink_budget <= 0):
        raise SwarmOptionError(f"--shrink-budget {args.shrink_budget}: must be a positive "
                               "number of seconds")
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
                            fixed_counts=args.fixed_counts or args.fixed_kinds,
                            seeds=args.seeds, shrink_budget=args.shrink_budget,
                            verbose=args.verbose)
    finally:
        progress.close()
    for line, runs in report.ticking.items():
        print(f"{runs} run{'s' * (runs != 1)}: {line}", file=sys.stderr)
    if not report.properties:
        print(f"{args.file}: no properties to test (declare `invariant`, `eventually` or "
              "`always`)")
        return 0
    what = f"{len(report.properties)} propert{'ies' if len(report.properties) != 1 else 'y'}"
    if not report.counterexamples:
        runs = report.examples
        longest = max(report.steps, report.as_written_steps)
        print(f"{args.file}: no counterexample to {what} in {runs} run{'s' * (runs != 1)} "
              f"of up to {longest} ticks: {report.coverage.tried()} "
              f"({report.seconds:.1f} s)")
        return _exercised(args, report)
    ces = report.counterexamples
    if len(report.properties) > 1 or len(ces) > 1:
        print(f"{args.file}: {len(ces)} of {what} failed: {', '.join(_failed(ce) for ce in ces)} "
              f"({report.examples} runs, {report.seconds:.1f} s)")
    code = 1
    paths = _save_paths(args.save_example, ces)
    for ce, saved in zip(ces, paths, strict=True):
        found = ce.found_after
        # printed before it is saved, so a failed save never loses it
        print(f"{args.file}: counterexample found after {found} run{'s' * (found != 1)} "
              f"({ce.found_seconds:.1f} s) in {ce.origin}, shrunk in {ce.shrink_runs} "
              f"more ({ce.shrink_seconds:.1f} s) to:")
        print(ce.describe(args.file))
        if saved is not None:
            ce.save(saved)          # creates missing folders, as `run --out` does
        else:
            saved = _cache_path(args.file, ce)
            try:
                ce.save(saved, option=None)
            except SwarmError as err:   # the user asked for no file: say so, keep exit 1
                print(f"warning: the example was not saved: {err.message}",
                      file=sys.stderr)
                continue
        print(f"  reproduce: {ce.command(args.file, saved)}", flush=True)
    print(_horizon(report))
    _coverage(report)
    return code


def _failed(ce) -> str:
    return f"`{ce.violations[0].name}`" if ce.violations else "a runtime fault"


def _save_paths(save: Path | None, ces) -> list:
    """Where each counterexample goes: `--save-example FILE` for one; for several,
    FILE with the property's name added (`case-bot.crowded.json`); None: the cache."""
    if save is None:
        return [None] * len(ces)
    if len(ces) == 1:
        return [save]
    out = []
    for ce in ces:
        name = ce.violations[0].name if ce.violations else "fault"
        name = "".join(c if c.isalnum() or c in "._-" else "_" for c in name)
        out.append(save.with_name(f"{save.stem}-{name}{save.suffix}"))
    return out


def _exercised(args, report) -> int:
    """Print how many runs exercised each property and which horizon they ran; warn
    about each property none exercised (exit 4 with --strict, else 0)."""
    from swarmdsl.testing.monitor import never_exercised

    print(_horizon(report))
    _coverage(report)
    declared = report.infos
    for name in report.unexercised():
        info = declared[name]
        print(f"{info.decl.name_span}: warning: {info.keyword} `{name}` was never "
              f"exercised: {never_exercised(info, report.steps)}, so its pass says "
              "nothing; try longer runs (--steps N) or other params (--set)"
              f"{'' if args.strict else '; --strict makes this a failure'}",
              file=sys.stderr)
    return 4 if args.strict and report.unexercised() else 0


def _coverage(report) -> None:
    """Per property still standing: runs and agent-ticks that exercised it, how often a
    premise (trigger) held; the largest swarm and longest run; what no run reached."""
    cov = report.coverage
    runs = cov.runs
    print(f"  tried: largest swarm {cov.largest} agent{'s' * (cov.largest != 1)}, "
          f"longest run {cov.longest} tick{'s' * (cov.longest != 1)}")
    failed = {ce.violations[0].name for ce in report.counterexamples if ce.violations}
    for name in report.properties:
        if name in failed:
            continue
        info, c = report.infos[name], cov.of(name)
        unit = "ticks" if info.kind is None else "agent-ticks"
        line = (f"  {info.keyword} `{name}`: exercised by {c.runs} of {runs} "
                f"run{'s' * (runs != 1)}, checked at {c.agent_ticks:,} {unit}")
        if info.keyword == "always":
            line += f"; its trigger held at {c.premise_ticks:,} {unit} in " \
                f"{c.premise_runs} run{'s' * (c.premise_runs != 1)}"
        elif c.premise_measured:
            premise = _premise_text(report, name)
            line += f"; its premise {premise} held at {c.premise_ticks:,} {unit} in " \
                f"{c.premise_runs} run{'s' * (c.premise_runs != 1)}"
        print(line)
    sys.stdout.flush()      # the warnings (stderr) after the report, on a terminal too
    if len(failed) < len(report.properties):    # what a pass rests on
        for text in cov.warnings(report.steps, report.horizon):
            print(f"warning: {text}", file=sys.stderr)


def _premise_text(report, name: str) -> str:
    from swarmdsl.testing.premises import compile_premise

    info = report.infos[name]
    premise = compile_premise(report.program, info) if report.program is not None else None
    return premise.text if premise is not None else "(its `if` or `not` part)"


def _horizon(report) -> str:
    """Which horizon the hunt ran, and why: a pass is only as good as its runs' length."""
    line = f"  horizon: up to {report.steps} ticks per run ({report.horizon})"
    if report.as_written_steps and report.as_written_steps != report.steps:
        line = f"  horizon: up to {report.steps} ticks per drawn run ({report.horizon}); " \
            f"the program as written ran {report.as_written_steps}, as `swarmdsl run` does"
    return line


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
