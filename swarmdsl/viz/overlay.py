"""Text drawn over the world: the status legend, tick counter, captions and key help.

Split from the frame renderer so pixel drawing and text layout change independently;
rendered text is cached because the same strings repeat frame after frame.
"""

from __future__ import annotations

from typing import Any

from swarmdsl.runtime.snapshot import Snapshot
from swarmdsl.viz.palette import TEXT, leaf_legend_entries, legend_entries

_LEGEND_ROWS = 24
_PAD, _GAP = 4, 2          # a panel's padding and the space between its rows


class Overlay:
    """Lays out and draws text panels on a surface of a fixed size."""

    def __init__(self, pg: Any, font_px: int, width: int, height: int):
        self._pg = pg
        self._font = pg.font.Font(None, font_px)
        self._cache: dict[tuple, Any] = {}
        self.width, self.height = width, height

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
        margin = 4
        panels: list[tuple] = []
        if opts.show_legend and snap.status_names:
            by_leaf = opts.by_tree_leaf and snap.tree_leaf is not None
            entries = leaf_legend_entries(snap) if by_leaf else legend_entries(snap)
            rows = [[colour, self.text(f"{name}  {count}")]
                    for name, count, colour in entries[:_LEGEND_ROWS]]
            if len(entries) > _LEGEND_ROWS:
                rows.append([self.text(f"... {len(entries) - _LEGEND_ROWS} more")])
            if opts.use_led and snap.led is not None:
                rows.append([self.text("agents coloured by LED")])
            panels.append((True, rows, margin, margin, False))
        if opts.show_tick:
            panels.append((False, [[self.text(f"tick {snap.tick}")]], self.width - margin,
                           margin, True))
        bottom = []
        if field is not None:
            bottom.append([self.text(f"field {field} ({opts.colormap}, per-frame scale)")])
        if opts.hud_text:
            bottom.append([self.text(opts.hud_text)])
        if bottom:
            line_h = self._font.get_linesize() + 2
            panels.append((False, bottom, margin,
                           self.height - margin - len(bottom) * line_h - 6, False))
        return panels
