"""Go to definition, find references and rename, over the index of a checked text.

A rename edits every occurrence of the symbol and of the symbols linked to it (the
variable `energy` of two kinds that `other.energy` reads), and is refused, with the
reason, when the new name is not a name, is a keyword or a built-in, is already taken
where the symbol is visible, or when the renamed text would not check as well as the
text did (the checker's own verdict on the result, so no clash it knows of slips by).
"""

from __future__ import annotations

import re

from swarmdsl.lsp.analysis import Analysis, Range, analyse
from swarmdsl.lsp.index import CATEGORY_WORDS, Occurrence, Symbol


class RenameRefused(Exception):
    """Why a rename is refused; its message is shown to the user."""


def definition(analysis: Analysis, line: int, col: int) -> list[Symbol]:
    index = analysis.index
    occ = index.at(line, col) if index is not None else None
    if occ is None:
        return []
    return [index.symbols[k] for k in occ.keys if k in index.symbols]


def references(analysis: Analysis, line: int, col: int,
               include_declaration: bool = True) -> list[Range]:
    index = analysis.index
    occ = index.at(line, col) if index is not None else None
    if occ is None:
        return []
    keys = set(occ.keys)
    return [o.range for o in index.occurrences
            if keys & set(o.keys) and (include_declaration or not o.is_def)]


_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def _reserved() -> set[str]:
    """Words that cannot name a declaration: the grammar's keywords, the checker's,
    and every built-in name agent code reads."""
    from swarmdsl.compiler.actions import ACTIONS
    from swarmdsl.compiler.builtins import AGGREGATES, FUNCTIONS
    from swarmdsl.compiler.checker import KEYWORDS
    from swarmdsl.compiler.info import BUILTIN_NAMES
    from swarmdsl.compiler.parse import keywords

    return (set(keywords()) | set(KEYWORDS) | set(BUILTIN_NAMES) | set(FUNCTIONS) | set(AGGREGATES)
            | set(ACTIONS) | {"neighbors", "neighbours"})


def prepare_rename(analysis: Analysis, line: int, col: int) -> Occurrence:
    """The occurrence a rename at (line, col) would start from, or RenameRefused."""
    index = analysis.index
    occ = index.at(line, col) if index is not None else None
    if occ is None:
        raise RenameRefused("there is no name here to rename")
    if occ.key[0] == "builtin":
        raise RenameRefused(f"`{occ.key[2]}` is built into the language and cannot be "
                            "renamed")
    return occ


def rename(analysis: Analysis, line: int, col: int, new: str) -> list[tuple[Range, str]]:
    """The edits renaming the symbol at (line, col) to `new`, or RenameRefused."""
    occ = prepare_rename(analysis, line, col)
    index = analysis.index
    old = index.symbols[occ.key].name if occ.key in index.symbols else None
    if old is None:
        raise RenameRefused("this name is declared nowhere in the file")
    if new == old:
        return []
    if not _NAME.match(new):
        raise RenameRefused(f"`{new}` is not a name: a letter or `_`, then letters, "
                            "digits or `_`")
    if new in _reserved():
        raise RenameRefused(f"`{new}` is a keyword or a built-in name of the language")
    keys = index.linked(occ.key)
    for key in keys:
        clash = _clash(index, key, new, keys)
        if clash is not None:
            where = f" of {clash.container}" if clash.container else ""
            what = CATEGORY_WORDS.get(clash.category, clash.category)
            raise RenameRefused(f"`{new}` is already the {what} `{new}`{where} "
                                f"(line {clash.range.line + 1})")
    lines = analysis.text.splitlines(keepends=True)
    edits = []
    for o in index.occurrences:
        if keys & set(o.keys):
            r = o.range
            if r.line < len(lines) and lines[r.line][r.col:r.end_col] == old:
                edits.append((r, new))
    _verify(analysis, edits)
    return edits


def _scope(key: tuple) -> tuple:
    """Where a symbol's name is visible: the program (top level), a kind, a status, a
    tree. Two symbols clash when one's scope holds the other's."""
    cat = key[0]
    if cat in ("var", "status", "slot", "objective"):
        return ("kind", key[1])
    if cat == "local":
        return ("status", key[1], key[2])
    if cat == "tree_param":
        return ("tree", key[1])
    if cat in ("metric", "property") and len(key) == 3:
        return ("kind", key[1])
    return ("program",)


def _visible_together(a: tuple, b: tuple) -> bool:
    """Whether names in scopes `a` and `b` can meet: a top-level name is seen
    everywhere; a kind's names inside its statuses; otherwise only the same scope."""
    if ("program",) in (a, b):
        return True
    if {a[0], b[0]} == {"kind", "status"}:
        return a[1] == b[1]
    return a == b


def _clash(index, key: tuple, new: str, renamed: set) -> Symbol | None:
    scope = _scope(key)
    for other_key, sym in index.symbols.items():
        if sym.name != new or other_key in renamed:
            continue
        if _visible_together(scope, _scope(other_key)):
            return sym
    return None


def _verify(analysis: Analysis, edits: list[tuple[Range, str]]) -> None:
    """Refuse edits after which the checker finds an error the text did not have."""
    text = apply_edits(analysis.text, edits)
    after = analyse(text, analysis.filename)
    before_errors = {d.message for d in analysis.diagnostics if d.severity == "error"}
    new_errors = [d for d in after.diagnostics if d.severity == "error"]
    if len(new_errors) > len(before_errors):
        fresh = next((d for d in new_errors if d.message not in before_errors), new_errors[0])
        raise RenameRefused(f"the renamed program would not check: line "
                            f"{fresh.range.line + 1}: {fresh.message}")


def apply_edits(text: str, edits: list[tuple[Range, str]]) -> str:
    """`text` with each single-line range replaced (ranges must not overlap)."""
    lines = text.splitlines(keepends=True)
    for r, new in sorted(edits, key=lambda e: (e[0].line, e[0].col), reverse=True):
        s = lines[r.line]
        lines[r.line] = s[:r.col] + new + s[r.end_col:]
    return "".join(lines)
