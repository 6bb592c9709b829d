"""Turning one `Snapshot` into pixels: the picture shared by the live viewer and videos.

Everything is drawn onto an off-screen pygame Surface, so the same code serves the
window (blit the surface) and GIF/MP4 recording (read it back as an `(H, W, 3)` array)
and runs headless under `SDL_VIDEODRIVER=dummy`. Per-agent work is numpy; the only
Python loop over agents is `pygame.draw.polygon` for the oriented markers, and it runs
only while the swarm is small (`RenderOptions.splat_above`); bigger swarms are written
straight into the pixel array, because drawing shapes one call at a time stops being
interactive around ten thousand agents.
"""

from __future__ import annotations

import math
import sys
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from swarmdsl.compiler.errors import SwarmError, did_you_mean
from swarmdsl.runtime.snapshot import Snapshot
from swarmdsl.viz import layers, require_pygame
from swarmdsl.viz.overlay import Overlay
from swarmdsl.viz.palette import (
    BACKGROUND,
    BELIEF_LINE,
    BORDER,
    LETTERBOX,
    LINK_COLOUR,
    REGION_COLOURS,
    REGION_DEFAULT,
    colormap_lut,
    leaf_colours,
    status_palette,
)

_PAD_PX = 2
_DENSE = 30_000                # above this many agents, splats shrink to 2 pixels
_SEGMENT_BUDGET = 200_000     # pixels sampled for links/belief lines per frame
_LINE_CALLS = 2000             # up to this many lines, draw each with one SDL call


@dataclass
class RenderOptions:
    """What to draw. The viewer flips these from the keyboard; videos use them as given.

    Attributes:
        show_field: draw the heatmap of `field` under the agents.
        field: which field; None means the first one in the snapshot.
        colormap: one of `COLORMAPS`; values are normalised per frame (min..max).
        field_alpha: heatmap opacity over the background, so agents stay visible.
        show_regions: outline and label regions.
        show_grid_points: mark every grid node (refined ones too) with a pixel.
        show_vectors: draw vector fields (physical twins) as arrows.
        show_links: draw communication links (when the snapshot has them).
        show_believed: draw believed positions as hollow markers tied to true ones.
        use_led: colour agents by their LED instead of status (when they have one).
        by_tree_leaf: colour agents by their active behaviour-tree leaf (when tracked).
        show_legend: the status legend with live counts.
        show_tick: the tick counter.
        marker_px: marker length in pixels; None picks one from the agent count.
        splat_above: above this many agents, markers are pixel splats, not polygons.
        hud_text: an extra status line (the viewer shows speed and pause state).
    """

    show_field: bool = True
    field: str | None = None
    colormap: str = "magma"
    field_alpha: float = 0.75
    show_regions: bool = True
    show_grid_points: bool = False
    show_vectors: bool = True
    show_links: bool = False
    show_believed: bool = False
    use_led: bool = True
    by_tree_leaf: bool = False
    show_legend: bool = True
    show_tick: bool = True
    marker_px: float | None = None
    splat_above: int = 3000
    hud_text: str = ""


def fit_size(world_size: tuple[float, float], max_px: int = 800, multiple: int = 16
             ) -> tuple[int, int]:
    """Frame size in pixels that keeps the world's aspect, each side a multiple of 16.

    Video encoders work in 16-pixel macro blocks; sizes that are not multiples get
    rescaled or padded, which blurs thin lines, so the CLI should size frames with this.
    """
    w, h = (float(v) for v in world_size)
    if not (w > 0 and h > 0 and math.isfinite(w) and math.isfinite(h)):
        raise SwarmError(f"world size must be positive, got {w:g} x {h:g}")
    if max_px < multiple:
        raise SwarmError(f"frame size must be at least {multiple} pixels, got {max_px}")
    scale = max_px / max(w, h)
    return (max(multiple, int(w * scale) // multiple * multiple),
            max(multiple, int(h * scale) // multiple * multiple))


class _Transform:
    """World (y up) to pixel (y down) coordinates with the aspect kept, world centred."""

    def __init__(self, world_size: tuple[float, float], width: int, height: int):
        ww, wh = (float(v) for v in world_size)
        if not (ww > 0 and wh > 0 and math.isfinite(ww) and math.isfinite(wh)):
            raise SwarmError(f"world size must be positive, got {ww:g} x {wh:g}")
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


class FrameRenderer:
    """Draws snapshots onto one reusable off-screen surface of a fixed pixel size.

    Args:
        width_px: frame width in pixels (at least 16; a multiple of 16 for video).
        height_px: frame height in pixels.
        font_px: text size; None scales it with the frame.
    """

    def __init__(self, width_px: int, height_px: int, *, font_px: int | None = None):
        for label, value in (("width", width_px), ("height", height_px)):
            if not isinstance(value, int | np.integer) or not 16 <= int(value) <= 16384:
                raise SwarmError(f"frame {label} must be an integer from 16 to 16384 "
                                 f"pixels, got {value!r}")
        self.width, self.height = int(width_px), int(height_px)
        self._pg = require_pygame()
        self._pg.font.init()
        self.surface = self._pg.Surface((self.width, self.height), 0, 32)
        size = font_px or max(12, min(22, self.height // 30))
        self._overlay = Overlay(self._pg, size, self.width, self.height)
        self._lut_key: tuple | None = None
        self._lut: np.ndarray | None = None
        self.legend_rect: tuple[int, int, int, int] | None = None

    # -- public -------------------------------------------------------------------------

    def render(self, snapshot: Snapshot, options: RenderOptions | None = None) -> np.ndarray:
        """Draw `snapshot` and return it as a new `(height, width, 3)` uint8 array."""
        self.draw(snapshot, options)
        return self.array()

    def array(self) -> np.ndarray:
        """The surface as last drawn, as a new `(height, width, 3)` uint8 array."""
        # Reading the packed pixels and picking bytes is ~4x faster than image.tobytes.
        out = np.empty((self.height, self.width, 3), dtype=np.uint8)
        with self._rows() as rows:
            quads = rows.view(np.uint8).reshape(self.height, self.width, 4)
            for channel, shift in enumerate(self.surface.get_shifts()[:3]):
                byte = shift // 8 if sys.byteorder == "little" else 3 - shift // 8
                out[..., channel] = quads[..., byte]
        return out

    def draw(self, snapshot: Snapshot, options: RenderOptions | None = None):
        """Draw `snapshot` onto `self.surface` and return it (reused by the next call)."""
        opts = options or RenderOptions()
        tf = _Transform(snapshot.world_size, self.width, self.height)
        surf = self.surface
        surf.fill(LETTERBOX)
        x0, y0, x1, y1 = tf.rect_px()
        surf.fill(BACKGROUND, self._pg.Rect(x0, y0, x1 - x0, y1 - y0))
        field_name = None
        if opts.show_field and snapshot.fields:
            field_name = self._draw_field(snapshot, opts, tf)
        if opts.show_grid_points:
            layers.draw_grid_points(surf, snapshot, tf.to_px)
        if opts.show_vectors and snapshot.vectors:
            layers.draw_vectors(surf, snapshot, tf.to_px)
        self._pg.draw.rect(surf, BORDER, self._pg.Rect(x0, y0, x1 - x0, y1 - y0), 1)
        pos = _points(snapshot.pos, "pos")
        if opts.show_links and snapshot.links is not None and len(pos):
            self._draw_links(pos, snapshot.links, tf)
        colours = self._agent_colours(snapshot, len(pos), opts)
        heading = np.asarray(snapshot.heading, dtype=np.float64).reshape(-1)
        if heading.shape[0] != len(pos):
            raise SwarmError(f"snapshot heading has {heading.shape[0]} entries for "
                             f"{len(pos)} agents")
        believed = None
        if opts.show_believed and snapshot.believed is not None:
            believed = _points(snapshot.believed, "believed")
            if len(believed) != len(pos):
                raise SwarmError(f"snapshot believed has {len(believed)} rows for "
                                 f"{len(pos)} agents")
            self._draw_segments(tf.to_px(believed), tf.to_px(pos), BELIEF_LINE)
        self._draw_agents(tf.to_px(pos), heading, colours, opts, hollow=False)
        if believed is not None:
            self._draw_agents(tf.to_px(believed), heading, colours, opts, hollow=True)
        if opts.show_regions:       # over the agents, so dense swarms cannot hide them
            self._draw_regions(snapshot.regions, tf)
        self.legend_rect = self._overlay.draw(surf, snapshot, opts, field_name)
        return surf

    def agent_at(self, snapshot: Snapshot, px: tuple[int, int], reach: float = 12.0
                 ) -> int | None:
        """The id of the agent drawn nearest pixel `px`, if within `reach` pixels."""
        pos = _points(snapshot.pos, "pos")
        if not len(pos):
            return None
        tf = _Transform(snapshot.world_size, self.width, self.height)
        d = np.hypot(*(tf.to_px(pos) - np.asarray(px, dtype=np.float64)).T)
        row = int(np.argmin(d))
        return int(snapshot.ids[row]) if d[row] <= reach else None

    def draw_note(self, target, text: str) -> None:
        """Draw a one-line note on `target` just above the field caption (the key help).

        Kept off `self.surface` so recorded frames do not carry the viewer's chrome.
        """
        self._overlay.note(target, text)

    # -- layers -------------------------------------------------------------------------

    def _draw_field(self, snap: Snapshot, opts: RenderOptions, tf: _Transform) -> str:
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
            self._lut, self._lut_key = self._map(lut), key
        x0, y0, x1, y1 = tf.rect_px()
        x0, y0 = max(x0, 0), max(y0, 0)
        x1, y1 = min(x1, self.width), min(y1, self.height)
        dx, dy = _spacing(gx), _spacing(gy)
        if dx is not None and dy is not None:
            self._blit_uniform_field(idx, gx, gy, dx, dy, tf, (x0, y0, x1, y1))
            return name
        # Irregular grid: nearest node for each pixel centre, one gather.
        wx = (np.arange(x0, x1) + 0.5 - tf.ox) / tf.scale
        wy = tf.world_h - (np.arange(y0, y1) + 0.5 - tf.oy) / tf.scale
        ix = _nearest_node(gx, wx)
        iy = _nearest_node(gy, wy)
        block = self._lut[idx[iy[:, None], ix[None, :]]]      # (rows, cols) uint32
        with self._rows() as rows:
            rows[y0:y1, x0:x1] = block
        return name

    def _blit_uniform_field(self, idx, gx, gy, dx, dy, tf: _Transform, clip) -> None:
        """Colour one pixel per node, then let SDL scale it up (nearest neighbour).

        Each node owns the cell of one spacing centred on it, so the small image spans
        half a spacing beyond the outer nodes; the world rectangle clips it.
        """
        pg = self._pg
        ny, nx = idx.shape
        small = pg.Surface((nx, ny), 0, self.surface)
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
        self.surface.set_clip(pg.Rect(x0, y0, x1 - x0, y1 - y0))
        try:
            self.surface.blit(pg.transform.scale(small, size), (ix0, iy0))
        finally:
            self.surface.set_clip(None)

    def _draw_regions(self, regions: list[dict], tf: _Transform) -> None:
        pg = self._pg
        for region in regions:
            shape = region.get("shape")
            colour = REGION_COLOURS.get(region.get("kind", ""), REGION_DEFAULT)
            name = region.get("label") or region.get("name") or ""
            if shape == "circle":
                (cx, cy), = tf.to_px([region["center"]])
                r = max(1, int(round(float(region["radius"]) * tf.scale)))
                pg.draw.circle(self.surface, colour, (int(cx), int(cy)), r, 1)
                anchor = (cx, cy - r)
            elif shape == "rect":
                (ax, ay), (bx, by) = tf.to_px([region["min"], region["max"]])
                left, top = min(ax, bx), min(ay, by)
                rect = pg.Rect(int(left), int(top), max(1, int(abs(bx - ax))),
                               max(1, int(abs(by - ay))))
                pg.draw.rect(self.surface, colour, rect, 1)
                anchor = (left + abs(bx - ax) / 2, top)
            elif shape == "polygon":
                pts = tf.to_px(region["points"])
                if len(pts) >= 3:
                    pg.draw.polygon(self.surface, colour, pts.tolist(), 1)
                anchor = (pts[:, 0].mean(), pts[:, 1].min()) if len(pts) else (0, 0)
            else:
                raise SwarmError(f"region '{name}' has unknown shape {shape!r}; "
                                 "expected circle, rect or polygon")
            if name:
                text = self._overlay.text(str(name), colour, LETTERBOX)    # readable over heat
                x = int(anchor[0] - text.get_width() / 2)
                y = int(anchor[1] - text.get_height() - 1)
                if y < 0:
                    y = int(anchor[1]) + 1
                self.surface.blit(text, (x, y))

    def _draw_links(self, pos: np.ndarray, links: np.ndarray, tf: _Transform) -> None:
        pairs = np.asarray(links).reshape(-1, 2)
        if not len(pairs):
            return
        pairs = pairs.astype(np.int64)
        ok = ((pairs >= 0) & (pairs < len(pos))).all(axis=1)
        pairs = pairs[ok]
        px = tf.to_px(pos)
        self._draw_segments(px[pairs[:, 0]], px[pairs[:, 1]], LINK_COLOUR)

    def _draw_segments(self, a: np.ndarray, b: np.ndarray, colour) -> None:
        """1-pixel lines from `a[i]` to `b[i]`.

        A few thousand lines are cheapest as SDL line calls; past that they are sampled
        in numpy (no loop over lines), dotted when there are too many pixels to sample.
        """
        keep = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
        lim = 4.0 * (self.width + self.height)    # SDL wants ints; clip far-off points
        a = np.clip(a[keep], -lim, lim)
        b = np.clip(b[keep], -lim, lim)
        if not len(a):
            return
        if len(a) <= _LINE_CALLS:
            line, surf = self._pg.draw.line, self.surface
            for p, q in zip(a.astype(np.int64).tolist(), b.astype(np.int64).tolist(),
                            strict=True):
                line(surf, colour, p, q)
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
        self._splat(pts, self._map(np.asarray(colour, np.uint8)))

    def _draw_agents(self, px: np.ndarray, heading: np.ndarray, colours: np.ndarray,
                     opts: RenderOptions, hollow: bool) -> None:
        n = len(px)
        if n == 0:
            return
        keep = np.isfinite(px).all(axis=1) & np.isfinite(heading)
        inside = keep & (px[:, 0] > -32) & (px[:, 0] < self.width + 32) \
            & (px[:, 1] > -32) & (px[:, 1] < self.height + 32)
        px, heading, colours = px[inside], heading[inside], colours[inside]
        # Heading is counter-clockwise with y up, so the pixel direction flips dy.
        direction = np.stack([np.cos(heading), -np.sin(heading)], axis=1)
        length = opts.marker_px if opts.marker_px is not None else _auto_marker(n)
        if n <= opts.splat_above:
            self._draw_triangles(px, direction, colours, float(length), hollow)
        else:
            self._draw_splats(px, direction, colours, hollow)

    def _draw_triangles(self, px, direction, colours, length, hollow) -> None:
        # Vertices chosen so the triangle's centroid is the agent's position.
        normal = np.stack([-direction[:, 1], direction[:, 0]], axis=1)
        nose = px + direction * (2.0 * length / 3.0)
        back = px - direction * (length / 3.0)
        half = normal * (0.35 * length)
        tris = np.stack([nose, back + half, back - half], axis=1)        # (N, 3, 2)
        width = 1 if hollow else 0
        polygon = self._pg.draw.polygon
        for tri, colour in zip(tris.tolist(), colours.tolist(), strict=True):
            polygon(self.surface, colour, tri, width)

    def _draw_splats(self, px, direction, colours, hollow) -> None:
        """Fixed pixel stencils for big swarms: a 3x3 body plus a nose pixel ahead.

        The loop runs over the (at most nine) stencil offsets, each writing every agent at once;
        bodies are clamped one pixel inside the frame so no per-offset bounds mask is
        needed (agents in the outermost pixel ring draw shifted by one pixel).
        """
        w, h = self.width, self.height
        bx = np.clip(np.floor(px[:, 0]).astype(np.int64), 1, w - 2)
        by = np.clip(np.floor(px[:, 1]).astype(np.int64), 1, h - 2)
        base = by * w + bx
        packed = self._map(colours)
        reach = 2.5 if len(px) <= _DENSE else 1.0
        nose_x = np.clip(bx + np.rint(direction[:, 0] * reach).astype(np.int64), 0, w - 1)
        nose_y = np.clip(by + np.rint(direction[:, 1] * reach).astype(np.int64), 0, h - 1)
        # Past _DENSE agents a 3x3 body would paint the whole frame: shrink to one pixel.
        if len(px) > _DENSE:
            stencil = [(0, 0)] if not hollow else [(-1, 0), (1, 0), (0, -1), (0, 1)]
        else:
            stencil = [(dx, dy) for dy in (-1, 0, 1) for dx in (-1, 0, 1)
                       if not (hollow and dx == 0 and dy == 0)]
        with self._rows() as rows:
            flat = rows.reshape(-1)
            for dx, dy in stencil:
                flat[base + (dy * w + dx)] = packed
            flat[nose_y * w + nose_x] = packed

    def _splat(self, pts: np.ndarray, values: np.ndarray) -> None:
        """Write `(K, 2)` integer pixels with packed values `(K,)` or one scalar, clipped."""
        ok = (pts[:, 0] >= 0) & (pts[:, 0] < self.width) \
            & (pts[:, 1] >= 0) & (pts[:, 1] < self.height)
        if not ok.any():
            return
        if values.ndim:
            values = values[ok]
        flat_index = pts[ok, 1] * self.width + pts[ok, 0]
        with self._rows() as rows:
            rows.reshape(-1)[flat_index] = values

    def _map(self, colours: np.ndarray) -> np.ndarray:
        """RGB uint8 `(..., 3)` to the surface's packed uint32 pixel values."""
        c = np.asarray(colours, dtype=np.uint32)
        r, g, b, _ = self.surface.get_shifts()
        return (c[..., 0] << r) | (c[..., 1] << g) | (c[..., 2] << b)

    @contextmanager
    def _rows(self):
        """The surface's pixels as a writable `(height, width)` uint32 view, row-major.

        One flat index per pixel is several times faster than 2-D fancy indexing into
        pygame's column-major `(width, height, 3)` view; the view locks the surface, so
        it is released as soon as the write is done.
        """
        pixels = self._pg.surfarray.pixels2d(self.surface)
        try:
            rows = pixels.T
            if not rows.flags["C_CONTIGUOUS"]:      # padded pitch: write a copy back
                buf = np.ascontiguousarray(rows)
                yield buf
                rows[...] = buf
            else:
                yield rows
        finally:
            del pixels

    def _agent_colours(self, snap: Snapshot, n: int, opts: RenderOptions) -> np.ndarray:
        if opts.by_tree_leaf and snap.tree_leaf is not None:
            return leaf_colours(snap)
        if opts.use_led and snap.led is not None:
            led = np.asarray(snap.led)
            if led.shape != (n, 3):
                raise SwarmError(f"snapshot led has shape {led.shape}, expected ({n}, 3)")
            return np.clip(led, 0, 255).astype(np.uint8)
        status = np.asarray(snap.status, dtype=np.int64).reshape(-1)
        if status.shape[0] != n:
            raise SwarmError(f"snapshot status has {status.shape[0]} entries for {n} agents")
        palette = status_palette(max(len(snap.status_names), 1))
        return palette[np.mod(status, len(palette))]


def _points(value, label: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.size == 0:
        return arr.reshape(0, 2)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise SwarmError(f"snapshot {label} has shape {arr.shape}, expected (N, 2)")
    return arr


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


def _auto_marker(n: int) -> float:
    if n <= 200:
        return 12.0
    if n <= 1000:
        return 9.0
    return 7.0
