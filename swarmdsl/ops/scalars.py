"""Every operation of the kernels' scalar trees, by its node name: the `scalar` of each
operator and function row, and the primitives the rows' lowerings use.

Plain Python functions of floats; the numba backend compiles each the first time a
kernel uses it (`runtime/compiled/kernels.py`), so importing this imports no numba.
Looked up when a kernel is built, so a row added to `FUNCTIONS` (an extension's, a
test's) is found like the shipped ones.
"""

from __future__ import annotations

from collections.abc import Callable

from swarmdsl.ops.functions import FUNCTIONS, PRIMITIVES
from swarmdsl.ops.operators import ARITHMETIC, COMPARISONS, NEGATE

OPERATOR_NODES: dict = {op.node: op.scalar
                        for op in (*ARITHMETIC.values(), *COMPARISONS.values(), NEGATE)}


def scalar(node: str) -> Callable:
    """The scalar function of tree node `node`; KeyError when no row or primitive has it."""
    if node in OPERATOR_NODES:
        return OPERATOR_NODES[node]
    row = FUNCTIONS.get(node)
    if row is not None and row.scalar is not None:
        return row.scalar
    return PRIMITIVES[node]
