"""The premise of an implication-shaped invariant, so coverage can say how often it held.

`invariant safe: not carrying or speed < 2` (or `status != crowded or ...`, or
`if carrying then speed < 2 else true`) holds trivially on every agent whose premise
is false: a hunt in which no agent ever carried anything passed it without testing
it. "Exercised by 75 of 75 runs" then claims too much, so the tester counts the
agent-ticks at which the premise held, and says so.

The premise is read off the expression: a top-level `or` whose disjuncts include a
negation (`not X`, `A != B`): the premise is that every such disjunct is false (when
every disjunct is one, all but the last: `not A or not B` reads as A -> not B); an
`if P then Q else true`: the premise is P. Its closures are compiled from the
property's own checked nodes. A premise that reads `previous(X)` is not counted (a
second evaluation would share the property's memory of the last tick): coverage then
says the premise was not measured, rather than a number it does not know.
"""

from __future__ import annotations

from dataclasses import dataclass

from swarmdsl.compiler import ast


@dataclass(frozen=True)
class Premise:
    """The premise of one property: closures of the disjuncts whose falsity is it
    (`negate` True) or of the one condition that is it (`negate` False)."""

    parts: tuple
    negate: bool
    text: str           # how the report names it, e.g. "`carrying`"


def premise_nodes(expr: ast.Expr) -> tuple[list[ast.Expr], bool] | None:
    """(nodes, negate) of an implication-shaped expression's premise, or None."""
    if isinstance(expr, ast.Cond) and isinstance(expr.orelse, ast.BoolLit) \
            and expr.orelse.value is True:
        return [expr.test], False
    disjuncts = _disjuncts(expr)
    if len(disjuncts) < 2:
        return None
    negative = [d for d in disjuncts if isinstance(d, ast.NotOp)
                or (isinstance(d, ast.Compare) and d.op == "!=")]
    if len(negative) == len(disjuncts):     # `not A or not B`: A -> not B
        negative = negative[:-1]
    if not negative:
        return None
    return negative, True


def _disjuncts(expr: ast.Expr) -> list[ast.Expr]:
    if isinstance(expr, ast.OrOp):
        return _disjuncts(expr.left) + _disjuncts(expr.right)
    if isinstance(expr, ast.Chain) and expr.rest and all(op == "or" for op, _ in expr.rest):
        return [expr.first, *(term for _, term in expr.rest)]
    return [expr]


def compile_premise(program, info) -> Premise | None:
    """The premise of an `invariant` of `program` (its `PropertyInfo`), or None when it
    is not implication-shaped or its premise reads `previous`."""
    if info.keyword != "invariant":
        return None
    found = premise_nodes(info.decl.expr)
    if found is None:
        return None
    nodes, negate = found
    if any(isinstance(n, ast.Call) and n.name == "previous"
           for node in nodes for n in ast.walk(node)):
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
