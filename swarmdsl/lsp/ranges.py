"""Ranges and diagnostics as the language server's features exchange them: 0-based
lines, 0-based columns counted in characters (the parser's count); `server.py`
converts them to the client's encoding."""

from __future__ import annotations

from dataclasses import dataclass

from swarmdsl.errors import Span


@dataclass(frozen=True)
class Range:
    """A 0-based, end-exclusive range: lines and character columns."""

    line: int
    col: int
    end_line: int
    end_col: int

    @classmethod
    def of(cls, span: Span) -> Range:
        end_line, end_col = span.end_line - 1, span.end_col - 1
        if (end_line, end_col) <= (span.line - 1, span.col - 1):
            end_line, end_col = span.line - 1, span.col   # a point: one character
        return cls(span.line - 1, span.col - 1, end_line, end_col)

    def contains(self, line: int, col: int) -> bool:
        """Whether (line, col) is inside, or just after its last character (where the
        cursor stands after typing a name)."""
        return (self.line, self.col) <= (line, col) <= (self.end_line, self.end_col)


@dataclass(frozen=True)
class Related:
    range: Range
    message: str


@dataclass(frozen=True)
class Diagnostic:
    range: Range
    severity: str            # "error", "warning" or "information"
    message: str             # as `swarmdsl check` prints it after `error: `
    hint: str | None = None
    related: tuple[Related, ...] = ()

    @property
    def text(self) -> str:
        """The message with its hint, as an editor shows it."""
        return f"{self.message}\nhint: {self.hint}" if self.hint else self.message
