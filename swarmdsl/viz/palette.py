"""Colours: the status palette, the fixed scene colours and heatmap colour maps.

One table of colours shared by the frame renderer, the legend and any tool that wants
to match the viewer (a plot of status counts should use the same hue per status).
"""

from __future__ import annotations

import numpy as np

from swarmdsl.errors import SwarmError, did_you_mean
from swarmdsl.runtime.snapshot import Snapshot

# Tableau 10: distinguishable hues that stay readable on a dark background.
PALETTE: tuple[tuple[int, int, int], ...] = (
    (31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
    (140, 86, 75), (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207),
)
BACKGROUND = (22, 24, 30)        # inside the world
LETTERBOX = (10, 10, 12)         # outside the world, when aspects differ
BORDER = (90, 92, 100)
LINK_COLOUR = (110, 110, 130)
BELIEF_LINE = (170, 170, 170)
TEXT = (235, 235, 235)
REGION_COLOURS = {"food": (250, 200, 60), "nest": (200, 140, 90)}
REGION_DEFAULT = (180, 180, 200)

# Anchor colours, interpolated to a 256-entry table (close to matplotlib's maps).
COLORMAPS: dict[str, tuple[tuple[int, int, int], ...]] = {
    "viridis": ((68, 1, 84), (59, 82, 139), (33, 145, 140), (94, 201, 98), (253, 231, 37)),
    "magma": ((0, 0, 4), (81, 18, 124), (183, 55, 121), (252, 137, 97), (252, 253, 191)),
    "gray": ((0, 0, 0), (255, 255, 255)),
    "coolwarm": ((59, 76, 192), (221, 221, 221), (180, 4, 38)),
}


def status_palette(n: int) -> np.ndarray:
    """`(n, 3)` uint8 colours, one per status: the fixed palette, then golden-angle hues."""
    colours = list(PALETTE[:n])
    for i in range(len(colours), n):
        hue = (i * 0.618033988749895) % 1.0
        colours.append(_hsv_to_rgb(hue, 0.65, 0.95))
    return np.array(colours, dtype=np.uint8).reshape(n, 3)


def legend_entries(snapshot: Snapshot) -> list[tuple[str, int, tuple[int, int, int]]]:
    """The legend as data: `(status name, live count, colour)` in status order."""
    names = list(snapshot.status_names)
    status = np.asarray(snapshot.status, dtype=np.int64).reshape(-1)
    valid = status[(status >= 0) & (status < len(names))]
    counts = np.bincount(valid, minlength=len(names))
    colours = status_palette(len(names))
    return [(name, int(counts[i]), tuple(int(c) for c in colours[i]))
            for i, name in enumerate(names)]


def colormap_lut(name: str, alpha: float = 1.0,
                 background: tuple[int, int, int] = BACKGROUND) -> np.ndarray:
    """A `(256, 3)` uint8 table for `name`, blended over `background` by `alpha`."""
    anchors = COLORMAPS.get(name)
    if anchors is None:
        raise SwarmError(f"unknown colour map '{name}'; choose one of "
                         + ", ".join(sorted(COLORMAPS)), hint=did_you_mean(name, COLORMAPS))
    a = np.array(anchors, dtype=np.float64)
    t = np.linspace(0.0, 1.0, 256)
    at = np.linspace(0.0, 1.0, len(a))
    lut = np.stack([np.interp(t, at, a[:, c]) for c in range(3)], axis=1)
    alpha = min(max(float(alpha), 0.0), 1.0)
    lut = lut * alpha + np.asarray(background, dtype=np.float64) * (1.0 - alpha)
    return np.clip(np.rint(lut), 0, 255).astype(np.uint8)


def _hsv_to_rgb(h: float, s: float, v: float) -> tuple[int, int, int]:
    i = int(h * 6.0) % 6
    f = h * 6.0 - int(h * 6.0)
    p, q, t = v * (1 - s), v * (1 - s * f), v * (1 - s * (1 - f))
    r, g, b = [(v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v), (v, p, q)][i]
    return int(r * 255), int(g * 255), int(b * 255)


NO_LEAF = (90, 92, 100)   # agents outside any tree (or before their first tick)


def leaf_colours(snapshot: Snapshot) -> np.ndarray:
    """`(N, 3)` colours by active behaviour-tree leaf: the status palette over leaf ids,
    grey for agents with no active leaf."""
    leaf = np.asarray(snapshot.tree_leaf, dtype=np.int64).reshape(-1)
    palette = np.vstack([np.array([NO_LEAF], np.uint8),
                         status_palette(max(len(snapshot.tree_leaf_names) - 1, 1))])
    return palette[np.clip(leaf, 0, len(palette) - 1)]


def leaf_legend_entries(snapshot: Snapshot) -> list[tuple[str, int, tuple[int, int, int]]]:
    """The legend when colouring by leaf: `(leaf, live count, colour)` of leaves in use."""
    leaf = np.asarray(snapshot.tree_leaf, dtype=np.int64).reshape(-1)
    names = snapshot.tree_leaf_names or [""]
    counts = np.bincount(np.clip(leaf, 0, len(names) - 1), minlength=len(names))
    palette = np.vstack([np.array([NO_LEAF], np.uint8),
                         status_palette(max(len(names) - 1, 1))])
    return [(names[i] or "(no leaf)", int(counts[i]), tuple(int(c) for c in palette[i]))
            for i in range(len(names)) if counts[i]]

