"""Text drawn over the world: the status legend, tick counter, captions and key help.

Split from the frame renderer so pixel drawing and text layout change independently;
rendered text is cached because the same strings repeat frame after frame.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from swarmdsl.runtime.snapshot import Snapshot
from swarmdsl.viz.palette import TEXT, leaf_legend_entries, legend_entries

_LEGEND_ROWS = 24
_PAD, _GAP = 4, 2          # a panel's padding and the space between its rows
_MARGIN = 4                # between a panel and the frame's edge
# Where the legend may go, in order of preference: it starts top left and moves to the
# corner that hides the fewest agents (a swarm gathered top left was hidden under it).
CORNERS = ("top-left", "bottom-right", "top-right", "bottom-left")
_MARKER_REACH = 6          # pixels of a marker around its agent's position


class Overlay:
    """Lays out and draws text panels on a surface of a fixed size."""

    def __init__(self, pg: Any, font_px: int, width: int, height: int):
        self._pg = pg
        self._font = pg.font.Font(None, font_px)
        self._cache: dict[tuple, Any] = {}
        self.width, self.height = width, height
        self.legend_corner = CORNERS[0]

    def place_legend(self, snap: Snapshot, opts, field: str | None,
                     agents_px: np.ndarray) -> str:
        """Move the legend off the agents: to the corner whose box covers the fewest
        of `agents_px` (pixel positions, `(N, 2)`). It moves only when that halves the
        agents it hides (or frees them all), so it does not flicker between corners
        as a swarm mills about; returns the corner."""
        rows = self._legend_rows(snap, opts)
        if rows is None or not len(agents_px):
            return self.legend_corner
        hidden = {corner: self._covered(self._box(rows, *self._legend_place(
            corner, rows, snap, opts, field)), agents_px) for corner in CORNERS}
        best = min(CORNERS, key=lambda c: (hidden[c], CORNERS.index(c)))
        now = hidden[self.legend_corner]
        if now and (hidden[best] == 0 or 2 * hidden[best] <= now):
            self.legend_corner = best
        return self.legend_corner

    @staticmethod
    def _covered(box: tuple[int, int, int, int], px: np.ndarray) -> int:
        x, y, w, h = box
        r = _MARKER_REACH
        inside = ((px[:, 0] >= x - r) & (px[:, 0] < x + w + r)
                  & (px[:, 1] >= y - r) & (px[:, 1] < y + h + r))
        return int(np.count_nonzero(inside))

    def text(self, text: str, colour=TEXT, background=None):
        """The rendered text as a surface, cached by content and colours."""
        key = (text, tuple(colour), background)
        surf = self._cache.get(key)
        if surf is None:
            if len(self._cache) > 512:
                self._cache.clear()
            surf = self._font.render(text, True, colour, background)
            self._cache[key] = surf
        return surf

    def note(self, target, text: str) -> None:
        """One line just above the field caption, at the bottom left."""
        box_h = self._font.get_linesize() + 8
        self.panel(target, [[self.text(text)]], 4, self.height - 4 - 2 * box_h - 2)

    def panel(self, target, lines: list, x: int, y: int, align_right: bool = False
              ) -> tuple[int, int, int, int]:
        """Draw text rows (each a list of text surfaces and colour swatches) on a dark box.

        Returns the box as `(x, y, w, h)`.
        """
        pg = self._pg
        x, y, w, h = self._box(lines, x, y, align_right)
        box = pg.Surface((w, h), pg.SRCALPHA)
        box.fill((0, 0, 0, 170))
        target.blit(box, (x, y))
        line_h = self._font.get_linesize()
        cy = y + _PAD
        for row in lines:
            cx = x + _PAD
            for part in row:
                if isinstance(part, tuple):
                    s = line_h - 4
                    pg.draw.rect(target, part, pg.Rect(cx, cy + 2, s, s))
                    cx += s + 4
                else:
                    target.blit(part, (cx, cy))
                    cx += part.get_width() + 4
            cy += line_h + _GAP
        return x, y, w, h

    def _box(self, lines: list, x: int, y: int, align_right: bool
             ) -> tuple[int, int, int, int]:
        """Where `panel` puts its box, as `(x, y, w, h)`, without drawing it."""
        line_h = self._font.get_linesize()
        widths = [sum(part.get_width() if not isinstance(part, tuple) else line_h - 4
                      for part in row) + 4 * (len(row) - 1) for row in lines]
        w = max(widths, default=0) + 2 * _PAD
        h = len(lines) * (line_h + _GAP) + 2 * _PAD - _GAP
        return (x - w if align_right else x), y, w, h

    def boxes(self, snap: Snapshot, opts, field: str | None
              ) -> list[tuple[int, int, int, int]]:
        """The boxes `draw` will cover, as `(x, y, w, h)`: what is drawn before the
        text (region labels) keeps clear of them rather than end up under them."""
        return [self._box(rows, x, y, right) for _legend, rows, x, y, right
                in self._panels(snap, opts, field)]

    def draw(self, target, snap: Snapshot, opts, field: str | None
             ) -> tuple[int, int, int, int] | None:
        """Legend (top left), tick (top right), field caption and HUD line (bottom left).

        Returns the legend's box, or None when no legend was drawn.
        """
        legend_rect = None
        for legend, rows, x, y, right in self._panels(snap, opts, field):
            box = self.panel(target, rows, x, y, align_right=right)
            if legend:
                legend_rect = box
        return legend_rect

    def _panels(self, snap: Snapshot, opts, field: str | None) -> list[tuple]:
        """Each panel as `(is_legend, rows, x, y, align_right)`, laid out once for
        both `boxes` and `draw`, so the boxes kept clear are the ones drawn."""
        panels: list[tuple] = []
        rows = self._legend_rows(snap, opts)
        if rows is not None:
            x, y, right = self._legend_place(self.legend_corner, rows, snap, opts, field)
            panels.append((True, rows, x, y, right))
        tick = self._tick_rows(snap, opts)
        if tick is not None:
            panels.append((False, tick, self.width - _MARGIN, _MARGIN, True))
        bottom = self._bottom_rows(opts, field)
        if bottom is not None:
            panels.append((False, bottom, _MARGIN, self._bottom_top(bottom), False))
        return panels

    def _legend_rows(self, snap: Snapshot, opts) -> list | None:
        if not (opts.show_legend and snap.status_names):
            return None
        by_leaf = opts.by_tree_leaf and snap.tree_leaf is not None
        entries = leaf_legend_entries(snap) if by_leaf else legend_entries(snap)
        rows = [[colour, self.text(f"{name}  {count}")]
                for name, count, colour in entries[:_LEGEND_ROWS]]
        if len(entries) > _LEGEND_ROWS:
            rows.append([self.text(f"... {len(entries) - _LEGEND_ROWS} more")])
        if opts.use_led and snap.led is not None:
            rows.append([self.text("agents coloured by LED")])
        return rows

    def _tick_rows(self, snap: Snapshot, opts) -> list | None:
        return [[self.text(f"tick {snap.tick}")]] if opts.show_tick else None

    def _bottom_rows(self, opts, field: str | None) -> list | None:
        bottom = []
        if field is not None:
            bottom.append([self.text(f"field {field} ({opts.colormap}, per-frame scale)")])
        if opts.hud_text:
            bottom.append([self.text(opts.hud_text)])
        return bottom or None

    def _bottom_top(self, bottom: list) -> int:
        line_h = self._font.get_linesize() + 2
        return self.height - _MARGIN - len(bottom) * line_h - 6

    def _legend_place(self, corner: str, rows: list, snap: Snapshot, opts,
                      field: str | None) -> tuple[int, int, bool]:
        """The legend's `(x, y, align_right)` in `corner`, clear of the tick counter
        (top right) and the captions (bottom left)."""
        _x, _y, _w, h = self._box(rows, 0, 0, False)
        right = corner.endswith("right")
        x = self.width - _MARGIN if right else _MARGIN
        if corner == "top-left":
            return x, _MARGIN, right
        if corner == "top-right":
            tick = self._tick_rows(snap, opts)
            below = _MARGIN
            if tick is not None:
                below += self._box(tick, 0, 0, False)[3] + _MARGIN
            return x, below, right
        floor = self.height - _MARGIN
        if corner == "bottom-left":
            bottom = self._bottom_rows(opts, field)
            if bottom is not None:
                floor = self._bottom_top(bottom) - _MARGIN
        return x, floor - h, right
