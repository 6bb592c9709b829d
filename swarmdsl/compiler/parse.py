"""Text -> AST. The only module that sees lark and its exceptions."""

from __future__ import annotations

import dataclasses
import functools
import re
import unicodedata

from lark import Lark, Token, Transformer, v_args
from lark.exceptions import (
    UnexpectedCharacters,
    UnexpectedEOF,
    UnexpectedInput,
    UnexpectedToken,
    VisitError,
)

from swarmdsl.compiler import ast
from swarmdsl.compiler.braces import left_open
from swarmdsl.compiler.grammar_cache import build_cached
from swarmdsl.compiler.keywords import closest, edit_distance, misspelt_keyword
from swarmdsl.compiler.nesting import flatten_and_limit
from swarmdsl.compiler.tree_ast import TreeToAst
from swarmdsl.errors import (
    Span,
    SwarmError,
    SwarmSyntaxError,
    article,
    cell_width,
    lone_cr_as_newline,
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


class _DropNewlinesInBrackets:
    """Post-lexer: a newline inside ( ) continues the line, as in Python."""

    always_accept = ("_SEP",)

    def process(self, stream):
        depth = 0
        for tok in stream:
            if tok.type == "LPAR":
                depth += 1
            elif tok.type == "RPAR":
                depth = max(depth - 1, 0)
            elif tok.type == "_SEP" and depth > 0:
                if ";" in tok:
                    yield tok  # a `;` inside brackets is a real error; let the parser say so
                continue
            yield tok


@functools.cache
def parser() -> Lark:
    """The LALR parser, built once per process and its tables cached between processes.

    Building the tables costs ~150 ms; loading them from the user's cache folder ~10 ms
    (`grammar_cache.py`).
    """
    return build_cached(functools.partial(
        Lark.open_from_package,
        "swarmdsl",
        "grammar.lark",
        parser="lalr",
        lexer="contextual",
        propagate_positions=True,
        maybe_placeholders=True,
        postlex=_DropNewlinesInBrackets(),
    ), "grammar")


def grammar_parser_without_postlex() -> Lark:
    """The same grammar without the post-lexer, for grammar-driven fuzzing."""
    return Lark.open_from_package(
        "swarmdsl", "grammar.lark", parser="lalr", lexer="contextual", maybe_placeholders=True
    )


def parse(text: str, filename: str = "<string>") -> ast.Program:
    """Parse program text into an AST, or raise SwarmSyntaxError located in `filename`."""
    if text.startswith("\ufeff"):
        text = text[1:]  # a UTF-8 byte-order mark, as some Windows editors write
    # A lone CR (old Mac line ends) ends a line, as CRLF and LF do; lark counts only LF.
    text = lone_cr_as_newline(text)
    if not text.endswith("\n"):
        text += "\n"
    try:
        tree = parser().parse(text)
    except UnexpectedInput as exc:
        raise _syntax_error(exc, text, filename) from None
    flatten_and_limit(tree, filename)
    to_ast = ToAst(filename, text)
    try:
        program = to_ast.transform(tree)
    except VisitError as exc:  # pragma: no cover - ToAst never raises by design
        raise SwarmError(f"internal error while building the syntax tree: {exc.orig_exc}") from exc
    if to_ast.three_dots:
        raise to_ast.three_dots[0]
    return program


@functools.cache
def keywords() -> frozenset[str]:
    """The words the grammar reserves (`param`, `when`, `food`, `sequence`...), read from
    its terminals, for tools that must not offer one as a name."""
    words = set()
    for t in parser().terminals:
        pattern = t.pattern.value
        if t.pattern.type == "str" and pattern.isalpha():
            words.add(pattern)
        elif t.pattern.type == "re" and re.fullmatch(r"\(\?:[a-z|]+\)", pattern):
            words.update(pattern[3:-1].split("|"))
        elif t.pattern.type == "re" and pattern.isalpha():
            words.add(pattern)
    return frozenset(words)


def tokens(text: str) -> list[tuple[str, str, int, int]]:
    """The text's tokens as the parser reads them: (terminal, text, start, end) offsets,
    without the separators (what lies between two tokens is blanks, line breaks, `;`
    and comments). Never raises: for the formatter and the editor's highlighting.

    Lexed by the parser itself, so a word is what its place makes it (`food_gain` is
    one name after `param`, where a lexer on its own would read the keyword `food`);
    past a syntax error the rest is lexed alone, skipping characters it cannot read.
    """
    text = lone_cr_as_newline(text)     # same length: offsets still point into it
    out: list[tuple[str, str, int, int]] = []

    def keep(tok) -> None:
        if tok.type != "_SEP":
            out.append((tok.type, str(tok), tok.start_pos, tok.end_pos))

    try:
        for tok in parser().parse_interactive(text if text.endswith("\n") else
                                              text + "\n").iter_parse():
            keep(tok)
        return [t for t in out if t[3] <= len(text)]
    except UnexpectedInput:
        pass
    pos = out[-1][3] if out else 0
    while pos < len(text):
        try:
            for tok in parser().lex(text[pos:]):
                if tok.type != "_SEP":
                    out.append((tok.type, str(tok), pos + tok.start_pos, pos + tok.end_pos))
            break
        except UnexpectedCharacters as exc:
            pos += exc.pos_in_stream + 1
            out = [t for t in out if t[2] < pos]
    return out


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


def _syntax_error(exc: UnexpectedInput, text: str, filename: str) -> SwarmSyntaxError:
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
        if tok.type == "NAME":   # named, then the condition
            missing = "`within TICKS:`" if word == "eventually" else "a `:`"
            message = f"unexpected {shown}: {missing} is missing after `{word} {name}`"
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
    if str(tok) == "if" and re.search(r"=\s*\S", before):
        return "a choice is written `if CONDITION then A else B`"
    if re.search(r"(?:^|[{;]|\s)if\s*$", before):
        return ("`if` chooses a value (`x = if C then A else B`); to act when a condition "
                "holds, use `when C -> STATUS` or a `tree`")
    return None


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


def _span(filename: str, meta) -> Span:
    if getattr(meta, "empty", True):
        return Span.point(filename, 1, 1)
    return Span(filename, meta.line, meta.column, meta.end_line, meta.end_column)


def _tok_span(filename: str, tok: Token) -> Span:
    return Span(filename, tok.line, tok.column, tok.end_line, tok.end_column)


def _names(children) -> list[Token]:
    return [c for c in children if isinstance(c, Token) and c.type == "NAME"]


def _nodes(children, cls=ast.Node) -> list:
    return [c for c in children if isinstance(c, cls)]


@v_args(meta=True)
class ToAst(Transformer):
    """Parse tree -> ast dataclasses. Never raises: the checker judges meaning."""

    def __init__(self, filename: str, text: str = ""):
        super().__init__()
        self.filename = filename
        self.text = text
        # id of a `a -b` subtraction (space before the `-`, none after) -> the `-` offset
        self.spaced_minus: dict[int, int] = {}
        self.three_dots: list[SwarmSyntaxError] = []   # `in 0...2`, raised after the walk

    def _s(self, meta) -> Span:
        return _span(self.filename, meta)

    def _t(self, tok: Token) -> Span:
        return _tok_span(self.filename, tok)

    # ---- declarations ----
    def start(self, meta, children):
        return ast.Program(self._s(meta), tuple(_nodes(children)))

    def param_decl(self, meta, c):
        name = c[0]
        exprs = _nodes(c[1:])
        lo, hi = (exprs[1], exprs[2]) if len(exprs) == 3 else (None, None)
        if hi is not None:
            self._three_dots(lo, hi)
        return ast.ParamDecl(self._s(meta), str(name), self._t(name), exprs[0], lo, hi)

    def _three_dots(self, lo, hi) -> None:
        """`in 0...2` lexes as `0 .. .2`, a range to 0.2 that was hardly meant: refused,
        as is any `..` run into a number that starts with a dot."""
        lines = source_lines(self.text)
        line = lines[hi.span.line - 1] if hi.span.line <= len(lines) else ""
        at = hi.span.col - 1              # where the upper bound starts: its `.`
        if line[at - 2:at + 1] != "...":
            return
        lo_text = line[lo.span.col - 1:lo.span.end_col - 1] if lo.span.line == \
            hi.span.line else "LO"
        hi_text = line[at + 1:hi.span.end_col - 1] if hi.span.end_line == hi.span.line \
            else "HI"
        self.three_dots.append(SwarmSyntaxError(
            "`...` is not a range: a range is written `LO..HI`",
            Span(self.filename, hi.span.line, at - 1, hi.span.line, at + 2),
            hint=f"write `{lo_text}..{hi_text}`, or `{lo_text}..0.{hi_text}` for a range "
                 f"up to 0.{hi_text}"))

    def world_decl(self, meta, c):
        return ast.WorldDecl(self._s(meta), tuple(_nodes(c, ast.Option)))

    def field_decl(self, meta, c):
        return ast.FieldDecl(self._s(meta), str(c[0]), self._t(c[0]),
                             tuple(_nodes(c, ast.Option)))

    def region_decl(self, meta, c):
        kw, name, shape = c[0], c[1], c[2]
        return ast.RegionDecl(self._s(meta), str(kw), str(name), self._t(name), shape)

    def robot_decl(self, meta, c):
        return ast.RobotDecl(self._s(meta), str(c[0]), self._t(c[0]),
                             tuple(_nodes(c, ast.Option)))

    def agent_decl(self, meta, c):
        return ast.AgentDecl(self._s(meta), str(c[0]), self._t(c[0]), tuple(_nodes(c[1:])))

    def option(self, meta, c):
        name = c[0]
        has_in = len(c) > 1 and c[1] is not None and not isinstance(c[1], ast.Node)
        args = tuple(part for a in _nodes(c[1:], ast.Expr)
                     for part in self._values(a, meta.start_pos))
        if str(name) == "message":   # `message seen bool at vec`: `at` is a value's name
            args = tuple(_message_words(args))
        return ast.Option(self._s(meta), str(name), self._t(name), has_in, args)

    def _values(self, e: ast.Expr, start: int) -> list[ast.Expr]:
        """The values an option's expression `e` was written as. Values are separated by
        spaces, so `origin 10 -20` is two values, not `10 - 20` (nor `edges repel 1 -2`
        a weight of -1): a `-` with a space before it and none after, outside brackets,
        starts a value, as a sign. `10 - 20` and `10-20` stay subtractions."""
        if not (isinstance(e, ast.BinOp) and e.op in "+-"):
            return [e]
        parts = self._values(e.left, start)
        at = self.spaced_minus.get(id(e))
        text = self.text[start:at] if at is not None else ""
        if at is not None and text.count("(") == text.count(")"):
            sign = self._s_from(at, e.right.span)
            return [*parts, ast.Neg(sign, e.right)]
        last = parts[-1]
        span = Span(self.filename, last.span.line, last.span.col, e.span.end_line,
                    e.span.end_col)
        return [*parts[:-1], ast.BinOp(span, e.op, last, e.right)]

    def _s_from(self, offset: int, end: Span) -> Span:
        """The span from text offset `offset` to the end of `end`."""
        line = self.text.count("\n", 0, offset) + 1
        col = offset - (self.text.rfind("\n", 0, offset) + 1) + 1
        return Span(self.filename, line, col, end.end_line, end.end_col)

    def var_decl(self, meta, c):
        return ast.VarDecl(self._s(meta), str(c[0]), self._t(c[0]), c[1])

    def attr_decl(self, meta, c):
        return ast.AttrDecl(self._s(meta), str(c[0]), self._t(c[0]), c[1])

    def status_decl(self, meta, c):
        return ast.StatusDecl(self._s(meta), str(c[0]), self._t(c[0]),
                              tuple(_nodes(c[1:], ast.Stmt)))

    def invariant_decl(self, meta, c):
        return ast.InvariantDecl(self._s(meta), str(c[0]), self._t(c[0]), c[1])

    def eventually_decl(self, meta, c):
        return ast.EventuallyDecl(self._s(meta), str(c[0]), self._t(c[0]), c[1], c[2])

    def response_decl(self, meta, c):
        return ast.ResponseDecl(self._s(meta), str(c[0]), self._t(c[0]), c[1], c[2], c[3])

    def final_status(self, meta, c):
        return dataclasses.replace(c[0], final=True)

    def metric_decl(self, meta, c):
        return ast.MetricDecl(self._s(meta), str(c[0]), self._t(c[0]), c[1])

    def objective_decl(self, meta, c):
        return ast.ObjectiveDecl(self._s(meta), str(c[0]), self._t(c[0]), c[1])

    # ---- statements ----
    def let_stmt(self, meta, c):
        return ast.LetStmt(self._s(meta), str(c[0]), self._t(c[0]), c[1])

    def assign_stmt(self, meta, c):
        return ast.AssignStmt(self._s(meta), str(c[0]), self._t(c[0]), str(c[1]), c[2])

    def when_stmt(self, meta, c):
        cond, target = c[0], c[1]
        body = c[2] if len(c) > 2 and c[2] is not None else ()
        return ast.WhenStmt(self._s(meta), cond, str(target), self._t(target), tuple(body))

    def when_body(self, meta, c):
        return tuple(_nodes(c, ast.Stmt))

    def action_stmt(self, meta, c):
        return ast.ActionStmt(self._s(meta), str(c[0]), self._t(c[0]),
                              tuple(x for x in c[1:] if x is not None))

    # ---- expressions ----
    def where(self, meta, c):
        return ast.Where(self._s(meta), c[0], c[1])

    def cond(self, meta, c):
        return ast.Cond(self._s(meta), c[0], c[1], c[2])

    def or_op(self, meta, c):
        return ast.OrOp(self._s(meta), c[0], c[1])

    def and_op(self, meta, c):
        return ast.AndOp(self._s(meta), c[0], c[1])

    def not_op(self, meta, c):
        return ast.NotOp(self._s(meta), c[0])

    def compare(self, meta, c):
        return ast.Compare(self._s(meta), str(c[1]), c[0], c[2])

    def bin_op(self, meta, c):
        node = ast.BinOp(self._s(meta), str(c[1]), c[0], c[2])
        at = c[1].start_pos
        if (str(c[1]) == "-" and at is not None and 0 < at < len(self.text) - 1
                and self.text[at - 1] in " \t" and self.text[at + 1] not in " \t\n"):
            self.spaced_minus[id(node)] = at   # `a -b`: a sign, in an option (`_values`)
        return node

    def chain(self, meta, c):
        rest = tuple((str(c[i]), c[i + 1]) for i in range(1, len(c), 2))
        return ast.Chain(self._s(meta), c[0], rest)

    def neg(self, meta, c):
        return ast.Neg(self._s(meta), c[1])

    def attr(self, meta, c):
        return ast.Attr(self._s(meta), c[0], str(c[1]), self._t(c[1]))

    def num(self, meta, c):
        text = str(c[0])
        is_int = text.isdigit()
        return ast.Num(self._s(meta), float(text), is_int)

    def bool_lit(self, meta, c):
        return ast.BoolLit(self._s(meta), str(c[0]) == "true")

    def str_lit(self, meta, c):
        return ast.StrLit(self._s(meta), str(c[0])[1:-1])

    def name(self, meta, c):
        return ast.Name(self._s(meta), str(c[0]))

    def call(self, meta, c):
        name = c[0]
        default = c[-1]
        each = c[-2]
        args = tuple(x for x in c[1:-2] if x is not None)
        return ast.Call(self._s(meta), str(name), self._t(name), args, each, default)

    def vec(self, meta, c):
        return ast.Vec(self._s(meta), c[0], c[1])

    def field_at(self, meta, c):
        return ast.FieldAt(self._s(meta), c[0], c[2], self._t(c[1]))


def _message_words(args):
    """A message layout lists names and types; between two of them the word `at` parses
    as `FIELD at POINT`, so it is split back into the three names it was written as."""
    for a in args:
        if isinstance(a, ast.FieldAt) and isinstance(a.field, ast.Name) \
                and isinstance(a.point, ast.Name):
            yield a.field
            yield ast.Name(a.at_span, "at")
            yield a.point
        else:
            yield a


# Rules that language extensions keep in their own modules (same conventions as above).
for _name, _rule in vars(TreeToAst).items():
    if callable(_rule) and not _name.startswith("_"):
        setattr(ToAst, _name, v_args(meta=True)(_rule))
