"""Where the world lands in a frame: frame sizes for a world, and world (y up) to pixel
(y down) coordinates, so every layer agrees on the same mapping."""

from __future__ import annotations

import math

import numpy as np

from swarmdsl.errors import SwarmError, SwarmOptionError
from swarmdsl.runtime.arguments import real, whole

_PAD_PX = 2
MAX_PX = 16384      # the longest frame side drawn


def fit_size(world_size: tuple[float, float], max_px: int = 800, multiple: int = 16
             ) -> tuple[int, int]:
    """Frame size in pixels that keeps the world's aspect, each side a multiple of 16.

    Video encoders work in 16-pixel macro blocks; sizes that are not multiples get
    rescaled or padded, which blurs thin lines, so the CLI should size frames with this.
    """
    w, h = world_extent(world_size)
    multiple = whole("fit_size multiple", multiple, 1, MAX_PX)
    scale = real("fit_size max_px", max_px, multiple, MAX_PX) / max(w, h)
    return (max(multiple, int(w * scale) // multiple * multiple),
            max(multiple, int(h * scale) // multiple * multiple))


def world_extent(world_size) -> tuple[float, float]:
    """`(width, height)` as two positive finite floats, or a SwarmError: a notebook may
    pass a snapshot's `world_size` or a size of its own."""
    try:
        w, h = (float(v) for v in world_size)
    except (TypeError, ValueError):
        raise SwarmOptionError(f"world size must be (width, height), got {world_size!r}"
                               ) from None
    if not (w > 0 and h > 0 and math.isfinite(w) and math.isfinite(h)):
        raise SwarmError(f"world size must be positive, got {w:g} x {h:g}")
    return w, h


class Transform:
    """World (y up) to pixel (y down) coordinates with the aspect kept, world centred."""

    def __init__(self, world_size: tuple[float, float], width: int, height: int):
        ww, wh = world_extent(world_size)
        self.world_w, self.world_h = ww, wh
        self.scale = min((width - 2 * _PAD_PX) / ww, (height - 2 * _PAD_PX) / wh)
        self.ox = (width - ww * self.scale) / 2.0
        self.oy = (height - wh * self.scale) / 2.0

    def to_px(self, xy: np.ndarray) -> np.ndarray:
        """`(N, 2)` world points to float pixel coordinates (x right, y down)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        out = np.empty_like(xy)
        out[:, 0] = self.ox + xy[:, 0] * self.scale
        out[:, 1] = self.oy + (self.world_h - xy[:, 1]) * self.scale
        return out

    def rect_px(self) -> tuple[int, int, int, int]:
        """Pixel bounds `(x0, y0, x1, y1)` of the world, end-exclusive."""
        x0, y0 = int(math.floor(self.ox)), int(math.floor(self.oy))
        x1 = int(math.ceil(self.ox + self.world_w * self.scale))
        y1 = int(math.ceil(self.oy + self.world_h * self.scale))
        return x0, y0, x1, y1
