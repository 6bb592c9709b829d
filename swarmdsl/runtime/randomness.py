"""The run's random source: every draw is a pure function of (seed, agent id, tick, stream, call).

A counter-based generator rather than one sequential ``numpy.random.Generator``: the
value an agent draws depends only on the run seed, the agent's `id`, the tick, the
stream (the kind and status, or a runtime feature such as motion noise), the draw's
place in the program's structure (`compiler/stream_places.py`: never its line or
column, so comments and layout change no draw) and how many times that place has drawn
this tick. It never depends on how many other
agents there are or in which rows they sit, so deleting agent 7 leaves agent 3's
draws, and in a program without interactions its whole trajectory, unchanged. That is
what lets a property search shrink a swarm agent by agent.

The mixer is splitmix64's finaliser over uint64 arrays (two rounds per value), so a
draw for a million agents is a handful of whole-array operations and no Python loop.
The state a checkpoint needs is tiny: the seed, the tick and the per-stream call
counters of the current tick (`state()` / `set_state()`).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from swarmdsl.errors import SwarmOptionError
from swarmdsl.ops import portable

_MASK = (1 << 64) - 1
_GOLDEN = 0x9E3779B97F4A7C15
_C_ID = 0xD1B54A32D192ED03
_C_TICK = 0xAEF17502108EF2D9
_C_CALL = 0xF1357AEA2E62A9C5
_U_GOLDEN = np.uint64(_GOLDEN)
_U_ID = np.uint64(_C_ID)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_TO_UNIT = 2.0 ** -53
PLACEMENT_TICK = -1   # placement draws happen "before" tick 0
RNG_NAME = "swarmdsl-counter-v2"   # recorded in run.json: which generator made a run
# (v2: draws keyed by their place in the program, not their line and column)


def _mix_int(z: int) -> int:
    """splitmix64's finaliser on one Python int (the per-call key)."""
    z &= _MASK
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK
    return z ^ (z >> 31)


def _mix(z: np.ndarray) -> np.ndarray:
    """The same finaliser over a uint64 array (wraps silently: arrays never warn)."""
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@lru_cache(maxsize=4096)
def stream_key(name: str) -> int:
    """FNV-1a of a stream name: stable across processes, unlike `hash()`."""
    h = 0xCBF29CE484222325
    for b in name.encode("utf-8"):
        h = ((h ^ b) * 0x100000001B3) & _MASK
    return h


def pair_ids(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """One key per (agent, neighbour) pair, so pair draws are stable per pair too."""
    ua = np.asarray(a).astype(np.uint64, copy=False).reshape(-1)
    ub = np.asarray(b).astype(np.uint64, copy=False).reshape(-1)
    return _mix(ua * _U_ID + _U_GOLDEN) ^ ub


class RandomSource:
    """The one random source of a run (``sim.rng``)."""

    def __init__(self, seed: int = 0):
        self.seed = int(seed)
        self._key = _mix_int(self.seed ^ 0x5EED5EED5EED5EED)
        self.tick = PLACEMENT_TICK
        self._calls: dict[str, int] = {}
        # (ids, key, lanes, open_low) -> the uniforms of `AgentRandom._unit`, compiled;
        # set by the numba backend (None: numpy).
        self.compiled_units = None

    # ---- state ----
    def begin_tick(self, tick: int) -> None:
        """Start counting calls afresh for `tick` (the simulation calls this)."""
        if tick != self.tick:
            self.tick = int(tick)
            self._calls = {}

    def state(self) -> dict:
        """Everything needed to continue the same draws later (JSON-friendly)."""
        return {"seed": self.seed, "tick": self.tick, "calls": dict(self._calls)}

    def set_state(self, state: dict) -> None:
        """Continue the draws `state()` returned; anything else is an option error, not
        a KeyError (a notebook may hand in anything; a checkpoint's comes from disk)."""
        try:
            seed, tick = int(state["seed"]), int(state["tick"])
            calls = {str(k): int(v) for k, v in state["calls"].items()}
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise SwarmOptionError(f"state must be what rng.state() returns: seed, tick and "
                                   f"calls ({type(exc).__name__}: {exc})") from None
        self.seed, self.tick, self._calls = seed, tick, calls
        self._key = _mix_int(self.seed ^ 0x5EED5EED5EED5EED)

    def call_key(self, stream: str) -> int:
        """The key of the next call on `stream` this tick (advances its counter)."""
        count = self._calls.get(stream, 0)
        self._calls[stream] = count + 1
        tick = (self.tick & _MASK) * _C_TICK
        return _mix_int(self._key ^ _mix_int(tick ^ stream_key(stream)) ^ (count * _C_CALL))

    # ---- views ----
    def agents(self, ids, stream: str) -> AgentRandom:
        """Draws for the agents `ids` (their `id` column, not their rows) on `stream`."""
        return AgentRandom(self, np.asarray(ids), stream)

    def rows(self, id_col: np.ndarray, idx: np.ndarray, stream: str) -> AgentRandom:
        """Draws for the agents at rows `idx` of the store whose `id` column is `id_col`
        (a frame's: a batch of replicas keys each row by its own replica's seed)."""
        return self.agents(np.take(id_col, idx), stream)

    def pair_rows(self, id_col: np.ndarray, i: np.ndarray, j: np.ndarray,
                  stream: str) -> AgentRandom:
        """Draws per (row i, row j) pair of the store whose `id` column is `id_col`,
        keyed by both ids (`pair_ids`)."""
        return self.agents(pair_ids(np.take(id_col, i), np.take(id_col, j)), stream)


class AgentRandom:
    """A Generator-like view: every draw has one value (or row of values) per agent.

    The first axis of every `size` must be the number of agents; further axes are
    extra lanes of the same agent (``uniform(0, 1, (n, 2))`` is a point per agent).
    """

    def __init__(self, source: RandomSource, ids: np.ndarray, stream: str):
        self.source = source
        self.ids = ids.astype(np.uint64, copy=False).reshape(-1)
        self.n = self.ids.size
        self.stream = stream

    def at(self, place: str) -> AgentRandom:
        """The same agents on a sub-stream: one per draw of the program, named by its
        place (`compiler/stream_places.py`), or a runtime feature's part ("turn")."""
        return AgentRandom(self.source, self.ids, f"{self.stream}@{place}")

    def pairs(self, seg, j, id_col) -> AgentRandom:
        """Draws per (agent, neighbour) pair: agent ``seg`` of this view, neighbour row `j`."""
        return AgentRandom(self.source, pair_ids(np.take(self.ids, seg), np.take(id_col, j)),
                           f"{self.stream}/pairs")

    def subset(self, rows) -> AgentRandom:
        """Some of the agents, on the same stream (their draws are unchanged)."""
        return AgentRandom(self.source, self.ids[rows], self.stream)

    # ---- raw bits ----
    def _shape(self, size) -> tuple[int, ...]:
        if size is None:
            size = (self.n,)
        shape = (int(size),) if np.ndim(size) == 0 else tuple(int(s) for s in size)
        if not shape or shape[0] != self.n:
            raise ValueError(f"per-agent draws need size ({self.n}, ...), got {size!r}")
        return shape

    def _bits(self, base: int, lanes: int, first_lane: int = 0) -> np.ndarray:
        """``(n, lanes) uint64`` hashes of (call, agent, lane)."""
        h = _mix(self.ids * _U_ID + np.uint64(base))                       # (n,)
        lane = np.arange(first_lane, first_lane + lanes, dtype=np.uint64) * _U_GOLDEN
        return _mix(h[:, None] + lane[None, :])

    def _unit(self, shape, open_low: bool = False) -> np.ndarray:
        lanes = int(np.prod(shape[1:], dtype=np.int64))
        base = self.source.call_key(self.stream)
        compiled = self.source.compiled_units
        if compiled is not None:   # the numba backend's loop: the same bits
            return compiled(self.ids, base, lanes, open_low).reshape(shape)
        bits = self._bits(base, lanes)
        u = (bits >> _S11).astype(np.float64)
        if open_low:
            u += 1.0
        return (u * _TO_UNIT).reshape(shape)

    # ---- numpy.random.Generator-like draws ----
    def random(self, size=None) -> np.ndarray:
        """Uniform in [0, 1)."""
        return self._unit(self._shape(size))

    def uniform(self, low=0.0, high=1.0, size=None) -> np.ndarray:
        u = self.random(size)
        low, high = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
        return low + u * (high - low)

    def standard_normal(self, size=None) -> np.ndarray:
        """Box-Muller over two lanes per value (exact per agent, no rejection)."""
        shape = self._shape(size)
        u = self._unit((*shape, 2), open_low=True)
        return np.sqrt(-2.0 * portable.log_array(u[..., 0])) * portable.cos_array(2.0 * np.pi * u[..., 1])

    def normal(self, loc=0.0, scale=1.0, size=None) -> np.ndarray:
        return loc + scale * self.standard_normal(size)

    def integers(self, low, high=None, size=None) -> np.ndarray:
        if high is None:
            low, high = 0, low
        u = self.random(size)
        return np.minimum(low + np.floor(u * (high - low)), high - 1).astype(np.int64)

    def choice(self, a, size=None, p=None) -> np.ndarray:
        """Indices into `a` (an int: ``range(a)``) by inverse CDF, one uniform per draw."""
        k = int(a) if np.ndim(a) == 0 else len(a)
        u = self.random(size)
        if p is None:
            idx = np.minimum((u * k).astype(np.int64), k - 1)
        else:
            cum = np.cumsum(np.asarray(p, dtype=np.float64))
            idx = np.minimum(np.searchsorted(cum / cum[-1], u, side="right"), k - 1)
        return idx if np.ndim(a) == 0 else np.asarray(a)[idx]

    def rejection(self, accept, low, high, batch: int = 8, rounds: int = 1000) -> np.ndarray:
        """``(n, d)`` points uniform in the box [low, high) for which `accept` holds.

        Agent by agent, candidates come from fixed lanes of one call, so an agent's point
        does not depend on how many tries the others needed.
        """
        low, high = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
        d = low.size
        base = self.source.call_key(self.stream)
        out = np.empty((self.n, d))
        pending = np.arange(self.n)
        for r in range(rounds):
            if pending.size == 0:
                return out
            sub = AgentRandom(self.source, self.ids[pending], self.stream)
            bits = sub._bits(base, batch * d, first_lane=r * batch * d)
            cand = low + (bits >> _S11).astype(np.float64).reshape(-1, batch, d) * _TO_UNIT \
                * (high - low)
            ok = np.asarray(accept(cand.reshape(-1, d)), dtype=bool).reshape(-1, batch)
            hit = ok.any(axis=1)
            first = ok.argmax(axis=1)
            out[pending[hit]] = cand[hit, first[hit]]
            pending = pending[~hit]
        if pending.size:
            raise ValueError(f"cannot place {pending.size} points: too few candidates fit")
        return out
