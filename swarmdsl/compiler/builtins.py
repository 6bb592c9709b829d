"""The checker's and codegen's view of the built-ins: the function rows (`ops/functions.py`,
one row per function with all its evaluators), the aggregates and the named constants.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from swarmdsl.ops.functions import FUNCTIONS, Builtin, vec_length
from swarmdsl.ops.types import (
    BOOL,
    FIELD,
    KIND,
    MEMORY,
    NUM,
    OTHER,
    REGION,
    SET,
    STATUS,
    STR,
    TYPE_TEXT,
    VALUE_TYPES,
    VEC,
)

__all__ = ["AGGREGATES", "Aggregate", "BOOL", "CONSTANTS", "FIELD", "FUNCTIONS", "KIND",
           "MEMORY", "NUM",
           "OTHER", "REGION", "SET", "STATUS", "STR", "TYPE_TEXT", "VALUE_TYPES", "VEC",
           "Builtin", "vec_length"]

class Aggregate(NamedTuple):
    """An aggregate over a neighbour set: whether it needs `: EACH`, the types EACH may
    have, and its one-line meaning (the language server's hover shows it)."""

    needs_each: bool
    each_types: tuple
    doc: str


AGGREGATES = {
    "count": Aggregate(False, (), "the number of neighbours in the set (0 when none)"),
    "sum": Aggregate(True, (NUM, VEC), "the sum of EACH over the set (0, or (0, 0) for a "
                     "vector, when none)"),
    "mean": Aggregate(True, (NUM, VEC), "the mean of EACH over the set (the `else`, or 0, "
                      "when none)"),
    "min": Aggregate(True, (NUM,), "the smallest EACH over the set (the `else`, or 0, "
                     "when none)"),
    "max": Aggregate(True, (NUM,), "the largest EACH over the set (the `else`, or 0, "
                     "when none)"),
    "nearest": Aggregate(True, (NUM, VEC, BOOL, STATUS),
                         "EACH for the nearest neighbour (the `else`, or 0, when none)"),
    "any": Aggregate(True, (BOOL,), "whether some neighbour satisfies EACH (false when "
                     "none)"),
    "all": Aggregate(True, (BOOL,), "whether every neighbour satisfies EACH (true when "
                     "none)"),
}

CONSTANTS = {"pi": float(np.pi), "tau": float(2 * np.pi), "inf": float("inf")}
