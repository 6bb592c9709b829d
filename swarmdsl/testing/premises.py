"""The premise of an implication-shaped invariant, so coverage can say how often it held.

`invariant safe: not carrying or speed < 2` (or `status != crowded or ...`, or
`if carrying then speed < 2 else true`) holds trivially on every agent whose premise
is false: a hunt in which no agent ever carried anything passed it without testing
it. "Exercised by 75 of 75 runs" then claims too much, so the tester counts the
agent-ticks at which the premise held, and says so.

The premise is read off the expression (`compiler/implication.py`: a top-level `or`
with negated disjuncts, or `if P then Q else true`). Its closures are compiled from the
property's own checked nodes. A premise that reads `previous(X)` is not counted (a
second evaluation would share the property's memory of the last tick): coverage then
says the premise was not measured, rather than a number it does not know.
"""

from __future__ import annotations

from dataclasses import dataclass

from swarmdsl.compiler import ast
from swarmdsl.compiler.implication import premise_nodes, reads_previous

__all__ = ["Premise", "compile_premise", "premise_nodes"]


@dataclass(frozen=True)
class Premise:
    """The premise of one property: closures of the disjuncts whose falsity is it
    (`negate` True) or of the one condition that is it (`negate` False)."""

    parts: tuple
    negate: bool
    text: str           # how the report names it, e.g. "`carrying`"


def compile_premise(program, info) -> Premise | None:
    """The premise of an `invariant` of `program` (its `PropertyInfo`), or None when it
    is not implication-shaped or its premise reads `previous`."""
    if info.keyword != "invariant":
        return None
    found = premise_nodes(info.decl.expr)
    if found is None:
        return None
    nodes, negate = found
    if reads_previous(nodes):
        return None
    from swarmdsl.compiler.lang_properties import _PropertyGen

    gen = _PropertyGen(program.info, program)
    try:
        parts = tuple(gen.expr(n) for n in nodes)
    except Exception:   # a shape the property codegen does not take alone: not counted
        return None
    text = " and ".join(f"`{_premise_text(program, n, negate)}`" for n in nodes)
    return Premise(parts, negate, text)


def _premise_text(program, node, negate: bool) -> str:
    """What must hold for the premise, as source: `X` for `not X`, `A == B` for
    `A != B`."""
    if not negate:
        return _source(program, node)
    if isinstance(node, ast.NotOp):
        return _source(program, node.operand)
    return f"{_source(program, node.left)} == {_source(program, node.right)}"


def _source(program, node) -> str:
    """The node's source text (one line), for the report."""
    s = node.span
    lines = program.source.splitlines()
    if s.line != s.end_line or not 1 <= s.line <= len(lines):
        return "..."
    return lines[s.line - 1][s.col - 1:s.end_col - 1]
