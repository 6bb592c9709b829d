"""Thin lines over the world: region outlines with their labels, communication links
and the lines tying believed positions to true ones."""

from __future__ import annotations

import numpy as np

from swarmdsl.compiler.errors import SwarmError
from swarmdsl.viz.geometry import Transform
from swarmdsl.viz.overlay import Overlay
from swarmdsl.viz.palette import LETTERBOX, LINK_COLOUR, REGION_COLOURS, REGION_DEFAULT
from swarmdsl.viz.pixels import Pixels

_SEGMENT_BUDGET = 200_000     # pixels sampled for links/belief lines per frame
_LINE_CALLS = 2000             # up to this many lines, draw each with one SDL call


def draw_regions(pixels: Pixels, overlay: Overlay, regions: list[dict], tf: Transform
                 ) -> None:
    """Outline each region (circle, rect or polygon) and label it above its top."""
    pg, surface = pixels.pg, pixels.surface
    for region in regions:
        shape = region.get("shape")
        colour = REGION_COLOURS.get(region.get("kind", ""), REGION_DEFAULT)
        name = region.get("label") or region.get("name") or ""
        if shape == "circle":
            (cx, cy), = tf.to_px([region["center"]])
            r = max(1, int(round(float(region["radius"]) * tf.scale)))
            pg.draw.circle(surface, colour, (int(cx), int(cy)), r, 1)
            anchor = (cx, cy - r)
        elif shape == "rect":
            (ax, ay), (bx, by) = tf.to_px([region["min"], region["max"]])
            left, top = min(ax, bx), min(ay, by)
            rect = pg.Rect(int(left), int(top), max(1, int(abs(bx - ax))),
                           max(1, int(abs(by - ay))))
            pg.draw.rect(surface, colour, rect, 1)
            anchor = (left + abs(bx - ax) / 2, top)
        elif shape == "polygon":
            pts = tf.to_px(region["points"])
            if len(pts) >= 3:
                pg.draw.polygon(surface, colour, pts.tolist(), 1)
            anchor = (pts[:, 0].mean(), pts[:, 1].min()) if len(pts) else (0, 0)
        else:
            raise SwarmError(f"region '{name}' has unknown shape {shape!r}; "
                             "expected circle, rect or polygon")
        if name:
            text = overlay.text(str(name), colour, LETTERBOX)    # readable over heat
            x = int(anchor[0] - text.get_width() / 2)
            y = int(anchor[1] - text.get_height() - 1)
            if y < 0:
                y = int(anchor[1]) + 1
            surface.blit(text, (x, y))


def draw_links(pixels: Pixels, pos: np.ndarray, links: np.ndarray, tf: Transform) -> None:
    """A line per `(i, j)` row of `links` between agents `i` and `j` (bad rows skipped)."""
    pairs = np.asarray(links).reshape(-1, 2)
    if not len(pairs):
        return
    pairs = pairs.astype(np.int64)
    ok = ((pairs >= 0) & (pairs < len(pos))).all(axis=1)
    pairs = pairs[ok]
    px = tf.to_px(pos)
    draw_segments(pixels, px[pairs[:, 0]], px[pairs[:, 1]], LINK_COLOUR)


def draw_segments(pixels: Pixels, a: np.ndarray, b: np.ndarray, colour) -> None:
    """1-pixel lines from `a[i]` to `b[i]`.

    A few thousand lines are cheapest as SDL line calls; past that they are sampled
    in numpy (no loop over lines), dotted when there are too many pixels to sample.
    """
    keep = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
    lim = 4.0 * (pixels.width + pixels.height)    # SDL wants ints; clip far-off points
    a = np.clip(a[keep], -lim, lim)
    b = np.clip(b[keep], -lim, lim)
    if not len(a):
        return
    if len(a) <= _LINE_CALLS:
        line, surface = pixels.pg.draw.line, pixels.surface
        for p, q in zip(a.astype(np.int64).tolist(), b.astype(np.int64).tolist(),
                        strict=True):
            line(surface, colour, p, q)
        return
    d = b - a
    n = np.ceil(np.abs(d).max(axis=1)).astype(np.int64) + 1
    total = int(n.sum())
    if total > _SEGMENT_BUDGET:
        n = np.maximum(2, (n * (_SEGMENT_BUDGET / total)).astype(np.int64))
    seg = np.repeat(np.arange(len(a)), n)
    k = np.arange(seg.shape[0]) - np.repeat(np.cumsum(n) - n, n)
    t = (k / np.maximum(n - 1, 1)[seg])[:, None]
    pts = np.floor(a[seg] + d[seg] * t).astype(np.int64)
    pixels.splat(pts, pixels.pack(np.asarray(colour, np.uint8)))
