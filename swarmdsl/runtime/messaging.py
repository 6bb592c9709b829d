"""Messages between agents: what each agent broadcast last tick, delivered this tick to
the agents within its hearing range, with optional loss and distance noise.

Each agent's outgoing values live in the agent store as columns `msg_NAME` (the last value
it broadcast on that channel) and `msg_tick` (the tick it last broadcast). At the start
of a tick the messenger builds the table of delivered messages, CSR by receiver, that
`heard()` gathers like a neighbour query; `dist` over it is the measured distance (a
Kilobot measures distance from the strength of the signal it receives).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmdsl.runtime.frame import NeighborSet
from swarmdsl.runtime.spatial import PairTable

NEVER = -1.0e9
"""`msg_tick` of an agent that never broadcast."""


@dataclass(frozen=True)
class MessageSpec:
    """Per kind (by kind index): hearing range, loss chance, distance noise."""

    ranges: np.ndarray          # (K,) float64
    loss: np.ndarray            # (K,) float64
    distance_noise: np.ndarray  # (K,) float64


class HeardSet(NeighborSet):
    """The messages one frame's agents received this tick, as (agent, sender) pairs."""

    heard = True

    def subset(self, keep: np.ndarray) -> HeardSet:
        return HeardSet(self.owner, self.seg[keep], self.j[keep], self.dist[keep],
                        self.delta[keep])


def _empty(n: int) -> PairTable:
    return PairTable(0.0, np.zeros(n + 1, np.int64), np.zeros(0, np.int64), np.zeros(0),
                     np.zeros((0, 2)))


class Messenger:
    """Runtime extension: delivers last tick's broadcasts at the start of each tick."""

    def __init__(self, sim, spec: MessageSpec, columns: dict | None = None):
        self.spec = spec
        self.columns = columns or {}   # column -> kind indices whose agents send it
        self.table = _empty(0)
        self.sent_count = 0        # messages that could have been heard this tick (in range)
        self.delivered_count = 0   # of those, how many arrived

    def after_placement(self, sim) -> None:
        kinds = sim.agents.cols["kind"]
        for column, senders in self.columns.items():
            sim.agents.declared[column][:] = np.isin(kinds, senders)

    def state_dict(self, sim) -> dict:
        """Nothing of its own: messages in flight are the `msg_*` agent columns (sent
        last tick), and the delivery table is rebuilt from them when a tick begins."""
        return {}

    def load_state(self, sim, state: dict) -> None:
        self.table = _empty(sim.agents.n)

    def begin_tick(self, sim) -> None:
        cols = sim.agents.cols
        n = sim.agents.n
        sent = cols["msg_tick"] == sim.tick - 1
        self.sent_count = self.delivered_count = 0
        if n < 2 or not sent.any():
            self.table = _empty(n)
            return
        spec = self.spec
        radius = float(spec.ranges.max())
        pairs = sim.pairs
        if pairs is None or pairs.radius < radius or pairs.offsets.size != n + 1:
            pairs = _search(sim, radius)
        i = pairs.i
        kinds = np.take(cols["kind"], i)               # each pair's receiver's kind
        keep = sent[pairs.j] & (pairs.dist <= spec.ranges[kinds])
        self.sent_count = int(keep.sum())
        rng = None
        if spec.loss.max() > 0:     # else no pair can be lost: no draw, as below
            loss = spec.loss[kinds]
            if (loss[keep] > 0).any():
                rng = sim.rng.pair_rows(cols["id"], i, pairs.j, "messages")
                keep &= rng.at("loss").random(i.size) >= loss
        dist = pairs.dist
        if spec.distance_noise.max() > 0:
            sigma = spec.distance_noise[kinds]
            if (sigma[keep] > 0).any():
                if rng is None:
                    rng = sim.rng.pair_rows(cols["id"], i, pairs.j, "messages")
                dist = np.maximum(dist + rng.at("range").standard_normal(i.size) * sigma,
                                  0.0)
        self.delivered_count = int(keep.sum())
        mine = i[keep]
        offsets = np.zeros(n + 1, np.int64)
        np.cumsum(np.bincount(mine, minlength=n), out=offsets[1:])
        self.table = PairTable(radius, offsets, pairs.j[keep], dist[keep],
                               pairs.delta[keep], mine)

    def heard(self, frame) -> HeardSet:
        if self.table.offsets.size != frame.sim.agents.n + 1:   # before the first tick
            self.table = _empty(frame.sim.agents.n)
        seg, j, dist, delta = self.table.gather(frame.idx)
        return HeardSet(frame, seg, j, dist, delta)

    def links(self) -> np.ndarray:
        """(L, 2) unordered (row, row) pairs that exchanged a message this tick."""
        t = self.table
        i = np.repeat(np.arange(t.offsets.size - 1), np.diff(t.offsets))
        pairs = np.stack([np.minimum(i, t.j), np.maximum(i, t.j)], axis=1)
        return np.unique(pairs, axis=0) if pairs.size else pairs.reshape(0, 2)

    def decorate_snapshot(self, sim, snap) -> None:
        snap.links = self.links()


def _search(sim, radius: float) -> PairTable:
    """The pairs within `radius`, wider than the tick's table: the backend's own search
    (every backend's finds the same pairs in the same order, `spatial.build_pairs`) in a
    run of its own, a batch's replica by replica."""
    if sim.replica_bounds().size == 2:    # one run
        return sim.backend.pairs_table(sim.agents.cols["pos"], radius, sim.world.box)
    return sim.reference_pairs(radius)


def messenger_of(sim) -> Messenger:
    for ext in sim.extensions:
        if isinstance(ext, Messenger):
            return ext
    raise LookupError("the program has no messaging")  # pragma: no cover
