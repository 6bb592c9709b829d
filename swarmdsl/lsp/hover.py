"""What hovering over a name shows: its type and declaration, or for a built-in its
signature and one-line meaning, read from the row that defines it (`ops/functions.py`
for functions, `compiler/builtins.py` for aggregates, `compiler/actions.py` for
actions, `compiler/options.py` for options, `compiler/tree_ast.py` for tree nodes), so
what the editor says and what the compiler does cannot drift apart."""

from __future__ import annotations

from swarmdsl.compiler import ast
from swarmdsl.lsp.analysis import Analysis
from swarmdsl.lsp.index import CATEGORY_WORDS, Occurrence


def hover_text(analysis: Analysis, line: int, col: int) -> tuple[str, object] | None:
    """Markdown for the name at (line, col) and the range it covers, or None."""
    index = analysis.index
    if index is None:
        return None
    occ = index.at(line, col)
    if occ is None:
        return None
    key = occ.key
    if key[0] == "builtin":
        text = builtin_doc(key[1], key[2])
    else:
        text = _declared(analysis, occ)
    if not text:
        return None
    return text, occ.range


def _type_of(analysis: Analysis, node) -> str | None:
    from swarmdsl.compiler.builtins import TYPE_TEXT

    chk = analysis.checker
    if chk is None or node is None:
        return None
    t = chk.facts.type_of(node)
    return TYPE_TEXT.get(t) if t and t != "error" else None


def _source(analysis: Analysis, decl) -> str:
    """The declaration as written (its first line, or the whole when short)."""
    lines = analysis.text.splitlines()
    span = decl.span
    first = lines[span.line - 1] if span.line - 1 < len(lines) else ""
    if span.end_line == span.line:
        return first[span.col - 1:span.end_col - 1].strip()
    return first[span.col - 1:].rstrip() + " ..."


def _declared(analysis: Analysis, occ: Occurrence) -> str | None:
    from swarmdsl.compiler.builtins import TYPE_TEXT

    index = analysis.index
    symbols = [index.symbols[k] for k in occ.keys if k in index.symbols]
    if not symbols:
        return None
    sym = symbols[0]
    cat = sym.category
    parts = [f"```swarm\n{_source(analysis, sym.decl)}\n```"]
    what = CATEGORY_WORDS.get(cat, cat)
    if cat == "attr":
        what += " (never changes)"
    where = f" of {sym.container}" if sym.container else ""
    line = f"{what} `{sym.name}`{where}, line {sym.range.line + 1}"
    chk = analysis.checker
    t = _type_of(analysis, occ.node if not occ.is_def else None)
    if cat in ("var", "attr") and chk is not None:
        kind = next((k for k in chk.kinds if k.name == sym.key[1]), None)
        v = kind.vars.get(sym.name) if kind is not None else None
        if v is not None and v.type in TYPE_TEXT:
            t = TYPE_TEXT[v.type]
    if cat == "local" and t is None:
        t = _type_of(analysis, sym.decl.value)
    if t:
        line += f": {t}"
    parts.append(line)
    if cat == "param" and chk is not None and sym.name in chk.params:
        decl: ast.ParamDecl = sym.decl
        value = chk.params[sym.name]
        shown = str(value).lower() if isinstance(value, bool) else f"{value:g}"
        extra = ""
        if decl.lo is not None:
            try:
                from swarmdsl.compiler.consteval import const_value

                lo, hi = const_value(decl.lo, chk.params), const_value(decl.hi, chk.params)
                extra = f", range {lo:g}..{hi:g}"
            except Exception:  # noqa: BLE001  a range the checker refused
                extra = ""
        parts.append(f"value {shown}{extra} (`--set {sym.name}=...` changes it)")
    if len(symbols) > 1:
        owners = ", ".join(f"`{s.container}`" for s in symbols)
        parts.append(f"(the same name in {owners})")
    return "\n\n".join(parts)


def signature(category: str, name: str) -> str | None:
    """A built-in's signature as a user writes it, from its row."""
    from swarmdsl.compiler.builtins import AGGREGATES, FUNCTIONS, TYPE_TEXT
    from swarmdsl.compiler.tree_ast import LONG_ACTIONS

    if category == "function" and name in FUNCTIONS:
        b = FUNCTIONS[name]
        args = ", ".join(_TYPE_WORD.get(p, p) for p in b.params)
        return f"{name}({args}) -> {TYPE_TEXT.get(b.result, b.result)}"
    if category == "aggregate" and name in AGGREGATES:
        row = AGGREGATES[name]
        if not row.needs_each:
            return f"{name}(SET) -> a number"
        each = " or ".join(TYPE_TEXT[t] for t in row.each_types)
        default = " [else DEFAULT]" if name in ("mean", "min", "max", "nearest") else ""
        return f"{name}(SET : EACH{default})   EACH: {each}"
    if category == "long_action" and name in LONG_ACTIONS:
        return LONG_ACTIONS[name][0]
    return None


_TYPE_WORD = {"num": "number", "vec": "vector", "bool": "boolean", "str": "string"}


def builtin_doc(category: str, name: str) -> str | None:
    """Markdown for a built-in: its signature and its row's one-line meaning."""
    from swarmdsl.compiler.actions import ACTIONS
    from swarmdsl.compiler.builtins import AGGREGATES, CONSTANTS, FUNCTIONS, TYPE_TEXT
    from swarmdsl.compiler.info import AGENT_STATE, GLOBAL_STATE, PAIR_NAMES
    from swarmdsl.compiler.typing_rules import CALL_RULES

    sig = signature(category, name)
    doc = None
    if category == "function" and name in FUNCTIONS:
        doc = FUNCTIONS[name].doc
    elif category == "aggregate" and name in AGGREGATES:
        doc = AGGREGATES[name].doc
    elif category == "action" and name in ACTIONS:
        doc = ACTIONS[name].doc
        sig = sig or f"{name}(...)"
    elif category == "long_action":
        doc = "a long action of a behaviour tree: running until it succeeds or fails"
    elif category == "neighbors":
        sig = f"{name}([RADIUS]) -> a neighbour set"
        doc = ("the other agents within RADIUS (the kind's `sense` radius without one), "
               "to filter with `where` and aggregate")
    elif category == "call" and name in CALL_RULES:
        sig = f"{name}(...)"
        doc = _first_line(CALL_RULES[name].__doc__)
    elif category == "state" and name in AGENT_STATE:
        t, assignable, column = AGENT_STATE[name]
        sig = f"{name}: {TYPE_TEXT[t]}"
        doc = (f"per-agent state, {'assignable' if assignable else 'read-only'}"
               f" (column `{column}`); `other.{name}` is a neighbour's")
    elif category == "global" and name in GLOBAL_STATE:
        sig, doc = f"{name}: {TYPE_TEXT[GLOBAL_STATE[name]]}", "the current tick, from 0"
    elif category == "pair":
        if name in PAIR_NAMES:
            sig = f"{name}: {TYPE_TEXT[PAIR_NAMES[name]]}"
            doc = "the distance to the neighbour, inside a `where` or an aggregate's `:`"
        else:
            sig, doc = "other", ("the neighbour, inside a `where` or an aggregate's `:`: "
                                 "`other.pos`, `other.status`, `other.VARIABLE`")
    elif category == "constant" and name in CONSTANTS:
        sig, doc = f"{name} = {CONSTANTS[name]!r}", "a named constant"
    elif category.endswith("_option"):
        doc = _option_doc(category.removesuffix("_option"), name)
        sig = f"{category.removesuffix('_option')} option `{name}`"
    elif category == "tree_node":
        from swarmdsl.compiler.tree_ast import Composite, Decorator

        cls = Composite if name in ("sequence", "fallback", "parallel", "reactive") \
            else Decorator
        sig, doc = f"tree node `{name}`", _first_line(cls.__doc__)
    elif category == "component":
        sig, doc = f".{name}: a number", f"the {name} component of a vector"
    parts = []
    if sig:
        parts.append(f"```swarm\n{sig}\n```")
    if doc:
        parts.append(doc)
    return "\n\n".join(parts) or None


def _option_doc(owner: str, name: str) -> str | None:
    from swarmdsl.compiler.options import AGENT_OPTIONS, WORLD_OPTIONS

    table = {"agent": AGENT_OPTIONS, "world": WORLD_OPTIONS}.get(owner, {})
    spec = table.get(name)
    if spec is None:
        return None
    return getattr(spec, "doc", None) or _first_line(getattr(spec, "__doc__", None))


def _first_line(doc: str | None) -> str | None:
    if not doc:
        return None
    return " ".join(doc.strip().split("\n\n")[0].split())
