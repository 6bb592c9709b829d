"""Misspelt keywords: the keyword a word at the start of a statement was meant to be,
for the parser's error message.

A misspelt keyword is a name to the lexer, so `stauts resting {` reads as an agent
option `stauts` with the value `resting`, and the parser stops at the `{` with a list
of the tokens it expected there: true, and no help. When a parse fails inside a
statement whose first word is no keyword but is one or two edits (a letter added,
dropped, changed, or two swapped) from a keyword that can start a statement in that
block, the message names the word and the keyword instead. The keywords are those of
the block the statement stands in (found by matching braces over the text before it),
so `lett x = 3` in a status suggests `let`, and nothing is suggested where only names
go (the options of `world { }`).
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass

# The keywords that start a declaration or statement, by the block it stands in.
TOP_LEVEL = ("param", "world", "field", "region", "food", "obstacle", "nest", "robot",
             "agent", "invariant", "eventually", "always", "metric", "tree")
AGENT_BLOCK = ("status", "var", "attr", "final", "objective", "invariant", "eventually",
               "always", "metric")
STATUS_BODY = ("let", "when", "tree", "on")


@functools.cache
def _blocks() -> tuple[tuple, dict, frozenset]:
    """The tree block's keywords (the tree node rows' words, `runtime/trees.py`, read
    when a parse first fails: checking a good program does not load the tree nodes),
    every block's, and all of them."""
    from swarmdsl.runtime.trees import node_keywords

    tree = node_keywords()
    blocks = {"": TOP_LEVEL, "agent": AGENT_BLOCK, "status": STATUS_BODY,
              "final": STATUS_BODY, "when": STATUS_BODY, "on": STATUS_BODY,
              "tree": tree, **{w: tree for w in tree}}
    return tree, blocks, frozenset(TOP_LEVEL + AGENT_BLOCK + STATUS_BODY + tree)

_FIRST_WORD = re.compile(r"[ \t]*([A-Za-z_]\w*)")
_HEADER_WORD = re.compile(r"([A-Za-z_]\w*)")
# after the first word, what makes it a name in use (`x = 1`, `deposit(f, 1)`, `p.x`)
_USED_AS_NAME = re.compile(r"[ \t]*(?:[-+*/]?=|\(|\.)")


@dataclass(frozen=True)
class Misspelt:
    word: str
    start: int          # offset of the word in the text
    keyword: str


def misspelt_keyword(text: str, pos: int) -> Misspelt | None:
    """The statement holding offset `pos` starts with a word that is a typo of a keyword
    its block allows there: that word and keyword, else None."""
    start = max(text.rfind(c, 0, pos) for c in "\n{;") + 1
    m = _FIRST_WORD.match(text, start)
    if m is None or m.start(1) > pos:
        return None
    word, keywords = m[1], None
    tree_block, block_keywords, every = _blocks()
    if word in ("tree", "reactive"):    # `tree sequnce {`: the node's word after it
        m = _FIRST_WORD.match(text, m.end(1))
        if m is None or m.start(1) > pos:
            return None
        word, keywords = m[1], tree_block
    if word in every or _USED_AS_NAME.match(text, m.end(1)):
        return None
    if keywords is None:
        header = _enclosing_header(text, m.start(1))
        if header is None:
            return None
        keywords = block_keywords.get(header, ())
    keyword = closest(word, keywords)
    return Misspelt(word, m.start(1), keyword) if keyword else None


def closest(word: str, keywords) -> str | None:
    """The keyword `word` is a typo of: at most one edit away (two for keywords longer
    than four letters), never the whole word changed; the first of the nearest."""
    best, best_distance = None, None
    for kw in keywords:
        limit = 1 if len(kw) <= 4 else 2
        d = edit_distance(word.lower(), kw)
        if d <= limit and d < len(word) and (best_distance is None or d < best_distance):
            best, best_distance = kw, d
    return best


def edit_distance(a: str, b: str) -> int:
    """Letters inserted, deleted, changed or two neighbours swapped to turn `a` into `b`
    (the optimal string alignment distance)."""
    prev2, prev = None, list(range(len(b) + 1))
    for i in range(1, len(a) + 1):
        row = [i] + [0] * len(b)
        for j in range(1, len(b) + 1):
            cost = a[i - 1] != b[j - 1]
            row[j] = min(prev[j] + 1, row[j - 1] + 1, prev[j - 1] + cost)
            if (i > 1 and j > 1 and a[i - 1] == b[j - 2] and a[i - 2] == b[j - 1]
                    and prev2 is not None):
                row[j] = min(row[j], prev2[j - 2] + 1)
        prev2, prev = prev, row
    return prev[len(b)]


def _enclosing_header(text: str, pos: int) -> str | None:
    """The first word of the innermost `{ }` block still open at `pos` ("" at top
    level; None when that block is not closed-off text the parser reads as blocks)."""
    stack: list[int] = []           # offsets of the open `{`s
    i = 0
    while i < pos:
        ch = text[i]
        if ch == "#":
            nl = text.find("\n", i)
            i = pos if nl < 0 else nl
            continue
        if ch == '"':
            close, nl = text.find('"', i + 1), text.find("\n", i + 1)
            i = close + 1 if 0 <= close and (nl < 0 or close < nl) else i + 1
            continue
        if ch == "{":
            stack.append(i)
        elif ch == "}" and stack:
            stack.pop()
        i += 1
    if not stack:
        return ""
    brace = stack[-1]
    line_start = max(text.rfind(c, 0, brace) for c in "\n{;}") + 1
    m = _HEADER_WORD.search(text, line_start, brace)
    return m[1] if m else None
