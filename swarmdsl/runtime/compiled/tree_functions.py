"""An expression tree's jitted function, written as one Python function of its pair.

A plan's tree (`plan.py`: tuples of operator names and column numbers) becomes one
function `f(S, O, r, j, d, dx, dy)` whose body is a single nested expression: leaves read
a column of the owner's row (`S[r, c]`) or the neighbour's (`O[j, c]`), operators call
their row's `scalar` (`ops/`), `if` is Python's conditional expression (only the branch
taken is evaluated, as before), `and`/`or` evaluate both sides, as the reference does.

Why one function per tree: a tree composed of one inlined function per node made numba
inline each node's IR into its parent, copying and typing it again at every level; one
function a tree compiles a program's own kernels in 0.62-0.89x the time (boids 3.9 s
against 5.9 s, docs/benchmarks.md), to the same machine code.

The function is built as a Python syntax tree from a fixed vocabulary (the names below,
the tree's column numbers as integer constants) and compiled from that tree; no source
text is made from a program and nothing is `exec`uted. Its scalar functions are globals
of its own namespace, so `disk_cache.fingerprint` reaches them as it reaches a
closure's cells.
"""

from __future__ import annotations

import ast
import types

ARGS = ("S", "O", "r", "j", "d", "dx", "dy")
# The tree's own leaves: the pair's values, which the arguments of these names hold.
_PAIR_LEAVES = ("d", "dx", "dy")
# A fixed template, parsed once: only its body is replaced.
_TEMPLATE = "def node(S, O, r, j, d, dx, dy):\n    return 0.0\n"


def build(tree: tuple, scalar_function, both) -> types.FunctionType:
    """The plain Python function of `tree`, for numba to compile. `scalar_function(op)`
    is the jitted scalar of operator `op`; `both(op)` the jitted `and`/`or` of two
    values that are both evaluated."""
    given: dict = {}     # a jitted function's id -> the global name it has

    def called(fn) -> ast.Name:
        name = given.get(id(fn))
        if name is None:
            name = given[id(fn)] = f"f{len(given)}"
            scope[name] = fn
        return ast.Name(name, ast.Load())

    scope: dict = {"__name__": __name__, "__builtins__": {}}

    def expr(t: tuple) -> ast.expr:
        op = t[0]
        if op in ("s", "sb", "o", "ob"):
            table = "S" if op[0] == "s" else "O"
            row = "r" if op[0] == "s" else "j"
            read = ast.Subscript(ast.Name(table, ast.Load()),
                                 ast.Tuple([ast.Name(row, ast.Load()),
                                            ast.Constant(_column(t[1]))], ast.Load()),
                                 ast.Load())
            if op.endswith("b"):
                return ast.Compare(read, [ast.NotEq()], [ast.Constant(0.0)])
            return read
        if op in _PAIR_LEAVES:
            return ast.Name(op, ast.Load())
        if op == "zero":
            return ast.Constant(0.0)
        if op == "true":
            return ast.Constant(True)
        if op == "if":
            return ast.IfExp(expr(t[1]), expr(t[2]), expr(t[3]))
        if op == "not":
            return ast.UnaryOp(ast.Not(), expr(t[1]))
        if op in ("and", "or"):
            return ast.Call(called(both(op)), [expr(t[1]), expr(t[2])], [])
        return ast.Call(called(scalar_function(op)), [expr(c) for c in t[1:]], [])

    module = ast.parse(_TEMPLATE)
    module.body[0].body = [ast.Return(expr(tree))]
    ast.fix_missing_locations(module)
    code = compile(module, __file__, "exec")
    body = next(c for c in code.co_consts if isinstance(c, types.CodeType))
    return types.FunctionType(body, scope, "node")


def _column(c) -> int:
    """A leaf's column number: an int, never anything else, since it becomes a
    constant of compiled code."""
    if type(c) is not int:
        raise TypeError(f"a column number, not {type(c).__name__}")
    return c
