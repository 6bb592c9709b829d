"""Text -> AST: the parse-tree transformer (`ToAst`), the text's tokens, the grammar's
keywords. With the parser (`lalr.py`) and the syntax errors' messages
(`syntax_messages.py`), the only modules that see lark and its exceptions."""

from __future__ import annotations

import dataclasses
import functools
import re

from lark import Token, Transformer, v_args
from lark.exceptions import (
    UnexpectedCharacters,
    UnexpectedInput,
    VisitError,
)

from swarmdsl.compiler import ast, syntax_rules, tree_ast  # noqa: F401  trees' rules register
from swarmdsl.compiler.facts import NodeTable
from swarmdsl.compiler.lalr import grammar_parser_without_postlex, parser  # noqa: F401
from swarmdsl.compiler.nesting import flatten_and_limit
from swarmdsl.compiler.syntax_messages import syntax_error
from swarmdsl.errors import (
    Span,
    SwarmError,
    SwarmSyntaxError,
    lone_cr_as_newline,
    source_lines,
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
        raise syntax_error(exc, text, filename) from None
    flatten_and_limit(tree, filename)
    _take_registered_rules()
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

    def __default__(self, data, children, meta):
        """A rule no method builds: a language extension's, registered when its module
        is imported (the extensions are imported once, at the first such rule); any
        other stays lark's tree, as without this method."""
        if not _extensions_imported[0]:
            _extensions_imported[0] = True
            _import_extensions()
            _take_registered_rules()
            rule = getattr(self, data, None)
            if rule is not None:
                return rule.visit_wrapper(rule, data, children, meta)
        return super().__default__(data, children, meta)

    def __init__(self, filename: str, text: str = ""):
        super().__init__()
        self.filename = filename
        self.text = text
        # id of a `a -b` subtraction (space before the `-`, none after) -> the `-` offset
        self.spaced_minus = NodeTable()   # a `-` read as a sign -> its offset
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
        at = self.spaced_minus.get(e)
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
            self.spaced_minus[node] = at   # `a -b`: a sign, in an option (`_values`)
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


def _take_registered_rules() -> None:
    """`ToAst` takes on the rules registered since it last looked (`syntax_rules`)."""
    while _taken[0] < len(syntax_rules.MIXINS):
        mixin = syntax_rules.MIXINS[_taken[0]]
        for name, rule in vars(mixin).items():
            if callable(rule) and not name.startswith("_"):
                setattr(ToAst, name, v_args(meta=True)(rule))
        _taken[0] += 1


def _import_extensions() -> None:
    from swarmdsl.compiler import extensions  # noqa: F401  their syntax registers


_taken = [0]     # how many of `syntax_rules.MIXINS` ToAst has taken on
_extensions_imported = [False]
_take_registered_rules()
