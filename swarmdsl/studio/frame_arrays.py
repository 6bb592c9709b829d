"""What a studio frame sends beside the agents: a field as bytes, a vector field's
arrows, the grid's nodes, an inspected agent's values as JSON (`Session.frame`)."""

from __future__ import annotations

import numpy as np

from swarmdsl.errors import SwarmError


def field_bytes(snap, name: str):
    """A field normalised per frame to 0..255 (as the viewer's heatmap), with its grid."""
    values = np.asarray(snap.fields[name], dtype=np.float64)
    ny, nx = values.shape
    finite = np.isfinite(values)
    lo = float(values[finite].min()) if finite.any() else 0.0
    hi = float(values[finite].max()) if finite.any() else 0.0
    norm = np.zeros_like(values)
    if hi > lo:
        np.divide(values - lo, hi - lo, out=norm, where=finite)
    idx = np.clip(np.rint(norm * 255.0), 0, 255).astype(np.uint8)
    gx = snap.grid_x if snap.grid_x is not None and len(snap.grid_x) == nx else None
    gy = snap.grid_y if snap.grid_y is not None and len(snap.grid_y) == ny else None
    w, h = snap.world_size
    grid = {"nx": nx, "ny": ny,
            "x0": float(gx[0]) if gx is not None else 0.0,
            "x1": float(gx[-1]) if gx is not None else float(w),
            "y0": float(gy[0]) if gy is not None else 0.0,
            "y1": float(gy[-1]) if gy is not None else float(h)}
    return grid, idx.reshape(-1), lo, hi


def vector_arrays(snap, name: str) -> tuple[dict, list]:
    """Vector field `name` as the viewer draws it (`viz.layers.draw_vectors`): on the
    base grid subsampled to at most `MAX_ARROWS` a side, with the scale (world units per
    unit of the field) that makes the longest arrow 0.8 of the spacing. The subsampled
    grid's coordinates and the vectors go as float32 (at most 32 x 32 arrows: 8 KB)."""
    from swarmdsl.viz.layers import _MAX_ARROWS as MAX_ARROWS

    gx, gy = np.asarray(snap.grid_x, np.float64), np.asarray(snap.grid_y, np.float64)
    values = np.asarray(snap.vectors[name], dtype=np.float64)
    if values.shape != (len(gy), len(gx), 2):
        raise SwarmError(f"snapshot vector field '{name}' has shape {values.shape}, "
                         f"expected ({len(gy)}, {len(gx)}, 2) on the grid")
    sx = max(1, int(np.ceil(len(gx) / MAX_ARROWS)))
    sy = max(1, int(np.ceil(len(gy) / MAX_ARROWS)))
    step = min((gx[sx] - gx[0]) if len(gx) > sx else snap.world_size[0],
               (gy[sy] - gy[0]) if len(gy) > sy else snap.world_size[1])
    v = values[::sy, ::sx]
    mag = np.hypot(v[..., 0], v[..., 1])
    finite = mag[np.isfinite(mag)]
    top = float(finite.max()) if finite.size else 0.0
    head = {"name": name, "nx": int(v.shape[1]), "ny": int(v.shape[0]), "top": top,
            "scale": float(0.8 * step / top) if top > 0 else 0.0}
    if top <= 0:            # nothing to draw: a still field
        return head, []
    return head, [("vector_x", gx[::sx].astype(np.float32)),
                  ("vector_y", gy[::sy].astype(np.float32)),
                  ("vectors", v.astype(np.float32).reshape(-1))]


def grid_arrays(snap) -> list:
    """The grid's nodes as the viewer marks them (`viz.layers.draw_grid_points`): a
    refined grid's every node as float32 (x, y) pairs, else the base grid's two axes
    (the page makes their product: a 1000 x 1000 grid costs 8 KB, not 8 MB)."""
    if snap.grid_points is not None:
        pts = np.asarray(snap.grid_points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2:
            raise SwarmError(f"snapshot grid_points has shape {pts.shape}, expected (P, 2)")
        return [("grid_points", pts.astype(np.float32).reshape(-1))]
    if snap.grid_x is None or snap.grid_y is None:
        return []
    return [("grid_x", np.asarray(snap.grid_x).astype(np.float32)),
            ("grid_y", np.asarray(snap.grid_y).astype(np.float32))]


def plain(value):
    """A numpy value as JSON: numbers, booleans, lists; NaN and infinities as text."""
    arr = np.asarray(value)
    if arr.ndim:
        return [plain(v) for v in arr]
    v = arr.item()
    if isinstance(v, float) and not np.isfinite(v):
        return str(v)
    return v
