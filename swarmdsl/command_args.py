"""Command-line arguments every subcommand reads the same way: the param overrides
`--set NAME=VALUE` of each command that compiles a program (`run`, `check`, `graph`,
`test`, `sweep`), and file or folder options. Below every command module (the
subcommands `cli.py` loads import these, not `cli.py`)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from swarmdsl.errors import SwarmOptionError


def parse_sets(items: list[str]) -> dict[str, str]:
    """`--set NAME=VALUE` options by name. A name given twice is refused: the last one
    winning silently hides a typo in a long command (`--set n=5 ... --set n=50`)."""
    out: dict[str, str] = {}
    for item in items:
        name, eq, value = item.partition("=")
        if not eq or not name.strip() or not value.strip():
            raise SwarmOptionError(f"--set {item}: expected NAME=VALUE, e.g. --set n=200")
        name = name.strip()
        if name in out:
            raise SwarmOptionError(f"--set {name} is given twice ({name}={out[name]}, "
                                   f"{name}={value.strip()}); give it once")
        out[name] = value.strip()
    return out


def path_arg(option: str, what: str, *, text: bool = False) -> Callable[[str], Path | str]:
    """An argparse `type` for a file or folder option: an empty path is refused while
    the command line is read, naming the option (exit 2). `Path("")` is `Path(".")`, so
    `--out ""` (an unset shell variable, as a rule) would otherwise write a run into the
    current folder, and `--record ""` was refused as `--record .`. `text` keeps the
    argument a string, for commands that print it back as given."""
    def convert(value: str) -> Path | str:
        if not value.strip():
            blank = "empty" if not value else "only spaces"
            raise SwarmOptionError(f'{option} "{value}": the path is {blank}; give {what}')
        if "\0" in value:    # only from `main([...])`: a command line cannot hold one
            raise SwarmOptionError(f"{option}: the path contains a NUL character")
        return value if text else Path(value)
    return convert
