"""Evaluation of constant expressions (params, world sizes, counts) at compile time."""

from __future__ import annotations

import math
import sys

from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import CONSTANTS, FUNCTIONS
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
    e = expr
    if isinstance(e, ast.Num):
        if not math.isfinite(e.value):
            raise OverflowError("the number is too large (over 1.8e308)")
        return int(e.value) if e.is_int else e.value
    if isinstance(e, ast.BoolLit):
        return e.value
    if isinstance(e, ast.StrLit):
        return e.value
    if isinstance(e, ast.Name):
        if e.id in params:
            return params[e.id]
        if e.id in CONSTANTS:
            return CONSTANTS[e.id]
        raise NotConstant(e)
    if isinstance(e, ast.Neg):
        v = const_value(e.operand, params)
        if isinstance(v, tuple):
            return (NEGATE.fold(v[0]), NEGATE.fold(v[1]))
        return NEGATE.fold(v)
    if isinstance(e, ast.Vec):
        return (float(const_value(e.x, params)), float(const_value(e.y, params)))
    if isinstance(e, ast.BinOp):
        return _arith(e, e.op, const_value(e.left, params), const_value(e.right, params))
    if isinstance(e, ast.Chain):
        if e.rest[0][0] in ("and", "or"):
            values = [bool(const_value(e.first, params))]
            values += [bool(const_value(t, params)) for _, t in e.rest]
            return all(values) if e.rest[0][0] == "and" else any(values)
        acc = const_value(e.first, params)
        for op, term in e.rest:
            acc = _arith(e, op, acc, const_value(term, params))
        return acc
    if isinstance(e, ast.Compare):
        return COMPARISONS[e.op].fold(const_value(e.left, params),
                                      const_value(e.right, params))
    if isinstance(e, ast.AndOp):
        return bool(const_value(e.left, params)) and bool(const_value(e.right, params))
    if isinstance(e, ast.OrOp):
        return bool(const_value(e.left, params)) or bool(const_value(e.right, params))
    if isinstance(e, ast.NotOp):
        return not const_value(e.operand, params)
    if isinstance(e, ast.Cond):
        test = const_value(e.test, params)
        return const_value(e.then if test else e.orelse, params)
    if (isinstance(e, ast.Call) and e.name in FUNCTIONS and FUNCTIONS[e.name].foldable
            and e.each is None and e.default is None):
        args = [const_value(a, params) for a in e.args]
        if any(isinstance(a, tuple) for a in args):
            raise NotConstant(e)
        return _call(e.name, args)
    raise NotConstant(e)


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
