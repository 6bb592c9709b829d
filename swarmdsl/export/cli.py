"""`swarmdsl export TARGET FILE -o DIR`: a checked program written for another platform
(today `kilobot`: C for kilolib, run in Kilombo or flashed to a robot)."""

from __future__ import annotations

from swarmdsl.command_args import parse_sets, path_arg

_PROGRAM = "a .swarm program file"


def register(sub) -> None:
    p = sub.add_parser("export", help="write a program for another platform (kilobot: C)",
                       description="Translate a checked program for a target platform. "
                       "What the target cannot run is refused, located (exit 2).")
    targets = p.add_subparsers(dest="target", metavar="TARGET", required=True)
    k = targets.add_parser("kilobot", help="C for the Kilobot's library (kilolib)",
                           description="Write DIR/NAME.c (kilolib), kilolib_api.h, a "
                           "Makefile (Kilombo headless, the AVR .hex, avr-size) and "
                           "Kilombo's kilombo.json and bots.json.")
    k.add_argument("file", type=path_arg("file", _PROGRAM, text=True),
                   help="the .swarm program (agent kinds on kilobot robots)")
    k.add_argument("-o", "--output", required=True, metavar="DIR",
                   type=path_arg("-o", "a folder name, e.g. out_c"),
                   help="the folder to write (created when missing; files in it replaced)")
    k.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override a param; repeatable")
    k.add_argument("--seed", type=int, default=0,
                   help="the seed whose placement Kilombo's bots.json holds (default 0)")
    k.set_defaults(func=_cmd_kilobot)


def _cmd_kilobot(args) -> int:
    import sys

    from swarmdsl.compiler import compile_file
    from swarmdsl.compiler.lowering import REFERENCE
    from swarmdsl.errors import SwarmOptionError
    from swarmdsl.export.kilobot import translate
    from swarmdsl.runtime.outputs import check_folder, make_folder, replace_with

    if not 0 <= args.seed < 2**32:
        raise SwarmOptionError(f"--seed {args.seed}: give a whole number from 0 to 2^32 - 1")
    check_folder(args.output, "-o")
    program = compile_file(args.file, parse_sets(args.set), lowering=REFERENCE)   # not run
    for w in program.info.warnings:
        print(w.with_source(program.source).render(), file=sys.stderr)
    warnings: list = []
    files = translate(program, args.seed, warnings)
    for w in warnings:
        print(w.render(), file=sys.stderr)
    folder = make_folder(args.output, "-o")
    for name, text in files.items():
        replace_with(folder / name, lambda tmp, text=text: tmp.write_text(text))
    print(f"wrote {', '.join(sorted(files))} to {folder}")
    return 0
