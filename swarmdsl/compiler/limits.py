"""The table of numeric limits lives in `swarmdsl/limits.py` (the runtime checks its
arguments against it too); this name stays for code written against the compiler's."""

from swarmdsl.limits import (  # noqa: F401
    MAX_DEPOSIT_NODES,
    MAX_EDGE_REACH,
    MAX_GRID_NODES,
    MAX_MAGNITUDE,
    MAX_MEMORY_BYTES,
    MAX_PAIR_BYTES,
    MIN_WORLD_SIZE,
    OPTION_LIMITS,
    PAIR_BYTES,
    constant_problem,
    over,
    upper,
)
