"""Long operator chains and deep nesting in the parse tree, handled without recursion.

A generated program may hold a sum of thousands of terms or thousands of nested `not`s.
Every later stage (tree transformer, checker, codegen, analyses, closures at run time)
walks the tree recursively, so the parse tree is made shallow here, before any of them
sees it: a long left-to-right chain of one precedence level (`a + b - c ...`,
`a * b / c ...`, `p and q and ...`) becomes one flat `chain` node, and anything still
nested deeper than `MAX_NESTING` is refused with a located error.
"""

from __future__ import annotations

from lark import Token, Tree

from swarmdsl.errors import Span, SwarmSyntaxError
from swarmdsl.ops.operators import ARITHMETIC

# Levels of expressions and blocks a program may nest. Hand-written programs stay under
# 20; the limit keeps every recursive stage far inside Python's recursion limit.
MAX_NESTING = 100

# A chain this long or longer becomes one flat node; shorter ones stay binary, which is
# what the checker's analyses and codegen's special cases look for.
CHAIN_MIN_TERMS = 8

_FAMILY = {op.symbol: op.family for op in ARITHMETIC.values() if op.family}   # ops rows


def _family(t) -> str | None:
    if not isinstance(t, Tree):
        return None
    if t.data == "bin_op":
        return _FAMILY.get(str(t.children[1]))
    if t.data in ("and_op", "or_op"):
        return t.data
    return None


def _op_and_right(t: Tree) -> tuple[str, object]:
    if t.data == "bin_op":
        return str(t.children[1]), t.children[2]
    return ("and" if t.data == "and_op" else "or"), t.children[1]


def _collapse(t):
    family = _family(t)
    if family is None:
        return t
    rest = []
    node = t
    while _family(node) == family:
        rest.append(_op_and_right(node))
        node = node.children[0]
    if len(rest) + 1 < CHAIN_MIN_TERMS:
        return t
    children = [node]
    for op, right in reversed(rest):
        children.extend((Token("CHAIN_OP", op), right))
    return Tree("chain", children, meta=t.meta)


def flatten_and_limit(tree: Tree, filename: str) -> Tree:
    """Flatten long chains in place, then refuse nesting deeper than MAX_NESTING."""
    stack = [tree]
    while stack:
        t = stack.pop()
        for i, c in enumerate(t.children):
            if isinstance(c, Tree):
                flat = _collapse(c)
                t.children[i] = flat
                stack.append(flat)
    depths = [(tree, 0)]
    while depths:
        t, depth = depths.pop()
        if depth > MAX_NESTING:
            meta = t.meta
            span = (Span(filename, meta.line, meta.column, meta.end_line, meta.end_column)
                    if not getattr(meta, "empty", True) else Span.point(filename, 1, 1))
            raise SwarmSyntaxError(
                f"nested too deeply: more than {MAX_NESTING} levels of expressions and "
                "blocks", span,
                hint="give parts of the expression names with `let` or `param`")
        depths.extend((c, depth + 1) for c in t.children if isinstance(c, Tree))
    return tree
