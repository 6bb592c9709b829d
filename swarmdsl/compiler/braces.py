"""Which `{ }` block a syntax error left open, named the way the user wrote it.

A missing `}` is reported where the parser notices, often far below where it is
missing: at the end of the file. The message is more useful when it names the block
left open and its line (`status seek` (line 3)). Braces are matched over the text
(comments and strings skipped); a block whose `}` stands alone on a line indented less
than the line that opened it most likely took an outer block's `}`, so it is the one named.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

_HEADER = re.compile(r"[^{};\n]*\Z")
_SPACE = re.compile(r"\s+")


@dataclass(frozen=True)
class Block:
    line: int        # 1-based line of its `{`
    header: str      # what opens it: `agent ant`, `status seek`, `world`, `when ... -> s`
    indent: int      # indentation of the line it opens on

    def named(self) -> str:
        return f"`{self.header}` (line {self.line})" if self.header else \
            f"the block opened on line {self.line}"


def _header(text: str, brace: int) -> str:
    """The words before a `{` on its line (after any `;` or brace), squeezed, short."""
    m = _HEADER.search(text, 0, brace)
    words = _SPACE.sub(" ", m.group(0) if m else "").strip()
    if words.startswith(("when ", "on ")):
        return words if len(words) <= 30 else words[:27] + "..."
    return " ".join(words.split(" ")[:3])


def _indent(text: str, pos: int) -> tuple[int, bool]:
    """The indentation of the line holding `pos`, and whether only spaces precede it."""
    start = text.rfind("\n", 0, pos) + 1
    before = text[start:pos]
    stripped = before.lstrip(" \t")
    return len(before) - len(stripped), not stripped


def _scan(text: str) -> tuple[list[Block], list[Block]]:
    """Blocks whose `}` is probably an outer block's (by indentation), in source order,
    and the blocks still open at the end, outermost first."""
    stack: list[Block] = []
    misplaced: list[Block] = []
    line, i, end = 1, 0, len(text)
    while i < end:
        ch = text[i]
        if ch == "\n":
            line += 1
        elif ch == "#":
            nl = text.find("\n", i)
            i = end if nl < 0 else nl
            continue
        elif ch == '"':
            close, nl = text.find('"', i + 1), text.find("\n", i + 1)
            i = close + 1 if 0 <= close and (nl < 0 or close < nl) else i + 1
            continue
        elif ch == "{":
            stack.append(Block(line, _header(text, i), _indent(text, i)[0]))
        elif ch == "}" and stack:
            block = stack.pop()
            indent, alone = _indent(text, i)
            if alone and indent < block.indent:
                misplaced.append(block)
        i += 1
    return misplaced, stack


def left_open(text: str) -> list[Block]:
    """The blocks a file that ends too early left open: first those whose `}` is
    probably an outer block's, in source order, then those still open, innermost first
    (empty when every `{` is closed)."""
    misplaced, stack = _scan(text)
    return misplaced + stack[::-1] if stack else []

