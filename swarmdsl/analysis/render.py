"""Status graphs as Graphviz DOT or Mermaid text.

Edges are labelled with their `when` condition as written; one whose condition is never
true is dashed and grey (DOT) or labelled "(never true)" (Mermaid). The initial status
has a double border (DOT) or an entry arrow from `[*]` (Mermaid); unreachable statuses
are dashed and grey, statuses with no way out (not `final`) are drawn bold (DOT) or
get a note (Mermaid: "unreachable", "no way out").
"""

from __future__ import annotations

from swarmdsl.compiler.labels import guard_text
from swarmdsl.compiler.status_graph import KindGraph


def _dot_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def to_dot(graphs: list[KindGraph], source: str, title: str = "statuses") -> str:
    out = [f"digraph {_dot_str(title)} {{", "  rankdir=LR;",
           '  node [shape=box, style=rounded, fontname="Helvetica"];',
           '  edge [fontname="Helvetica", fontsize=10];']
    for g in graphs:
        out.append(f"  subgraph {_dot_str('cluster_' + g.kind)} {{")
        out.append(f"    label={_dot_str(g.kind)};")
        unreachable, dead = set(g.unreachable), set(g.dead_ends)
        for s in g.statuses:
            attrs = [f"label={_dot_str(s)}"]
            if s in g.initial:
                attrs.append("peripheries=2")
            if s in g.final:
                attrs.append("shape=doubleoctagon")
            if s in unreachable:
                attrs.append('style="rounded,dashed", color=grey, fontcolor=grey')
            elif s in dead:
                attrs.append('style="rounded,bold"')
            out.append(f"    {_dot_str(g.kind + '.' + s)} [{', '.join(attrs)}];")
        out.append("  }")
        for t in g.transitions:
            label = guard_text(source, t.guard.span)
            attrs = [f"label={_dot_str(label)}"]
            if t.never:
                attrs.append("style=dashed, color=grey")
            out.append(f"  {_dot_str(g.kind + '.' + t.source)} -> "
                       f"{_dot_str(g.kind + '.' + t.target)} [{', '.join(attrs)}];")
    out.append("}")
    return "\n".join(out) + "\n"


def _mermaid_label(text: str) -> str:
    # Mermaid ends a transition label at the line end and reads `:` and `;` specially.
    return text.replace(";", ",").replace(":", "∶") or "always"


# Words Mermaid's state-diagram lexer reads as keywords (case-insensitively) wherever a
# state id may stand: a status named `note` or `State` cannot be its own id.
_MERMAID_WORDS = frozenset({"state", "note", "scale", "direction", "class", "classdef",
                            "style", "acctitle", "accdescr", "hide", "end", "as"})


def _mermaid_ids(graphs: list[KindGraph], nested: bool) -> dict[tuple[str, str], str]:
    """A Mermaid id for each (kind, status), distinct from every other id and kind.

    The readable id is the status (one kind) or `kind_status` (several, inside a
    composite state named after the kind). That spelling is not one-to-one: kind `a`
    with status `b_c` and kind `a_b` with status `c` both read `a_b_c`, and Mermaid then
    draws one state with both kinds' edges. A clash or a keyword gets `_2`, `_3`, ...;
    the status keeps its name as the state's label.
    """
    used = {g.kind for g in graphs} if nested else set()
    ids: dict[tuple[str, str], str] = {}
    for g in graphs:
        for s in g.statuses:
            base = f"{g.kind}_{s}" if nested else s
            ident, n = base, 1
            while ident in used or ident.lower() in _MERMAID_WORDS:
                n += 1
                ident = f"{base}_{n}"
            used.add(ident)
            ids[g.kind, s] = ident
    return ids


def to_mermaid(graphs: list[KindGraph], source: str) -> str:
    out = ["stateDiagram-v2"]
    nested = len(graphs) > 1
    ids = _mermaid_ids(graphs, nested)
    for g in graphs:
        pad = "    " if nested else "  "
        if nested:
            out.append(f"  state {g.kind} {{")
        ident = {s: ids[g.kind, s] for s in g.statuses}
        for s in g.statuses:
            if ident[s] != s:
                out.append(f"{pad}state \"{s}\" as {ident[s]}")
        for s in g.initial:
            out.append(f"{pad}[*] --> {ident[s]}")
        for t in g.transitions:
            # Mermaid's state diagrams cannot dash an edge (DOT does): say it instead,
            # rather than leave out a transition the program has
            label = _mermaid_label(guard_text(source, t.guard.span)
                                   + (" (never true)" if t.never else ""))
            out.append(f"{pad}{ident[t.source]} --> {ident[t.target]} : {label}")
        for s in g.statuses:
            if s in g.final:
                out.append(f"{pad}{ident[s]} --> [*]")
            elif not any(t.source == s or t.target == s for t in g.transitions) \
                    and s not in g.initial:
                out.append(f"{pad}{ident[s]}")
        for s in g.unreachable:
            out.append(f"{pad}note right of {ident[s]} : unreachable")
        for s in g.dead_ends:      # DOT draws them bold; Mermaid's states have no style
            if s not in g.unreachable:
                out.append(f"{pad}note right of {ident[s]} : no way out")
        if nested:
            out.append("  }")
    return "\n".join(out) + "\n"
