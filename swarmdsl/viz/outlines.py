"""Thin lines over the world: region outlines with their labels, communication links
and the lines tying believed positions to true ones."""

from __future__ import annotations

import math

import numpy as np

from swarmdsl.errors import SwarmError
from swarmdsl.internal import describe
from swarmdsl.viz.geometry import Transform
from swarmdsl.viz.overlay import Overlay
from swarmdsl.viz.palette import LETTERBOX, LINK_COLOUR, REGION_COLOURS, REGION_DEFAULT
from swarmdsl.viz.pixels import Pixels

_SEGMENT_BUDGET = 200_000     # pixels sampled for links/belief lines per frame
_LINE_CALLS = 2000             # up to this many lines, draw each with one SDL call
_MAX_COPIES = 2                # copies either side of the one centred in the world


def draw_regions(pixels: Pixels, overlay: Overlay, regions: list[dict], tf: Transform,
                 wraps: bool = False, keep_clear: list[tuple[int, int, int, int]] = ()
                 ) -> None:
    """Outline each region (circle, rect or polygon) and label it above its top.

    A label that would fall under one of the `keep_clear` boxes (the legend and other
    panels drawn over the frame afterwards) moves the least way out of them, so a
    region near the frame's corner keeps a readable name.

    In a wrap-around world a region stands for all its copies a world size apart, as
    the runtime's region tests measure it, so a region that crosses an edge is drawn
    on both sides: every copy that reaches into the world, clipped to the world (what
    lies beyond an edge is drawn where it is, across the other one). The label goes on
    the copy whose centre is inside the world.
    """
    if not isinstance(regions, list | tuple):
        raise SwarmError(f"snapshot regions must be a list of dicts as in run.json, got "
                         f"{type(regions).__name__}")
    for region in regions:
        if not isinstance(region, dict):
            raise SwarmError(f"a snapshot region must be a dict as in run.json, got "
                             f"{type(region).__name__}")
        try:
            _draw_region(pixels, overlay, region, tf, wraps, keep_clear)
        except (KeyError, TypeError, ValueError) as exc:    # a snapshot built by hand
            raise SwarmError(f"region '{region.get('name', '')}' is not as run.json "
                             f"gives it ({describe(exc)})") from None


def _draw_region(pixels: Pixels, overlay: Overlay, region: dict, tf: Transform,
                 wraps: bool, keep_clear) -> None:
    """One region's outline (every copy of it, wrapped) and its label."""
    pg, surface = pixels.pg, pixels.surface
    clip = surface.get_clip()
    shape = region.get("shape")
    colour = REGION_COLOURS.get(region.get("kind", ""), REGION_DEFAULT)
    name = region.get("label") or region.get("name") or ""
    if shape not in ("circle", "rect", "polygon"):
        raise SwarmError(f"region '{name}' has unknown shape {shape!r}; "
                         "expected circle, rect or polygon")
    shifts, home = [(0.0, 0.0)], (0.0, 0.0)
    if wraps:
        shifts, home = _copies(_bounds(region), tf.world_w, tf.world_h)
        x0, y0, x1, y1 = tf.rect_px()
        surface.set_clip(pg.Rect(x0, y0, x1 - x0, y1 - y0).clip(clip))
    try:                        # a world shift as pixels: y points down
        anchors = {(dx, dy): _outline(pg, surface, shape, region, tf, colour,
                                      (dx * tf.scale, -dy * tf.scale))
                   for dx, dy in shifts}
    finally:
        surface.set_clip(clip)
    anchor = anchors[home]
    if name:
        text = overlay.text(str(name), colour, LETTERBOX)    # readable over heat
        x = int(anchor[0] - text.get_width() / 2)
        y = int(anchor[1] - text.get_height() - 1)
        if y < 0:
            y = int(anchor[1]) + 1
        surface.blit(text, _label_place(x, y, text.get_width(), text.get_height(),
                                        pixels.width, pixels.height, keep_clear))


def _label_place(x: int, y: int, w: int, h: int, width: int, height: int,
                 keep_clear) -> tuple[int, int]:
    """Where a `w` x `h` label wanted at `(x, y)` goes: on the frame (a region at its
    edge, or across it wrapped, keeps its label), and clear of every box in
    `keep_clear` when some nearby place is, else where it was wanted."""
    def on_frame(px: int, py: int) -> tuple[int, int]:
        return min(max(px, 0), width - w), min(max(py, 0), height - h)

    def clear(px: int, py: int) -> bool:
        return all(px >= bx + bw or px + w <= bx or py >= by + bh or py + h <= by
                   for bx, by, bw, bh in keep_clear)

    wanted = on_frame(x, y)
    places = [wanted]
    for bx, by, bw, bh in keep_clear:   # just below, above, right of, left of a box
        places += [on_frame(*p) for p in ((wanted[0], by + bh + 1), (wanted[0], by - h - 1),
                                          (bx + bw + 1, wanted[1]), (bx - w - 1, wanted[1]))]
    places.sort(key=lambda p: abs(p[0] - wanted[0]) + abs(p[1] - wanted[1]))
    return next((p for p in places if clear(*p)), wanted)


def _outline(pg, surface, shape: str, region: dict, tf: Transform, colour,
             offset: tuple[float, float]) -> tuple[float, float]:
    """Draw one copy of a region moved by `offset` pixels; the top of it, for a label."""
    ox, oy = offset
    if shape == "circle":
        (cx, cy), = tf.to_px([region["center"]])
        cx, cy = cx + ox, cy + oy
        r = max(1, int(round(float(region["radius"]) * tf.scale)))
        pg.draw.circle(surface, colour, (int(cx), int(cy)), r, 1)
        return cx, cy - r
    if shape == "rect":
        (ax, ay), (bx, by) = tf.to_px([region["min"], region["max"]])
        left, top = min(ax, bx) + ox, min(ay, by) + oy
        rect = pg.Rect(int(left), int(top), max(1, int(abs(bx - ax))),
                       max(1, int(abs(by - ay))))
        pg.draw.rect(surface, colour, rect, 1)
        return left + abs(bx - ax) / 2, top
    pts = tf.to_px(region["points"]) + (ox, oy)
    if len(pts) >= 3:
        pg.draw.polygon(surface, colour, pts.tolist(), 1)
    return (pts[:, 0].mean(), pts[:, 1].min()) if len(pts) else (ox, oy)


def _bounds(region: dict) -> tuple[float, float, float, float]:
    """`(x0, y0, x1, y1)` of a region as run.json gives it (world units)."""
    if region["shape"] == "circle":
        (cx, cy), r = region["center"], float(region["radius"])
        return cx - r, cy - r, cx + r, cy + r
    if region["shape"] == "rect":
        (ax, ay), (bx, by) = region["min"], region["max"]
        return min(ax, bx), min(ay, by), max(ax, bx), max(ay, by)
    pts = np.asarray(region["points"], dtype=np.float64).reshape(-1, 2)
    if not len(pts):
        return 0.0, 0.0, 0.0, 0.0
    return (*pts.min(axis=0), *pts.max(axis=0))


def _copies(bounds, width: float, height: float
            ) -> tuple[list[tuple[float, float]], tuple[float, float]]:
    """The world shifts of a region's copies that reach into a wrap-around world, and
    the shift that puts its centre inside (the copy that carries the label). A region
    several worlds wide has copies over the whole world; only the nearest
    `_MAX_COPIES` either side of the centred one are drawn."""
    x0, y0, x1, y1 = (float(v) for v in bounds)
    if not all(math.isfinite(v) for v in (x0, y0, x1, y1)):
        return [(0.0, 0.0)], (0.0, 0.0)
    axes = []
    for lo, hi, size in ((x0, x1, width), (y0, y1, height)):
        home = -math.floor((lo + hi) / 2 / size)
        first = max(math.ceil(-hi / size), home - _MAX_COPIES)
        last = min(math.floor((size - lo) / size), home + _MAX_COPIES)
        axes.append(([k * size for k in range(first, last + 1)] or [home * size],
                     home * size))
    (xs, hx), (ys, hy) = axes
    return [(dx, dy) for dx in xs for dy in ys], (hx, hy)


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
