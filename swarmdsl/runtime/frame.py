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
        self.rng = sim.rng
        self.tick = sim.tick
        self.locals: dict[str, object] = {}
        self.overlay: dict[str, np.ndarray] = {}
        self.active = np.ones(self.n, dtype=bool)
        self.next_status: np.ndarray | None = None
        self.effects: list = []             # callables run after every frame of the tick

    def state(self, col: str) -> np.ndarray:
        got = self.overlay.get(col)
        if got is not None:
            return got
        return self.sim.agents.cols[col][self.idx]

    def local(self, name: str):
        return self.locals[name]

    def neighbors(self, radius) -> NeighborSet:
        table = self.sim.pairs
        if table is None:  # no kind senses anything this tick: nobody is in range
            empty = np.zeros(0, np.int64)
            return NeighborSet(self, empty, empty, np.zeros(0), np.zeros((0, 2)))
        seg, j, dist, delta = table.gather(self.idx)
        limit = self.sim.agents.cols["sense"][self.idx]
        if radius is not None:
            limit = np.minimum(limit, radius)
        keep = dist <= np.asarray(limit)[seg]
        if not keep.all():
            seg, j, dist, delta = seg[keep], j[keep], dist[keep], delta[keep]
        return NeighborSet(self, seg, j, dist, delta)


class NeighborSet:
    """Pairs (seg, j): agent `seg` of the owner frame sees agent row `j` at `dist`."""

    def __init__(self, owner: AgentFrame, seg, j, dist, delta):
        self.owner = owner
        self.seg, self.j, self.dist, self.delta = seg, j, dist, delta

    def subset(self, keep: np.ndarray) -> NeighborSet:
        return NeighborSet(self.owner, self.seg[keep], self.j[keep], self.dist[keep],
                           self.delta[keep])

    def pair_frame(self) -> PairFrame:
        return PairFrame(self)


class PairFrame:
    def __init__(self, pairs: NeighborSet):
        owner = pairs.owner
        self.owner = owner
        self.pairs = pairs
        self.sim = owner.sim
        self.seg = pairs.seg
        self.j = pairs.j
        self.dist = pairs.dist
        self.n = pairs.seg.size
        self.rng = owner.rng
        self.tick = owner.tick
        self.kind = owner.kind
        self.status_name = owner.status_name

    def state(self, col: str) -> np.ndarray:
        return self.owner.state(col)[self.seg]

    def local(self, name: str):
        return self.owner.locals[name][self.seg]

    def other(self, col: str) -> np.ndarray:
        if col == "pos" and self.sim.world.wraps:
            return self.owner.state("pos")[self.seg] + self.pairs.delta
        return self.sim.agents.cols[col][self.j]
