"""The `swarmdsl` command: run, check, and the commands extensions register.

A SwarmError (a bad program, option or run) is shown as a located message (exit 2).
Any other exception is a bug in swarmdsl (`swarmdsl.internal`): one line `error:
internal error: TYPE: MESSAGE (please report this; ...)`, exit 3, no traceback unless
SWARMDSL_DEBUG=1; during a run's ticks `Run` records it as a fault (`internal error at
tick N: ...`) and keeps the outputs. KeyboardInterrupt and SystemExit (argparse's exit
2 for a bad option) pass untouched.
"""

from __future__ import annotations

import sys

from swarmdsl import stopping


def _is_the_command() -> bool:
    """True in the `swarmdsl` process itself (console script or `python -m swarmdsl`)."""
    from pathlib import Path

    mp = sys.modules.get("multiprocessing")
    if mp is not None and mp.parent_process() is not None:
        return False            # a sweep's worker process re-importing the main module
    argv0 = Path(sys.argv[0]) if sys.argv and sys.argv[0] else Path()
    return argv0.name == "swarmdsl" or (argv0.name == "__main__.py"
                                         and argv0.parent.name == "swarmdsl")


_COMMAND = _is_the_command()
if _COMMAND:            # a Ctrl-C while the command still imports is noted, not a traceback
    stopping.hold()
    # numpy, imported after this, asks the system to back each array of 4 MB or more
    # with 2 MB pages. Where the system grants them only when asked (Linux's usual
    # `madvise` setting), a big run's fresh arrays then wait while it compacts memory
    # to find and zero such pages: Vicsek at 10^6 agents, 20 ticks, load 4.6, took
    # 15.2-19.5 s asking (system CPU 1.9-2.1 s) against 13.1-13.8 s not (0.4-0.6 s).
    # The command's own processes (a sweep's workers, the tiered start's compile)
    # inherit this; a user's own setting is kept.
    import os

    os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")

import argparse  # noqa: E402
import importlib  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402

from swarmdsl import internal  # noqa: E402
from swarmdsl.command_args import parse_sets, path_arg  # noqa: E402
from swarmdsl.errors import SwarmError, SwarmOptionError  # noqa: E402
from swarmdsl.runtime.backends import environment_backend, names  # noqa: E402
from swarmdsl.version import __version__  # noqa: E402

# Modules that add subcommands with `register(subparsers)`; missing ones are skipped.
_COMMAND_MODULES = ("swarmdsl.train.cli", "swarmdsl.testing.cli", "swarmdsl.analysis.cli",
                    "swarmdsl.sweep.cli", "swarmdsl.plot.cli", "swarmdsl.studio.cli",
                    "swarmdsl.export.cli", "swarmdsl.lsp.cli", "swarmdsl.format.cli")
_OWN_COMMANDS = ("run", "check")
_VIDEO_EXTENSIONS = (".gif", ".mp4")
_PROGRAM = "a .swarm program file"
_NUMPY_FP_WARNING = r"(invalid value|divide by zero|overflow|underflow) encountered"


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The whole command tree, or only `run` and `check` when `command` is one of them:
    the other commands' modules (training, sweeps, tests, plots) cost about 25 ms to
    import, a tenth of `swarmdsl check`, and have no say in those two."""
    parser = argparse.ArgumentParser(
        prog="swarmdsl",
        description="Run and check swarm-robot behaviour written in the swarm language.")
    parser.add_argument("--version", action="version", version=f"swarmdsl {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    run = sub.add_parser("run", help="run a .swarm program (live window or headless)",
                         description="Run a .swarm program. Without --headless a pygame "
                         "window opens when a display exists.")
    run.add_argument("file", type=path_arg("file", _PROGRAM, text=True),
                     help="the .swarm program")
    run.add_argument("--headless", action="store_true", help="run without a window")
    run.add_argument("--steps", type=int,
                     help="ticks to run (default: the world's `steps`, 1000 when it "
                     "sets none)")
    run.add_argument("--seed", type=int, help="random seed (default 0)")
    run.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                     help="override a param; repeatable")
    run.add_argument("--out", type=path_arg("--out", "a folder name, e.g. out"),
                     metavar="DIR",
                     help="write agents.parquet, metrics.parquet (when the program "
                     "declares a `metric`), fields.npz and run.json to DIR")
    run.add_argument("--every", type=int, metavar="K",
                     help="record every K ticks (tick 0 and the last tick always; default 1)")
    run.add_argument("--tree-leaf", action="store_true",
                     help="record each agent's active behaviour-tree leaf and its tree's "
                     "result as the columns `tree_leaf` and `tree_result` of "
                     "agents.parquet (and colour by leaf in the viewer: `t`)")
    run.add_argument("--tree-memory", action="store_true",
                     help="record every agent's behaviour-tree memory (running child, "
                     "counters, clocks) as int64 columns `tree:KIND.STATUS:...`")
    run.add_argument("--record", type=path_arg("--record", "a file name, e.g. run.mp4"),
                     metavar="FILE.gif|FILE.mp4",
                     help="also render frames to a GIF or MP4")
    run.add_argument("--fps", type=int, default=30,
                     help="frames per second of the window and of the --record video "
                     "(one frame per recorded tick, see --every; default 30)")
    run.add_argument("--check", action="store_true",
                     help="check the program's invariant, eventually and always properties "
                     "every tick; "
                     "stop at the first violation (exit 1)")
    run.add_argument("--property", action="append", dest="properties", metavar="NAME",
                     help="check only this property (implies --check); repeatable")
    run.add_argument("--example", type=path_arg("--example", "a saved example's file"),
                     metavar="FILE.json",
                     help="replay an example saved by `swarmdsl test --save-example`: its "
                     "params, seed, ticks and initial swarm, with checks on")
    run.add_argument("--checkpoint-every", type=int, metavar="K",
                     help="save a checkpoint in OUT/checkpoint every K ticks and at the end "
                     "(default 0: none)")
    run.add_argument("--resume", type=path_arg("--resume", "the --out folder of the run"),
                     metavar="DIR",
                     help="continue the run whose --out was DIR from its checkpoint; its "
                     "outputs continue the same files (give --steps to run longer). It "
                     "keeps the checkpoint's seed, --steps, --every, --checkpoint-every, "
                     "--backend, tree columns and checks unless given, needs the same "
                     "--set values, and refuses options that would not continue that run")
    run.add_argument("--backend", choices=names(), default=None,
                     help="numba (compiled kernels) or numpy (the reference), for the "
                     "whole run. Default: $SWARMDSL_BACKEND, else, when numba is "
                     "installed, numba for a run whose kernels are on disk and long "
                     "enough to repay loading them, and for a first run long enough to "
                     "matter a tiered start: numpy at once while another process "
                     "compiles the kernels, numba from the tick they are ready (one line "
                     "says which and why; -v says when it changed)")
    run.add_argument("-v", "--verbose", action="store_true",
                     help="say which backend ran, what it compiled and how long that took")
    run.set_defaults(func=cmd_run)

    check = sub.add_parser("check", help="check a program and print its diagnostics",
                           description="Parse and check a .swarm program; print errors and "
                           "warnings. Exit 0 when it compiles, 2 when it does not.")
    check.add_argument("file", type=path_arg("file", _PROGRAM, text=True),
                       help="the .swarm program")
    check.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                       help="override a param; repeatable")
    check.add_argument("--target", choices=("kilobot",),
                       help="also refuse, located, what the target platform cannot run "
                       "(as `swarmdsl export TARGET` would)")
    check.set_defaults(func=cmd_check)

    if command in _OWN_COMMANDS:
        return parser
    for module in _COMMAND_MODULES:
        try:
            mod = importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name and module.startswith(exc.name):
                continue
            raise
        mod.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run one command; SIGINT, SIGTERM and SIGHUP stop it cleanly (exit 128 + signal).

    A SwarmError is printed located (exit 2, or its own `exit_code`); any other
    exception is a bug in swarmdsl, printed as one line (exit 3) unless SWARMDSL_DEBUG=1
    asks for it to be raised with its traceback.
    """
    return reported(lambda: _main(argv))


def reported(command: Callable[[], int]) -> int:
    """Run `command` as the `swarmdsl` command runs its subcommands, for the tools run
    with `python -m` too (`swarmdsl.analysis.picture`): a user of either should see the
    same one-line `error:` (exit 2) for a bad input, and a bug reported the same way."""
    old: dict = {}
    try:
        old = stopping.install()
        try:
            return command()
        except ImportError as exc:
            # A stop that lands while a C extension imports surfaces as its ImportError.
            raise stopping.cause(exc) or exc from None
    except KeyboardInterrupt as stop:
        name = stop.name if isinstance(stop, stopping.Stopped) else "SIGINT"
        print(f"swarmdsl: stopped by {name}", file=sys.stderr)
        return stop.exit_code if isinstance(stop, stopping.Stopped) else 130
    except SwarmError as err:
        internal.raise_when_debugging(err)
        print(err.render(), file=sys.stderr)
        return getattr(err, "exit_code", 2)
    except Exception as exc:    # a bug in swarmdsl; SystemExit (argparse) is not caught
        if isinstance(exc, BrokenPipeError) and _reader_gone():
            return _EXIT_SIGPIPE
        if internal.debugging():
            raise
        print(internal.internal_error(exc), file=sys.stderr)
        return internal.EXIT_CODE
    finally:
        if _COMMAND:
            stopping.ignore()
        else:
            stopping.restore(old)


_EXIT_SIGPIPE = 141     # 128 + SIGPIPE, as a shell reports `yes | head`


def _reader_gone() -> bool:
    """Whether standard output is a pipe whose reader has gone (`swarmdsl graph F | head`),
    so that a BrokenPipeError is the reader's doing, not a bug: the command stops
    quietly, as other tools do, instead of reporting an internal error. Standard output
    then goes to the null device, so Python's last flush of it has nothing to fail on."""
    import os
    import select

    try:
        fd = sys.stdout.fileno()
        poll = select.poll()
        poll.register(fd, select.POLLOUT)
        gone = any(events & select.POLLERR for _fd, events in poll.poll(0))
    except (AttributeError, OSError, ValueError):  # no poll (Windows), no real stdout
        return False
    if gone:
        os.dup2(os.open(os.devnull, os.O_WRONLY), fd)
    return gone


def _main(argv: list[str] | None) -> int:
    with stopping.uncut():   # a stop while the commands import is raised once they have
        parser = build_parser(_command_word(sys.argv[1:] if argv is None else argv))
    args = parse_command_line(parser, argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    # numpy's floating-point warnings name files inside swarmdsl and numpy; the values
    # they warn about are caught as located errors (NaN guards, finite checks) instead.
    warnings.filterwarnings("ignore", _NUMPY_FP_WARNING, RuntimeWarning)
    return int(args.func(args) or 0)


def parse_command_line(parser: argparse.ArgumentParser, argv: list[str] | None):
    """`parser.parse_args`, except that words no option takes are reported by the
    subcommand they were given to: its usage, and the option meant when one is close
    (`swarmdsl run F --stpes 3`: `did you mean --steps?`), exit 2. argparse itself
    passes them up to the top-level parser, which prints the top-level usage."""
    args, extra = parser.parse_known_args(argv)
    if extra:
        command = _innermost(parser, args)
        message = f"unrecognized arguments: {' '.join(extra)}"
        hint = _closest_option(command, extra)
        command.error(f"{message} (did you mean {hint}?)" if hint else message)
    return args


def _innermost(parser: argparse.ArgumentParser, args) -> argparse.ArgumentParser:
    """The (sub)command parser the command line reached (`swarmdsl plot time ...`)."""
    while True:
        action = next((a for a in parser._actions
                       if isinstance(a, argparse._SubParsersAction)), None)
        name = getattr(args, action.dest, None) if action is not None else None
        if name not in getattr(action, "choices", {}):
            return parser
        parser = action.choices[name]


def _closest_option(parser: argparse.ArgumentParser, words: list[str]) -> str | None:
    """The option of `parser` closest to the first unknown word that looks like one."""
    from swarmdsl.errors import close_match

    options = [o for o in parser._option_string_actions if o.startswith("--")]
    for word in words:
        if word.startswith("-") and len(word) > 1:
            close = close_match(word.partition("=")[0], options)
            if close:
                return close
    return None


def _command_word(argv: list[str]) -> str | None:
    """The subcommand `argv` names: its first word, when no option comes before it (the
    top-level options, `--help` and `--version`, need the whole tree)."""
    return argv[0] if argv and not argv[0].startswith("-") else None


def _compile(args, lowering=None):
    from swarmdsl.compiler import compile_file

    program = compile_file(args.file, parse_sets(args.set), lowering=lowering)
    for w in program.info.warnings:
        print(w.with_source(program.source).render(), file=sys.stderr)
    return program


def cmd_check(args) -> int:
    from swarmdsl.compiler.lowering import REFERENCE

    program = _compile(args, REFERENCE)   # never run: no backend's paths to plan
    if args.target:
        from swarmdsl.export import check_target

        check_target(args.target, program)
    for note in program.info.extra.get("notes", []):
        print(note.with_source(program.source).render(), file=sys.stderr)
    kinds = program.info.kinds
    statuses = sum(len(k.statuses) for k in kinds)
    print(f"{args.file}: ok ({len(kinds)} agent kind{'s' * (len(kinds) != 1)}, "
          f"{statuses} status{'es' * (statuses != 1)}, "
          f"{len(program.info.warnings)} warning{'s' * (len(program.info.warnings) != 1)})")
    return 0


def check_run_ranges(seed: int | None, steps: int | None, every: int | None) -> None:
    """`--seed`, `--steps` and `--every` within what `Run` accepts, refused naming the
    option: `Run`'s own check names its Python argument (`seed must be ...`), which a
    user of the command never typed (and a sweep would only record it as failed runs)."""
    from swarmdsl.limits import upper

    for option, value, lo, hi in (("--seed", seed, 0, 2**63 - 1),
                                  ("--steps", steps, 0, upper("steps")),
                                  ("--every", every, 1, 2**62)):
        if value is not None and not lo <= value <= hi:
            raise SwarmOptionError(f"{option} {value}: must be from {lo:,} to {hi:,}")


def cmd_run(args) -> int:
    from swarmdsl.runtime.runner import Run

    if args.backend is None:    # given, the option wins over the variable
        environment_backend()
    if args.steps is not None and args.steps < 0:
        raise SwarmOptionError(f"--steps {args.steps}: must be 0 or more")
    if args.every is not None and args.every < 1:
        raise SwarmOptionError(f"--every {args.every}: must be 1 or more")
    check_run_ranges(args.seed, args.steps, args.every)
    if args.fps < 1:
        raise SwarmOptionError(f"--fps {args.fps}: must be 1 or more")
    if args.record is not None and args.record.suffix.lower() not in _VIDEO_EXTENSIONS:
        raise SwarmOptionError(f"--record {args.record}: the file must end in .gif or .mp4")
    replay = None
    if args.example is not None:
        from swarmdsl.testing.example import replay_example

        replay = replay_example(args.example, args.file, args.seed, parse_sets(args.set),
                                args.steps, args.properties, args.resume is not None)
        args.set = [*args.set, *(f"{k}={v}" for k, v in replay.params.items())]
        args.seed, args.steps, args.properties = replay.seed, replay.steps, replay.properties
        args.check = True
    resume = _resume_options(args)
    _check_outputs(args)
    if args.seed is None:
        args.seed = 0
    # The backend the run takes lowers the program when it starts, but one named up
    # front may as well be compiled for (numba's lowering; None: the reference's).
    from swarmdsl.runtime.backends import lowering as backend_lowering

    lowering = backend_lowering(args.backend)
    program = (_compile(args, lowering) if replay is None
               else replay.compile(lambda: _compile(args, lowering)))
    layout = None if replay is None else replay.layout(program)
    if resume is not None:
        _resume_program(args, resume, program)
    _warn_without_trees(args, program)
    if args.check or args.properties:
        from swarmdsl.testing.monitor import enable_checks

        enable_checks(program, args.properties)
        if not _checked_set(program, "all"):    # a run that looks checked, and is not
            print(f"warning: --check: {args.file} declares no `invariant`, `eventually` "
                  "or `always`; nothing is checked", file=sys.stderr)
    steps = args.steps if args.steps is not None else program.world.steps
    try:
        run = Run(program, seed=args.seed, steps=steps, out=args.out, every=args.every or 1,
                  record=args.record, layout=layout, backend=args.backend,
                  tree_leaf=args.tree_leaf, tree_memory=args.tree_memory)
    except SwarmError as err:  # placing agents runs program code: quote its line
        raise err.with_source(program.source) from None
    run.checkpoint_every = args.checkpoint_every or 0
    _say_backend(run.sim.backend.choice)
    if resume is not None:
        tick = run.resume(args.resume)
        print(f"resuming {args.resume} at tick {tick}", file=sys.stderr)
    headless = args.headless
    if not headless:
        if not _display_available():
            print("no display available: running headless", file=sys.stderr)
            headless = True
    started = time.perf_counter()
    outcome = run.execute(headless=headless, fps=args.fps)
    print(run.summary(outcome, time.perf_counter() - started))
    if args.verbose:
        print("\n".join(_checked_ticking(run, run.sim.backend.summary(program))),
              file=sys.stderr)
    if outcome == "interrupted":
        return run.stop_exit_code
    if outcome in ("fault", "violation"):
        internal.raise_when_debugging(run.fault)    # outputs closed, traceback shown
        print(run.fault.render(), file=sys.stderr)
        return getattr(run.fault, "exit_code", 2)
    if outcome == "completed":
        _warn_unexercised(run)
    if args.record is not None and not run.video_complete:
        print(SwarmOptionError(f"--record {args.record}: no video written "
                               f"({run.video_error or 'the encoder did not finish it'})"),
              file=sys.stderr)
        return 2
    return 0


def _say_backend(choice) -> None:
    """One line on the backend the default chose and why (a first numba run waits for
    its kernels to compile; a long run on numpy should know numba exists). Nothing when
    --backend or $SWARMDSL_BACKEND chose, or numba is missing and would not pay."""
    if choice is not None and choice.worth_saying:
        print(choice.line, file=sys.stderr)


def _checked_ticking(run, lines: list[str]) -> list[str]:
    """The backend's `-v` lines, and why a `--check` run checked ticks one by one in
    Python where its backend runs whole ticks (an `always`, an `eventually` still
    open): one line, as `swarmdsl test -v` says how its runs ticked."""
    from swarmdsl.testing.monitor import _CheckExtension

    whole = getattr(run.sim.backend, "whole_ticks_ready", None) is not None
    for ext in run.sim.extensions:
        if not (whole and isinstance(ext, _CheckExtension) and ext.stepped):
            continue
        at = next((k for k, line in enumerate(lines)
                   if line.startswith("whole-tick kernel")), None)
        if at is None:
            lines = [*lines, f"whole-tick kernel: no (--check: {ext.stepped})"]
        else:
            lines = [*lines[:at + 1], f"--check: ticks checked one by one while "
                     f"{ext.stepped}", *lines[at + 1:]]
    return lines


def _warn_unexercised(run) -> None:
    """A `--check` run that passed a property it never put to the test (an `always`
    whose trigger never held, an `eventually` the run ended before deciding) says so:
    a longer run may break it."""
    from swarmdsl.testing.monitor import _CheckExtension, never_exercised

    for ext in run.sim.extensions:
        if not isinstance(ext, _CheckExtension):
            continue
        for info in ext.unexercised():
            print(f"{info.decl.name_span}: warning: --check: {info.keyword} "
                  f"`{info.qualified}` was never exercised: "
                  f"{never_exercised(info, run.sim.tick, one_run=True)}; a longer run "
                  "(--steps N) may break it", file=sys.stderr)


def _warn_without_trees(args, program) -> None:
    """`--tree-leaf` and `--tree-memory` on a program without behaviour trees record a
    column of nulls, or no column: say so, rather than let it look recorded."""
    given = [flag for flag, on in (("--tree-leaf", args.tree_leaf),
                                   ("--tree-memory", args.tree_memory)) if on]
    if given and not getattr(program, "tree_index", None):
        print(f"warning: {' and '.join(given)}: {args.file} has no behaviour tree, so "
              "there is nothing to record", file=sys.stderr)


def _check_outputs(args) -> None:
    """Every output path is usable before the program is even compiled (exit 2)."""
    from swarmdsl.runtime.outputs import check_file, check_folder

    if args.out is not None:
        check_folder(args.out, "--out")
    if args.record is not None:
        check_file(args.record, "--record", example="run.mp4")


def _resume_options(args) -> dict | None:
    """Checkpoint options. A resumed run writes into the folder it resumes, and takes
    from the checkpoint what it must share with the run it continues: an option given
    again is honoured where the continuation stays that run (`--steps`, `--every`,
    `--checkpoint-every`, `--backend`) and refused where it cannot (another `--seed`,
    other tree columns), never silently dropped."""
    if args.checkpoint_every is not None and args.checkpoint_every < 0:
        raise SwarmOptionError(f"--checkpoint-every {args.checkpoint_every}: must be 0 or more")
    if args.resume is None:
        if args.checkpoint_every and args.out is None:
            raise SwarmOptionError("--checkpoint-every needs --out DIR (checkpoints go in "
                                   "DIR/checkpoint)")
        return None
    from swarmdsl.runtime.resume import read

    if args.out is not None and args.out.resolve() != args.resume.resolve():
        raise SwarmOptionError(f"--resume {args.resume} continues that folder's outputs; "
                               "leave out --out")
    meta = read(args.resume)
    args.out = args.resume
    try:
        seed, steps, tick = int(meta["seed"]), int(meta["steps"]), int(meta["tick"])
        every = int(meta.get("every", 1))
        checkpoint_every = int(meta.get("checkpoint_every", 0))
    except (KeyError, TypeError, ValueError) as exc:
        raise SwarmOptionError(f"--resume {args.resume}: the checkpoint is incomplete "
                               f"({exc!r})") from None
    # the random streams are keyed by seed and tick: ticks after the checkpoint drawn
    # with another seed would belong to no run that can be made from tick 0
    if args.seed is not None and args.seed != seed:
        raise SwarmOptionError(f"--seed {args.seed}: the checkpoint in {args.resume} is of "
                               f"a run with seed {seed}, and a resumed run keeps it; leave "
                               "out --seed")
    args.seed = seed
    if args.steps is None:
        args.steps = steps
    if args.steps < tick:
        raise SwarmOptionError(f"--steps {args.steps}: the checkpoint is at tick {tick} "
                               "already")
    if args.every is None:
        args.every = every
    if args.checkpoint_every is None:
        args.checkpoint_every = checkpoint_every
    if args.backend is None and meta.get("backend") in names():
        # not the default for the resumed length: the run goes on as it was timed
        args.backend = meta["backend"]
        from swarmdsl.runtime.backends import installed

        if not installed(args.backend):
            raise SwarmOptionError(f"--resume {args.resume}: the run used the "
                                   f"{args.backend} backend, which is not installed here; "
                                   f"install it (pip install swarmdsl[{args.backend}]) or "
                                   "give --backend numpy")
    for option in ("tree_leaf", "tree_memory"):
        if option not in meta:          # a checkpoint from before it was recorded
            continue
        flag = "--" + option.replace("_", "-")
        # agents.parquet has one set of columns: the rows before the checkpoint fix it
        if getattr(args, option) and not meta[option]:
            raise SwarmOptionError(f"{flag}: the run in {args.resume} was made without "
                                   f"it, so its agents.parquet has no columns for it; "
                                   f"leave out {flag}")
        setattr(args, option, bool(meta[option]))
    return meta


def _resume_program(args, meta: dict, program) -> None:
    """The compiled program against the checkpoint: the same text, the same params
    (named, rather than only the hash that `Run.resume` compares) and the same
    properties checked."""
    from swarmdsl.runtime.arguments import param_text
    from swarmdsl.runtime.checkpoint import program_hash

    saved = meta.get("params")
    if isinstance(saved, dict) and meta.get("program_hash") not in (
            None, program_hash(program), program_hash(program, saved)):
        # the text itself differs: no --set makes this program that run's
        raise SwarmOptionError(f"--resume {args.resume}: {args.file} is not the program "
                               f"the run was made with ({meta.get('program')}, as it was "
                               "then); resume with that file unchanged")
    if isinstance(saved, dict):
        sets = parse_sets(args.set)
        for name, value in program.params.items():
            if name not in saved or repr(saved[name]) == repr(value):
                continue
            old = param_text(saved[name])
            if name in sets:
                raise SwarmOptionError(f"--set {name}={sets[name]}: the run in "
                                       f"{args.resume} has {name}={old}; resume with the "
                                       "same params")
            raise SwarmOptionError(f"--resume {args.resume}: the run has {name}={old}, "
                                   f"this one {name}={param_text(value)}; give --set "
                                   f"{name}={old}")
    if "check" in meta:
        _resume_checks(args, meta["check"], program)


def _resume_checks(args, saved, program) -> None:
    """Take over the checkpoint's checks, or refuse others: the check state (`eventually`
    progress, pending `always` triggers) holds only the properties it checked, so checks
    that start mid-run would judge ticks they never saw."""
    given = args.properties if args.properties else ("all" if args.check else None)
    if given is not None and _checked_set(program, given) != _checked_set(program, saved):
        before = ("no properties" if saved is None else "every property" if saved == "all"
                  else ", ".join(sorted(_checked_set(program, saved))))
        option = ("--property " + ",".join(args.properties) if args.properties
                  else "--check")
        raise SwarmOptionError(f"{option}: the run in {args.resume} checked {before} "
                               "before its checkpoint; resume with the same --check and "
                               "--property, or leave them out")
    args.check = saved == "all"
    args.properties = list(saved) if isinstance(saved, list) else None


def _checked_set(program, selection) -> frozenset[str]:
    """The qualified names a --check/--property selection checks (None: none)."""
    from swarmdsl.testing.monitor import Monitor

    if selection is None:
        return frozenset()
    names = None if selection == "all" else list(selection)
    return frozenset(p.info.qualified for p in Monitor(program, names).properties)


def _display_available() -> bool:
    try:
        from swarmdsl.viz import display_available
    except ImportError:
        return False
    return display_available()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
