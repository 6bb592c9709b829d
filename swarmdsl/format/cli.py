"""`swarmdsl fmt FILE... [--check]`: lay programs out the one way (`format/__init__`).

Each file is rewritten in place when its layout changes; `--check` changes nothing and
exits 1 naming the files that would change (for CI); `-` reads standard input and
writes the result to standard output (for editors' format commands). A file that does
not parse is refused, located, exit 2, and left as it was.
"""

from __future__ import annotations

import sys

from swarmdsl.command_args import path_arg


def register(sub) -> None:
    p = sub.add_parser("fmt", help="format programs (in place; --check only reports)",
                       description="Lay out .swarm programs one way: indentation, spaces "
                       "around operators, blank lines. Lines, comments and meaning are "
                       "kept (the syntax tree before and after is checked to be the same).")
    p.add_argument("files", nargs="+", metavar="FILE",
                   type=path_arg("FILE", "a .swarm program file, or - for standard input",
                                 text=True),
                   help="the .swarm programs; - reads standard input and writes the "
                   "result to standard output")
    p.add_argument("--check", action="store_true",
                   help="change nothing; exit 1 and name the files formatting would change")
    p.set_defaults(func=cmd_fmt)


def cmd_fmt(args) -> int:
    from swarmdsl.errors import SwarmError
    from swarmdsl.format import format_source, moved_draws

    changed = []
    for name in args.files:
        text = _read(name)
        try:
            new = format_source(text, "<stdin>" if name == "-" else name)
        except SwarmError as err:
            raise err.with_source(text) from None
        if name == "-":
            if not args.check:
                sys.stdout.write(new)
            elif new != text:
                changed.append(name)
            continue
        if new == text:
            continue
        changed.append(name)
        _say_moved(name, moved_draws(text, new))
        if not args.check:
            _write(name, new)
            print(f"reformatted {name}", file=sys.stderr)
    if args.check:
        for name in changed:
            print(f"would reformat {name}", file=sys.stderr)
        return 1 if changed else 0
    return 0


def _say_moved(name: str, moved: list) -> None:
    """Name the random draws whose stream formatting moved: none unless the formatter
    broke the structure it checks it keeps (streams are keyed by a draw's place)."""
    if not moved:
        return
    shown = ", ".join(f"`{n}` {a[0]}:{a[1]} -> {b[0]}:{b[1]}" for n, a, b in moved[:5])
    more = f" and {len(moved) - 5} more" if len(moved) > 5 else ""
    print(f"note: {name}: formatting moves {len(moved)} random draw"
          f"{'s' * (len(moved) != 1)} ({shown}{more}) to another place in the program, "
          "so runs of the formatted program draw other numbers there (same seed, other "
          "bits)", file=sys.stderr)


def _read(name: str) -> str:
    from pathlib import Path

    from swarmdsl.compiler import _not_utf8
    from swarmdsl.errors import SwarmOptionError
    from swarmdsl.files import MAX_PROGRAM_BYTES, ContainmentError, read_regular

    if name == "-":
        data = sys.stdin.buffer.read(MAX_PROGRAM_BYTES + 1)
        if len(data) > MAX_PROGRAM_BYTES:
            raise SwarmOptionError(f"standard input holds more than {MAX_PROGRAM_BYTES} "
                                   "bytes, the most a program may have")
    else:
        path = Path(name)
        if path.is_dir():
            raise SwarmOptionError(f"{name} is a folder, not a .swarm file")
        try:
            data = read_regular(path, "program file", MAX_PROGRAM_BYTES, name)
        except ContainmentError as exc:
            raise SwarmOptionError(exc.message) from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise _not_utf8(name, data, exc) from None


def _write(name: str, text: str) -> None:
    """Replace the file's text at once (a crash mid-write leaves the old or the new)."""
    import os
    import tempfile
    from pathlib import Path

    path = Path(name)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as f:
            f.write(text)
        os.chmod(tmp, path.stat().st_mode & 0o7777)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
