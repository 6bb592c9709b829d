"""The one base of the AST walkers: dispatch by node class to `visit_ClassName`.

Every walker that gives each kind of expression (or statement) its own meaning (the
checker, constant folding, codegen, the numba backend's planners, the metric ranges,
the language server's index) subclasses `Visitor`. What the base guarantees:

- **Dispatch by class, cached.** `visit(node, *args)` calls `self.visit_<Class>(node,
  *args)` for the node's exact class; the method is looked up once per (walker class,
  node class), so a walk costs one dict lookup per node, not a string concatenation
  and a `getattr`.
- **Extensions.** Node classes a language extension adds (`FieldAt`, a behaviour tree's
  `TreeResult`) are compiled by the rules it registers (`checker.EXPR_RULES`,
  `codegen.EXPR_CODEGEN`): a walker looks in its table in `extension_rule()`, and a class
  without a method is looked up there at each visit (an extension may register after
  the first walk).
- **Nothing skipped silently.** A class of `NODES` (expressions, say, or statements)
  with neither a method nor a rule is one the walker *refuses* on purpose (named in
  `REFUSED`; `refuse(node, *args)` says what that means to it: "not a constant", "no
  compiled form", "no known range"), one whose children it walks through (named in
  `WALKED`: a search for names has nothing to do at an operator), or a bug, raised as
  an `InternalError` naming the walker and the class. `tests/test_visit.py` checks
  every expression and statement class of the language against every walker: adding
  a node class and forgetting a walker fails it.
- **A children walk that knows every class.** `children(node)` yields a node's child
  nodes in source order (a `Chain`'s `(op, term)` pairs included), from a per-class
  field list computed once; `generic_visit` visits them.

How a walker moves onto it (the kilobot C writer was the last): subclass `Visitor`,
turn each `isinstance` branch into a `visit_<Class>` method taking the same arguments,
list in `REFUSED` the classes the old code's final `else` covered and write `refuse` as
that `else`, read the checker's facts with `facts.type_of(node)` / `name_of(node)`, and
add the walker to `WALKERS` in `tests/test_visit.py`. A walker keeps its own state
between nodes on `self`; its own per-node notes go in a `facts.NodeTable`.
"""

from __future__ import annotations

from swarmdsl.compiler import ast
from swarmdsl.internal import InternalError


class Visitor:
    """Base of the AST walkers (see the module docstring)."""

    # The node classes this walker walks (their subclasses: `tests/test_visit.py`).
    NODES: tuple[type, ...] = (ast.Expr,)
    # Names of the node classes this walker refuses on purpose (`refuse` handles them).
    REFUSED: frozenset[str] = frozenset()
    # Names of the node classes that mean nothing to this walker themselves: their
    # children are walked (`generic_visit`), as a search for names walks an operator.
    WALKED: frozenset[str] = frozenset()

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        cls._methods = {}   # node class -> the function that visits it (own per class)

    def visit(self, node: ast.Node, *args):
        """Visit `node` with the method for its class."""
        method = self._methods.get(type(node))
        if method is None:
            return self._dispatch(node, args)
        return method(self, node, *args)

    def _dispatch(self, node: ast.Node, args: tuple):
        cls = type(node)
        method = getattr(type(self), "visit_" + cls.__name__, None)
        if method is not None:
            type(self)._methods[cls] = method
            return method(self, node, *args)
        rule = self.extension_rule(cls)
        if rule is not None:
            return rule(self, node, *args)
        if cls.__name__ in self.REFUSED:
            return self.refuse(node, *args)
        if cls.__name__ in self.WALKED:
            return self.generic_visit(node, *args)
        return self.unhandled(node)

    @classmethod
    def handles(cls, node_cls: type, rules: dict | None = None) -> bool:
        """Whether this walker has a method for `node_cls` (or a rule in `rules`, an
        extension's table), or refuses or walks through it on purpose."""
        return (hasattr(cls, "visit_" + node_cls.__name__) or node_cls in (rules or {})
                or node_cls.__name__ in cls.REFUSED | cls.WALKED)

    def extension_rule(self, node_cls: type):
        """The rule an extension registered for `node_cls`, fn(walker, node, *args),
        or None."""
        return None

    def refuse(self, node: ast.Node, *args):
        """What this walker does with a class in `REFUSED`."""
        return self.unhandled(node)

    def unhandled(self, node: ast.Node):
        raise InternalError(f"internal: {type(self).__name__} has no rule for "
                            f"{type(node).__name__} nodes", getattr(node, "span", None))

    def generic_visit(self, node: ast.Node, *args) -> None:
        """Visit every child of `node`, in source order."""
        for child in children(node):
            self.visit(child, *args)


def children(node: ast.Node):
    """The child nodes of `node`, in source order (inside tuples and a `Chain`'s
    `(op, term)` pairs too)."""
    for name in ast.node_fields(type(node)):
        value = getattr(node, name)
        if isinstance(value, ast.Node):
            yield value
        elif isinstance(value, tuple):
            yield from _in_tuple(value)


def _in_tuple(items: tuple):
    for item in items:
        if isinstance(item, ast.Node):
            yield item
        elif isinstance(item, tuple):
            yield from _in_tuple(item)


def node_classes(base: type = ast.Node) -> list[type]:
    """Every concrete node class under `base` (dataclasses with fields), the language
    extensions' included once they are imported."""
    out, stack = [], [base]
    while stack:
        cls = stack.pop()
        stack.extend(cls.__subclasses__())
        if "__dataclass_fields__" in cls.__dict__ and cls not in out:
            out.append(cls)
    return sorted(out, key=lambda c: (c.__module__, c.__name__))
