"""Pheromone trails in a recorded run: which regions a trail links, and from which tick.

A trail is a connected set of grid nodes (8-neighbour connectivity) whose field value is
above a threshold. A region's nodes are the nodes within one grid spacing of its shape,
so a source smaller than the grid still owns a node. Two regions are linked at a
recorded tick when one trail component touches the nodes of both.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from scipy import ndimage

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


def region_nodes(region: Region, grid_x: np.ndarray, grid_y: np.ndarray) -> np.ndarray:
    """``(ny, nx) bool``: nodes within one grid spacing of the region."""
    x, y = np.meshgrid(grid_x, grid_y)
    spacing = float(grid_x[1] - grid_x[0]) if len(grid_x) > 1 else 1.0
    d = region.distance(np.stack([x.ravel(), y.ravel()], axis=1))
    return (d <= spacing).reshape(x.shape)


def linked_pairs(values: np.ndarray, masks: dict[str, np.ndarray], threshold: float,
                 pairs: list[tuple[str, str]]) -> dict[tuple[str, str], bool]:
    """For one frame ``(ny, nx)``: which region pairs one above-threshold trail links."""
    labels, _n = ndimage.label(values > threshold, structure=_EIGHT)
    comps = {name: set(np.unique(labels[m])) - {0} for name, m in masks.items()}
    return {(a, b): bool(comps[a] & comps[b]) for a, b in pairs}


def trail_steps(values: np.ndarray, threshold: float, mask_a: np.ndarray,
                mask_b: np.ndarray, limit: int = 1000) -> int | None:
    """Fewest node-to-node steps (8-neighbour) from region A to region B along nodes
    above ``threshold`` (A's and B's own nodes always passable); None if no trail joins
    them. A breadth-first search by repeated dilation, whole-grid per step."""
    allowed = (values > threshold) | mask_a | mask_b
    reached = mask_a.copy()
    for k in range(limit):
        if (reached & mask_b).any():
            return k
        grown = ndimage.binary_dilation(reached, structure=_EIGHT) & allowed
        if (grown == reached).all():
            return None
        reached = grown
    return None


def first_direct_link(run_dir, a: str, b: str, field: str = "pheromone",
                      threshold: float = 0.05, slack: float = 1.5) -> int | None:
    """First recorded tick at which a trail joins regions `a` and `b` *directly*: in at
    most ``slack`` times the node steps of the straight gap between their nodes. A fork
    through a third source is longer and does not count (the thesis' triangle)."""
    run_dir = Path(run_dir)
    meta = json.loads((run_dir / "run.json").read_text())
    regions = {d["name"]: region_from_json(d) for d in meta["world"]["regions"]}
    with open_fields(run_dir) as data:   # fields.npz, or a killed run's frames
        frames, ticks = data[field], data["ticks"]
        gx, gy = data["grid_x"], data["grid_y"]
    ma, mb = region_nodes(regions[a], gx, gy), region_nodes(regions[b], gx, gy)
    gap = trail_steps(np.ones_like(frames[0]), 0.0, ma, mb)
    for tick, values in zip(ticks, frames, strict=True):
        steps = trail_steps(values, threshold, ma, mb, limit=int(slack * gap) + 1)
        if steps is not None and steps <= slack * gap:
            return int(tick)
    return None


def first_linked(run_dir, field: str = "pheromone", threshold: float = 0.05,
                 pairs: list[tuple[str, str]] | None = None) -> dict:
    """Tick at which each pair of regions is first linked by a trail (None = never).

    Args:
        run_dir: a folder holding `fields.npz` and `run.json`.
        field: the field that carries the trails.
        threshold: the value a node must exceed to belong to a trail.
        pairs: (region, region) names; default: the nest with every food source.

    Returns:
        ``{(a, b): tick or None}`` in the order of ``pairs``.
    """
    run_dir = Path(run_dir)
    meta = json.loads((run_dir / "run.json").read_text())
    regions = [region_from_json(d) for d in meta["world"]["regions"]]
    with open_fields(run_dir) as data:   # fields.npz, or a killed run's frames
        frames, ticks = data[field], data["ticks"]
        gx, gy = data["grid_x"], data["grid_y"]
    if pairs is None:
        nest = next(r.name for r in regions if r.kind == "nest")
        pairs = [(nest, r.name) for r in regions if r.kind == "food"]
    masks = {r.name: region_nodes(r, gx, gy) for r in regions}
    out: dict[tuple[str, str], int | None] = {p: None for p in pairs}
    for tick, values in zip(ticks, frames, strict=True):
        todo = [p for p in pairs if out[p] is None]
        if not todo:
            break
        for p, linked in linked_pairs(values, masks, threshold, todo).items():
            if linked:
                out[p] = int(tick)
    return out
