"""Completion in context: what may be written where the cursor stands.

The text being typed rarely parses (`other.` is not a program yet), so the context
comes from the text itself: which `{ }` blocks are open at the cursor (an agent, a
status, the world, a tree) and what precedes the cursor on its line (`other.`, `->`,
`at`). The names offered come from the last analysis of the document that parsed (the
checker's declarations and types), plus the `let`s written above the cursor in the
open status, which are read from the current text so the newest one is there.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass

from swarmdsl.lsp.analysis import Analysis


@dataclass(frozen=True)
class Item:
    label: str
    kind: str                 # function, variable, keyword, enum (status), ...
    detail: str = ""
    doc: str | None = None
    insert: str | None = None  # snippet text (with $1 placeholders) when set
    sort: str = "5"           # lower sorts first


@dataclass
class Context:
    blocks: list              # headers of the `{` blocks open at the cursor, outermost first
    kind: str | None
    status: str | None
    in_tree: bool
    status_start: int | None  # offset of the open status's `{`


_HEADER_KIND = re.compile(r"^\s*agent\s+(\w+)")
_HEADER_STATUS = re.compile(r"^\s*(?:final\s+)?status\s+(\w+)")
@functools.cache
def _tree_words() -> re.Pattern:
    """The words that put the cursor inside a tree: the tree node rows'
    (`runtime/trees.py`), loaded on the first completion."""
    from swarmdsl.runtime.trees import node_keywords

    return re.compile(r"\b(tree|" + "|".join(w for w in node_keywords() if w != "reactive")
                      + r")\b")


def context_at(text: str, offset: int) -> Context:
    """The blocks open at `offset`: a `{` pushes the words written before it on its
    statement, a `}` pops one. Comments and strings are skipped."""
    stack: list[tuple[str, int]] = []
    start = 0              # where the current statement's words began
    i, n = 0, min(offset, len(text))
    while i < n:
        c = text[i]
        if c == "#":
            j = text.find("\n", i)
            i = n if j < 0 or j > n else j
            continue
        if c == '"':
            j = text.find('"', i + 1)
            i = n if j < 0 or j >= n else j + 1
            continue
        if c == "{":
            stack.append((text[start:i], i))
            start = i + 1
        elif c == "}":
            if stack:
                stack.pop()
            start = i + 1
        elif c in ";\n":
            start = i + 1
        i += 1
    headers = [h for h, _ in stack]
    kind = status = None
    status_start = None
    in_tree = False
    for h, at in stack:
        m = _HEADER_KIND.match(h)
        if m:
            kind = m.group(1)
        m = _HEADER_STATUS.match(h)
        if m:
            status, status_start = m.group(1), at
        if _tree_words().search(h):
            in_tree = True
    return Context(headers, kind, status, in_tree, status_start)


TOP_KEYWORDS = ("param", "world", "field", "region", "food", "obstacle", "nest", "robot",
                "agent", "tree", "invariant", "eventually", "always", "metric")
KIND_KEYWORDS = ("var", "attr", "status", "final status", "objective", "invariant",
                 "eventually", "always", "metric")
STATUS_KEYWORDS = ("let", "when", "tree", "on success ->", "on failure ->")
EXPR_KEYWORDS = ("if", "then", "else", "and", "or", "not", "where", "true", "false")


def tree_keywords() -> tuple[str, ...]:
    """The words a tree node may start with, from the rows (`runtime/trees.py`)."""
    from swarmdsl.runtime.trees import COMPOSITES, DECORATORS

    return (*COMPOSITES, "reactive", *DECORATORS, "forever")
_FIELD_TAKERS = ("sample", "gradient", "ahead", "deposit", "follow")


def completions(analysis: Analysis | None, text: str, offset: int) -> list[Item]:
    """Items for the cursor at `offset` of `text`; `analysis` is the document's last
    analysis that parsed (None before any did)."""
    before = text[:offset]
    line = before[before.rfind("\n") + 1:]
    ctx = context_at(text, offset)
    index = analysis.index if analysis is not None else None
    if re.search(r"\bother\.\w*$", line):
        return _other_members(analysis)
    if re.search(r"\.\w*$", line):
        return [Item("x", "field", "a number"), Item("y", "field", "a number")]
    if re.search(r"->\s*\w*$", line):
        return _statuses(index, ctx.kind, "0")
    if re.search(r"\bat\s+\w*$", line):
        return [i for i in _names(analysis, before, ctx) if i.detail == "a vector"] + [
            Item("pos", "variable", "a vector", "the agent's own position", sort="0")]
    items: list[Item] = []
    if not ctx.blocks:
        return [Item(k, "keyword", sort="1") for k in TOP_KEYWORDS]
    head = ctx.blocks[-1]
    if re.match(r"^\s*world\b", head):
        return _options("world") + [Item(k, "keyword") for k in ("in",)]
    if ctx.kind and ctx.status is None:
        items += _options("agent") + [Item(k, "keyword", sort="1") for k in KIND_KEYWORDS]
    if ctx.status is not None:
        statement_start = not line.strip() or re.fullmatch(r"\s*\w*", line)
        if statement_start:
            items += [Item(k, "keyword", sort="1") for k in STATUS_KEYWORDS]
            items += _actions()
        if ctx.in_tree:
            items += [Item(k, "keyword", sort="1") for k in tree_keywords()]
            items += _long_actions()
    items += [Item(k, "keyword", sort="6") for k in EXPR_KEYWORDS]
    items += _names(analysis, before, ctx)
    items += _builtins()
    m = re.search(r"\b(\w+)\(\s*\w*$", line)
    if m and m.group(1) in _FIELD_TAKERS:
        items = [Item(i.label, i.kind, i.detail, i.doc, i.insert, "0")
                 if i.detail == "field" else i for i in items]
    return _unique(items)


def _unique(items: list[Item]) -> list[Item]:
    seen, out = set(), []
    for i in items:
        if i.label not in seen:
            seen.add(i.label)
            out.append(i)
    return out


def _other_members(analysis: Analysis | None) -> list[Item]:
    from swarmdsl.compiler.builtins import TYPE_TEXT
    from swarmdsl.compiler.info import AGENT_STATE

    items = [Item(n, "property", TYPE_TEXT[t], f"the neighbour's `{n}`", sort="1")
             for n, (t, _a, _c) in AGENT_STATE.items()]
    chk = analysis.checker if analysis is not None else None
    if chk is not None:
        for k in chk.kinds:
            for v in k.vars.values():
                items.append(Item(v.name, "field", TYPE_TEXT.get(v.type, v.type),
                                  f"variable of `{k.name}`", sort="0"))
    return _unique(items)


def _statuses(index, kind: str | None, sort: str) -> list[Item]:
    if index is None:
        return []
    out = []
    for key, sym in index.symbols.items():
        if key[0] == "status" and (kind is None or key[1] == kind):
            out.append(Item(sym.name, "enum", "status", f"status of `{key[1]}`", sort=sort))
    if not out and kind is not None:
        return _statuses(index, None, sort)
    return out


def _options(owner: str) -> list[Item]:
    from swarmdsl.compiler.options import AGENT_OPTIONS, WORLD_OPTIONS
    from swarmdsl.lsp.hover import _option_doc

    table = AGENT_OPTIONS if owner == "agent" else WORLD_OPTIONS
    return [Item(n, "property", f"{owner} option", _option_doc(owner, n), sort="2")
            for n in table]


def _actions() -> list[Item]:
    from swarmdsl.compiler.actions import ACTIONS

    return [Item(n, "method", "action", a.doc, f"{n}($1)", sort="3")
            for n, a in ACTIONS.items()]


def _long_actions() -> list[Item]:
    from swarmdsl.compiler.tree_ast import LONG_ACTIONS

    out = []
    for n, (usage, lo, _hi) in LONG_ACTIONS.items():
        args = re.findall(r"[A-Za-z_]+", usage.split("(", 1)[1])[:lo]
        snippet = ", ".join(f"${{{i + 1}:{a}}}" for i, a in enumerate(args))
        out.append(Item(n, "method", usage, "long action", f"{n}({snippet})", "3"))
    return out


def _builtins() -> list[Item]:
    from swarmdsl.compiler.builtins import AGGREGATES, CONSTANTS, FUNCTIONS
    from swarmdsl.compiler.info import GLOBAL_STATE, PAIR_NAMES
    from swarmdsl.lsp.hover import _TYPE_WORD, signature

    items = []
    for n, row in AGGREGATES.items():
        snippet = f"{n}(${{1:near}})" if not row.needs_each else \
            f"{n}(${{1:near}} : ${{2:other.pos}})"
        items.append(Item(n, "function", signature("aggregate", n), row.doc, snippet, "4"))
    for n, b in FUNCTIONS.items():
        args = ", ".join(f"${{{i + 1}:{_TYPE_WORD.get(p, p)}}}" for i, p in enumerate(b.params))
        items.append(Item(n, "function", signature("function", n), b.doc, f"{n}({args})",
                          "4"))
    items.append(Item("neighbors", "function", "neighbors([RADIUS]) -> a neighbour set",
                      "the other agents within RADIUS", "neighbors(${1:radius})", "4"))
    items += [Item(n, "constant", "a number", "a named constant", sort="5")
              for n in CONSTANTS]
    items += [Item(n, "variable", "a number", sort="5") for n in (*GLOBAL_STATE, *PAIR_NAMES)]
    items.append(Item("other", "variable", "the neighbour", sort="5"))
    return items


def _names(analysis: Analysis | None, text: str, ctx: Context) -> list[Item]:
    from swarmdsl.compiler.builtins import TYPE_TEXT
    from swarmdsl.compiler.info import AGENT_STATE

    items: list[Item] = []
    if ctx.status_start is not None:      # the `let`s above the cursor, as typed now
        for m in re.finditer(r"\blet\s+(\w+)", text[ctx.status_start:]):
            items.append(Item(m.group(1), "variable", _local_type(analysis, ctx, m.group(1)),
                              "`let` binding", sort="0"))
    if analysis is not None and analysis.index is not None:
        chk = analysis.checker
        for key, sym in analysis.index.symbols.items():
            cat = key[0]
            if cat == "var" and key[1] == ctx.kind:
                t = _var_type(chk, key[1], sym.name)
                items.append(Item(sym.name, "variable", t, f"{sym.category} of `{key[1]}`",
                                  sort="0"))
            elif cat in ("param", "field", "region", "kind"):
                detail = {"param": "param", "field": "field", "region": "region",
                          "kind": "agent kind"}[cat]
                items.append(Item(sym.name, "constant" if cat == "param" else "struct",
                                  detail, sort="1"))
            elif cat in ("slot", "objective") and key[1] == ctx.kind:
                items.append(Item(sym.name, "variable", sym.category, sort="1"))
            elif cat == "tree" and ctx.in_tree:
                items.append(Item(sym.name, "function", "behaviour tree", sort="2"))
        if ctx.kind:
            items += _statuses(analysis.index, ctx.kind, "2")
    items += [Item(n, "variable", TYPE_TEXT[t], "built-in agent state", sort="3")
              for n, (t, _a, _c) in AGENT_STATE.items()]
    return items


def _var_type(chk, kind: str, name: str) -> str:
    from swarmdsl.compiler.builtins import TYPE_TEXT

    if chk is None:
        return "variable"
    k = next((k for k in chk.kinds if k.name == kind), None)
    v = k.vars.get(name) if k is not None else None
    return TYPE_TEXT.get(v.type, "variable") if v is not None else "variable"


def _local_type(analysis, ctx: Context, name: str) -> str:
    from swarmdsl.compiler.builtins import TYPE_TEXT

    if analysis is None or analysis.index is None or analysis.checker is None:
        return "let"
    sym = analysis.index.symbols.get(("local", ctx.kind, ctx.status, name))
    if sym is None:
        return "let"
    t = analysis.checker.facts.type_of(sym.decl.value)
    return TYPE_TEXT.get(t, "let")
