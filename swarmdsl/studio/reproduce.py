"""The studio's Reproduce line: the `swarmdsl run FILE --set ...` command that makes the
run on screen, or, when the text running differs from the file on disk in a way `--set`
cannot express, the sentence saying to save first.

A command is given only when it is exact. The text running may differ from the file in
the values of its `param` declarations and nothing else: the file compiled with the
`--set` values must then give every param the very value the run uses (the same type,
the same bits), and every other declaration must be the same, down to where it stands
in the text (a message at run time names a line and column). Anything else (a changed
rule, a comment added, a param renamed or moved) is not a `--set`, so the line says to
save first rather than give a command that makes another run.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Reproduce:
    """What the Reproduce line shows: `line` is a command when `exact`, else the reason
    there is none."""

    line: str
    exact: bool


def reproduce(path: Path, disk_text: str | None, text: str, params: dict,
              overrides: dict[str, str], seed: int) -> Reproduce:
    """The line for a run of `text` compiled with `overrides` (its params' values
    `params`) and `seed`, the program's file at `path` holding `disk_text` (None: it
    cannot be read)."""
    from swarmdsl.studio.params import set_line

    name = Path(path).name
    if disk_text is None:
        return Reproduce(f"save first: {name} cannot be read, so no command makes this "
                         "run", False)
    sets = file_overrides(path, disk_text, text, params, overrides)
    if sets is None:
        return Reproduce(f"save first (Ctrl-S): the text running differs from {name} "
                         "in more than param values, which --set cannot express", False)
    return Reproduce(set_line(str(path), sets, seed), True)


def file_overrides(path: Path, disk_text: str, text: str, params: dict,
                   overrides: dict[str, str]) -> dict[str, str] | None:
    """The `--set` values that make the file's text `disk_text` the program `text`
    compiled with `overrides` (whose params are `params`), or None when no `--set` can."""
    if disk_text == text:
        return dict(overrides)
    from swarmdsl.compiler.parse import parse
    from swarmdsl.errors import SwarmError

    try:
        disk, shown = parse(disk_text, str(path)), parse(text, str(path))
    except SwarmError:
        return None
    changed = _changed_params(disk.decls, shown.decls)
    if changed is None:
        return None
    from swarmdsl.runtime.arguments import param_text

    sets = dict(overrides)
    for name in changed:
        if name not in sets:
            sets[name] = param_text(params[name])
    return sets if _same_params(path, disk_text, sets, params) else None


def _changed_params(disk, shown) -> list[str] | None:
    """The params whose value expression differs between two programs' declarations, or
    None when they differ otherwise. Declarations other than params must be equal with
    their spans; a param only in its name and range (spans aside: a longer value shifts
    them)."""
    from swarmdsl.compiler.ast import ParamDecl, shape

    if len(disk) != len(shown):
        return None
    changed = []
    for a, b in zip(disk, shown, strict=True):
        if isinstance(a, ParamDecl) and isinstance(b, ParamDecl):
            if (a.name, shape(a.lo), shape(a.hi)) != (b.name, shape(b.lo), shape(b.hi)):
                return None
            if shape(a.value) != shape(b.value):
                changed.append(a.name)
        elif a != b:
            return None
    return changed


def _same_params(path: Path, disk_text: str, sets: dict[str, str], params: dict) -> bool:
    """The file compiled with `sets` gives every param the value (type and bits) of
    `params`: the proof that the command is the run."""
    from swarmdsl.compiler import compile_source
    from swarmdsl.compiler.lowering import REFERENCE
    from swarmdsl.errors import SwarmError

    try:
        got = compile_source(disk_text, str(path), sets, Path(path).resolve().parent,
                             lowering=REFERENCE).params
    except SwarmError:
        return False
    return got.keys() == params.keys() and all(
        type(got[k]) is type(params[k]) and repr(got[k]) == repr(params[k]) for k in got)
