"""The numpy reference backend: the compiler's closures run as they are, over whole
arrays; the neighbour search is the KD-tree's (`runtime/spatial.py`), fields are numpy's
`Field`, motion and draws the runtime's own. Every other backend gives its bits.

It registers itself with `runtime/backends.py` when imported (the registry imports it
by name the first time a run asks for `numpy`).
"""

from __future__ import annotations

import contextlib

from swarmdsl.runtime import backends, spatial


class NumpyBackend:
    """The reference `protocols.Backend`: nothing compiled, nothing to report but why
    the default chose it."""

    name = "numpy"
    fused = False                # no compiled path: lowered closures run the reference
    random_units = None          # the runtime's own draws
    random_units_rows = None

    def __init__(self):
        self.why = ""                       # why the default chose this backend, if it did
        self.choice = None                  # the default's choice, when it chose
        self.motion_compiled: bool | None = None
        self.fields_compiled: bool | None = None
        self.compile_seconds = 0.0
        self.load_seconds = 0.0
        self.parts: dict = {}

    def prepare(self, program) -> None:
        """The reference closures run as compiled: nothing to lower."""

    def field_type(self, reference: type) -> type:
        """numpy's `Field` itself."""
        return reference

    def finished(self, program, ticks: int) -> None:
        """Nothing is kept between runs (no compiled kernels to mark warm)."""

    def build_pairs(self, pos, radius, box, bounds=None):
        """The tick's KD-tree pair table; with `bounds`, every replica's of a batch
        (`replica_pairs`), or None when they are searched replica by replica."""
        if bounds is None:
            return spatial.build_pairs(pos, radius, box)
        return self.replica_pairs(pos, bounds, radius, box)

    def pairs_table(self, pos, radius, box):
        """The pairs of `pos` as a row-order `PairTable`, keeping no state between calls:
        one replica's table of a batch (`runtime/batch.py`)."""
        return spatial.build_pairs(pos, radius, box)

    def replica_pairs(self, pos, bounds, radius, box):
        """Every replica's pairs in one call, as `pairs_table` finds each, or None: call
        `pairs_table` per replica (`spatial.build_replica_pairs` decides)."""
        return spatial.build_replica_pairs(pos, bounds, radius, box)

    def neighbors_within(self, frame, table, limit, view=None):
        """None: the frame selects the rows of a narrower `neighbors(r)` itself."""
        return None

    def move(self, sim):
        """None: the runtime's numpy motion moves the agents."""
        return None

    def note(self, part, compiled: bool) -> None:
        """Counted like the numba backend's, for a lowered program run here."""
        calls = self.parts.setdefault(part, [0, 0])
        calls[0 if compiled else 1] += 1

    def batch_threads(self, agents: int) -> tuple[int, str]:
        """The threads a batch of `agents` ticks on, and why: numpy's arrays' own."""
        return 1, "numpy"

    def threads_limited(self, n: int):
        """numpy's threads are its own: nothing to limit."""
        return contextlib.nullcontext()

    def summary(self, program) -> list[str]:
        """`swarmdsl run -v`: the backend, and why the default chose it."""
        line = f"backend: {self.name}"
        return [line + f" ({self.why})" if self.why else line]


backends.register("numpy", NumpyBackend)
