"""The abstract syntax tree: small frozen dataclasses, each carrying its source span.

Class names are the CamelCase of the grammar's rule aliases; `parse.ToAst` builds them
mechanically and never raises (semantic errors belong to the checker).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from functools import cache
from typing import Any

from swarmdsl.errors import Span


def node(cls):
    """A frozen dataclass AST node. Its `repr` is `Node.__repr__`, written once: a
    generated one per class costs about a third of building this module's classes,
    which every command pays at start-up."""
    return dataclass(frozen=True, repr=False)(cls)


@node
class Node:
    span: Span

    def __repr__(self) -> str:   # what dataclass's would say
        inner = ", ".join(f"{f.name}={getattr(self, f.name)!r}" for f in fields(self))
        return f"{type(self).__qualname__}({inner})"

    def children(self):
        """Yield child nodes (for generic visitors), in source order."""
        for name in node_fields(type(self)):
            yield from _nodes_in(getattr(self, name))


@cache
def node_fields(cls: type) -> tuple[str, ...]:
    """The fields of node class `cls` that may hold nodes, in declaration order: not its
    spans nor its words (a field declared `str`, `bool`, `int` or `float` holds no
    node). Worked out once per class: walks ask it for every node."""
    return tuple(f.name for f in fields(cls) if f.name != "span"
                 and not f.name.endswith(("_span", "_spans"))
                 and f.type not in ("str", "bool", "float", "int"))


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


@node
class Num(Expr):
    value: float
    is_int: bool


@node
class BoolLit(Expr):
    value: bool


@node
class StrLit(Expr):
    value: str


@node
class Name(Expr):
    id: str


@node
class Attr(Expr):
    obj: Expr
    name: str
    name_span: Span


@node
class Call(Expr):
    """`f(a, b)`; aggregates add `: each` and `else default`: `sum(near : other.pos)`."""

    name: str
    name_span: Span
    args: tuple[Expr, ...]
    each: Expr | None
    default: Expr | None


@node
class FieldAt(Expr):
    """`heat at other.pos`: a field read at a point (the checker wants a field's name on
    the left and a vector on the right)."""

    field: Expr
    point: Expr
    at_span: Span


@node
class Vec(Expr):
    x: Expr
    y: Expr


@node
class BinOp(Expr):
    op: str
    left: Expr
    right: Expr


@node
class Chain(Expr):
    """A long chain `a + b - c ...` of one precedence level, evaluated left to right.

    Kept flat (see `nesting.py`) so no walk over it recurses once per term; `rest` holds
    `(op, term)` pairs with op one of `+ - * / %` or `and`/`or`.
    """

    first: Expr
    rest: tuple[tuple[str, Expr], ...]


@node
class Neg(Expr):
    operand: Expr


@node
class Compare(Expr):
    op: str
    left: Expr
    right: Expr


@node
class AndOp(Expr):
    left: Expr
    right: Expr


@node
class OrOp(Expr):
    left: Expr
    right: Expr


@node
class NotOp(Expr):
    operand: Expr


@node
class Cond(Expr):
    test: Expr
    then: Expr
    orelse: Expr


@node
class Where(Expr):
    """`near where cond`: filter a neighbour set by a per-pair condition."""

    source: Expr
    cond: Expr


# ---- statements ----


class Stmt(Node):
    """One line of a status body."""


@node
class LetStmt(Stmt):
    name: str
    name_span: Span
    value: Expr


@node
class AssignStmt(Stmt):
    target: str
    target_span: Span
    op: str
    value: Expr


@node
class WhenStmt(Stmt):
    cond: Expr
    target: str
    target_span: Span
    body: tuple[Stmt, ...]


@node
class ActionStmt(Stmt):
    name: str
    name_span: Span
    args: tuple[Expr, ...]


# ---- declarations ----


@node
class Option(Node):
    """A `name arg arg ...` line in a world, field, robot or agent block."""

    name: str
    name_span: Span
    has_in: bool
    args: tuple[Expr, ...]


@node
class ParamDecl(Node):
    name: str
    name_span: Span
    value: Expr
    lo: Expr | None
    hi: Expr | None


@node
class WorldDecl(Node):
    options: tuple[Option, ...]


@node
class FieldDecl(Node):
    name: str
    name_span: Span
    options: tuple[Option, ...]


@node
class RegionDecl(Node):
    keyword: str
    name: str
    name_span: Span
    shape: Expr


@node
class RobotDecl(Node):
    name: str
    name_span: Span
    options: tuple[Option, ...]


@node
class VarDecl(Node):
    name: str
    name_span: Span
    value: Expr


@node
class AttrDecl(Node):
    name: str
    name_span: Span
    value: Expr


@node
class StatusDecl(Node):
    name: str
    name_span: Span
    body: tuple[Stmt, ...]
    final: bool = False      # `final status NAME { ... }`: an intended end


@node
class InvariantDecl(Node):
    name: str
    name_span: Span
    expr: Expr


@node
class EventuallyDecl(Node):
    name: str
    name_span: Span
    within: Expr
    expr: Expr


@node
class ResponseDecl(Node):
    """`always NAME: TRIGGER -> eventually RESPONSE within N`."""

    name: str
    name_span: Span
    trigger: Expr
    response: Expr
    within: Expr


@node
class MetricDecl(Node):
    name: str
    name_span: Span
    expr: Expr


@node
class ObjectiveDecl(Node):
    """`objective NAME = TARGET` in an agent kind (compiler/lang_objectives.py)."""

    name: str
    name_span: Span
    target: Expr


@node
class AgentDecl(Node):
    name: str
    name_span: Span
    items: tuple[Node, ...]

    def items_of(self, cls):
        return tuple(i for i in self.items if isinstance(i, cls))


@node
class Program(Node):
    decls: tuple[Node, ...]

    def decls_of(self, cls):
        return tuple(d for d in self.decls if isinstance(d, cls))
