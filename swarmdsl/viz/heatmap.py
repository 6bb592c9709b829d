"""A field drawn as a heatmap under the agents: values normalised per frame, coloured
through a lookup table, one pixel per node scaled up by SDL on an even grid, one
nearest-node gather per pixel on an uneven one."""

from __future__ import annotations

import numpy as np

from swarmdsl.errors import SwarmError, did_you_mean
from swarmdsl.runtime.snapshot import Snapshot
from swarmdsl.viz.geometry import Transform
from swarmdsl.viz.palette import colormap_lut
from swarmdsl.viz.pixels import Pixels


class Heatmap:
    """Draws one field of a snapshot; keeps the packed colour table between frames."""

    def __init__(self, pixels: Pixels):
        self._pixels = pixels
        self._lut_key: tuple | None = None
        self._lut: np.ndarray | None = None

    def draw(self, snap: Snapshot, opts, tf: Transform) -> str:
        """Draw the field `opts.field` (the first one when None); return its name."""
        name = opts.field if opts.field is not None else next(iter(snap.fields))
        if name not in snap.fields:
            raise SwarmError(f"no field named '{name}' to show; fields are "
                             + ", ".join(snap.fields), hint=did_you_mean(name, snap.fields))
        values = np.asarray(snap.fields[name], dtype=np.float64)
        if values.ndim != 2 or values.size == 0:
            raise SwarmError(f"field '{name}' has shape {values.shape}, expected (ny, nx)")
        ny, nx = values.shape
        gx = _grid_axis(snap.grid_x, nx, tf.world_w, "grid_x")
        gy = _grid_axis(snap.grid_y, ny, tf.world_h, "grid_y")
        finite = np.isfinite(values)
        if finite.any():
            lo, hi = float(values[finite].min()), float(values[finite].max())
        else:
            lo = hi = 0.0
        norm = np.zeros_like(values)
        if hi > lo:
            np.divide(values - lo, hi - lo, out=norm, where=finite)
        idx = np.clip(np.rint(norm * 255.0), 0, 255).astype(np.uint8)
        key = (opts.colormap, opts.field_alpha)
        if key != self._lut_key:
            lut = colormap_lut(opts.colormap, opts.field_alpha)
            self._lut, self._lut_key = self._pixels.pack(lut), key
        x0, y0, x1, y1 = tf.rect_px()
        x0, y0 = max(x0, 0), max(y0, 0)
        x1, y1 = min(x1, self._pixels.width), min(y1, self._pixels.height)
        dx, dy = _spacing(gx), _spacing(gy)
        if dx is not None and dy is not None:
            self._blit_uniform(idx, gx, gy, dx, dy, tf, (x0, y0, x1, y1))
            return name
        # Irregular grid: nearest node for each pixel centre, one gather.
        wx = (np.arange(x0, x1) + 0.5 - tf.ox) / tf.scale
        wy = tf.world_h - (np.arange(y0, y1) + 0.5 - tf.oy) / tf.scale
        ix = _nearest_node(gx, wx)
        iy = _nearest_node(gy, wy)
        block = self._lut[idx[iy[:, None], ix[None, :]]]      # (rows, cols) uint32
        with self._pixels.rows() as rows:
            rows[y0:y1, x0:x1] = block
        return name

    def _blit_uniform(self, idx, gx, gy, dx, dy, tf: Transform, clip) -> None:
        """Colour one pixel per node, then let SDL scale it up (nearest neighbour).

        Each node owns the cell of one spacing centred on it, so the small image spans
        half a spacing beyond the outer nodes; the world rectangle clips it.
        """
        pg, surface = self._pixels.pg, self._pixels.surface
        ny, nx = idx.shape
        small = pg.Surface((nx, ny), 0, surface)
        cells = pg.surfarray.pixels2d(small)
        try:
            cells[...] = self._lut[idx[::-1]].T             # row 0 of the image is top
        finally:
            del cells
        left = tf.ox + (gx[0] - dx / 2.0) * tf.scale
        top = tf.oy + (tf.world_h - (gy[-1] + dy / 2.0)) * tf.scale
        right = tf.ox + (gx[-1] + dx / 2.0) * tf.scale
        bottom = tf.oy + (tf.world_h - (gy[0] - dy / 2.0)) * tf.scale
        ix0, iy0 = int(round(left)), int(round(top))
        size = (max(1, int(round(right)) - ix0), max(1, int(round(bottom)) - iy0))
        x0, y0, x1, y1 = clip
        surface.set_clip(pg.Rect(x0, y0, x1 - x0, y1 - y0))
        try:
            surface.blit(pg.transform.scale(small, size), (ix0, iy0))
        finally:
            surface.set_clip(None)


def _grid_axis(axis, n: int, extent: float, label: str) -> np.ndarray:
    if axis is None:
        return np.linspace(0.0, extent, n)
    arr = np.asarray(axis, dtype=np.float64).reshape(-1)
    if arr.shape[0] != n:
        raise SwarmError(f"snapshot {label} has {arr.shape[0]} nodes, field has {n}")
    return arr


def _spacing(nodes: np.ndarray) -> float | None:
    """The step of an evenly spaced ascending axis, or None if it is not one."""
    if len(nodes) < 2:
        return None
    steps = np.diff(nodes)
    step = float(steps.mean())
    if not (step > 0 and np.allclose(steps, step, rtol=1e-6, atol=0.0)):
        return None
    return step


def _nearest_node(nodes: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """Index of the nearest node (nodes ascending) for each coordinate."""
    if len(nodes) == 1:
        return np.zeros(len(coords), dtype=np.int64)
    mids = (nodes[1:] + nodes[:-1]) / 2.0
    return np.searchsorted(mids, coords).astype(np.int64)
