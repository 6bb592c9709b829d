"""numba, as every compiled module of swarmdsl imports it: with machine-code names that
no other process gives out.

numba names a function's machine code by its qualified name, its argument types and a
counter that starts at 1 in every process. Two kernels alike but for a constant (two
programs' `body` closures, say), each compiled first in a fresh process, so get the same
name; a third process that loads both from disk resolves the name to whichever it loaded
first and runs that code for both (seen: one program's neighbour count computed with
another's loop). Starting the counter at a random point makes the names of two processes
practically never meet, so every kernel kept on disk calls its own code
(`disk_cache.py`). The counter is numba's own class attribute: the name it keeps is
checked, and without it kernels are not kept on disk at all.
"""

from __future__ import annotations

import itertools
import secrets

from numba import njit, prange
from numba.core import bytecode

__all__ = ["njit", "prange", "distinct_names"]

# 2^60 starting points: two processes that each compile 10^5 functions overlap with odds
# of about 10^-13.
_START_BITS = 60


def _distinct() -> bool:
    identity = getattr(bytecode, "FunctionIdentity", None)
    counter = getattr(identity, "_unique_ids", None)
    if counter is None:
        return False
    if not getattr(identity, "_swarmdsl_distinct", False):
        identity._unique_ids = itertools.count(secrets.randbits(_START_BITS) + 1)
        identity._swarmdsl_distinct = True
    return True


distinct_names = _distinct()
