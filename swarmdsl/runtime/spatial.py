"""Neighbour pairs from one spatial index per tick, and segment reductions over them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree


@dataclass
class PairTable:
    """Every ordered pair (i, j), i != j, within `radius`, sorted by i (CSR layout).

    `offsets[i]:offsets[i+1]` indexes the pairs of agent i. `delta` is `pos[j] - pos[i]`,
    the shortest way round in a wrap-around world.
    """

    radius: float
    offsets: np.ndarray   # (N+1,) int64
    j: np.ndarray         # (P,) int64
    dist: np.ndarray      # (P,) float64
    delta: np.ndarray     # (P, 2) float64

    def gather(self, idx: np.ndarray):
        """Pairs whose i is in `idx` (sorted): (seg (P',) local row in idx, j, dist, delta)."""
        starts = self.offsets[idx]
        counts = self.offsets[idx + 1] - starts
        total = int(counts.sum())
        seg = np.repeat(np.arange(idx.size), counts)
        if total == 0:
            return seg, self.j[:0], self.dist[:0], self.delta[:0]
        first = np.cumsum(counts) - counts
        rows = np.arange(total) - np.repeat(first - starts, counts)
        return seg, self.j[rows], self.dist[rows], self.delta[rows]


def build_pairs(pos: np.ndarray, radius: float, box: tuple[float, float] | None) -> PairTable:
    """All neighbour pairs within `radius` (a KD-tree; `box` makes the world wrap around)."""
    n = pos.shape[0]
    if n < 2 or radius <= 0:
        return PairTable(radius, np.zeros(n + 1, np.int64), np.zeros(0, np.int64),
                         np.zeros(0), np.zeros((0, 2)))
    if box is not None:
        pts = np.mod(pos, box)
        # cKDTree needs points strictly inside [0, box); mod can return box for -tiny.
        pts = np.where(pts >= box, 0.0, pts)
        tree = cKDTree(pts, boxsize=box)
    else:
        pts = pos
        tree = cKDTree(pts)
    half = tree.query_pairs(radius, output_type="ndarray")
    i = np.concatenate([half[:, 0], half[:, 1]]).astype(np.int64)
    j = np.concatenate([half[:, 1], half[:, 0]]).astype(np.int64)
    order = np.argsort(i, kind="stable")
    i, j = i[order], j[order]
    delta = pts[j] - pts[i]
    if box is not None:
        b = np.asarray(box)
        delta -= b * np.round(delta / b)
    dist = np.sqrt(np.einsum("ij,ij->i", delta, delta))
    offsets = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(i, minlength=n), out=offsets[1:])
    return PairTable(radius, offsets, j, dist, delta)


def segment_sum(values: np.ndarray, seg: np.ndarray, m: int) -> np.ndarray:
    """Sum of `values` per segment; works for (P,) and (P, 2)."""
    if values.ndim == 2:
        return np.stack([np.bincount(seg, weights=values[:, c], minlength=m)
                         for c in range(values.shape[1])], axis=1)
    return np.bincount(seg, weights=values.astype(np.float64), minlength=m)


def segment_count(seg: np.ndarray, m: int) -> np.ndarray:
    return np.bincount(seg, minlength=m).astype(np.float64)


def segment_extreme(ufunc, values: np.ndarray, seg: np.ndarray, m: int, default) -> np.ndarray:
    """`ufunc.reduceat` per non-empty segment of a sorted `seg`; `default` elsewhere."""
    out = np.empty(m, dtype=np.float64)
    out[...] = default
    if seg.size == 0:
        return out
    starts = np.flatnonzero(np.r_[True, seg[1:] != seg[:-1]])
    out[seg[starts]] = ufunc.reduceat(values.astype(np.float64), starts)
    return out


def segment_argmin(keys: np.ndarray, seg: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """For each non-empty segment, the row of its smallest key: (segments, rows)."""
    if seg.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    order = np.lexsort((keys, seg))
    sorted_seg = seg[order]
    first = np.r_[True, sorted_seg[1:] != sorted_seg[:-1]]
    return sorted_seg[first], order[first]
