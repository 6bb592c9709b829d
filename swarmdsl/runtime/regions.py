"""Region shapes (circle, rect, polygon): membership, distance, placement, obstacles.

Shapes are closed: a point on the boundary is inside and at distance 0. Every query is
vectorised over points ``(M, 2)``; ``to_json`` is the run.json ``world.regions`` form.

A wrap-around world is a torus: a shape stands for all its copies a whole number of
world sizes apart, so a shape near one edge is near the points just across the other
edge, and a shape that crosses an edge continues on the other side. The ``box`` queries
(``distance_around``, ``contains_around``) measure against the nearest copy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from swarmdsl.ops import portable
from swarmdsl.runtime.world import short_way


def _points(pts) -> np.ndarray:
    pts = np.asarray(pts, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"points must have shape (M, 2), got {pts.shape}")
    return pts


def _finite(name: str, value) -> float:
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{name} must be finite, got {number}")
    return number


class Shape:
    """Operations every shape shares, written once on top of ``contains``/``bounds``."""

    def contains(self, pts) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def distance(self, pts) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def bounds(self) -> tuple[float, float, float, float]:  # pragma: no cover - abstract
        raise NotImplementedError

    def area(self) -> float:  # pragma: no cover - abstract
        raise NotImplementedError

    def images(self, pts, box) -> np.ndarray:
        """``(S, M, 2)``: each point moved onto the copies of the shape in a wrap-around
        world of size ``box`` = ``(W, H)`` that can hold its nearest point.

        Moving the point by ``(-kW, -lH)`` is measuring against the copy moved by
        ``(kW, lH)``. Each point is first moved, by whole world sizes, to within half a
        world of the centre of the shape's box. A circle or rect is then nearest in that
        copy (along each axis its distance grows with the offset from its centre), so
        one position does. Any other shape is also tried ``K`` worlds either side, ``K``
        being 1 unless the shape is wider (taller) than the world: a copy further out
        lies wholly beyond a nearer one, seen from the point, so it is never nearer.
        """
        pts = _points(pts)
        x0, y0, x1, y1 = self.bounds()
        size = np.array([float(box[0]), float(box[1])])
        centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
        d = pts - centre
        near = centre + short_way(d, size)   # (M, 2)
        if isinstance(self, (Circle, Rect)):
            return near[None]
        kx = math.ceil(0.5 + (x1 - x0) / (2 * size[0]))
        ky = math.ceil(0.5 + (y1 - y0) / (2 * size[1]))
        i, j = np.meshgrid(np.arange(-kx, kx + 1), np.arange(-ky, ky + 1), indexing="ij")
        shifts = np.stack([i.ravel() * size[0], j.ravel() * size[1]], axis=1)   # (S, 2)
        return near[None] + shifts[:, None, :]

    def distance_around(self, pts, box) -> np.ndarray:
        """``(M,)`` distance to the nearest copy of the shape in a wrap-around world of
        size ``box``; the plain distance when ``box`` is None (a world with walls)."""
        if box is None:
            return self.distance(pts)
        q = self.images(pts, box)
        return self.distance(q.reshape(-1, 2)).reshape(q.shape[:2]).min(axis=0)

    def contains_around(self, pts, box) -> np.ndarray:
        """``(M,) bool``: inside some copy of the shape in a wrap-around world of size
        ``box``; plain ``contains`` when ``box`` is None."""
        if box is None:
            return self.contains(pts)
        q = self.images(pts, box)
        return self.contains(q.reshape(-1, 2)).reshape(q.shape[:2]).any(axis=0)

    def nodes_inside(self, grid) -> np.ndarray:
        """``(ny, nx) bool``: which grid nodes lie in the shape (food labels, masks)."""
        x, y = grid.nodes()
        return self.contains(np.stack([x.ravel(), y.ravel()], axis=1)).reshape(grid.shape)

    def sample_points_inside(self, rng, n: int) -> np.ndarray:
        """``(n, 2)`` points uniform over the shape, by batched rejection sampling.

        Candidates are drawn uniformly in the bounding box a batch at a time (sized
        from the area ratio) and the inside ones kept in order, so the result depends
        only on the generator's state.
        """
        if int(n) != n or n < 0:
            raise ValueError(f"number of points must be a whole number >= 0, got {n}")
        n = int(n)
        x0, y0, x1, y1 = self.bounds()
        if hasattr(rng, "rejection"):   # a per-agent view: each agent keeps its own point
            return rng.rejection(self.contains, (x0, y0), (x1, y1)) if n else np.empty((0, 2))
        box_area = (x1 - x0) * (y1 - y0)
        if box_area == 0.0:  # a point or a segment: the box is the shape
            return np.column_stack(
                [rng.uniform(x0, x1, n), rng.uniform(y0, y1, n)]
            ) if n else np.empty((0, 2))
        accept = self.area() / box_area
        if accept <= 0.0:
            raise ValueError(f"cannot place points inside {self!r}: it has no area")
        kept: list[np.ndarray] = []
        have = 0
        for _ in range(1000):
            if have >= n:
                break
            batch = int(1.2 * (n - have) / accept) + 16
            cand = np.column_stack([rng.uniform(x0, x1, batch), rng.uniform(y0, y1, batch)])
            cand = cand[self.contains(cand)]
            kept.append(cand)
            have += len(cand)
        else:
            raise ValueError(f"cannot place {n} points inside {self!r}")
        return np.concatenate(kept)[:n] if kept else np.empty((0, 2))


@dataclass(frozen=True)
class Circle(Shape):
    """A disc of radius ``r`` around ``(cx, cy)``."""

    cx: float
    cy: float
    r: float

    def __post_init__(self):
        for name in ("cx", "cy", "r"):
            object.__setattr__(self, name, _finite(f"circle {name}", getattr(self, name)))
        if self.r < 0:
            raise ValueError(f"circle radius must not be negative, got {self.r:g}")

    @property
    def center(self) -> tuple[float, float]:
        return (self.cx, self.cy)

    def contains(self, pts) -> np.ndarray:
        pts = _points(pts)
        dx, dy = pts[:, 0] - self.cx, pts[:, 1] - self.cy
        return dx * dx + dy * dy <= self.r * self.r

    def distance(self, pts) -> np.ndarray:
        pts = _points(pts)
        d = portable.hypot_array(pts[:, 0] - self.cx, pts[:, 1] - self.cy) - self.r
        return np.where(self.contains(pts), 0.0, np.maximum(d, 0.0))

    def bounds(self):
        return (self.cx - self.r, self.cy - self.r, self.cx + self.r, self.cy + self.r)

    def area(self) -> float:
        return math.pi * self.r * self.r

    def to_json(self) -> dict:
        return {"shape": "circle", "center": [self.cx, self.cy], "radius": self.r}


@dataclass(frozen=True)
class Rect(Shape):
    """An axis-aligned rectangle from ``(x0, y0)`` (min corner) to ``(x1, y1)`` (max)."""

    x0: float
    y0: float
    x1: float
    y1: float

    def __post_init__(self):
        for name in ("x0", "y0", "x1", "y1"):
            object.__setattr__(self, name, _finite(f"rect {name}", getattr(self, name)))
        if self.x1 < self.x0 or self.y1 < self.y0:
            raise ValueError(
                f"rect corners must be (min x, min y, max x, max y), got "
                f"({self.x0:g}, {self.y0:g}, {self.x1:g}, {self.y1:g})"
            )

    @property
    def center(self) -> tuple[float, float]:
        return ((self.x0 + self.x1) / 2, (self.y0 + self.y1) / 2)

    def contains(self, pts) -> np.ndarray:
        pts = _points(pts)
        x, y = pts[:, 0], pts[:, 1]
        return (x >= self.x0) & (x <= self.x1) & (y >= self.y0) & (y <= self.y1)

    def distance(self, pts) -> np.ndarray:
        pts = _points(pts)
        dx = np.maximum(np.maximum(self.x0 - pts[:, 0], pts[:, 0] - self.x1), 0.0)
        dy = np.maximum(np.maximum(self.y0 - pts[:, 1], pts[:, 1] - self.y1), 0.0)
        return portable.hypot_array(dx, dy)

    def bounds(self):
        return (self.x0, self.y0, self.x1, self.y1)

    def area(self) -> float:
        return (self.x1 - self.x0) * (self.y1 - self.y0)

    def to_json(self) -> dict:
        return {"shape": "rect", "min": [self.x0, self.y0], "max": [self.x1, self.y1]}


@dataclass(frozen=True)
class Polygon(Shape):
    """A simple polygon through ``points`` (at least 3, either winding, not closed twice).

    Inside is decided by the even-odd rule, so a self-intersecting outline gives holes
    rather than an error; boundary points count as inside.
    """

    points: tuple[tuple[float, float], ...]
    _xy: np.ndarray = field(init=False, repr=False, compare=False)  # (P, 2)

    def __post_init__(self):
        xy = np.asarray(self.points, dtype=np.float64)
        if xy.ndim != 2 or xy.shape[1] != 2 or len(xy) < 3:
            raise ValueError(f"a polygon needs at least 3 (x, y) points, got shape {xy.shape}")
        if not np.isfinite(xy).all():
            raise ValueError("polygon points must be finite")
        object.__setattr__(self, "points", tuple((float(x), float(y)) for x, y in xy))
        object.__setattr__(self, "_xy", xy)

    def _edges(self):
        a = self._xy  # (P, 2) edge starts
        b = np.roll(self._xy, -1, axis=0)  # (P, 2) edge ends
        return a, b

    def _edge_distance(self, pts: np.ndarray) -> np.ndarray:
        """Distance ``(M,)`` from each point to the nearest edge (segment)."""
        a, b = self._edges()
        ab = b - a  # (P, 2)
        len2 = (ab * ab).sum(axis=1)  # (P,)
        ap = pts[:, None, :] - a[None, :, :]  # (M, P, 2)
        with np.errstate(all="ignore"):   # t is used only where len2 > 0
            t = (ap * ab[None]).sum(axis=2) / len2[None]  # (M, P)
        t = np.clip(np.where(len2[None] > 0, t, 0.0), 0.0, 1.0)
        closest = a[None] + t[..., None] * ab[None]  # (M, P, 2)
        d = pts[:, None, :] - closest
        return np.sqrt((d * d).sum(axis=2)).min(axis=1)

    def _crossings_odd(self, pts: np.ndarray) -> np.ndarray:
        """Even-odd ray cast toward +x, vectorised over points and edges."""
        a, b = self._edges()
        x, y = pts[:, 0, None], pts[:, 1, None]  # (M, 1)
        ya, yb = a[None, :, 1], b[None, :, 1]  # (1, P)
        straddles = (ya > y) != (yb > y)  # (M, P); excludes horizontal edges
        with np.errstate(all="ignore"):   # used only where the edge straddles y
            x_cross = a[None, :, 0] + (y - ya) * (b[None, :, 0] - a[None, :, 0]) / (yb - ya)
        hits = straddles & (x < x_cross)
        return hits.sum(axis=1) % 2 == 1

    @property
    def center(self) -> tuple[float, float]:
        """Area centroid (shoelace); the vertex mean for a degenerate outline."""
        a, b = self._edges()
        cross = a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]  # (P,)
        area2 = cross.sum()
        if area2 == 0.0:
            mean = self._xy.mean(axis=0)
            return (float(mean[0]), float(mean[1]))
        c = ((a + b) * cross[:, None]).sum(axis=0) / (3.0 * area2)
        return (float(c[0]), float(c[1]))

    def contains(self, pts) -> np.ndarray:
        pts = _points(pts)
        return self._crossings_odd(pts) | (self._edge_distance(pts) == 0.0)

    def distance(self, pts) -> np.ndarray:
        pts = _points(pts)
        return np.where(self._crossings_odd(pts), 0.0, self._edge_distance(pts))

    def bounds(self):
        lo, hi = self._xy.min(axis=0), self._xy.max(axis=0)
        return (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))

    def area(self) -> float:
        a, b = self._edges()
        return abs(float((a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]).sum())) / 2.0

    def to_json(self) -> dict:
        return {"shape": "polygon", "points": [[x, y] for x, y in self.points]}


@dataclass(frozen=True)
class Region:
    """A named shape the program declared: ``region nest = ...``, ``food alpha = ...``.

    ``kind`` is ``"food"`` for food sources and the declaring keyword otherwise;
    ``label`` is the food label (alpha, beta ...) or None.
    """

    name: str
    kind: str
    label: str | None
    shape: Shape

    @property
    def center(self) -> tuple[float, float]:
        return self.shape.center

    def contains(self, pts, box=None) -> np.ndarray:
        return self.shape.contains_around(pts, box)

    def distance(self, pts, box=None) -> np.ndarray:
        return self.shape.distance_around(pts, box)

    def nodes_inside(self, grid) -> np.ndarray:
        return self.shape.nodes_inside(grid)

    def sample_points_inside(self, rng, n: int) -> np.ndarray:
        return self.shape.sample_points_inside(rng, n)

    def to_json(self) -> dict:
        return {"name": self.name, "kind": self.kind, "label": self.label,
                **self.shape.to_json()}


def block_moves(old, new, obstacles, box=None) -> np.ndarray:
    """Positions ``(M, 2)`` after moving ``old -> new``, never ending inside an obstacle.

    Rule: a move whose end point lies inside (or on) any obstacle is cancelled and the
    agent stays at ``old``; every other move is kept whole. Only the end point is
    tested, so a step longer than an obstacle is thick can jump it; keep steps shorter
    than the thinnest wall. An agent already inside an obstacle (placed there, say) may
    move out but not to another inside point, so it never goes deeper.

    Args:
        old: ``(M, 2)`` positions at the start of the tick.
        new: ``(M, 2)`` proposed positions.
        obstacles: shapes or Regions.
        box: ``(W, H)`` of a wrap-around world, where an obstacle crossing an edge
            blocks on both sides; None for a world with walls.
    """
    old, new = _points(old), _points(new)
    if old.shape != new.shape:
        raise ValueError(f"old and new positions differ in shape: {old.shape} vs {new.shape}")
    blocked = np.zeros(len(new), dtype=bool)  # (M,)
    for obstacle in obstacles:  # a loop over obstacles, never over agents
        blocked |= getattr(obstacle, "shape", obstacle).contains_around(new, box)
    return np.where(blocked[:, None], old, new)
