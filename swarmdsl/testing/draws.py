"""A hunt's draws depend on its inputs only (the program, the options, the seed), never
on what ran before it in the same process.

Hypothesis (from 6.131) now and then draws a literal taken from the source of the
process's own modules (those outside site-packages and the standard library) that are
imported at the time of the draw. Which swarmdsl modules are imported depends on what
the process ran before the hunt (a run of a program that uses fields or a compiled
kernel imports more), so the same seeded hunt drew other values and went elsewhere:
after 5 ticks of `programs/aco.swarm` a crowd hunt made 168 runs instead of 162, and a
hunt could shrink to another swarm. While a hunt draws, that pool is empty; hypothesis'
own constants (0, 1, the float edges...) still come up.

The pool is process-wide in hypothesis, so it is emptied once for hunts that overlap
(threads) and given back when the last one ends. A hypothesis without the pool has
nothing to empty.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager

_lock = threading.Lock()
_hunts = 0                  # hunts drawing now
_restore = None             # hypothesis' own pool function, while emptied


@contextmanager
def inputs_only() -> Iterator[None]:
    """Hypothesis draws no constants of the process's own modules inside the block."""
    global _hunts, _restore
    try:
        from hypothesis.internal.conjecture import providers
        from hypothesis.internal.constants_ast import Constants
    except ImportError:         # an older hypothesis: it draws no such constants
        yield
        return
    cache = getattr(providers, "CONSTANTS_CACHE", None)
    if getattr(providers, "_get_local_constants", None) is None or cache is None:
        yield
        return
    empty = Constants()
    with _lock:
        if _hunts == 0:
            _restore = providers._get_local_constants
            providers._get_local_constants = lambda: empty
        _hunts += 1
    cache.cache.clear()         # constants allowed per draw, worked out from the pool
    try:
        yield
    finally:
        cache.cache.clear()
        with _lock:
            _hunts -= 1
            if _hunts == 0:
                providers._get_local_constants = _restore
                _restore = None
