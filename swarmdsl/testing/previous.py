"""What `previous(X)` in a property remembers: X at the previous checked tick, per call
site (and per agent id in a per-agent property), kept by the property monitor of one run.

At the first checked tick (tick 0, or the tick a run's checks start), and for an agent
at the first tick it is checked, there is no previous value: `previous(X)` is X. Checking
the same tick again (a state machine checks after every rule) answers as the first check
of that tick did, so a re-check never compares a tick with itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class _Seen:
    """One call site at its last checked tick: X then, and what `previous(X)` answered
    then (for a re-check of that tick); `ids` sorted, None for a swarm property."""

    tick: int
    now: np.ndarray
    before: np.ndarray
    ids: np.ndarray | None = None


class PreviousValues:
    """Per call site, what X was at the last checked tick (`recall`)."""

    def __init__(self):
        self.sites: dict[str, _Seen] = {}

    def recall(self, key: str, tick: int, now: np.ndarray, ids: np.ndarray | None = None):
        """X at the previous checked tick, given X `now` at `tick` (one row per agent of
        `ids`, or one value for the swarm); remembers `now` for the next tick."""
        seen = self.sites.get(key)
        if ids is None:
            before = now if seen is None else (seen.before if seen.tick == tick else seen.now)
            self.sites[key] = _Seen(tick, now, before)
            return before
        order = np.argsort(ids, kind="stable")
        ids, now_sorted = np.asarray(ids)[order], now[order]
        if seen is None:
            before = now_sorted
        else:
            old = seen.before if seen.tick == tick else seen.now
            before = _by_id(seen.ids, old, ids, now_sorted)
        self.sites[key] = _Seen(tick, now_sorted, before, ids)
        out = np.empty_like(before)
        out[order] = before
        return out

    def state(self) -> dict:
        """The sites as plain JSON values, for a checkpoint."""
        return {key: {"tick": s.tick, "now": s.now.tolist(), "before": s.before.tolist(),
                      "ids": None if s.ids is None else s.ids.tolist()}
                for key, s in self.sites.items()}

    def load(self, state: dict) -> None:
        self.sites = {key: _Seen(int(s["tick"]), np.asarray(s["now"]),
                                 np.asarray(s["before"]),
                                 None if s["ids"] is None else np.asarray(s["ids"], np.int64))
                      for key, s in state.items()}


def _by_id(old_ids: np.ndarray, old: np.ndarray, ids: np.ndarray, now: np.ndarray):
    """For each of `ids` (sorted), its value in `old` (rows of sorted `old_ids`), or its
    value `now` when it was not there (an agent checked for the first time)."""
    at = np.searchsorted(old_ids, ids)
    at = np.minimum(at, max(old_ids.size - 1, 0))
    found = old_ids[at] == ids if old_ids.size else np.zeros(ids.size, bool)
    out = now.copy()
    out[found] = old[at[found]]
    return out
