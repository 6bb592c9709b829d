"""Source spans, the SwarmError family and the gcc-style renderer users see.

This module imports nothing from swarmdsl so every phase (parser, checker, runtime,
CLI) can raise and render errors without import cycles.
"""

from __future__ import annotations

import difflib
import re
import unicodedata
from collections.abc import Iterable
from dataclasses import dataclass


@dataclass(frozen=True)
class Span:
    """A 1-based, end-exclusive region of a source file."""

    filename: str
    line: int
    col: int
    end_line: int
    end_col: int

    @classmethod
    def point(cls, filename: str, line: int, col: int) -> Span:
        return cls(filename, line, col, line, col + 1)

    def __str__(self) -> str:
        return f"{self.filename}:{self.line}:{self.col}"


class SwarmError(Exception):
    """A mistake in a user's program, options or run, located where possible.

    `str(err)` is the one-line `file:line:col: error: message`; `render(source)` adds the
    source line, a caret under the span and the hint.
    """

    phase = "error"

    def __init__(
        self,
        message: str,
        span: Span | None = None,
        hint: str | None = None,
        severity: str = "error",
    ):
        super().__init__(message)
        self.message = message
        self.span = span
        self.hint = hint
        self.severity = severity
        self.source: str | None = None

    def __str__(self) -> str:
        where = f"{self.span}: " if self.span else ""
        return f"{where}{self.severity}: {self.message}"

    def with_source(self, source: str) -> SwarmError:
        """Attach the program text once, at the boundary, so `render` can quote it."""
        if self.source is None:
            self.source = source
        return self

    def render(self, source: str | None = None) -> str:
        source = source if source is not None else self.source
        lines = [str(self)]
        if self.span is not None and source is not None:
            lines.extend(_quote(source, self.span))
        if self.hint:
            lines.append(f"  hint: {self.hint}")
        return "\n".join(lines)


class SwarmSyntaxError(SwarmError):
    phase = "syntax"


class SwarmCheckError(SwarmError):
    """One or more checker diagnostics; `diagnostics` holds every one of them."""

    phase = "check"

    def __init__(self, diagnostics: list[SwarmError]):
        first = diagnostics[0]
        super().__init__(first.message, first.span, first.hint)
        self.diagnostics = diagnostics
        self.args = (diagnostics,)      # so it unpickles (raised in another process)

    def with_source(self, source: str) -> SwarmError:
        for d in self.diagnostics:
            d.with_source(source)
        return super().with_source(source)

    def render(self, source: str | None = None) -> str:
        return "\n".join(d.render(source) for d in self.diagnostics)


class SwarmRuntimeError(SwarmError):
    phase = "runtime"


class SwarmOptionError(SwarmError):
    """A bad command-line option or `--set` value; names the option, has no span."""

    phase = "option"


def article(word: str) -> str:
    """`a` or `an` for a message naming `word` (a keyword, a kind, a type), by its first
    letter: "an `invariant`", "a `status`"."""
    return "an" if word[:1].lower() in "aeiou" and word[:1] else "a"


def did_you_mean(name: str, candidates: Iterable[str]) -> str | None:
    """Return a `did you mean 'x'?` hint for the closest candidate, if any is close."""
    close = close_match(name, candidates)
    return f"did you mean '{close}'?" if close else None


def close_match(name: str, candidates: Iterable[str]) -> str | None:
    """The candidate closest to `name` (a typo of it), if any is close enough."""
    close = difflib.get_close_matches(name, sorted(set(candidates)), n=1, cutoff=0.6)
    return close[0] if close else None


# A line ends at `\r\n`, `\n` or a lone `\r` (old Mac files), and nowhere else: not at
# the form feeds, `\x85` or `\u2028` that `str.splitlines` also breaks at.
_LINE_BREAK = re.compile(r"\r\n|\r|\n")
_LONE_CR = re.compile(r"\r(?!\n)")


def lone_cr_as_newline(text: str) -> str:
    """`text` with each lone `\r` read as `\n` (same length, so every offset, line and
    column still points into the original text as `source_lines` splits it)."""
    return _LONE_CR.sub("\n", text)


def source_lines(text: str) -> list[str]:
    """The lines of program text, as the parser counts them (see `_LINE_BREAK`)."""
    lines = _LINE_BREAK.split(text)
    if lines[-1] == "":
        lines.pop()   # a final line break ends the last line; it starts none
    return lines


def cell_width(char: str) -> int:
    """Terminal cells one character takes: 0 for a combining mark or an invisible format
    character (it draws on the character before it), 2 for a wide or full-width East
    Asian character, 1 otherwise. The caret is laid out in cells, not characters, or
    it drifts right of `é` written as `e` + U+0301 and left of `漢`."""
    if unicodedata.category(char) in ("Mn", "Me", "Cf") and char != "\u00ad":
        return 0    # the soft hyphen is Cf but terminals draw it
    return 2 if unicodedata.east_asian_width(char) in ("W", "F") else 1


def cell_count(text: str) -> int:
    """Terminal cells `text` takes (see `cell_width`)."""
    return sum(cell_width(c) for c in text)


def _quote(source: str, span: Span) -> list[str]:
    text_lines = source_lines(source)
    if not 1 <= span.line <= len(text_lines):
        return []
    line = text_lines[span.line - 1].expandtabs(1)
    start = max(span.col - 1, 0)
    if span.end_line == span.line and span.end_col > span.col:
        width = span.end_col - span.col
    else:
        width = max(len(line) - start, 1)
    width = max(1, min(width, max(len(line) - start, 1)))
    if len(line) > _MAX_QUOTE:  # a generated line thousands of characters long
        left = max(0, start - _MAX_QUOTE // 3)
        shown = line[left:left + _MAX_QUOTE]
        prefix = "..." if left else ""
        suffix = "..." if left + _MAX_QUOTE < len(line) else ""
        line = prefix + shown + suffix
        start = start - left + len(prefix)
        width = max(1, min(width, len(shown) - (start - len(prefix))))
    end = start + width
    # A span that starts on a combining mark points at the character it is drawn on.
    while 0 < start < len(line) and cell_width(line[start]) == 0:
        start -= 1
    pad = cell_count(line[:start])
    cells = max(1, cell_count(line[start:end]))
    gutter = f"{span.line:>4} | "
    return [gutter + line, " " * len(gutter) + " " * pad + "^" + "~" * (cells - 1)]


_MAX_QUOTE = 120  # characters of a source line quoted under an error


class NotPerReplica(Exception):
    """A swarm aggregate a batch's frame cannot reduce per replica in one pass (nested
    in another, or with an `else`): the batch evaluates that metric replica by replica
    (`runtime/batch.py`)."""
