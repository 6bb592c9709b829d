"""Per-agent path memories and food-label sets, kept as columns of the AgentStore.

A path memory is a bounded ring buffer of points per agent: ``NAME:pts (N, K, 2)``,
``NAME:start (N,)`` and ``NAME:len (N,)``. A label set is one ``int64`` bit mask per agent
(``NAME:bits (N,)``), bit ``i`` standing for the ``i``-th declared food source. Only the
owning agent reads its memory, so writes go straight to the store: an agent sees its
own writes at once and no other agent can observe the order.
"""

from __future__ import annotations

import numpy as np

MAX_LABELS = 63  # bits of an int64 mask, the sign bit left alone


class PathMemory:
    """The columns of one named path memory of capacity ``k`` points per agent."""

    def __init__(self, agents, name: str, capacity: int):
        if int(capacity) != capacity or capacity < 1:
            raise ValueError(f"memory capacity must be a whole number >= 1, got {capacity}")
        self.name = name
        self.k = int(capacity)
        self.pts, self.start, self.len = f"{name}:pts", f"{name}:start", f"{name}:len"
        agents.add_column(self.pts, (self.k, 2), np.float64, 0.0)
        agents.add_column(self.start, (), np.int64, 0)
        agents.add_column(self.len, (), np.int64, 0)

    def length(self, cols, rows: np.ndarray) -> np.ndarray:
        """``(M,) int64`` points remembered by each agent in ``rows``."""
        return cols[self.len][rows]

    def push(self, cols, rows: np.ndarray, points: np.ndarray) -> None:
        """Append ``points (M, 2)``; a full memory forgets its oldest point."""
        if rows.size == 0:
            return
        start, n = cols[self.start][rows], cols[self.len][rows]
        cols[self.pts][rows, (start + n) % self.k] = points
        full = n >= self.k
        cols[self.start][rows] = np.where(full, (start + 1) % self.k, start)
        cols[self.len][rows] = np.minimum(n + 1, self.k)

    def pop(self, cols, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Remove each agent's newest point: ``(points (M, 2), had_one (M,) bool)``.

        Agents with an empty memory get ``had_one`` False and an undefined point.
        """
        start, n = cols[self.start][rows], cols[self.len][rows]
        had = n > 0
        slot = (start + np.maximum(n - 1, 0)) % self.k
        points = cols[self.pts][rows, slot]
        cols[self.len][rows] = np.maximum(n - 1, 0)
        return points, had

    def clear(self, cols, rows: np.ndarray) -> None:
        cols[self.len][rows] = 0
        cols[self.start][rows] = 0


class LabelSet:
    """One named per-agent set of food labels, as a bit mask column."""

    def __init__(self, agents, name: str):
        self.name = name
        self.bits = f"{name}:bits"
        agents.add_column(self.bits, (), np.int64, 0)

    @staticmethod
    def _mask(labels: np.ndarray) -> np.ndarray:
        labels = np.asarray(labels, dtype=np.int64)
        return np.where(labels >= 0, np.left_shift(1, np.clip(labels, 0, MAX_LABELS - 1)), 0)

    def contains(self, cols, rows: np.ndarray, labels: np.ndarray) -> np.ndarray:
        """``(M,) bool``: does each agent know its label (``-1`` = no label: False)."""
        return (cols[self.bits][rows] & self._mask(labels)) != 0

    def add(self, cols, rows: np.ndarray, labels: np.ndarray) -> None:
        cols[self.bits][rows] |= self._mask(labels)

    def size(self, cols, rows: np.ndarray) -> np.ndarray:
        """``(M,) int64`` number of labels each agent knows (a popcount)."""
        bits = cols[self.bits][rows].astype(np.uint64)
        count = np.zeros(bits.shape, dtype=np.int64)
        for _ in range(MAX_LABELS):  # loop over bits, never over agents
            count += (bits & np.uint64(1)).astype(np.int64)
            bits >>= np.uint64(1)
            if not bits.any():
                break
        return count

    def clear(self, cols, rows: np.ndarray) -> None:
        cols[self.bits][rows] = 0
