"""`swarmdsl fmt`: one layout for every program, without changing what it means.

The formatter keeps the program's lines as its author broke them and its comments
where they are; it rewrites only the whitespace: two spaces of indentation per open
`{` (a line continued inside `( )` keeps its alignment, moved with the line that
opened the bracket), one space around binary operators, `=`, `->`, `{` and `}`, after
`,` and `;`, none inside brackets or around `.` and `..`, at most one blank line in a
row, no trailing spaces, one final newline.

It works on the grammar's own tokens (the lexer of `compiler/parse.py`), and it
checks its own work: the program formatted must parse to the same syntax tree, spans
aside (`meaning`), or the original text is kept and the discrepancy reported as an
internal error. Formatting twice changes nothing (tests/test_fmt.py checks both on
every shipped and documented program). Runs are the same bit for bit: random streams
are keyed by a draw's place in the program's structure, which formatting keeps
(`moved_draws` checks it, and `swarmdsl fmt` would name a draw it moved).
"""

from __future__ import annotations

import re

from swarmdsl.errors import SwarmError

INDENT = "  "
_BINARY = {"EQ", "ASSIGN_OP", "CMP_OP", "PLUS", "MUL_OP", "POW_OP", "__ANON_1"}
_OPENING = {"LPAR", "CALL_LPAR", "COMMA", "EQ", "ASSIGN_OP", "CMP_OP", "PLUS", "MINUS", "MUL_OP",
            "POW_OP", "__ANON_1", "COLON", "LBRACE", "__ANON_0", "SEMI", "SIGN"}
_WORD_OPERATORS = {"IF", "THEN", "_ELSE", "AND", "OR", "NOT", "WHERE", "IN", "AT_KW",
                   "WITHIN", "RETURN"}


class FormatError(SwarmError):
    """The formatter would have changed the program's meaning: a bug in swarmdsl."""


def format_source(text: str, filename: str = "<string>") -> str:
    """`text` laid out; SwarmSyntaxError (located) when it does not parse."""
    from swarmdsl.compiler.parse import parse

    text = text.removeprefix("\ufeff")
    text = re.sub(r"\r\n|\r", "\n", text)
    before = parse(text, filename)
    out = _layout(text, *_offsets(before, text))
    try:
        after = parse(out, filename)
    except SwarmError as err:
        raise FormatError(f"internal error: formatting made the program unreadable "
                          f"({err}); the file is left as it was (please report this)"
                          ) from None
    if meaning(after) != meaning(before):
        raise FormatError("internal error: formatting would change the program's meaning; "
                          "the file is left as it was (please report this)")
    return out


def meaning(tree) -> object:
    """What a parsed program says, without where it says it: `ast.shape` with every
    span dropped, also those a node keeps in a tuple (a named tree's parameters)."""
    from swarmdsl.compiler.ast import shape

    return _without_spans(shape(tree))


def _without_spans(value):
    from swarmdsl.errors import Span

    if isinstance(value, Span):
        return None
    if isinstance(value, tuple):
        return tuple(_without_spans(v) for v in value)
    return value


def moved_draws(text: str, formatted: str) -> list[tuple[str, tuple, tuple]]:
    """The random draws whose stream formatting moved, as (name, (line, col) before,
    after). A draw's stream is keyed by its place in the program's structure
    (`compiler/stream_places.py`), never by where it is written, and formatting keeps
    the structure (`meaning`): this is empty unless the formatter is wrong, so a
    formatted program runs the same, bit for bit."""
    from swarmdsl.compiler import ast
    from swarmdsl.compiler.parse import parse
    from swarmdsl.compiler.stream_places import places

    def calls(tree):
        table = places(tree)
        return [(n, table[id(n)][1]) for n in ast.walk(tree) if isinstance(n, ast.Call)]

    out = []
    for (a, pa), (b, pb) in zip(calls(parse(text)), calls(parse(formatted)), strict=True):
        if pa != pb:
            out.append((a.name, (a.span.line, a.span.col), (b.span.line, b.span.col)))
    return out


class _Line:
    def __init__(self):
        self.tokens: list[tuple[str, str]] = []   # (terminal, text)
        self.comment: str | None = None
        self.comment_gap = 1
        self.old_indent = 0
        self.continued = False                   # starts inside ( )


_GAP = re.compile(r"#[^\n]*|;|\n|[^\S\n]+")


def _lines(text: str, calls: set[int], signs: set[int]) -> list[_Line]:
    """The text as lines of tokens, with each line's comment and first indentation.
    A `(` that opens a call's arguments is typed `CALL_LPAR` (no space before it), a
    `-` that starts an option's value is typed `SIGN` (none after it). `calls`: the
    offsets of the names of calls; `signs`: of those `-`."""
    from swarmdsl.compiler.parse import tokens

    lines = [_Line()]
    parens = 0
    end = 0

    def gap(between: str) -> None:
        width = 0
        for piece in _GAP.finditer(between):
            p = piece.group()
            cur = lines[-1]
            if p == "\n":
                lines.append(_Line())
                lines[-1].continued = parens > 0
            elif p == ";":
                cur.tokens.append(("SEMI", ";"))
            elif p.startswith("#"):
                cur.comment = p.rstrip()
                cur.comment_gap = max(1, width)
            elif not cur.tokens and cur.comment is None:
                cur.old_indent = len(p.expandtabs(2))
            width = len(p) if not p.strip() else 0

    prev_start = -1
    for ttype, value, start, stop in tokens(text):
        gap(text[end:start])
        if ttype == "LPAR":
            parens += 1
            if prev_start in calls:
                ttype = "CALL_LPAR"
        elif ttype == "RPAR":
            parens = max(0, parens - 1)
        elif ttype == "MINUS" and start in signs:
            ttype = "SIGN"
        lines[-1].tokens.append((ttype, value))
        end, prev_start = stop, start
    gap(text[end:])
    return lines


def _offsets(tree, text: str) -> tuple[set[int], set[int]]:
    """Offsets of the names written right before a call's `(` (calls, actions, named
    trees' declarations), and of the `-` signs that start an option's value."""
    from swarmdsl.compiler import ast
    from swarmdsl.compiler.tree_ast import TreeDecl

    starts = [0] + [m.end() for m in re.finditer("\n", text)]
    calls, signs = set(), set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Call | ast.ActionStmt | TreeDecl):
            span = node.name_span
            calls.add(starts[span.line - 1] + span.col - 1)
        elif isinstance(node, ast.Option):
            # `origin 10 -20`: values are separated by spaces, and a `-` with a space
            # before it and none after starts one (parse.ToAst._values): kept so
            for arg in node.args:
                if isinstance(arg, ast.Neg):
                    signs.add(starts[arg.span.line - 1] + arg.span.col - 1)
    return calls, signs


def _space(prev: tuple[str, str] | None, tok: tuple[str, str], prev2, parens: int) -> str:
    """The space between two tokens of a line."""
    if prev is None:
        return ""
    pt, t = prev[0], tok[0]
    if t in ("RPAR", "COMMA", "SEMI", "DOT", "__ANON_0") or pt in ("LPAR", "CALL_LPAR",
                                                                    "DOT", "__ANON_0"):
        return ""
    if t == "COLON":
        return " " if parens > 0 else ""
    if t == "CALL_LPAR":
        return ""
    if pt == "SIGN" or pt == "MINUS" and _unary(prev2):
        return ""
    return " "


def _unary(before_minus: tuple[str, str] | None) -> bool:
    """Whether a `-` after this token is a negation (no space after it)."""
    if before_minus is None:
        return True
    t = before_minus[0]
    return t in _OPENING or t in _WORD_OPERATORS or t in ("RETURN", "COUNTED_KW")


def _layout(text: str, calls: set[int], signs: set[int]) -> str:
    out: list[str] = []
    depth = 0
    parens = 0
    shift = 0          # how far the line that opened the current ( moved
    blank = 0
    for line in _lines(text, calls, signs):
        if not line.tokens and line.comment is None:
            blank += 1
            continue
        if out and blank:
            out.append("")
        blank = 0
        closing_first = bool(line.tokens) and line.tokens[0][0] == "RBRACE"
        if line.continued and parens > 0:
            indent = " " * max(0, line.old_indent + shift)
        else:
            level = depth - 1 if closing_first else depth
            indent = INDENT * max(0, level)
            shift = len(indent) - line.old_indent
        parts = []
        prev = prev2 = None
        for tok in line.tokens:
            if tok[0] == "RPAR":
                parens = max(0, parens - 1)
            parts.append(_space(prev, tok, prev2, parens) + tok[1])
            if tok[0] in ("LPAR", "CALL_LPAR"):
                parens += 1
            elif tok[0] == "LBRACE":
                depth += 1
            elif tok[0] == "RBRACE":
                depth = max(0, depth - 1)
            prev2, prev = prev, tok
        code = "".join(parts)
        if line.comment is not None:
            code = f"{code}{' ' * line.comment_gap}{line.comment}" if code else line.comment
        out.append(indent + code)
    while out and out[-1] == "":
        out.pop()
    return "\n".join(out) + "\n" if out else ""
