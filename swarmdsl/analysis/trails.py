"""Pheromone trails in a recorded run: which regions a trail links, and from which tick.

A trail is a connected set of grid nodes (8-neighbour connectivity) whose field value is
above a threshold. A region's nodes are the nodes within one grid spacing of its shape,
so a source smaller than the grid still owns a node. Two regions are linked at a
recorded tick when one trail component touches the nodes of both.

In a wrap-around world (`run.json`: `world.edges` is `wrap`) the grid is a torus: its
last node in a row is one spacing before the first node's copy, so a trail leaving
across one edge continues at the other, and a region's nodes are those within one
spacing of any of its copies a whole world away (a region wholly beyond an edge owns
the nodes of its copy in the world). A run folder whose `run.json` does not say the
world's size and edges is read as a world with walls.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from swarmdsl.runtime.regions import Circle, Polygon, Rect, Region
from swarmdsl.runtime.spool import open_fields

_EIGHT = np.ones((3, 3), dtype=bool)


def region_from_json(d: dict) -> Region:
    """The Region a run.json `world.regions` entry describes."""
    if d["shape"] == "circle":
        shape = Circle(d["center"][0], d["center"][1], d["radius"])
    elif d["shape"] == "rect":
        shape = Rect(*d["min"], *d["max"])
    else:
        shape = Polygon(tuple(tuple(p) for p in d["points"]))
    return Region(d["name"], d["kind"], d.get("label"), shape)


def world_box(world: dict, grid_x: np.ndarray, grid_y: np.ndarray
              ) -> tuple[float, float] | None:
    """``(W, H)`` of a recorded wrap-around world (run.json's ``world``), whose grid
    wraps with it; None for a world with walls, and for a ``world`` that does not say
    its size and edges (such a run folder reads as walled, as it always did)."""
    if world.get("edges") != "wrap" or "size" not in world:
        return None
    box = (float(world["size"][0]), float(world["size"][1]))
    spacing = _spacing(grid_x, box)
    for n, extent in ((len(grid_x), box[0]), (len(grid_y), box[1])):
        # a periodic grid (runtime/fields.py): n nodes, the period n spacings
        if abs(n * spacing - extent) > 1e-9 * max(1.0, extent):
            raise ValueError(
                f"the recorded grid ({len(grid_x)} x {len(grid_y)} nodes, spacing "
                f"{spacing:g}) does not wrap around the {box[0]:g} x {box[1]:g} world")
    return box


def _spacing(grid_x: np.ndarray, box=None) -> float:
    """The grid's spacing; a periodic row of one node spans the whole world."""
    if len(grid_x) > 1:
        return float(grid_x[1] - grid_x[0])
    return float(box[0]) if box is not None else 1.0


def region_nodes(region: Region, grid_x: np.ndarray, grid_y: np.ndarray,
                 box: tuple[float, float] | None = None) -> np.ndarray:
    """``(ny, nx) bool``: nodes within one grid spacing of the region; in a wrap-around
    world of size ``box`` = ``(W, H)``, within one spacing of any of its copies."""
    x, y = np.meshgrid(grid_x, grid_y)
    spacing = _spacing(grid_x, box)
    d = region.distance(np.stack([x.ravel(), y.ravel()], axis=1), box)
    return (d <= spacing).reshape(x.shape)


def trail_labels(above: np.ndarray, wrap: bool = False) -> np.ndarray:
    """``(ny, nx) int``: the 8-connected component of each ``above`` node (0 elsewhere).

    With ``wrap`` the grid is a torus: a node in the last column neighbours the nodes
    of the first column in its own and the adjacent rows (rows likewise), so a
    component touching one edge continues at the other."""
    labels, n = ndimage.label(above, structure=_EIGHT)
    if not wrap or n == 0:
        return labels
    # each node of the first column against its three neighbours in the last column,
    # each node of the first row against its three in the last row (corners included)
    p = np.pad(labels, 1, mode="wrap")     # p[1:-1, 1:-1] is labels
    rows, cols = p.shape
    here, there = [], []
    for off in (-1, 0, 1):
        here += [p[1:-1, 1], p[1, 1:-1]]
        there += [p[1 + off:rows - 1 + off, 0], p[0, 1 + off:cols - 1 + off]]
    here, there = np.concatenate(here), np.concatenate(there)
    join = (here > 0) & (there > 0) & (here != there)
    if not join.any():
        return labels
    graph = coo_matrix((np.ones(int(join.sum())), (here[join], there[join])),
                       shape=(n + 1, n + 1))
    _k, comp = connected_components(graph, directed=False)
    lut = comp + 1
    lut[0] = 0                              # the background joins nothing
    return lut[labels]


def linked_pairs(values: np.ndarray, masks: dict[str, np.ndarray], threshold: float,
                 pairs: list[tuple[str, str]], wrap: bool = False
                 ) -> dict[tuple[str, str], bool]:
    """For one frame ``(ny, nx)``: which region pairs one above-threshold trail links
    (``wrap``: across the edges of a wrap-around world too)."""
    labels = trail_labels(values > threshold, wrap)
    comps = {name: set(np.unique(labels[m])) - {0} for name, m in masks.items()}
    return {(a, b): bool(comps[a] & comps[b]) for a, b in pairs}


def _grow(reached: np.ndarray, wrap: bool) -> np.ndarray:
    """``reached`` and its 8 neighbours, around the torus with ``wrap``."""
    if not wrap:
        return ndimage.binary_dilation(reached, structure=_EIGHT)
    p = np.pad(reached, 1, mode="wrap")    # each edge's neighbours across it
    return ndimage.binary_dilation(p, structure=_EIGHT)[1:-1, 1:-1]


def trail_steps(values: np.ndarray, threshold: float, mask_a: np.ndarray,
                mask_b: np.ndarray, limit: int = 1000, wrap: bool = False) -> int | None:
    """Fewest node-to-node steps (8-neighbour) from region A to region B along nodes
    above ``threshold`` (A's and B's own nodes always passable); None if no trail joins
    them. A breadth-first search by repeated dilation, whole-grid per step; with
    ``wrap`` a step may cross the edge of a wrap-around world."""
    allowed = (values > threshold) | mask_a | mask_b
    reached = mask_a.copy()
    for k in range(limit):
        if (reached & mask_b).any():
            return k
        grown = _grow(reached, wrap) & allowed
        if (grown == reached).all():
            return None
        reached = grown
    return None


def _read_run(run_dir, field: str):
    """A run folder's regions by name, its frames of ``field`` with their ticks, the
    grid's nodes and the world's ``box`` (None: walls)."""
    run_dir = Path(run_dir)
    meta = json.loads((run_dir / "run.json").read_text())
    world = meta["world"]
    regions = {d["name"]: region_from_json(d) for d in world["regions"]}
    with open_fields(run_dir) as data:   # fields.npz, or a killed run's frames
        frames, ticks = data[field], data["ticks"]
        gx, gy = data["grid_x"], data["grid_y"]
    return regions, frames, ticks, gx, gy, world_box(world, gx, gy)


def first_direct_link(run_dir, a: str, b: str, field: str = "pheromone",
                      threshold: float = 0.05, slack: float = 1.5) -> int | None:
    """First recorded tick at which a trail joins regions `a` and `b` *directly*: in at
    most ``slack`` times the node steps of the straight gap between their nodes. A fork
    through a third source is longer and does not count (the thesis' triangle)."""
    regions, frames, ticks, gx, gy, box = _read_run(run_dir, field)
    wrap = box is not None
    ma, mb = region_nodes(regions[a], gx, gy, box), region_nodes(regions[b], gx, gy, box)
    gap = trail_steps(np.ones_like(frames[0]), 0.0, ma, mb, wrap=wrap)   # the short way
    for tick, values in zip(ticks, frames, strict=True):
        steps = trail_steps(values, threshold, ma, mb, limit=int(slack * gap) + 1,
                            wrap=wrap)
        if steps is not None and steps <= slack * gap:
            return int(tick)
    return None


def first_linked(run_dir, field: str = "pheromone", threshold: float = 0.05,
                 pairs: list[tuple[str, str]] | None = None) -> dict:
    """Tick at which each pair of regions is first linked by a trail (None = never).

    Args:
        run_dir: a folder holding `fields.npz` and `run.json` (in a wrap-around
            world trails and regions continue across its edges).
        field: the field that carries the trails.
        threshold: the value a node must exceed to belong to a trail.
        pairs: (region, region) names; default: the nest with every food source.

    Returns:
        ``{(a, b): tick or None}`` in the order of ``pairs``.
    """
    by_name, frames, ticks, gx, gy, box = _read_run(run_dir, field)
    regions = list(by_name.values())
    if pairs is None:
        nest = next(r.name for r in regions if r.kind == "nest")
        pairs = [(nest, r.name) for r in regions if r.kind == "food"]
    masks = {r.name: region_nodes(r, gx, gy, box) for r in regions}
    out: dict[tuple[str, str], int | None] = {p: None for p in pairs}
    for tick, values in zip(ticks, frames, strict=True):
        todo = [p for p in pairs if out[p] is None]
        if not todo:
            break
        for p, linked in linked_pairs(values, masks, threshold, todo,
                                      wrap=box is not None).items():
            if linked:
                out[p] = int(tick)
    return out
