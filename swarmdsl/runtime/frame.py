"""Evaluation frames: the set of agents (or neighbour pairs) a closure runs over.

An agent frame holds the agents of one status for one tick: their start-of-tick state,
their own writes so far (visible to themselves only) and their `let` values. A pair
frame evaluates a neighbour filter or aggregate over (agent, neighbour) pairs: `self`
values are gathered from the owning agent frame, `other` values from the start-of-tick
state of the neighbour.
"""

from __future__ import annotations

import numpy as np


class AgentFrame:
    def __init__(self, sim, idx: np.ndarray, kind, status_name: str | None):
        self.sim = sim
        self.idx = idx                       # (M,) int64 rows in the agent store
        self.n = idx.size
        self.kind = kind
        self.status_name = status_name
        self._rng = None                     # keyed on first use (`rng`)
        self.tick = sim.tick
        self.locals: dict[str, object] = {}
        self.overlay: dict[str, np.ndarray] = {}
        self.active = np.ones(self.n, dtype=bool)
        self.next_status: np.ndarray | None = None
        self.effects: list = []             # callables run after every frame of the tick

    @property
    def rng(self):
        """Draws keyed by agent id and (kind, status): stable whoever else is in the
        frame. Keyed on first use: most frames draw nothing (a frame per status a
        tick, and the metrics' and properties' frames)."""
        if self._rng is None:
            sim = self.sim
            stream = f"{getattr(self.kind, 'name', self.kind)}/{self.status_name or '(place)'}"
            self._rng = sim.rng.rows(sim.agents.cols["id"], self.idx, stream)
        return self._rng

    @rng.setter
    def rng(self, value) -> None:
        self._rng = value

    def close(self) -> None:
        """Drop what the frame holds for the tick (lets, writes, effects) once it is over.

        Neighbour sets in `locals` refer back to this frame, so without this the frame,
        its neighbour sets and the tick's pair table would form a cycle that only the
        garbage collector frees.
        """
        self.locals.clear()
        self.overlay.clear()
        self.effects.clear()
        self.next_status = None

    def state(self, col: str) -> np.ndarray:
        got = self.overlay.get(col)
        if got is not None:
            return got
        return np.take(self.sim.agents.cols[col], self.idx, axis=0)

    def local(self, name: str):
        return self.locals[name]

    def neighbors(self, radius) -> NeighborSet:
        table = self.sim.pairs
        if table is None:  # no kind senses anything this tick: nobody is in range
            empty = np.zeros(0, np.int64)
            return NeighborSet(self, empty, empty, np.zeros(0), np.zeros((0, 2)))
        limit = self.sim.agents.cols["sense"][self.idx]
        if radius is not None:
            limit = np.minimum(limit, radius)
        narrower = not (limit.size and limit.min() >= table.radius)
        sensing = self.sim.sensing   # a robot profile's sensing model
        view = None if sensing is None else sensing.view(self)
        if view is not None and view.everything:   # this kind's sensing lets all through
            sensing = view = None
        if not narrower and sensing is None:
            # The whole table's pairs of these agents: which rows they are is worked out
            # only if something reads them (a compiled aggregate reads the table as is).
            return NeighborSet(self, None, base=table, query=self.idx)
        if sensing is None or view is not None:
            # the backend's own table may narrow itself, and test a field of view that
            # depends on where the neighbour is only (a compiled pass)
            narrowed = self.sim.backend.neighbors_within(self, table, limit, view)
            if narrowed is not None:
                return narrowed
        seg, rows = table.select(self.idx)
        pairs = NeighborSet(self, seg, base=table, rows=rows)
        if narrower:
            keep = pairs.dist <= np.asarray(limit)[seg]
            pairs = pairs if keep.all() else pairs.subset(keep)
        return pairs if sensing is None else sensing.neighbors(self, pairs)


class NeighborSet:
    """Pairs (seg, j): agent `seg` of the owner frame sees agent row `j` at `dist`
    (`delta`: the offset to it). What closures read is `seg`, `j`, `dist`, `delta`,
    `subset` and `pair_frame`, whichever of three ways the set holds its pairs:

    - as arrays: `seg`, `j`, `dist`, `delta` given;
    - as a view: `seg` given, `j`, `dist` and `delta` taken on first read from `base`
      (a pair table or another set) at `rows` (None: all of them), so a filter copies
      only the columns read later;
    - as a query: the owners' rows `query` in the whole table `base`; `seg` and `rows`
      are selected on first read, through `keep` when a backend gave one (a mask over
      the cell-order pairs of a `spatial.CellPairs`, or a pending one with `mask()`).
      Until then a backend may read the table as it is (`selected` is False).

    The columns may be the tick's pair table itself: read-only.
    """

    perceived = False  # True: what a sensing model let through; `delta` is sensed, noisy

    def __init__(self, owner: AgentFrame, seg, j=None, dist=None, delta=None, *,
                 base=None, rows=None, query=None, keep=None):
        self.owner = owner
        self.base = base         # where `j`, `dist`, `delta` come from (None: given)
        self.query = query       # a query's owner rows (None: not a query)
        self.keep = keep         # a query's mask over the cell-order pairs, or None
        self._seg, self._rows = (None, None) if query is not None else (seg, rows)
        self._cols = {} if base is not None else {"j": j, "dist": dist, "delta": delta}

    @property
    def selected(self) -> bool:
        """Whether `seg` and `rows` are worked out (always, unless a query not read)."""
        return self._seg is not None

    @property
    def seg(self) -> np.ndarray:
        if self._seg is None:
            self._seg, self._rows = self._selected()
        return self._seg

    @property
    def rows(self):
        """The pairs of `base` this set holds, by row (None: all of them, in order)."""
        if self._seg is None:
            self._seg, self._rows = self._selected()
        return self._rows

    @property
    def j(self) -> np.ndarray:
        return self._column("j")

    @property
    def dist(self) -> np.ndarray:
        return self._column("dist")

    @property
    def delta(self) -> np.ndarray:
        return self._column("delta")

    def _column(self, name: str):
        cols = self._cols
        if name not in cols:
            value = getattr(self.base, name)
            rows = self.rows
            cols[name] = value if rows is None else np.take(value, rows, axis=0)
        return cols[name]

    def _selected(self):
        """(seg, rows) of the queried owners' pairs in the row-order table, masked."""
        seg, rows = self.base.select(self.query)
        keep = self.keep
        if keep is None:
            return seg, rows
        if not isinstance(keep, np.ndarray):   # a compiled filter's, not worked out yet
            keep = keep.mask()
        cells = self.base.cell_index if rows is None else np.take(self.base.cell_index, rows)
        sel = np.flatnonzero(np.take(keep, cells))
        return np.take(seg, sel), sel if rows is None else np.take(rows, sel)

    def subset(self, keep: np.ndarray) -> NeighborSet:
        sel = np.flatnonzero(keep)  # take() by index: 2-10x faster than a bool mask
        if self.base is None:
            base, rows = self, sel
        else:
            base, rows = self.base, sel if self.rows is None else np.take(self.rows, sel)
        out = NeighborSet(self.owner, np.take(self.seg, sel), base=base, rows=rows)
        out.perceived = self.perceived
        return out

    def pair_frame(self) -> PairFrame:
        return PairFrame(self)


class PairFrame:
    def __init__(self, pairs: NeighborSet):
        owner = pairs.owner
        self.owner = owner
        self.pairs = pairs
        self.sim = owner.sim
        self.seg = pairs.seg
        self.n = pairs.seg.size
        self._rng = None
        self.tick = owner.tick
        self.kind = owner.kind
        self.status_name = owner.status_name

    @property
    def rng(self):
        """Per-pair draws, keyed on first use: most pair expressions draw nothing, and
        keying every pair costs a quarter of a boids tick."""
        if self._rng is None:
            owner = self.owner
            self._rng = owner.rng.pairs(self.seg, self.pairs.j, owner.sim.agents.cols["id"])
        return self._rng

    @rng.setter
    def rng(self, value) -> None:
        self._rng = value

    @property
    def j(self) -> np.ndarray:
        return self.pairs.j

    @property
    def dist(self) -> np.ndarray:
        return self.pairs.dist

    def state(self, col: str) -> np.ndarray:
        return np.take(self.owner.state(col), self.seg, axis=0)

    def local(self, name: str):
        return np.take(self.owner.locals[name], self.seg, axis=0)

    def other(self, col: str) -> np.ndarray:
        if col == "pos" and (self.sim.world.wraps or self.pairs.perceived):
            return np.take(self.owner.state("pos"), self.seg, axis=0) + self.pairs.delta
        return np.take(self.sim.agents.cols[col], self.j, axis=0)

    def other_minus_own_pos(self) -> np.ndarray:
        """`other.pos - pos`: the pair's `delta` (the same bits outside wrap-around worlds)."""
        if (self.sim.world.wraps or "pos" in self.owner.overlay) and not self.pairs.perceived:
            return self.other("pos") - self.state("pos")
        return self.pairs.delta
