"""World: bounds, edge behaviour and the motion step that every agent shares."""

from __future__ import annotations

import math

import numpy as np


def short_way(d, period):
    """The offset `d` (any shape) taken the short way round a period: `period` a number
    for one axis, or ``[W, H]`` against ``(..., 2)`` offsets. The one rule for steering,
    region distances and targets across the edge of a wrap-around world."""
    return d - period * np.round(d / period)


def corner_nodes(width: float, height: float, g: float) -> tuple[bool, bool, bool]:
    """Which end nodes of the bottom and top sides a left or right side already holds:
    (top's first, bottom's last, top's last). A corner is one node, pushing once: the
    bottom's first node is always the left side's first, `(0, 0)`; the right side
    starts at `(W, 0)`, the bottom's last node when the width is a whole number of
    spacings; the sides end at `(0, H)` and `(W, H)` when the height is."""
    def whole(length: float) -> bool:
        return abs(length / g - math.floor(length / g + 1e-9)) < 1e-9

    return whole(height), whole(width), whole(width) and whole(height)


class World:
    def __init__(self, width: float, height: float, grid: float, edges: str,
                 edge_weight: float = 1.0, edge_range: float | None = None):
        self.width = float(width)
        self.height = float(height)
        self.grid = float(grid)
        self.edges = edges
        self.edge_weight = float(edge_weight)
        self.edge_range = float(edge_range) if edge_range else 2.0 * self.grid

    @property
    def wraps(self) -> bool:
        return self.edges == "wrap"

    @property
    def box(self) -> tuple[float, float] | None:
        return (self.width, self.height) if self.wraps else None

    def short_way(self, d: np.ndarray) -> np.ndarray:
        """An offset ``target - pos`` taken the short way round a wrap-around world (as
        `other.pos - pos` is), unchanged otherwise: steering at a target just across
        the edge crosses the edge instead of driving across the whole world."""
        if not self.wraps:
            return d
        return short_way(d, np.array([self.width, self.height]))

    def edge_push(self, pos: np.ndarray) -> np.ndarray:
        """Repulsion from the grid nodes along the world's edge, (range/d)^2 per node.

        Each node within `edge_range` pushes an agent straight away from itself with
        magnitude (range / d)^2: 1 at the range, 4 at half of it, and the pushes add up:
        the thesis makes every edge grid point a repellent, like a neighbour in the
        separation sum (docs/language.md has a worked example and how the sum scales
        with the spacing). The loop runs over the few node offsets within range, never
        over agents.
        """
        push = np.zeros_like(pos)
        r = self.edge_range
        g = self.grid
        reach = int(math.ceil(r / g))
        lo_top, hi_bottom, hi_top = corner_nodes(self.width, self.height, g)
        walls = (  # (distance to wall, coordinate along it, along-axis, outward sign, length,
            #         perpendicular axis, whether its first / last node is a side's corner)
            (pos[:, 0], pos[:, 1], 1, +1.0, self.height, 0, False, False),
            (self.width - pos[:, 0], pos[:, 1], 1, -1.0, self.height, 0, False, False),
            (pos[:, 1], pos[:, 0], 0, +1.0, self.width, 1, True, hi_bottom),
            (self.height - pos[:, 1], pos[:, 0], 0, -1.0, self.width, 1, lo_top, hi_top),
        )
        for d_perp, along, along_axis, sign, length, perp_axis, skip_lo, skip_hi in walls:
            near = np.flatnonzero(d_perp < r)
            if near.size == 0:
                continue
            dp = d_perp[near]
            al = along[near]
            base = np.round(al / g)
            kmax = math.floor(length / g + 1e-9)
            for m in range(-reach, reach + 1):
                k = base + m
                diff = al - k * g
                d2 = dp * dp + diff * diff
                ok = ((k >= 0 + skip_lo) & (k <= kmax - skip_hi) & (d2 < r * r)
                      & (d2 > 0))
                if not ok.any():
                    continue
                d = np.sqrt(d2[ok])
                mag = (r / d) ** 2 / d
                rows = near[ok]
                push[rows, perp_axis] += sign * dp[ok] * mag
                push[rows, along_axis] += diff[ok] * mag
        return push * self.edge_weight

    def move(self, pos: np.ndarray, vel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Integrate one tick and apply the edges; returns new (pos, vel)."""
        new = pos + vel
        if self.wraps:
            return np.mod(new, (self.width, self.height)), vel
        vel = vel.copy()
        for axis, size in ((0, self.width), (1, self.height)):
            low = new[:, axis] < 0
            high = new[:, axis] > size
            if low.any():
                new[low, axis] = -new[low, axis]
                vel[low, axis] = np.abs(vel[low, axis])
            if high.any():
                new[high, axis] = 2 * size - new[high, axis]
                vel[high, axis] = -np.abs(vel[high, axis])
            np.clip(new[:, axis], 0.0, size, out=new[:, axis])
        return new, vel
