"""The numba backend: compiled kernels, a plug-in of `runtime/backends.py`.

A run picks its backend once (`Simulation(..., backend=)`, `swarmdsl run --backend`); the
registry imports this package the first time a run asks for `numba` (or the default
asks whether numba pays, `choice.py`), and the package registers itself. The numba
backend replaces the KD-tree with a compiled cell list and runs each neighbour
aggregate it can fuse as one compiled loop per owner; everything else, and any aggregate
it cannot fuse, runs the reference closures. Both visit each agent's neighbours in the
cell list's order (`spatial.cell_order`), so it gives the numpy reference's bits
(`runtime/numpy_backend/`). Nothing here imports numba until a numba run starts.
"""

from __future__ import annotations

import importlib.util
import time
import weakref

from swarmdsl.ops import portable
from swarmdsl.runtime import backends
from swarmdsl.runtime.compiled import warm
from swarmdsl.runtime.compiled.choice import WHOLE_TICKS_MAX, Choice, choose

_NEEDS_NUMBA = "needs numba: pip install swarmdsl[numba] (or choose --backend numpy)"


def numba_installed() -> bool:
    return importlib.util.find_spec("numba") is not None




class _EverySizeAnd:
    """A paced tick's block, inside which the runtime's own portable math also goes to
    the compiled loops at every size (`portable.EVERY_SIZE`)."""

    __slots__ = ("inner",)

    def __init__(self, inner):
        self.inner = inner

    def __enter__(self):
        portable.EVERY_SIZE.__enter__()
        try:
            return self.inner.__enter__()
        except BaseException:
            portable.EVERY_SIZE.__exit__(None, None, None)
            raise

    def __exit__(self, *exc):
        try:
            return self.inner.__exit__(*exc)
        finally:
            portable.EVERY_SIZE.__exit__()


# Every this many ticks, sums try searching the cell list themselves again even though
# something read the pairs last tick.
DIRECT_RETRY = 64


class NumbaBackend:
    """The run's numba backend, a `protocols.Backend`, with what ran compiled and what it
    cost.

    `parts` maps each fused aggregate and statement to [compiled calls, reference
    calls]; `compile_seconds` is the time numba spent compiling this run's new kernels.
    """

    name = "numba"
    fused = True     # the lowered closures take their compiled paths

    def __init__(self):
        self.why = ""                       # why the default chose this backend, if it did
        self.choice: Choice | None = None   # the default's choice, when it chose
        self.motion_compiled: bool | None = None   # None: no tick has moved yet
        self.fields_compiled: bool | None = None   # None: the program has no fields
        from swarmdsl.runtime.compiled import math_loops

        math_loops.install()
        from swarmdsl.runtime.choice import use_compiled
        from swarmdsl.runtime.compiled import direction_choice

        use_compiled(direction_choice.loops)
        self.compile_seconds = 0.0
        self.parts: dict = {}
        self._others: tuple | None = None   # (tick, pos column, {columns: table}) per tick
        self._pairs_last = 0                # last tick's pair offsets: room for this one
        self._last_table = None             # weakref to it, and its writable arrays:
        self._spare = None                  # written again once the table is gone
        self._filled = False                # whether this tick's table wrote its pairs
        self._paces = weakref.WeakKeyDictionary()   # run -> its threads.Pace
        self._counts = None                 # 0, then each agent's pairs found by a search
        self._counted = False               # whether a search found them this tick
        self._tables = self._writes = 0     # tables built, and those that wrote pairs
        self.search_directly = False        # whether sums search the cell list this tick
        self.viewed: set = set()            # kinds whose robots' view the search tested
        t0 = time.perf_counter()
        from swarmdsl.runtime.compiled import cells, motion, random

        self._build = cells.build_pairs_cells
        self._move = motion.move_agents
        self.random_units = random.units
        self.random_units_rows = random.units_rows   # a call key per agent (batches)
        self.load_seconds = time.perf_counter() - t0

    def prepare(self, program) -> None:
        """Before a run of `program` starts: lower it (its aggregates, filters and
        statements with compiled paths, `compiled/lowering.py`) unless it was compiled
        so."""
        from swarmdsl.runtime.compiled.lowering import NUMBA

        program.lower(NUMBA)

    def field_type(self, reference: type) -> type:
        """The class that keeps a grid field: numba's loops (`compiled/fields.py`, the
        same bits as `reference`, numpy's `Field`)."""
        from swarmdsl.runtime.compiled.fields import CompiledField

        return CompiledField

    def finished(self, program, ticks: int) -> None:
        """A run of `program` ended: after a numba run that ticked, mark the program
        compiled on this machine (`warm.py`), so later, shorter runs may take numba."""
        if ticks > 0:
            warm.note_compiled(program)

    def build_pairs(self, pos, radius, box, bounds=None):
        """The tick's pair table, a cell list; with `bounds`, every replica's of a batch
        in one call (`replica_cells.replica_cells`: sums search each replica's cells
        directly), or None when they are searched replica by replica."""
        if bounds is not None and not self._replica_search(pos, bounds, radius):
            return None
        gone = self._last_table is None or self._last_table() is None
        # Last tick's arrays are written again only if nobody holds its table any more
        # (the simulation drops it before building this one); until this table writes
        # its pairs, they are its own.
        self._spare = self._spare if gone else None
        # Sums search the cell list themselves unless last tick something read the pairs
        # anyway (then they read them too): tried again now and then, in case that was
        # a one-off.
        self._tables += 1
        self.search_directly = not self._filled or self._tables % DIRECT_RETRY == 0
        if not self._filled and self._counted:   # room for as many pairs as were found
            self._pairs_last = self._counts.cumsum()
        self._filled = self._counted = False
        if bounds is None:
            table = self._build(pos, radius, box, self._pairs_last, self._spare,
                                self._on_fill)
        else:
            from swarmdsl.runtime.compiled.replica_cells import replica_cells

            table = replica_cells(pos, bounds, radius, box, self._spare, self._on_fill)
        self._last_table = weakref.ref(table)
        return table

    def pairs_table(self, pos, radius, box):
        """The pairs of `pos` as a row-order `PairTable`, each owner's in this backend's
        order (the cell list's), keeping no state between calls: one
        replica's table of a batch (`runtime/batch.py`)."""
        table = self._build(pos, radius, box)
        return getattr(table, "table", table)

    def replica_pairs(self, pos, bounds, radius, box):
        """The row-order table of every replica's pairs (`bounds[r]:bounds[r+1]` of
        `pos`), each as `pairs_table` finds it, in one call; None: call `pairs_table`
        per replica (numpy's KD-tree, whose order only a tree of the replica's own
        gives, or replicas of fewer than two agents, or a position not finite: the solo
        search handles those its own way)."""
        if not self._replica_search(pos, bounds, radius):
            return None
        from swarmdsl.runtime.compiled.replica_cells import replica_pairs

        return replica_pairs(pos, bounds, radius, box)

    def _replica_search(self, pos, bounds, radius) -> bool:
        """Whether replicas `bounds` are searched in one call."""
        from swarmdsl.runtime.spatial import positions_finite

        return radius > 0 and (bounds[1:] - bounds[:-1]).min() >= 2 and \
            positions_finite(pos)

    def _on_fill(self, table, soff, buffers) -> None:
        """A table wrote its pairs: room for next tick's, and arrays to write them in."""
        if self._last_table is not None and self._last_table() is table:
            self._filled = True
            self._writes += 1
            self._pairs_last = soff
            self._spare = buffers

    def neighbors_within(self, frame, table, limit, view=None):
        """`neighbors(r)` narrower than the tick's table `table`, for `frame`'s agents
        within `limit` (and `view`'s field of view): the numba backend masks its
        cell-order pairs in one compiled pass, pending until read (sums that search the
        cells test the condition themselves); None when the frame selects the rows."""
        from swarmdsl.runtime.spatial import CellPairs

        if not isinstance(table, CellPairs) or (view is not None and not self.fused):
            # (the reference closures would read a view's pairs at once: the sensing
            # model's numpy pass, rather than a view kernel compiled for one tick)
            return None
        from swarmdsl.runtime.compiled.fused import within

        if view is not None:
            self.viewed.add(frame.kind.name)
        return within(frame, table, limit, view)

    def _sensing_lines(self, program) -> list[str]:
        """`-v`: where each kind's sensing model chose its neighbours: tested in the
        compiled search (a view by place only), or by the model on numpy (draws)."""
        spec = next((make.spec for make in program.extensions
                     if getattr(make, "spec", None) is not None), None)
        lines = []
        for k, kind in enumerate(program.kinds if spec is not None else ()):
            view = spec.view(k)
            if view is not None and view.everything:
                continue
            where = ("compiled (its range and field of view tested in the search)"
                     if kind.name in self.viewed else
                     "numpy (the sensing model's dropout, noise or resolution)"
                     if view is None else "numpy (the sensing model)")
            lines.append(f"sensing of `{kind.name}`: {where}")
        return lines

    def pair_counts(self, n: int):
        """Where sums that search the cell list note each agent's pairs (in sorted order,
        n agents): next tick's estimate of how many pairs there are, and where."""
        if self._counts is None or self._counts.size != n + 1:
            import numpy as np

            self._counts = np.zeros(n + 1, np.int64)
        self._counted = True
        return self._counts[1:]

    def pair_offsets(self, n: int):
        """The latest offsets of n agents' pairs (sorted order), or None."""
        last = self._pairs_last
        return last if getattr(last, "size", 0) == n + 1 else None

    def move(self, sim):
        """The tick's motion compiled: (pos, vel, heading), or None for the numpy path
        (a robot profile's motion model moves the agents)."""
        got = self._move(sim)
        self.motion_compiled = got is not None
        return got

    def note(self, part, compiled: bool) -> None:
        calls = self.parts.setdefault(part, [0, 0])
        calls[0 if compiled else 1] += 1

    def summary(self, program) -> list[str]:
        """Lines for `swarmdsl run -v`: which aggregates and statements ran compiled, and
        why not."""
        lines = [f"backend: {self.name}"]
        lines[0] += (f" ({self.why + '; ' if self.why else ''}numba import "
                     f"{self.load_seconds:.2f} s, kernel compilation "
                     f"{self.compile_seconds:.2f} s)")
        search = "neighbour search: compiled cell list"
        if self._tables > self._writes:
            search += (f" (in {self._tables - self._writes:,} of {self._tables:,} ticks the sums "
                       "searched the cells themselves and no pair was written)")
        lines.append(search)
        if self.motion_compiled is not None:
            lines.append("motion (edge push, speed clamp, move, edges): " + (
                "compiled" if self.motion_compiled
                else "numpy (a robot profile's motion model moves the agents)"))
        if self.fields_compiled is not None:
            lines.append("fields (sample, gradient, deposit, decay and diffusion): " + (
                "compiled" if self.fields_compiled else "numpy (a refined grid)"))
        lines += self._sensing_lines(program)
        from swarmdsl.runtime.compiled import tick_run
        from swarmdsl.runtime.compiled.fused import part_line
        from swarmdsl.runtime.compiled.statements import summary

        lines += tick_run.summary(self)
        for part in getattr(program, "fused_parts", []):
            calls = self.parts.get(part, (0, 0))
            if part.name == "where" and not sum(calls):
                continue   # a filter an aggregate fuses never runs on its own
            line = part_line(part, part.name, calls,
                             "its neighbour set is not a pair-table query")
            derived = [c for c, _col, _t in (part.plan.others if part.plan else ())
                       if c == "derived"]
            if derived and calls[0]:
                line += (f" ({len(derived)} part{'s' if len(derived) > 1 else ''} of the "
                         "neighbour alone worked out once per agent)")
            if getattr(part, "siblings", None) is not None:
                line += part.siblings.note(part)
            lines.append(line)

        return lines + summary(program, self)

    def batch_threads(self, agents: int) -> tuple[int, str]:
        """How many threads a batch of `agents` ticks its kernels on, and why
        (`threads.for_batch`)."""
        from swarmdsl.runtime.compiled import threads

        return threads.for_batch(agents)

    def advance(self, sim, ticks: int, watch=None) -> int:
        """Run up to `ticks` ticks of `sim` in one compiled call (`tick_kernel.py`): how
        many ran, 0 if a check stopped the first, -1 if its ticks cannot run whole;
        with a `watch` (`driver.Watch`), its properties checked after every tick in
        the call (`tick_checks.py`)."""
        from swarmdsl.runtime.compiled import tick_run

        if self._too_many(sim):
            return -1
        got = tick_run.advance(self, sim, ticks, watch)
        if got > 0 and sim.sensing is not None:   # the kernel tested its robots' views
            self.viewed.update(kind.name for kind in sim.program.kinds)
        return got

    def whole_ticks_ready(self, sim, left: float = 0.0, watch=None) -> bool:
        """Whether `advance` would run ticks of `sim` whole now without compiling first
        (`tick_run.ready`; `left`, the seconds of ticks the run has left; `watch`,
        what its observers need checked after every tick): the driver asks before it
        hands over several ticks."""
        from swarmdsl.runtime.compiled import tick_run

        if self._too_many(sim):
            return False
        return tick_run.ready(self, sim, left, watch)

    def _too_many(self, sim) -> bool:
        """Whether `sim` has more agents than whole ticks pay for (`WHOLE_TICKS_MAX`);
        if so, `-v` says so. Asked before anything else, so a big run never has
        another process compile the whole-tick kernel beside it."""
        n = sim.agents.n
        if n <= WHOLE_TICKS_MAX:
            return False
        from swarmdsl.runtime.compiled import tick_run

        tick_run.state_of(self, sim).refused = (
            f"{n:,} agents: above {WHOLE_TICKS_MAX:,} the per-tick kernels are faster")
        return True

    def ticking(self, sim):
        """Around one `step()` of `sim`: its kernels on threads or on one, whichever
        ticks faster here and now (`threads.Pace`, one per run)."""
        from swarmdsl.runtime.compiled import threads

        if sim.agents.n < threads.PACE_FROM:
            return portable.EVERY_SIZE   # no pace to choose: no cost (about 20 us a tick)
        pace = self._paces.get(sim)
        if pace is None:
            pace = self._paces[sim] = threads.Pace()
        return _EverySizeAnd(pace.ticking(sim.agents.n, lambda: self.compile_seconds))

    def threads_limited(self, n: int):
        """A block whose kernels use at most `n` threads (`threads.limited`)."""
        from swarmdsl.runtime.compiled import threads

        return threads.limited(n)


def _lowering():
    from swarmdsl.runtime.compiled.lowering import NUMBA

    return NUMBA


def _tiered():
    from swarmdsl.runtime.compiled.tiered import TieredBackend

    return TieredBackend()


def _notes() -> list[str]:
    """A sweep plan's line on a batch's threads."""
    from swarmdsl.runtime.compiled import threads

    _n, why = threads.for_batch(2**62)
    return [f"threads: a numba batch of {threads.MIN_PARALLEL:,} agents or more ticks on "
            f"{why}"]


# Late-bound (each looks up this module's names when called), so a test may stand in
# for numba being absent by replacing `numba_installed`.
backends.register("numba", NumbaBackend, installed=lambda: numba_installed(),
                  missing=_NEEDS_NUMBA,
                  chooser=lambda program, work, tiered=False: choose(
                      program, work, numba_installed(), tiered),
                  lowering=_lowering, notes=_notes, tiered=_tiered)
# The tiered start's backend by name: only to continue a run that had it (the studio
# carrying a run over to new param values, a resumed checkpoint), never a user's choice.
backends.register("tiered", _tiered, installed=lambda: numba_installed(),
                  missing=_NEEDS_NUMBA, hidden=True)
