"""Evaluation of constant expressions (params, world sizes, counts) at compile time."""

from __future__ import annotations

import math
import sys

from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import CONSTANTS, FUNCTIONS
from swarmdsl.compiler.visit import Visitor
from swarmdsl.ops.operators import ARITHMETIC, COMPARISONS, NEGATE


class NotConstant(Exception):
    """Raised (internally) when an expression depends on agents or randomness."""

    def __init__(self, node: ast.Node):
        super().__init__("not constant")
        self.node = node


def const_value(expr: ast.Expr, params: dict[str, object]):
    """Return the Python value (float, bool or (x, y) tuple) of a constant expression.

    Raises NotConstant when the expression needs run-time state, ArithmeticError or
    ValueError on a math fault (division by zero, sqrt of a negative).
    """
    return _FOLD.visit(expr, params)


class _Folder(Visitor):
    """Constant folding, one method per expression class; `params` is passed down (one
    folder serves every call)."""

    # Known per agent or per pair only, or no value at all: never a constant.
    REFUSED = frozenset({"Attr", "Where", "FieldAt", "TreeResult", "Forever"})

    def refuse(self, e, params):
        raise NotConstant(e)

    def visit_Num(self, e, params):
        if not math.isfinite(e.value):
            raise OverflowError("the number is too large (over 1.8e308)")
        return int(e.value) if e.is_int else e.value

    def visit_BoolLit(self, e, params):
        return e.value

    def visit_StrLit(self, e, params):
        return e.value

    def visit_Name(self, e, params):
        if e.id in params:
            return params[e.id]
        if e.id in CONSTANTS:
            return CONSTANTS[e.id]
        raise NotConstant(e)

    def visit_Neg(self, e, params):
        v = self.visit(e.operand, params)
        if isinstance(v, tuple):
            return (NEGATE.fold(v[0]), NEGATE.fold(v[1]))
        return NEGATE.fold(v)

    def visit_Vec(self, e, params):
        return (float(self.visit(e.x, params)), float(self.visit(e.y, params)))

    def visit_BinOp(self, e, params):
        return _arith(e, e.op, self.visit(e.left, params), self.visit(e.right, params))

    def visit_Chain(self, e, params):
        if e.rest[0][0] in ("and", "or"):
            values = [bool(self.visit(e.first, params))]
            values += [bool(self.visit(t, params)) for _, t in e.rest]
            return all(values) if e.rest[0][0] == "and" else any(values)
        acc = self.visit(e.first, params)
        for op, term in e.rest:
            acc = _arith(e, op, acc, self.visit(term, params))
        return acc

    def visit_Compare(self, e, params):
        return COMPARISONS[e.op].fold(self.visit(e.left, params),
                                      self.visit(e.right, params))

    def visit_AndOp(self, e, params):
        return bool(self.visit(e.left, params)) and bool(self.visit(e.right, params))

    def visit_OrOp(self, e, params):
        return bool(self.visit(e.left, params)) or bool(self.visit(e.right, params))

    def visit_NotOp(self, e, params):
        return not self.visit(e.operand, params)

    def visit_Cond(self, e, params):
        test = self.visit(e.test, params)
        return self.visit(e.then if test else e.orelse, params)

    def visit_Call(self, e, params):
        if not (e.name in FUNCTIONS and FUNCTIONS[e.name].foldable
                and e.each is None and e.default is None):
            raise NotConstant(e)
        args = [self.visit(a, params) for a in e.args]
        if any(isinstance(a, tuple) for a in args):
            raise NotConstant(e)
        return _call(e.name, args)


_FOLD = _Folder()


def _call(name: str, args: list):
    """`name(args)` on constants: the row's value (numpy's, to the bit), refused with a
    message in the language's words when finite arguments give no real number or one
    too large for a float."""
    want = len(FUNCTIONS[name].params)
    if len(args) != want:
        raise TypeError(f"`{name}` takes {want} argument{'' if want == 1 else 's'}, "
                        f"got {len(args)}")
    value = FUNCTIONS[name].folded(*args)
    if isinstance(value, float) and not math.isfinite(value) and all(
            math.isfinite(a) for a in args):
        text = f"{name}({', '.join(_short(a) for a in args)})"
        if value != value:
            raise ValueError(f"{text} is not a real number")
        if value < 0:
            raise ValueError(f"{text} is minus infinity")
        raise OverflowError(f"{text} is too large (over 1.8e308)")
    return value


def _arith(e: ast.Expr, op: str, a, b):
    """`a op b` on constants, refusing results no float can hold before building them.

    Python integers grow without bound, so `9 ^ 9 ^ 9` would take minutes and gigabytes
    to build exactly; its size is estimated from the logarithm first.
    """
    if isinstance(a, tuple) or isinstance(b, tuple):
        raise NotConstant(e)
    if op == "/" and b == 0:
        raise ZeroDivisionError("division by zero")
    if op == "%" and b == 0:
        raise ZeroDivisionError(f"{_short(a)} % 0: the remainder of a division by zero")
    if op == "^" and abs(a) > 1 and b > 0 and b * math.log2(abs(a)) > _MAX_EXPONENT:
        raise OverflowError(f"{_short(a)} ^ {_short(b)} is too large (over 1.8e308)")
    if op == "^" and a == 0 and b < 0:
        raise ZeroDivisionError("0 raised to a negative power")
    try:
        value = ARITHMETIC[op].fold(a, b)
    except OverflowError:
        raise OverflowError(f"{_short(a)} {op} {_short(b)} is too large (over 1.8e308)") \
            from None
    if isinstance(value, float) and not math.isfinite(value) and math.isfinite(a) \
            and math.isfinite(b):
        if value != value:
            raise ValueError(f"{_short(a)} ^ {_short(b)} is not a real number")
        raise OverflowError(f"{_short(a)} {op} {_short(b)} is too large (over 1.8e308)")
    if isinstance(value, int) and abs(value) > _MAX_FLOAT:
        raise OverflowError(f"{_short(a)} {op} {_short(b)} is too large (over 1.8e308)")
    return value


_MAX_FLOAT = sys.float_info.max
_MAX_EXPONENT = 1024  # log2 of the largest float


def _short(v) -> str:
    """A number as a user would write it, never thousands of digits long."""
    if isinstance(v, int) and abs(v) >= 10**15:
        return f"{float(v):.3g}"
    return f"{v:g}" if isinstance(v, float) else str(v)


def scoped_params(node: ast.Node, params: dict[str, object]) -> dict[str, object]:
    """The params as names read under `node`: a named tree's parameters hide the params
    of their names (`tree t(k) { ... }` reads its own `k`, not `param k`)."""
    from swarmdsl.compiler.tree_ast import TreeDecl

    if not isinstance(node, TreeDecl) or not set(node.params) & set(params):
        return params
    return {k: v for k, v in params.items() if k not in node.params}


def walk_with_params(node: ast.Node, params: dict[str, object]):
    """(node, the params it reads) for `node` and every node under it, parents first,
    without recursion."""
    stack = [(node, params)]
    while stack:
        n, p = stack.pop()
        p = scoped_params(n, p)
        yield n, p
        stack.extend((c, p) for c in reversed(list(n.children())))


def is_constant(expr: ast.Expr, params: dict[str, object]) -> bool:
    try:
        const_value(expr, params)
    except NotConstant:
        return False
    except (ArithmeticError, ValueError, TypeError):
        return True
    return True


def constant_radius(expr: ast.Expr, params: dict) -> float | None:
    """The value of a neighbour radius when it is a constant, else None."""
    try:
        v = const_value(expr, params)
    except (NotConstant, ArithmeticError, ValueError, TypeError):
        return None
    return float(v) if isinstance(v, int | float) and not isinstance(v, bool) else None
