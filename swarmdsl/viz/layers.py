"""Drawing the multi-agent framework's environment: the grid's nodes (refined ones too)
and vector fields as arrows. Called from `frames.FrameRenderer.draw`; both layers are
bounded in size whatever the grid (at most `_MAX_ARROWS` arrows, nodes as single pixels).
"""

from __future__ import annotations

import numpy as np

from swarmdsl.errors import SwarmError

GRID_POINT = (110, 110, 130)
ARROW = (235, 235, 245)
_MAX_ARROWS = 32        # arrows per side at most


def draw_grid_points(surf, snap, to_px) -> None:
    """One pixel per grid node (a refined grid's `grid_points`, else `grid_x x grid_y`)."""
    import pygame

    pts = snap.grid_points
    if pts is None:
        if snap.grid_x is None or snap.grid_y is None:
            return
        x, y = np.meshgrid(snap.grid_x, snap.grid_y)
        pts = np.stack([x.ravel(), y.ravel()], axis=1)
    pts = np.asarray(pts, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:      # a snapshot built by hand
        raise SwarmError(f"snapshot grid_points has shape {pts.shape}, expected (P, 2)")
    w, h = surf.get_size()
    p = np.round(to_px(pts)).astype(np.int64)
    keep = (p[:, 0] >= 0) & (p[:, 0] < w) & (p[:, 1] >= 0) & (p[:, 1] < h)
    p = p[keep]
    pixels = pygame.surfarray.pixels3d(surf)      # (w, h, 3) view
    pixels[p[:, 0], p[:, 1]] = GRID_POINT
    del pixels                                    # unlock the surface


def draw_vectors(surf, snap, to_px) -> None:
    """Arrows for each vector field of the snapshot on a subsample of the base grid."""
    import pygame

    if snap.grid_x is None or snap.grid_y is None:
        return
    gx, gy = np.asarray(snap.grid_x), np.asarray(snap.grid_y)
    sx = max(1, int(np.ceil(len(gx) / _MAX_ARROWS)))
    sy = max(1, int(np.ceil(len(gy) / _MAX_ARROWS)))
    x, y = np.meshgrid(gx[::sx], gy[::sy])
    step = min((gx[sx] - gx[0]) if len(gx) > sx else snap.world_size[0],
               (gy[sy] - gy[0]) if len(gy) > sy else snap.world_size[1])
    for name, values in snap.vectors.items():
        values = np.asarray(values, dtype=np.float64)
        if values.shape != (len(gy), len(gx), 2):   # a snapshot built by hand
            raise SwarmError(f"snapshot vector field '{name}' has shape {values.shape}, "
                             f"expected ({len(gy)}, {len(gx)}, 2) on the grid")
        v = values[::sy, ::sx].reshape(-1, 2)
        mag = np.hypot(v[:, 0], v[:, 1])
        top = mag.max() if mag.size else 0.0
        if not np.isfinite(top) or top <= 0:
            continue
        tail = np.stack([x.ravel(), y.ravel()], axis=1)
        head = tail + v * (0.8 * step / top)
        a, b = to_px(tail), to_px(head)
        d = b - a
        n = np.hypot(d[:, 0], d[:, 1])
        u = d / np.where(n > 0, n, 1.0)[:, None]
        barb = 0.3 * np.minimum(n, 12.0)[:, None]
        left = b - barb * (u + u[:, ::-1] * [1, -1])
        right = b - barb * (u - u[:, ::-1] * [1, -1])
        for i in np.flatnonzero(n >= 1.0):           # a bounded loop over arrows
            pygame.draw.line(surf, ARROW, a[i], b[i])
            pygame.draw.line(surf, ARROW, b[i], left[i])
            pygame.draw.line(surf, ARROW, b[i], right[i])
