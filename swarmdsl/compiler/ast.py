"""The abstract syntax tree: small frozen dataclasses, each carrying its source span.

Class names are the CamelCase of the grammar's rule aliases; `parse.ToAst` builds them
mechanically and never raises (semantic errors belong to the checker).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from swarmdsl.compiler.errors import Span


@dataclass(frozen=True)
class Node:
    span: Span

    def children(self):
        """Yield child nodes (for generic visitors), in source order."""
        for f in fields(self):
            if f.name == "span":
                continue
            yield from _nodes_in(getattr(self, f.name))


def walk(node: Node):
    """`node` and every node under it, parents first, in source order (without
    recursion, so no depth of nesting can exhaust the stack)."""
    stack = [node]
    while stack:
        n = stack.pop()
        yield n
        stack.extend(reversed(list(n.children())))


def shape(node) -> object:
    """A span-free structural key of an AST node (equal for equal expressions)."""
    if isinstance(node, Node):
        return (type(node).__name__,) + tuple(
            shape(getattr(node, f.name)) for f in fields(node)
            if f.name != "span" and not f.name.endswith("_span"))
    if isinstance(node, tuple):
        return tuple(shape(x) for x in node)
    return node


def _nodes_in(value: Any):
    if isinstance(value, Node):
        yield value
    elif isinstance(value, tuple):
        for v in value:
            yield from _nodes_in(v)


# ---- expressions ----


class Expr(Node):
    """Anything that evaluates to a value per agent (or per neighbour pair)."""


@dataclass(frozen=True)
class Num(Expr):
    value: float
    is_int: bool


@dataclass(frozen=True)
class BoolLit(Expr):
    value: bool


@dataclass(frozen=True)
class StrLit(Expr):
    value: str


@dataclass(frozen=True)
class Name(Expr):
    id: str


@dataclass(frozen=True)
class Attr(Expr):
    obj: Expr
    name: str
    name_span: Span


@dataclass(frozen=True)
class Call(Expr):
    """`f(a, b)`; aggregates add `: each` and `else default`: `sum(near : other.pos)`."""

    name: str
    name_span: Span
    args: tuple[Expr, ...]
    each: Expr | None
    default: Expr | None


@dataclass(frozen=True)
class FieldAt(Expr):
    """`heat at other.pos`: a field read at a point (the checker wants a field's name on
    the left and a vector on the right)."""

    field: Expr
    point: Expr
    at_span: Span


@dataclass(frozen=True)
class Vec(Expr):
    x: Expr
    y: Expr


@dataclass(frozen=True)
class BinOp(Expr):
    op: str
    left: Expr
    right: Expr


@dataclass(frozen=True)
class Chain(Expr):
    """A long chain `a + b - c ...` of one precedence level, evaluated left to right.

    Kept flat (see `nesting.py`) so no walk over it recurses once per term; `rest` holds
    `(op, term)` pairs with op one of `+ - * / %` or `and`/`or`.
    """

    first: Expr
    rest: tuple[tuple[str, Expr], ...]


@dataclass(frozen=True)
class Neg(Expr):
    operand: Expr


@dataclass(frozen=True)
class Compare(Expr):
    op: str
    left: Expr
    right: Expr


@dataclass(frozen=True)
class AndOp(Expr):
    left: Expr
    right: Expr


@dataclass(frozen=True)
class OrOp(Expr):
    left: Expr
    right: Expr


@dataclass(frozen=True)
class NotOp(Expr):
    operand: Expr


@dataclass(frozen=True)
class Cond(Expr):
    test: Expr
    then: Expr
    orelse: Expr


@dataclass(frozen=True)
class Where(Expr):
    """`near where cond`: filter a neighbour set by a per-pair condition."""

    source: Expr
    cond: Expr


# ---- statements ----


class Stmt(Node):
    """One line of a status body."""


@dataclass(frozen=True)
class LetStmt(Stmt):
    name: str
    name_span: Span
    value: Expr


@dataclass(frozen=True)
class AssignStmt(Stmt):
    target: str
    target_span: Span
    op: str
    value: Expr


@dataclass(frozen=True)
class WhenStmt(Stmt):
    cond: Expr
    target: str
    target_span: Span
    body: tuple[Stmt, ...]


@dataclass(frozen=True)
class ActionStmt(Stmt):
    name: str
    name_span: Span
    args: tuple[Expr, ...]


# ---- declarations ----


@dataclass(frozen=True)
class Option(Node):
    """A `name arg arg ...` line in a world, field, robot or agent block."""

    name: str
    name_span: Span
    has_in: bool
    args: tuple[Expr, ...]


@dataclass(frozen=True)
class ParamDecl(Node):
    name: str
    name_span: Span
    value: Expr
    lo: Expr | None
    hi: Expr | None


@dataclass(frozen=True)
class WorldDecl(Node):
    options: tuple[Option, ...]


@dataclass(frozen=True)
class FieldDecl(Node):
    name: str
    name_span: Span
    options: tuple[Option, ...]


@dataclass(frozen=True)
class RegionDecl(Node):
    keyword: str
    name: str
    name_span: Span
    shape: Expr


@dataclass(frozen=True)
class RobotDecl(Node):
    name: str
    name_span: Span
    options: tuple[Option, ...]


@dataclass(frozen=True)
class VarDecl(Node):
    name: str
    name_span: Span
    value: Expr


@dataclass(frozen=True)
class AttrDecl(Node):
    name: str
    name_span: Span
    value: Expr


@dataclass(frozen=True)
class StatusDecl(Node):
    name: str
    name_span: Span
    body: tuple[Stmt, ...]
    final: bool = False      # `final status NAME { ... }`: an intended end


@dataclass(frozen=True)
class InvariantDecl(Node):
    name: str
    name_span: Span
    expr: Expr


@dataclass(frozen=True)
class EventuallyDecl(Node):
    name: str
    name_span: Span
    within: Expr
    expr: Expr


@dataclass(frozen=True)
class ResponseDecl(Node):
    """`always NAME: TRIGGER -> eventually RESPONSE within N`."""

    name: str
    name_span: Span
    trigger: Expr
    response: Expr
    within: Expr


@dataclass(frozen=True)
class MetricDecl(Node):
    name: str
    name_span: Span
    expr: Expr


@dataclass(frozen=True)
class ObjectiveDecl(Node):
    """`objective NAME = TARGET` in an agent kind (compiler/lang_objectives.py)."""

    name: str
    name_span: Span
    target: Expr


@dataclass(frozen=True)
class AgentDecl(Node):
    name: str
    name_span: Span
    items: tuple[Node, ...]

    def items_of(self, cls):
        return tuple(i for i in self.items if isinstance(i, cls))


@dataclass(frozen=True)
class Program(Node):
    decls: tuple[Node, ...]

    def decls_of(self, cls):
        return tuple(d for d in self.decls if isinstance(d, cls))
