"""Turning one `Snapshot` into pixels: the picture shared by the live viewer and videos.

Everything is drawn onto an off-screen pygame Surface, so the same code serves the
window (blit the surface) and GIF/MP4 recording (read it back as an `(H, W, 3)` array)
and runs headless under `SDL_VIDEODRIVER=dummy`. This module decides what is drawn and
in which order; each layer has its own module: `heatmap` (a field), `layers` (grid
nodes, vector arrows), `outlines` (regions, links, belief lines), `markers` (agents),
`overlay` (text), over `geometry` (world to pixels) and `pixels` (numpy writes).
Per-agent work is numpy; the only Python loop over agents is `pygame.draw.polygon`
for the oriented markers, and it runs only while the swarm is small
(`RenderOptions.splat_above`); bigger swarms are written straight into the pixel
array, because drawing shapes one call at a time stops being interactive around ten
thousand agents.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmdsl.compiler.errors import SwarmError, SwarmOptionError
from swarmdsl.runtime.arguments import real, text, whole
from swarmdsl.runtime.snapshot import Snapshot
from swarmdsl.viz import layers, require_pygame
from swarmdsl.viz.geometry import MAX_PX, Transform, fit_size
from swarmdsl.viz.heatmap import Heatmap
from swarmdsl.viz.markers import agent_colours, draw_agents
from swarmdsl.viz.outlines import draw_links, draw_regions, draw_segments
from swarmdsl.viz.overlay import Overlay
from swarmdsl.viz.palette import BACKGROUND, BELIEF_LINE, BORDER, LETTERBOX
from swarmdsl.viz.pixels import Pixels

__all__ = ["FrameRenderer", "RenderOptions", "fit_size"]

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


def checked_options(options) -> RenderOptions:
    """`options` (None: the defaults), each value of a type and range the layers can
    draw, or a SwarmOptionError naming it: set by hand in a notebook, `colormap=None`
    or `splat_above="10"` used to fail as a TypeError deep inside a layer, and a NaN
    `field_alpha` painted the heatmap in garbage."""
    if options is None:
        return RenderOptions()
    if not isinstance(options, RenderOptions):
        raise SwarmOptionError(f"options must be a RenderOptions, got "
                               f"{type(options).__name__}")
    if options.field is not None:
        text("RenderOptions.field", options.field)
    text("RenderOptions.colormap", options.colormap)     # its name: palette.colormap_lut
    real("RenderOptions.field_alpha", options.field_alpha, 0.0, 1.0)
    if options.marker_px is not None:
        real("RenderOptions.marker_px", options.marker_px, 0.0, MAX_PX)
    whole("RenderOptions.splat_above", options.splat_above, 0, 2**63 - 1)
    text("RenderOptions.hud_text", options.hud_text)
    return options


def _check_snapshot(snapshot) -> Snapshot:
    if not isinstance(snapshot, Snapshot):
        raise SwarmOptionError(f"the renderer draws a Snapshot (sim.snapshot()), got "
                               f"{type(snapshot).__name__}")
    return snapshot



class FrameRenderer:
    """Draws snapshots onto one reusable off-screen surface of a fixed pixel size.

    Args:
        width_px: frame width in pixels (at least 16; a multiple of 16 for video).
        height_px: frame height in pixels.
        font_px: text size; None scales it with the frame.
    """

    def __init__(self, width_px: int, height_px: int, *, font_px: int | None = None):
        for label, value in (("width", width_px), ("height", height_px)):
            if not isinstance(value, int | np.integer) or not 16 <= int(value) <= MAX_PX:
                raise SwarmError(f"frame {label} must be an integer from 16 to {MAX_PX} "
                                 f"pixels, got {value!r}")
        self.width, self.height = int(width_px), int(height_px)
        if font_px is not None:     # pygame cannot open a font of 10^6 pixels
            font_px = whole("font_px", font_px, 1, 1024)
        self._pg = require_pygame()
        self._pg.font.init()
        self.surface = self._pg.Surface((self.width, self.height), 0, 32)
        self._pixels = Pixels(self._pg, self.surface)
        self._heatmap = Heatmap(self._pixels)
        size = font_px or max(12, min(22, self.height // 30))
        self._overlay = Overlay(self._pg, size, self.width, self.height)
        self.legend_rect: tuple[int, int, int, int] | None = None

    def render(self, snapshot: Snapshot, options: RenderOptions | None = None) -> np.ndarray:
        """Draw `snapshot` and return it as a new `(height, width, 3)` uint8 array."""
        self.draw(snapshot, options)
        return self.array()

    def array(self) -> np.ndarray:
        """The surface as last drawn, as a new `(height, width, 3)` uint8 array."""
        return self._pixels.array()

    def draw(self, snapshot: Snapshot, options: RenderOptions | None = None):
        """Draw `snapshot` onto `self.surface` and return it (reused by the next call)."""
        snapshot, opts = _check_snapshot(snapshot), checked_options(options)
        tf = Transform(snapshot.world_size, self.width, self.height)
        surf, pixels = self.surface, self._pixels
        surf.fill(LETTERBOX)
        x0, y0, x1, y1 = tf.rect_px()
        surf.fill(BACKGROUND, self._pg.Rect(x0, y0, x1 - x0, y1 - y0))
        field_name = None
        if opts.show_field and snapshot.fields:
            field_name = self._heatmap.draw(snapshot, opts, tf)
        if opts.show_grid_points:
            layers.draw_grid_points(surf, snapshot, tf.to_px)
        if opts.show_vectors and snapshot.vectors:
            layers.draw_vectors(surf, snapshot, tf.to_px)
        self._pg.draw.rect(surf, BORDER, self._pg.Rect(x0, y0, x1 - x0, y1 - y0), 1)
        pos = _points(snapshot.pos, "pos")
        if opts.show_links and snapshot.links is not None and len(pos):
            draw_links(pixels, pos, snapshot.links, tf)
        colours = agent_colours(snapshot, len(pos), opts)
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
            draw_segments(pixels, tf.to_px(believed), tf.to_px(pos), BELIEF_LINE)
        agents_px = tf.to_px(pos)
        draw_agents(pixels, agents_px, heading, colours, opts, hollow=False)
        self._overlay.place_legend(snapshot, opts, field_name, agents_px)
        if believed is not None:
            draw_agents(pixels, tf.to_px(believed), heading, colours, opts, hollow=True)
        if opts.show_regions:       # over the agents, so dense swarms cannot hide them
            draw_regions(pixels, self._overlay, snapshot.regions, tf, snapshot.wraps,
                         self._overlay.boxes(snapshot, opts, field_name))
        self.legend_rect = self._overlay.draw(surf, snapshot, opts, field_name)
        return surf

    def agent_at(self, snapshot: Snapshot, px: tuple[int, int], reach: float = 12.0
                 ) -> int | None:
        """The id of the agent drawn nearest pixel `px`, if within `reach` pixels."""
        pos = _points(_check_snapshot(snapshot).pos, "pos")
        if not len(pos):
            return None
        tf = Transform(snapshot.world_size, self.width, self.height)
        d = np.hypot(*(tf.to_px(pos) - _pixel(px)).T)
        row = int(np.argmin(d))
        return int(snapshot.ids[row]) if d[row] <= reach else None

    def draw_note(self, target, text: str) -> None:
        """Draw a one-line note on `target` just above the field caption (the key help).

        Kept off `self.surface` so recorded frames do not carry the viewer's chrome.
        """
        self._overlay.note(target, text)


def _pixel(px) -> np.ndarray:
    """A pixel `(x, y)` as two floats, or a SwarmOptionError naming `px`."""
    try:
        return np.asarray(px, dtype=np.float64).reshape(2)
    except (TypeError, ValueError):
        raise SwarmOptionError(f"px must be a pixel (x, y), got {px!r}") from None


def _points(value, label: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.size == 0:
        return arr.reshape(0, 2)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise SwarmError(f"snapshot {label} has shape {arr.shape}, expected (N, 2)")
    return arr
