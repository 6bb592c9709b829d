"""The read-only picture of a run at one tick that viewers and recorders consume."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Snapshot:
    """State of every live agent at one tick, plus what the world draws under them.

    Arrays are copies owned by the snapshot; agent axis first.
    """

    tick: int
    world_size: tuple[float, float]          # (width, height), origin at (0, 0), y up
    pos: np.ndarray                          # (N, 2) float64 true positions
    heading: np.ndarray                      # (N,) float64 radians, 0 = +x, counter-clockwise
    status: np.ndarray                       # (N,) int32 index into status_names
    kind: np.ndarray                         # (N,) int32 index into kind_names
    ids: np.ndarray                          # (N,) int64 stable agent ids
    status_names: list[str]                  # display names, "kind.status" when kinds > 1
    kind_names: list[str]
    fields: dict[str, np.ndarray] = field(default_factory=dict)   # name -> (ny, nx)
    vectors: dict[str, np.ndarray] = field(default_factory=dict)  # name -> (ny, nx, 2)
    grid_x: np.ndarray | None = None         # (nx,) node x coordinates
    grid_y: np.ndarray | None = None         # (ny,) node y coordinates
    grid_points: np.ndarray | None = None    # (P, 2) every grid node (refined ones too)
    regions: list[dict] = field(default_factory=list)             # as in run.json
    wraps: bool = False                      # edges wrap: a region repeats a world away
    led: np.ndarray | None = None            # (N, 3) uint8 colours, or None
    believed: np.ndarray | None = None       # (N, 2) believed positions, or None
    links: np.ndarray | None = None          # (L, 2) int pairs of row indices, or None
    tree_leaf: np.ndarray | None = None      # (N,) int active leaf ids (0: none), if tracked
    tree_leaf_names: list[str] = field(default_factory=list)   # id -> "LINE:COL text"
    tree_leaf_paths: list[str] = field(default_factory=list)   # id -> "root > ... > leaf"
