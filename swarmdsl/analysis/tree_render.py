"""Behaviour trees drawn beside the status graph: Graphviz DOT clusters, Mermaid
flowcharts.

Composites and decorators are labelled with their keyword (`reactive fallback`,
`timeout 20`), leaves with their source text; a named tree's use is a node of its own
above the expanded body. Conditions are ellipses, instant actions boxes, long actions
bold boxes, composites and decorators rounded boxes.
"""

from __future__ import annotations

from swarmdsl.compiler.facts import NodeTable
from swarmdsl.compiler.labels import describe


def status_trees(info, kinds=None) -> list[tuple[str, str, object]]:
    """`(kind, status, expanded root)` for every status whose body holds a tree."""
    from swarmdsl.compiler.tree_ast import TreeStmt

    roots = info.extra["trees"].roots if "trees" in info.extra else NodeTable()
    out = []
    for k in info.kinds:
        if kinds is not None and k.name not in kinds:
            continue
        for s in k.statuses:
            for st in k.status_decls[s].body:
                if isinstance(st, TreeStmt) and st in roots:
                    out.append((k.name, s, roots[st]))
    return out


def _walk(root, source, leaves):
    """(index, parent index or None, label, shape) in depth-first order, no recursion."""
    stack = [(root, None)]
    count = 0
    while stack:
        node, parent = stack.pop()
        label, shape, kids = describe(node, source, leaves)
        me = count
        count += 1
        yield me, parent, label, shape
        stack.extend((k, me) for k in reversed(kids))


def _dot_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


_DOT_SHAPE = {
    "composite": 'shape=box, style="rounded,filled", fillcolor="#e8eef7"',
    "decorator": 'shape=box, style="rounded,dashed"',
    "subtree": 'shape=tab',
    "condition": 'shape=ellipse',
    "action": 'shape=box',
    "long": 'shape=box, style=bold',
}


def dot_clusters(info, source: str, kinds=None) -> list[str]:
    """DOT lines (clusters and the dashed edge from each status to its tree) to put
    inside the status graph's digraph."""
    leaves = info.extra["trees"].leaves if "trees" in info.extra else NodeTable()
    out = []
    for kind, status, root in status_trees(info, kinds):
        prefix = f"tree:{kind}.{status}:"
        out.append(f"  subgraph {_dot_str('cluster_tree_' + kind + '.' + status)} {{")
        out.append(f"    label={_dot_str('tree of ' + kind + '.' + status)}; rankdir=TB;")
        edges = []
        for i, parent, label, shape in _walk(root, source, leaves):
            out.append(f"    {_dot_str(prefix + str(i))} [label={_dot_str(label)}, "
                       f"{_DOT_SHAPE[shape]}];")
            if parent is not None:
                edges.append(f"    {_dot_str(prefix + str(parent))} -> "
                             f"{_dot_str(prefix + str(i))};")
        out.extend(edges)
        out.append("  }")
        out.append(f"  {_dot_str(kind + '.' + status)} -> {_dot_str(prefix + '0')} "
                   "[style=dashed, arrowhead=none, color=grey];")
    return out


_MERMAID_SHAPE = {
    "composite": ('(["', '"])'), "decorator": ('{{"', '"}}'), "subtree": ('[["', '"]]'),
    "condition": ('("', '")'), "action": ('["', '"]'), "long": ('[/"', '"/]'),
}


def _mermaid_text(s: str) -> str:
    return s.replace('"', "#quot;")


def mermaid_flowcharts(info, source: str, kinds=None) -> list[str]:
    """One Mermaid flowchart (as text) per tree."""
    leaves = info.extra["trees"].leaves if "trees" in info.extra else NodeTable()
    charts = []
    for kind, status, root in status_trees(info, kinds):
        lines = ["flowchart TD", f"  %% the tree of {kind}.{status}"]
        for i, parent, label, shape in _walk(root, source, leaves):
            left, right = _MERMAID_SHAPE[shape]
            lines.append(f"  n{i}{left}{_mermaid_text(label)}{right}")
            if parent is not None:
                lines.append(f"  n{parent} --> n{i}")
        charts.append("\n".join(lines) + "\n")
    return charts
