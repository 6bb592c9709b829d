"""The documented limits on numbers a program computes at compile time, in one table.

Every param and option value passes `check_constant`; options with a tighter range name
it in `OPTION_LIMITS`; `resources.py` checks what the options add up to (grid nodes,
neighbour pairs, memory columns) before a run allocates any of it. docs/limits.md
lists the same numbers; a test keeps the two in step.
"""

from __future__ import annotations

import math

# Any constant (a param, an option value): finite and at most this large in magnitude.
# Beyond 2^53 (~9e15) whole numbers are no longer exact as floats.
MAX_MAGNITUDE = 1e15

# name -> (lowest, highest, what it is); the lowest is exclusive when it is 0 and the
# option must be positive.
OPTION_LIMITS = {
    "size": (0.0, 1e9, "the world's width and height"),
    "grid": (0.0, 1e9, "the grid spacing"),
    "edges": (0.0, 1e9, "the edge repulsion weight and range"),
    "steps": (0, 10**12, "the number of steps"),
    "count": (0, 50_000_000, "agents of one kind (and of all kinds together)"),
    "sense": (0.0, 1e9, "the sense radius"),
    "memory": (1, 1_000_000, "the capacity of a path memory"),
    "within": (1, 10**12, "the bound of `within`, in ticks"),
    "tree count": (0, 10**12, "a tree's count of ticks or runs (`repeat`, `retry`, "
                   "`timeout`, `cooldown`, `wait`)"),
}

# The smallest world side: below it positions lose their precision (subnormal floats)
# and the world's area can round to 0.
MIN_WORLD_SIZE = 1e-6

# Resources the options add up to, checked before a run allocates them.
MAX_GRID_NODES = 25_000_000          # nodes of the world grid when fields live on it
MAX_EDGE_REACH = 10_000              # edge repulsion range / grid spacing
MAX_PAIR_BYTES = 8 * 2**30           # estimated neighbour-pair table, uniform placement
MAX_DEPOSIT_NODES = 10_000          # grid nodes one radius deposit spreads over
MAX_MEMORY_BYTES = 4 * 2**30         # path memory columns: agents x capacity x 16 bytes
PAIR_BYTES = 40                      # per directed pair: two ids, distance, offset


def constant_problem(value) -> str | None:
    """Why a compile-time value is refused (not finite, too large), or None."""
    if isinstance(value, tuple):
        for v in value:
            problem = constant_problem(v)
            if problem:
                return problem
        return None
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    if isinstance(value, float) and math.isnan(value):
        return "is not a number (NaN)"
    if isinstance(value, float) and math.isinf(value):
        return "is infinite"
    if abs(value) > MAX_MAGNITUDE:
        return f"is {float(value):.3g}; constants are limited to {MAX_MAGNITUDE:.0e} in size"
    return None


def upper(name: str):
    """The highest value the option `name` allows."""
    return OPTION_LIMITS[name][1]


def over(name: str, value) -> str | None:
    """A message when `value` exceeds the limit of option `name`, else None."""
    hi = OPTION_LIMITS[name][1]
    if value is not None and value > hi:
        return f"{OPTION_LIMITS[name][2]} is limited to {_fmt(hi)}, got {_fmt(value)}"
    return None


def _fmt(v) -> str:
    if isinstance(v, int) or float(v).is_integer() and abs(v) < 1e15:
        return f"{int(v):,}"
    return f"{v:g}"
