"""The random source of a batch of replicas: every row drawn with its own replica's keys.

A solo run's draw is a pure function of (seed, agent id, tick, stream, call), the
stream named by the draw's place in the program (the same names here): the call
key (`RandomSource.call_key`) mixes the seed with the stream and how many times the
stream was drawn this tick, then each agent's number mixes the key with its id. A batch
(`runtime/batch.py`) computes the key of every replica at once and gives each row its own
replica's (`ids * C + key_of_row`: elementwise, so the same integers as the solo draw).

Counters are per replica and advance only for the replicas that have agents in a call:
a solo run skips a call that has nobody to draw for (a status nobody is in, a sensing
model's dropout over no pairs), and a later call on the same stream in the same tick
must then see the count the solo run sees.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from swarmdsl.errors import SwarmOptionError, SwarmRuntimeError
from swarmdsl.runtime.randomness import (
    _C_CALL,
    _C_TICK,
    _MASK,
    _TO_UNIT,
    AgentRandom,
    RandomSource,
    _mix,
    _mix_int,
    pair_ids,
    stream_key,
)

_U_CALL = np.uint64(_C_CALL)
_S11 = np.uint64(11)


class ReplicaRandom(AgentRandom):
    """`AgentRandom` over rows of several replicas: `replica` holds each agent's replica,
    whose call key it draws with."""

    def __init__(self, source: BatchRandom, ids: np.ndarray, stream: str,
                 replica: np.ndarray):
        super().__init__(source, ids, stream)
        self.replica = replica

    def at(self, place: str) -> ReplicaRandom:
        return ReplicaRandom(self.source, self.ids, f"{self.stream}@{place}", self.replica)

    def pairs(self, seg, j, id_col) -> ReplicaRandom:
        return ReplicaRandom(self.source, pair_ids(np.take(self.ids, seg), np.take(id_col, j)),
                             f"{self.stream}/pairs", np.take(self.replica, seg))

    def subset(self, rows) -> ReplicaRandom:
        return ReplicaRandom(self.source, self.ids[rows], self.stream, self.replica[rows])

    def _unit(self, shape, open_low: bool = False) -> np.ndarray:
        lanes = int(np.prod(shape[1:], dtype=np.int64))
        base = np.take(self.source.call_keys(self.stream, self.replica), self.replica)
        compiled = self.source.compiled_rows
        if compiled is not None:   # the numba backend's loop: the same bits
            return compiled(self.ids, base, lanes, open_low).reshape(shape)
        bits = self._bits(base, lanes)   # ids * C + base: elementwise, the solo bits
        u = (bits >> _S11).astype(np.float64)
        if open_low:
            u += 1.0
        return (u * _TO_UNIT).reshape(shape)

    def rejection(self, accept, low, high, batch: int = 8, rounds: int = 1000):
        raise SwarmRuntimeError("internal: a batch places each replica with its own "
                                "random source; rejection draws are not batched")


class BatchRandom(RandomSource):
    """One key per replica's seed; per stream, one call counter per replica."""

    def __init__(self, seeds: Sequence[int], replica_of_row: np.ndarray, compiled_rows=None):
        super().__init__(seeds[0])
        self.seeds = list(seeds)
        self.keys = np.array([_mix_int(s ^ 0x5EED5EED5EED5EED) for s in self.seeds],
                             dtype=np.uint64)
        self.replica_of_row = replica_of_row
        self.compiled_rows = compiled_rows   # the backend's `units_rows`, or None

    def call_keys(self, stream: str, replica: np.ndarray) -> np.ndarray:
        """(R,) uint64: each replica's key of its next call on `stream`; the counters of
        the replicas in `replica` (those drawing) advance."""
        counts = self._calls.get(stream)
        if counts is None:
            counts = self._calls[stream] = np.zeros(len(self.seeds), np.uint64)
        tick = (self.tick & _MASK) * _C_TICK
        salt = np.uint64(_mix_int(tick ^ stream_key(stream)))
        keys = _mix(self.keys ^ salt ^ (counts * _U_CALL))   # wraps: & _MASK
        counts[replica] += np.uint64(1)
        return keys

    def call_key(self, stream: str):
        raise SwarmRuntimeError("internal: a batch draws per replica (`call_keys`)")

    def calls_of(self, r: int) -> dict[str, int]:
        """Replica r's call counters this tick, as its solo source keeps them."""
        return {k: int(v[r]) for k, v in self._calls.items() if v[r]}

    def state(self) -> dict:
        """What a checkpoint saves: a batch keeps none (its runs resume per run)."""
        raise SwarmOptionError("a batch of replicas keeps no checkpoint: its runs resume "
                               "per run (a stopped sweep runs again the runs it did not "
                               "finish); checkpoint a long run as a Run")

    def rows(self, id_col, idx, stream: str) -> ReplicaRandom:
        return ReplicaRandom(self, np.take(id_col, idx), stream,
                             np.take(self.replica_of_row, idx))

    def pair_rows(self, id_col, i, j, stream: str) -> ReplicaRandom:
        return ReplicaRandom(self, pair_ids(np.take(id_col, i), np.take(id_col, j)), stream,
                             np.take(self.replica_of_row, i))

    def agents(self, ids, stream: str):
        raise SwarmRuntimeError("internal: a batch draws by rows (`rows`), not by ids")
