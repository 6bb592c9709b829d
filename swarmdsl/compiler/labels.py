"""The labels a status graph and a behaviour tree are read by: a guard's source text on
one line, and a tree node's label and shape.

They live in the compiler because the compiled trees are named with them (the
`tree_leaf` column of `--tree-leaf`, the path to a tree node); `swarmdsl graph`
(`analysis/`) draws with the same ones, so a node reads alike everywhere.
"""

from __future__ import annotations


def guard_text(source: str, span, limit: int = 40) -> str:
    """The source text of a span on one line, squeezed and cut to `limit` characters."""
    lines = source.splitlines()
    if not 1 <= span.line <= len(lines):
        return ""
    if span.end_line == span.line:
        text = lines[span.line - 1][span.col - 1:span.end_col - 1]
    else:
        text = " ".join([lines[span.line - 1][span.col - 1:]]
                        + lines[span.line:span.end_line - 1]
                        + [lines[span.end_line - 1][:span.end_col - 1]])
    text = " ".join(text.split())
    return text if len(text) <= limit else text[:limit - 1] + "…"


def describe(node, source: str, leaves: dict) -> tuple[str, str, list]:
    """`(label, shape, children)` of a tree node: shape is one of composite, decorator,
    condition, action, long, subtree."""
    from swarmdsl.compiler.tree_ast import AssignLeaf, Composite, Decorator, Subtree

    if isinstance(node, Subtree):
        return guard_text(source, node.span, 40), "subtree", [node.root]
    if isinstance(node, Composite):
        word = ("reactive " if node.reactive else "") + node.kind
        if node.threshold is not None:
            word += " " + guard_text(source, node.threshold.span, 12)
        return word, "composite", list(node.kids)
    if isinstance(node, Decorator):
        word = node.kind
        if node.count is not None:
            word += " " + guard_text(source, node.count.span, 12)
        return word, "decorator", [node.child]
    text = guard_text(source, node.span, 40)
    if isinstance(node, AssignLeaf):
        return text, "action", []
    what = leaves.get(node, ("cond", None))[0]
    return text, {"cond": "condition", "action": "action", "long": "long"}[what], []
