"""Syntax errors in the language's words: lark's exceptions -> `SwarmSyntaxError`.

What the parser expected, translated from terminal names (`RBRACE` -> "`}`"); the
common mistakes recognised by example (a missing `}` and the block it left open, a
misspelt keyword, a habit from another language, `when x - > s`); where the text
parses once repaired, the repair as the hint. Split from `parse.py`, the only other
module that sees lark: `parse.parse` hands its `UnexpectedInput` to `syntax_error`.
"""

from __future__ import annotations

import functools
import re
import unicodedata

from lark.exceptions import (
    UnexpectedCharacters,
    UnexpectedEOF,
    UnexpectedInput,
    UnexpectedToken,
)

from swarmdsl.compiler.braces import left_open
from swarmdsl.compiler.keywords import closest, edit_distance, misspelt_keyword
from swarmdsl.compiler.lalr import parser
from swarmdsl.errors import (
    Span,
    SwarmSyntaxError,
    article,
    cell_width,
    source_lines,
)

# Readable names for terminals in "expected ..." messages.
_TERMINAL_TEXT = {
    "NAME": "a name",
    "NUMBER": "a number",
    "STRING": "a string",
    "_SEP": "a new line or `;`",
    "$END": "the end of the file",
    "LBRACE": "`{`",
    "RBRACE": "`}`",
    "LPAR": "`(`",
    "RPAR": "`)`",
    "COMMA": "`,`",
    "COLON": "`:`",
    "EQ": "`=`",
    "ASSIGN_OP": "`+=`, `-=`, `*=` or `/=`",
    "CMP_OP": "a comparison",
    "PLUS": "`+`",
    "MINUS": "`-`",
    "MUL_OP": "`*`, `/` or `%`",
    "POW_OP": "`^`",
    "AT_KW": "`at`",
    "DOT": "`.`",
    "REGION_KW": "`region`, `food`, `obstacle` or `nest`",
    "TRUE": "`true`",
    "FALSE": "`false`",
    "_ELSE": "`else`",
    "REACTIVE": "`reactive`",
    "SEQ_KW": "`sequence` or `fallback`",
    "PARALLEL_KW": "`parallel`",
    "INVERT_KW": "`invert`",
    "FORCE_KW": "`force`",
    "TREE_OUTCOME": "`success` or `failure`",
    "TREE_STATE": "`succeeded`, `failed` or `running`",
}

# `when` and then a `-` just before the token: the `->` of a `when` with no condition.
_WHEN_DASH = re.compile(r"\bwhen[ \t]*-\Z")
# A property keyword and one word, then something else: the word was meant as the start
# of the condition, and the property's name is missing.
_UNNAMED_PROPERTY = re.compile(
    r"(?:^|[;{])[ \t]*(invariant|eventually|always)[ \t]+(\w+)[ \t]*\Z")
_PROPERTY_FORMS = {
    "invariant": "`invariant NAME: CONDITION`, e.g. `invariant calm: speed <= 3`",
    "eventually": "`eventually NAME within TICKS: CONDITION`, e.g. "
                  "`eventually home within 50: status == resting`",
    "always": "`always NAME: TRIGGER -> eventually RESPONSE within TICKS`",
}
_DECL_KEYWORDS = ("param", "world", "field", "region", "food", "obstacle", "nest", "robot",
                  "agent", "invariant", "eventually", "always", "metric", "tree")


_CHARACTER_HINTS = {"[": "a vector is written `(x, y)`", "]": "a vector is written `(x, y)`",
                    "'": 'a string is written in double quotes: "models/net.pt"',
                    "&": "conditions are joined with `and`", "|": "conditions are joined with `or`",
                    "!": "a condition is negated with `not`; `!=` compares",
                    "?": "a choice is written `if CONDITION then A else B`"}


def _bad_string(text: str, pos: int, span: Span) -> SwarmSyntaxError:
    """A `"` the lexer cannot start a string at: the string holds a backslash (a Windows
    path, `nn("models\\x.pt")`) or does not end on its line. Saying "unexpected
    character '\"'" pointed at the quote without saying what was wrong with it."""
    rest = text[pos + 1:].split("\n", 1)[0]
    close = rest.find('"')
    if "\\" in (rest if close < 0 else rest[:close]):
        return SwarmSyntaxError("a string cannot contain a backslash", span,
                                hint='write paths with `/`, e.g. "models/x.pt"')
    if close < 0:
        return SwarmSyntaxError("this string does not end on its line", span,
                                hint='close it with `"` before the end of the line')
    return SwarmSyntaxError("unexpected character '\"'", span)


def syntax_error(exc: UnexpectedInput, text: str, filename: str) -> SwarmSyntaxError:
    if isinstance(exc, UnexpectedEOF) or (
        isinstance(exc, UnexpectedToken) and exc.token.type == "$END"
    ):
        lines = source_lines(text) or [""]
        span = Span.point(filename, len(lines), len(lines[-1]) + 1)
        if text.count("{") > text.count("}"):
            blocks = left_open(text)
            if blocks:
                return SwarmSyntaxError(f"unexpected end of file: {blocks[0].named()} is "
                                        "not closed", span,
                                        hint="every `{` needs a matching `}`")
            return SwarmSyntaxError("unexpected end of file: a `}` is missing", span,
                                    hint="every `{` needs a matching `}`")
        if text.count("(") > text.count(")"):
            return SwarmSyntaxError("unexpected end of file: a `)` is missing", span)
        return SwarmSyntaxError("unexpected end of file", span)
    line, col = exc.line, exc.column
    if isinstance(exc, UnexpectedCharacters):
        char = text[exc.pos_in_stream] if 0 <= exc.pos_in_stream < len(text) else "?"
        if char == '"':
            return _bad_string(text, exc.pos_in_stream, Span.point(filename, line, col))
        hint = _CHARACTER_HINTS.get(char)
        if char.isalpha() or char.isdigit():   # `é`, `漢`: a letter, but not a name's
            hint = "names are ASCII letters, digits and `_`"
        shown = repr(char)
        if cell_width(char) == 0:   # quoted, it would draw on the quote mark
            shown = f"U+{ord(char):04X} ({unicodedata.name(char, 'unnamed')})"
            hint = ("it is drawn on the character before it, or not at all; names are "
                    "ASCII letters, digits and `_`")
        return SwarmSyntaxError(f"unexpected character {shown}", Span.point(filename, line, col),
                                hint=hint)
    assert isinstance(exc, UnexpectedToken)
    tok = exc.token
    span = Span(filename, line, col, tok.end_line or line, tok.end_column or col + 1)
    typo = misspelt_keyword(text, tok.start_pos) if tok.start_pos is not None else None
    if typo is not None:        # `stauts resting {`: the word, not the `{` it led to
        at_line = text.count("\n", 0, typo.start) + 1
        at_col = typo.start - text.rfind("\n", 0, typo.start)
        return SwarmSyntaxError(
            f"unknown keyword `{typo.word}`; did you mean `{typo.keyword}`?",
            Span(filename, at_line, at_col, at_line, at_col + len(typo.word)))
    shown = "a new line" if tok.type == "_SEP" and "\n" in tok else f"`{tok}`"
    anon = {t.name: t.pattern.value for t in parser().terminals if t.name.startswith("__")}
    expected_text = {anon.get(t, t) for t in exc.expected}
    expected = sorted({_terminal_text(t) for t in expected_text})
    message, hint = f"unexpected {shown}", None
    after = text[tok.end_pos:tok.end_pos + 1] if tok.end_pos is not None else ""
    if tok.type == "EQ" and after == ">":   # `when c => s`
        return SwarmSyntaxError(message, span, hint="a transition is written `->`")
    if tok.type == "EQ" and ("CMP_OP" in exc.expected or "->" in expected_text):
        return SwarmSyntaxError(message, span, hint="use `==` to compare")
    if tok.type == "EQ" and tok.start_pos and text[tok.start_pos - 1] == "=":   # `v == 1`
        return SwarmSyntaxError(message, span, hint="`==` compares; a statement assigns "
                                                    "with `=`, e.g. `v = 1`")
    lines = source_lines(text)
    line_text = lines[line - 1][: col - 1] if 1 <= line <= len(lines) else ""
    if (tok.type == "CMP_OP" and str(tok) == ">" and tok.start_pos is not None
            and _WHEN_DASH.search(text, 0, tok.start_pos)):
        # `when -> s`: where a condition must start, `->` lexes as a minus and a `>`
        arrow = Span(filename, line, col - 1, line, col + 1)
        return SwarmSyntaxError("`when` needs a condition before `->`", arrow,
                                hint="`when CONDITION -> STATUS`, e.g. `when x > 3 -> s`")
    unnamed = _UNNAMED_PROPERTY.search(line_text)
    if unnamed and tok.type != "_SEP":
        word, name = unnamed.groups()
        missing = "`within TICKS:`" if word == "eventually" else "a `:`"
        if tok.type == "NAME" or str(tok) == ":":   # named, then the condition
            message = f"unexpected {shown}: {missing} is missing after `{word} {name}`"
        elif str(tok) == "=":   # `invariant calm = speed <= 3`: named, `=` for `:`
            message = f"unexpected {shown}: {missing} follows `{word} {name}`, not `=`"
        else:
            message = f"unexpected {shown}: `{word}` needs a name before its condition"
        return SwarmSyntaxError(message, span, hint=_PROPERTY_FORMS[word])
    in_tree = _in_tree(line_text, tok) or _in_status(line_text, tok, exc.expected)
    if in_tree:
        message, hint, word = in_tree
        if word is None:
            return SwarmSyntaxError(f"unexpected {shown}: {message}", span, hint=hint)
        at = Span(filename, line, word.start(1) + 1, line, word.end(1) + 1)
        return SwarmSyntaxError(message, at, hint=hint)
    meant = None
    if tok.type == "NAME":      # `param n = 3 ni 0..10`, `if c then a els b`
        meant = closest(str(tok), _keyword_words(exc.expected)) or _repaired(text, tok)
    if meant is not None:
        return SwarmSyntaxError(f"unknown keyword `{tok}`; did you mean `{meant}`?", span)
    if tok.type == "CMP_OP":
        message = f"unexpected {shown}: comparisons cannot be chained"
        hint = "join them with `and`: `a < b and b < c`"
    elif "->" in expected_text and re.search(r"\bwhen\b", line_text):
        message = f"unexpected {shown}: `when CONDITION -> STATUS` needs `->`"
    elif str(tok) in _DECL_KEYWORDS and "_SEP" in exc.expected:
        message = f"unexpected `{tok}`: start it on a new line or after `;`"
    elif tok.type == "_SEP" and ("RPAR" in exc.expected):
        message = "unexpected `;` inside brackets"
    elif tok.type == "NAME" and str(tok) in _DECL_KEYWORDS and "RBRACE" in exc.expected:
        message = f"unexpected `{tok}`: a `}}` is missing before it"
    elif tok.type == "_SEP" and "RBRACE" not in exc.expected and expected:
        message = f"unexpected new line: expected {_join(expected)}"
    elif expected:
        hint = _habit(tok, line_text, text, expected_text) or f"expected {_join(expected)}"
    return SwarmSyntaxError(message, span, hint=hint)


def _terminal_text(name: str) -> str:
    """How an "expected ..." message names terminal `name`; the counted decorators read
    off the tree node rows (`runtime/trees.py`, loaded only when a parse fails)."""
    if name == "COUNTED_KW":
        from swarmdsl.runtime.trees import counted_keywords

        words = [f"`{w}`" for w in counted_keywords()]
        return " or ".join([", ".join(words[:-1]), words[-1]] if len(words) > 1 else words)
    return _TERMINAL_TEXT.get(name, f"`{name.lower()}`")


@functools.cache
def _tree_word() -> re.Pattern:
    """A word before the error that puts it inside a tree (the counted decorators'
    words from the rows, read when a parse first fails)."""
    from swarmdsl.runtime.trees import counted_keywords

    return re.compile(r"(?:^|[\s{;])(when|let|tree|" + "|".join(counted_keywords())
                      + r"|parallel)[ \t]*\Z")


_TREE_NODE_TOKENS = ("SEQ_KW", "PARALLEL_KW", "REACTIVE", "COUNTED_KW", "INVERT_KW",
                     "FORCE_KW")


def _in_tree(before: str, tok):
    """(message, hint, the word's match or None) for a statement written inside a
    behaviour tree, where only nodes go (`when`, `let`, a second `tree`: the message is
    about that word), or a count written with a bare minus sign (about the sign)."""
    match = _tree_word().search(before)
    if match is None:
        return None
    word = match[1]
    if word == "when" and tok.type != "_SEP":
        return ("a `when` cannot go inside a tree",
                "put transitions after the tree: `on success -> STATUS`, "
                "`when tree failed and ... -> STATUS`", match)
    if word == "let" and tok.type == "NAME":
        return ("a `let` cannot go inside a tree",
                "bind it with `let` before the tree, or keep it in a `var`", match)
    if word == "tree" and tok.type in _TREE_NODE_TOKENS:
        return ("a status has one `tree`; inside it, nodes are written without `tree`",
                f"write `{tok} ...` alone", match)
    if word not in ("tree", "when", "let") and str(tok) == "-":
        return (f"a count after `{word}` that is not a number or a name takes brackets",
                f"`{word} (-1) ...`", None)
    return None


_KIND_WORD = re.compile(r"(?:^|[\s{;])(var|attr|status|final|objective|metric|invariant)"
                        r"[ \t]*\Z")
_KIND_ITEMS = {
    "var": ("a `var` is declared in the agent block, not in a status",
            "declare it beside `count`, or bind a value of this tick with `let`"),
    "attr": ("an `attr` is declared in the agent block, not in a status",
             "declare it beside `count`"),
    "objective": ("an `objective` is declared in the agent block, not in a status",
                  "declare it beside `count`"),
    "invariant": ("an `invariant` is declared in the agent block or at top level, not "
                  "in a status", "declare it beside `count` (about each agent), or at "
                  "top level (about the swarm)"),
    "metric": ("a `metric` is declared in the agent block or at top level, not in a "
               "status", "declare it beside `count`, or at top level"),
}


def _in_status(before: str, tok, expected) -> tuple | None:
    """(message, hint, the word's match) for a declaration of the agent block written
    in a status body, where the word parses as a variable being assigned."""
    match = _KIND_WORD.search(before)
    if match is None or "EQ" not in expected:
        return None
    if match[1] == "final" and str(tok) == "status":   # `final` read as a variable
        return ("a `final status` cannot go inside a status", "is a `}` missing above it?",
                match)
    if tok.type != "NAME":
        return None
    message, hint = _KIND_ITEMS.get(match[1], (
        f"{article(match[1])} `{match[1]}` cannot go inside a status",
        "is a `}` missing above it?"))
    return message, hint, match


def _habit(tok, before: str, text: str, expected: set[str]) -> str | None:
    """A hint for what another language's habit typed where a statement goes."""
    target = re.search(r"(?:^|[{;]|\s)([A-Za-z_]\w*)\s*$", before)
    if str(tok) == "." and target and "EQ" in expected:
        name = target[1]
        after = text[tok.end_pos:tok.end_pos + 1] if tok.end_pos is not None else ""
        whole = f"({name}.x, Y)" if after == "y" else f"(X, {name}.y)"
        return f"a component cannot be assigned alone; set the whole vector: `{name} = {whole}`"
    if str(tok) == "*" and tok.start_pos and text[tok.start_pos - 1] == "*":
        return "`^` raises to a power: `x ^ 2`"
    if str(tok) in "+-" and target and tok.end_pos is not None \
            and text[tok.end_pos:tok.end_pos + 1] == str(tok):
        return f"write `{target[1]} {tok}= 1`"
    if target and tok.type in ("NUMBER", "NAME") and target[1] in _callables():
        # `wait 3`, `sqrt x`: a call written without its brackets
        return f"`{target[1]}` takes its arguments in brackets: `{target[1]}({tok})`"
    if str(tok) == "if" and re.search(r"=\s*\S", before):
        return "a choice is written `if CONDITION then A else B`"
    if re.search(r"(?:^|[{;]|\s)if\s*$", before):
        return ("`if` chooses a value (`x = if C then A else B`); to act when a condition "
                "holds, use `when C -> STATUS` or a `tree`")
    return None


def _callables() -> set[str]:
    """Every name the language calls: functions, aggregates and the calls its features
    add, actions, a tree's long actions (read when a parse fails)."""
    from swarmdsl.compiler import actions, typing_rules
    from swarmdsl.compiler.builtins import AGGREGATES, FUNCTIONS
    from swarmdsl.compiler.tree_long import LONG

    return {*FUNCTIONS, *AGGREGATES, *typing_rules.CALL_RULES, *actions.ACTIONS, *LONG}


def _keyword_words(expected) -> list[str]:
    """The keywords among the terminals the parser expected (`WITHIN` -> within,
    `SEQ_KW` -> sequence, fallback): what a name in their place was probably meant as."""
    return [w for t in parser().terminals if t.name in expected for w in _words_of(t)]


@functools.cache
def _all_keywords() -> tuple[str, ...]:
    """Every keyword of the grammar."""
    return tuple(sorted({w for t in parser().terminals for w in _words_of(t)}))


def _words_of(terminal) -> list[str]:
    value = terminal.pattern.value
    if terminal.pattern.type == "str" and value.isalpha():
        return [value]
    if terminal.pattern.type == "re" and re.fullmatch(r"\(\?:[a-z|]+\)", value):
        return value[3:-1].split("|")
    return []


def _repaired(text: str, tok) -> str | None:
    """The keyword a misspelt name stands for when the parser's expected set cannot say
    (LALR may reduce before it notices the error: after `speed > 0`, `adn` is met
    where only the end of the statement is expected): the nearest keyword that, put in
    its place, lets the parse go past it. Tried only on a syntax error, a few parses."""
    if tok.start_pos is None or tok.end_pos is None or len(text) > _REPAIR_LIMIT:
        return None     # a huge text's error is not worth three more parses
    word = str(tok)
    near = sorted((kw for kw in _all_keywords() if closest(word, [kw])),
                  key=lambda kw: edit_distance(word, kw))
    for kw in near[:3]:
        fixed = text[:tok.start_pos] + kw + text[tok.end_pos:]
        try:
            parser().parse(fixed)
        except UnexpectedInput as again:
            at = _offset(again, fixed)
            if at is None or at < tok.start_pos + len(kw):
                continue
        return kw
    return None


_REPAIR_LIMIT = 30_000      # characters: about 0.1 s a parse (the shipped programs: 1-8k)


def _offset(exc: UnexpectedInput, text: str) -> int | None:
    """Where in `text` the parse failed."""
    if isinstance(exc, UnexpectedEOF):
        return len(text)
    if isinstance(exc, UnexpectedToken):
        return len(text) if exc.token.type == "$END" else exc.token.start_pos
    return getattr(exc, "pos_in_stream", None)


def _join(items: list[str]) -> str:
    if len(items) > 6:
        items = items[:6] + ["..."]
    return ", ".join(items[:-1]) + (" or " if len(items) > 1 else "") + items[-1]
