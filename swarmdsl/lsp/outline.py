"""The shape of a document: its outline (document symbols), the blocks an editor can
fold, and semantic tokens (what each word is, for highlighting by meaning).

The outline and folds come from the AST's spans; semantic tokens from the index (names
by what the checker resolved them to) and from the grammar's own lexer (keywords,
numbers, strings, comments), so the highlighting knows exactly the words the parser
knows.
"""

from __future__ import annotations

import bisect
import re
from dataclasses import dataclass, field

from swarmdsl.compiler import ast
from swarmdsl.lsp.analysis import Analysis
from swarmdsl.lsp.ranges import Range


@dataclass
class OutlineItem:
    name: str
    kind: str            # an LSP SymbolKind name: Class, Variable, Constant, ...
    detail: str
    range: Range
    selection: Range
    children: list = field(default_factory=list)


def outline(analysis: Analysis) -> list[OutlineItem]:
    from swarmdsl.compiler.tree_ast import TreeDecl

    tree = analysis.tree
    if tree is None:
        return []
    out = []
    for d in tree.decls:
        r = Range.of(d.span)
        if isinstance(d, ast.ParamDecl):
            out.append(OutlineItem(d.name, "Constant", "param", r, Range.of(d.name_span)))
        elif isinstance(d, ast.WorldDecl):
            out.append(OutlineItem("world", "Namespace", "world", r, r))
        elif isinstance(d, ast.FieldDecl):
            out.append(OutlineItem(d.name, "Field", "field", r, Range.of(d.name_span)))
        elif isinstance(d, ast.RegionDecl):
            out.append(OutlineItem(d.name, "Object", d.keyword, r, Range.of(d.name_span)))
        elif isinstance(d, ast.RobotDecl):
            out.append(OutlineItem(d.name, "Interface", "robot", r, Range.of(d.name_span)))
        elif isinstance(d, TreeDecl):
            out.append(OutlineItem(d.name, "Function", "tree", r, Range.of(d.name_span)))
        elif isinstance(d, ast.AgentDecl):
            out.append(_agent(d))
        elif hasattr(d, "name_span"):
            kind = "Event" if isinstance(d, ast.MetricDecl) else "Boolean"
            word = "metric" if isinstance(d, ast.MetricDecl) else "property"
            out.append(OutlineItem(d.name, kind, word, r, Range.of(d.name_span)))
    return out


def _agent(d: ast.AgentDecl) -> OutlineItem:
    item = OutlineItem(d.name, "Class", "agent", Range.of(d.span), Range.of(d.name_span))
    for i in d.items:
        r = Range.of(i.span)
        if isinstance(i, ast.VarDecl | ast.AttrDecl):
            word = "var" if isinstance(i, ast.VarDecl) else "attr"
            item.children.append(OutlineItem(i.name, "Variable", word, r,
                                             Range.of(i.name_span)))
        elif isinstance(i, ast.StatusDecl):
            s = OutlineItem(i.name, "EnumMember", "final status" if i.final else "status",
                            r, Range.of(i.name_span))
            for st in i.body:
                if isinstance(st, ast.LetStmt):
                    s.children.append(OutlineItem(st.name, "Variable", "let",
                                                  Range.of(st.span), Range.of(st.name_span)))
            item.children.append(s)
        elif isinstance(i, ast.ObjectiveDecl):
            item.children.append(OutlineItem(i.name, "Variable", "objective", r,
                                             Range.of(i.name_span)))
        elif isinstance(i, ast.Option):
            continue
        elif hasattr(i, "name_span"):
            kind = "Event" if isinstance(i, ast.MetricDecl) else "Boolean"
            word = "metric" if isinstance(i, ast.MetricDecl) else "property"
            item.children.append(OutlineItem(i.name, kind, word, r, Range.of(i.name_span)))
    return item


def folds(analysis: Analysis) -> list[tuple[int, int, str]]:
    """(first line, last line, "region" | "comment"), 0-based, each spanning lines."""
    out = []
    if analysis.tree is not None:
        from swarmdsl.compiler.tree_ast import Composite, TreeDecl, TreeStmt

        foldable = (ast.WorldDecl, ast.FieldDecl, ast.RobotDecl, ast.AgentDecl,
                    ast.StatusDecl, ast.WhenStmt, TreeStmt, TreeDecl, Composite)
        for node in ast.walk(analysis.tree):
            if isinstance(node, foldable) and node.span.end_line > node.span.line:
                out.append((node.span.line - 1, node.span.end_line - 1, "region"))
    run_start = None
    lines = analysis.text.splitlines()
    for i, line in enumerate([*lines, ""]):
        if line.lstrip().startswith("#"):
            run_start = i if run_start is None else run_start
        else:
            if run_start is not None and i - 1 > run_start:
                out.append((run_start, i - 1, "comment"))
            run_start = None
    return sorted(set(out))


TOKEN_TYPES = ["namespace", "type", "class", "enum", "enumMember", "parameter", "variable",
               "property", "function", "method", "keyword", "comment", "string", "number",
               "operator", "event", "macro"]
TOKEN_MODIFIERS = ["declaration", "readonly", "defaultLibrary"]

_CATEGORY_TOKEN = {
    "param": ("variable", {"readonly"}), "var": ("variable", set()),
    "attr": ("variable", {"readonly"}), "local": ("variable", set()),
    "status": ("enumMember", set()), "kind": ("class", set()),
    "field": ("property", set()), "region": ("namespace", set()),
    "robot": ("type", set()), "tree": ("function", set()),
    "tree_param": ("parameter", set()), "objective": ("variable", set()),
    "slot": ("variable", set()), "metric": ("event", set()), "property": ("event", set()),
}
_BUILTIN_TOKEN = {
    "function": "function", "aggregate": "function", "neighbors": "function",
    "call": "function", "action": "method", "long_action": "method",
    "state": "variable", "global": "variable", "pair": "variable", "constant": "variable",
    "tree_node": "keyword", "component": "property",
}


def semantic_tokens(analysis: Analysis) -> list[tuple[int, int, int, str, set]]:
    """(line, col, length, type, modifiers), sorted, not overlapping, one line each."""
    found: dict[tuple[int, int], tuple[int, str, set]] = {}
    for line, col, length, ttype in _lexed(analysis.text):
        found[(line, col)] = (length, ttype, set())
    index = analysis.index
    if index is not None:
        for occ in index.occurrences:
            r = occ.range
            if r.end_line != r.line:
                continue
            key = occ.key
            if key[0] == "builtin":
                ttype = _BUILTIN_TOKEN.get(key[1], "property" if key[1].endswith("_option")
                                           else "variable")
                mods = {"defaultLibrary"}
                if key[1] in ("constant", "global"):
                    mods.add("readonly")
            else:
                ttype, mods = _CATEGORY_TOKEN.get(key[0], ("variable", set()))
                mods = set(mods)
            if occ.is_def:
                mods.add("declaration")
            found[(r.line, r.col)] = (r.end_col - r.col, ttype, mods)
    out = []
    last_end = (-1, -1)
    for (line, col), (length, ttype, mods) in sorted(found.items()):
        if (line, col) < last_end or length <= 0:
            continue    # overlaps the token before it
        out.append((line, col, length, ttype, mods))
        last_end = (line, col + length)
    return out


_COMMENT = re.compile(r"#[^\n]*")


def _lexed(text: str):
    """(line, col, length, type) of keywords, numbers, strings, operators and comments,
    from the parser's own tokens (`parse.tokens`: a word is what its place makes it)."""
    from swarmdsl.compiler.parse import tokens

    starts = [0] + [m.end() for m in re.finditer("\n", text)]
    end = 0
    kinds = {"NUMBER": "number", "STRING": "string"}
    for ttype, value, start, stop in tokens(text):
        yield from _comments(text, end, start, starts)
        end = stop
        if ttype in kinds:
            yield (*_line_col(starts, start), len(value), kinds[ttype])
        elif ttype != "NAME" and value[:1].isalpha():
            yield (*_line_col(starts, start), len(value), "keyword")
        elif ttype in ("PLUS", "MINUS", "MUL_OP", "POW_OP", "CMP_OP", "EQ", "ASSIGN_OP",
                       "__ANON_1"):
            yield (*_line_col(starts, start), len(value), "operator")
    yield from _comments(text, end, len(text), starts)


def _comments(text: str, a: int, b: int, starts: list[int]):
    """The comments between two tokens (nothing else but blanks and `;` lies there)."""
    for m in _COMMENT.finditer(text, a, b):
        yield (*_line_col(starts, m.start()), len(m.group().rstrip()), "comment")


def _line_col(starts: list[int], offset: int) -> tuple[int, int]:
    line = bisect.bisect_right(starts, offset) - 1
    return line, offset - starts[line]
