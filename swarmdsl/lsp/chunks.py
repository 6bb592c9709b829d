"""Parsing as the text changes: only the top-level declarations that changed.

Parsing is half of an analysis (lark builds a parse tree token by token), and an edit
usually touches one declaration. The text is cut at the lines where a top-level
declaration starts (outside every `{ }` and `( )`; a newline there always ends the
declaration before it), each piece is parsed alone, placed at its own lines by
leading line breaks (so every span is the one the whole parse gives), and kept for
the next analysis while its text and first line stay the same.

An agent kind is cut the same way, one level down: its header and closing `}` are
parsed as an empty kind, each of its items (option, variable, status...) inside a
stand-in kind written on the line before it, and the kind put together from them, so
an edit in one status of a 500-line kind parses that status again, not the kind.

The result is the whole parse's: the same declarations with the same spans, and a
`Program` spanning what the whole parse's does (tests/test_lsp_chunks.py compares
them on every shipped and documented program and on fuzzed text). Whenever a piece
does not parse, the whole text is parsed instead, so a syntax error is the one
`swarmdsl check` reports, word for word.
"""

from __future__ import annotations

import dataclasses
import re

from swarmdsl.compiler import ast
from swarmdsl.errors import Span, SwarmError, lone_cr_as_newline

_TOKENS = re.compile(r'#[^\n]*|"[^"\n]*"?|[{}()\n]')
_LEADING = re.compile(r"[ \t\f\r]*(?:#[^\n]*)?")


def pieces(text: str) -> list[tuple[int, str]] | None:
    """(first line, 0-based; text) of each run of lines that starts a top-level
    declaration, or None when the brackets do not balance (the whole parse says why)."""
    depth = 0
    cuts = [0]
    line_start = 0
    line = 0
    for m in _TOKENS.finditer(text):
        c = m.group()
        if c in "{(":
            depth += 1
        elif c in "})":
            depth -= 1
            if depth < 0:
                return None
        elif c == "\n":
            line += 1
            line_start = m.end()
            if depth == 0 and line_start < len(text) and not text[line_start].isspace() \
                    and text[line_start] not in "#}":
                cuts.append(line_start)
    if depth != 0:
        return None
    out = []
    for a, b in zip(cuts, [*cuts[1:], len(text)], strict=True):
        out.append((text.count("\n", 0, a), text[a:b]))
    return out


class ChunkParser:
    """`parse(text, filename)` with the pieces of the last text kept."""

    def __init__(self):
        self.kept: dict[tuple, tuple] = {}

    def parse(self, text: str, filename: str) -> ast.Program:
        from swarmdsl.compiler.parse import parse

        norm = lone_cr_as_newline(text.removeprefix("\ufeff"))
        if not norm.endswith("\n"):
            norm += "\n"
        cut = pieces(norm)
        if cut is None:
            return parse(text, filename)
        kept: dict[tuple, tuple] = {}
        decls: list = []

        def parsed(key: tuple, source) -> tuple:
            found = self.kept.get(key)
            if found is None:
                found = source()
            kept[key] = found
            return found

        try:
            for first, piece in cut:
                decls.extend(parsed((filename, first, piece),
                                    lambda f=first, p=piece: self._piece(f, p, filename,
                                                                         parsed)))
        except (SwarmError, ValueError, IndexError):
            # the pieces that did parse are kept for the edit that mends this one
            self.kept = {**self.kept, **kept} if len(self.kept) < 4 * len(cut) + 64 \
                else kept
            return parse(text, filename)   # the whole text's error, as check gives it
        # a kind's items stay known while the kind comes whole from its own entry
        parts = {k: v for k, v in self.kept.items() if k[1] in ("shell", "item")}
        self.kept = {**parts, **kept} if len(parts) < 4 * len(cut) + 256 else kept
        if not decls:
            return parse(text, filename)
        return ast.Program(_program_span(norm, filename), tuple(decls))

    @staticmethod
    def _piece(first: int, piece: str, filename: str, parsed) -> tuple:
        """The declarations of one piece; an agent kind from its shell and items."""
        from swarmdsl.compiler.parse import parse

        parts = _agent_parts(first, piece)
        if parts is None:
            return parse("\n" * first + piece, filename).decls
        shell, items = parts
        (kind,) = parsed((filename, "shell", shell), lambda: parse(shell, filename).decls)
        body = []
        for line, item in items:
            body.extend(parsed((filename, "item", line, item), lambda n=line, i=item:
                               parse("\n" * (n - 1) + "agent _ {\n" + i + "}\n",
                                     filename).decls[0].items))
        return (dataclasses.replace(kind, items=tuple(body)),)


def _agent_parts(first: int, piece: str) -> tuple[str, list] | None:
    """An agent kind's piece as (its shell: the text with every line between the
    header and the closing `}` blanked, placed at its lines; its items: (first line,
    text) each), or None when the piece is not a kind laid out one item per line."""
    lines = piece.splitlines(keepends=True)
    if not lines or not re.match(r"[ \t]*agent\b", lines[0]):
        return None
    depth = 0
    starts_at: list[int] = []        # the depth at the start of each line
    for line in lines:
        starts_at.append(depth)
        for m in _TOKENS.finditer(line):
            c = m.group()
            depth += {"{": 1, "(": 1, "}": -1, ")": -1}.get(c, 0)
    if len(lines) < 3 or starts_at[1] != 1:
        return None
    close = next((i for i in range(1, len(lines)) if starts_at[i] == 1
                  and i + 1 < len(starts_at) and starts_at[i + 1] == 0), None)
    if close is None and starts_at[-1] == 1:
        close = len(lines) - 1
    if close is None or close < 2 or not re.fullmatch(r"[ \t]*\}[ \t]*(#[^\n]*)?\n?",
                                                      lines[close]):
        return None
    if _LEADING_ITEM.match(lines[0]) is None:
        return None
    shell = "\n" * first + lines[0] + "\n" * (close - 1) + "".join(lines[close:])
    items: list[tuple[int, str]] = []
    for i in range(1, close):
        text = lines[i]
        starts_item = starts_at[i] == 1 and text.strip() and text.lstrip()[0] not in "#}"
        if starts_item or not items:
            items.append((first + i, text))
        else:
            items[-1] = (items[-1][0], items[-1][1] + text)
    return shell, items


# `agent NAME {` alone on its line (a comment after it aside): its items are below it
_LEADING_ITEM = re.compile(r"[ \t]*agent[ \t]+[A-Za-z_][A-Za-z0-9_]*[ \t]*\{[ \t]*"
                           r"(#[^\n]*)?\n")


def _program_span(norm: str, filename: str) -> Span:
    """What the whole parse's `Program` spans: from its first token (the first line's
    first character that is neither a blank nor in a comment) to the end of the text,
    which its last separator reaches."""
    start = _LEADING.match(norm).end()
    end_line = norm.count("\n") + 1
    return Span(filename, 1, start + 1, end_line, 1)
