"""The checker's and codegen's view of the built-ins: the function rows (`ops/functions.py`,
one row per function with all its evaluators), the aggregates and the named constants.
"""

from __future__ import annotations

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

__all__ = ["AGGREGATES", "BOOL", "CONSTANTS", "FIELD", "FUNCTIONS", "KIND", "MEMORY", "NUM",
           "OTHER", "REGION", "SET", "STATUS", "STR", "TYPE_TEXT", "VALUE_TYPES", "VEC",
           "Builtin", "vec_length"]

# Aggregates over a neighbour set: name -> (needs `: each`, allowed each types, result rule)
AGGREGATES = {
    "count": (False, ()),
    "sum": (True, (NUM, VEC)),
    "mean": (True, (NUM, VEC)),
    "min": (True, (NUM,)),
    "max": (True, (NUM,)),
    "nearest": (True, (NUM, VEC, BOOL, STATUS)),
    "any": (True, (BOOL,)),
    "all": (True, (BOOL,)),
}

CONSTANTS = {"pi": float(np.pi), "tau": float(2 * np.pi), "inf": float("inf")}
