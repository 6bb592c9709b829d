"""The live pygame window: steps a driver, draws each frame, answers the keyboard.

The viewer owns no simulation state. It asks a *driver* (anything with `step()`,
`snapshot()`, `tick` and `done`) to advance and draws what `snapshot()` returns, so the
same loop serves the real runtime and the fake driver in the tests. Keys change only
`RenderOptions` and the pace; see `docs/viewer.md`.
"""

from __future__ import annotations

import math
import numbers
import os
import sys
from dataclasses import replace
from typing import Any, Protocol

import numpy as np

from swarmdsl.errors import SwarmError, SwarmOptionError
from swarmdsl.runtime.arguments import real, text
from swarmdsl.runtime.snapshot import Snapshot
from swarmdsl.viz import require_pygame
from swarmdsl.viz.frames import FrameRenderer, RenderOptions, checked_options, fit_size

_MIN_SPEED = 1.0 / 16.0      # one tick every 16 frames
_MAX_SPEED = 1024.0          # ticks per frame
KEYS_HELP = ("space pause  . step  +/- speed  f field  tab next  l links  b belief  t leaf  "
             "q quit")


class Driver(Protocol):
    """What the viewer needs from a running simulation: a `Run` (whose `step` is its
    `runtime.driver.Driver`'s, so a windowed run stops and records as a headless one)."""

    tick: int
    done: bool

    def step(self) -> None: ...

    def snapshot(self) -> Snapshot: ...


class Recorder(Protocol):
    """Anything that takes rendered `(H, W, 3)` frames, such as `VideoWriter`."""

    def add(self, frame: Any) -> None: ...


def display_available() -> bool:
    """Whether a real window can open: pygame present and a non-dummy video driver works.

    The CLI calls this to decide between the window and "no display, running headless".
    """
    try:
        pg = require_pygame()
    except SwarmError:
        return False
    if os.environ.get("SDL_VIDEODRIVER", "").strip().lower() in ("dummy", "offscreen"):
        return False
    if sys.platform.startswith("linux") and not (
            os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return False
    was_init = pg.display.get_init()
    try:
        pg.display.init()
        name = pg.display.get_driver()
    except pg.error:
        return False
    finally:
        if not was_init:
            pg.display.quit()
    return name not in ("dummy", "offscreen")


class ViewState:
    """Pause, pace and drawing toggles, changed by key presses.

    Kept apart from the loop so key handling is testable without a window.
    """

    def __init__(self, options: RenderOptions | None = None, ticks_per_frame: float = 1.0):
        self.options = options or RenderOptions()
        self.paused = False
        speed = real("ticks_per_frame", ticks_per_frame, 0.0, math.inf)   # NaN: refused
        self.speed = min(max(speed, _MIN_SPEED), _MAX_SPEED)
        self._owed = 0.0
        self.field_names: list[str] = []
        self.click: tuple[int, int] | None = None   # a pixel clicked, not yet resolved
        self.selected: int | None = None            # the id of the agent followed

    def handle(self, pg: Any, event: Any) -> str | None:
        """Apply one pygame event; return "quit", "step" or None."""
        if event.type == pg.QUIT:
            return "quit"
        if event.type == pg.MOUSEBUTTONDOWN:
            self.click = tuple(event.pos)
            return None
        if event.type != pg.KEYDOWN:
            return None
        key, char = event.key, getattr(event, "unicode", "") or ""
        opts = self.options
        if key in (pg.K_q, pg.K_ESCAPE):
            return "quit"
        if key == pg.K_SPACE:
            self.paused = not self.paused
            self._owed = 0.0
        elif key in (pg.K_PERIOD, pg.K_RIGHT, pg.K_KP_PERIOD) or char == ".":
            return "step" if self.paused else None
        elif key in (pg.K_PLUS, pg.K_EQUALS, pg.K_KP_PLUS) or char in ("+", "="):
            self.speed = min(self.speed * 2.0, _MAX_SPEED)
        elif key in (pg.K_MINUS, pg.K_KP_MINUS, pg.K_UNDERSCORE) or char in ("-", "_"):
            self.speed = max(self.speed / 2.0, _MIN_SPEED)
        elif key == pg.K_f:
            opts.show_field = not opts.show_field
        elif key == pg.K_TAB:
            self._next_field()
        elif key == pg.K_l:
            opts.show_links = not opts.show_links
        elif key == pg.K_b:
            opts.show_believed = not opts.show_believed
        elif key == pg.K_t:
            opts.by_tree_leaf = not opts.by_tree_leaf
        elif key == pg.K_g:
            opts.show_grid_points = not opts.show_grid_points
        elif key == pg.K_v:
            opts.show_vectors = not opts.show_vectors
        return None

    def ticks_due(self) -> int:
        """Ticks to run this frame; fractional speeds accumulate across frames."""
        if self.paused:
            return 0
        self._owed += self.speed
        n = int(self._owed)
        self._owed -= n
        return n

    def sync_fields(self, snapshot: Snapshot) -> None:
        """Track the snapshot's field names so `tab` can cycle through them."""
        self.field_names = list(snapshot.fields)
        if self.options.field is not None and self.options.field not in snapshot.fields:
            self.options.field = None

    def hud(self, done: bool) -> str:
        if done:
            state = "finished"
        elif self.paused:
            state = "paused"
        else:
            state = "running"
        if self.speed == 1:
            pace = "1 tick/frame"
        elif self.speed > 1:
            pace = f"{self.speed:g} ticks/frame"
        else:
            pace = f"1 tick/{round(1 / self.speed)} frames"
        return f"{state}  {pace}   {KEYS_HELP}"

    def selection_note(self, snapshot: Snapshot) -> str:
        """The selected agent's id, status and running path (when leaves are tracked)."""
        if self.selected is None:
            return ""
        rows = np.flatnonzero(np.asarray(snapshot.ids) == self.selected)
        if not rows.size:
            return f"agent {self.selected}: gone"
        row = int(rows[0])
        text = f"agent {self.selected} ({snapshot.status_names[int(snapshot.status[row])]})"
        if snapshot.tree_leaf is not None:
            leaf = int(snapshot.tree_leaf[row])
            text += ": " + (snapshot.tree_leaf_paths[leaf] if leaf else "no active leaf")
        return text

    def _next_field(self) -> None:
        if not self.field_names:
            return
        current = self.options.field or self.field_names[0]
        i = self.field_names.index(current) if current in self.field_names else -1
        self.options.field = self.field_names[(i + 1) % len(self.field_names)]
        self.options.show_field = True


def _check_arguments(driver, fps, title, recorder) -> None:
    """Refuse what would fail once the window is open, as a TypeError from pygame or an
    AttributeError from the loop, with a SwarmOptionError naming the argument."""
    missing = [name for name in ("step", "snapshot", "tick", "done")
               if not hasattr(driver, name)]
    if missing:
        raise SwarmOptionError(f"the viewer's driver needs step(), snapshot(), tick and "
                               f"done; {type(driver).__name__} has no {', '.join(missing)}",
                               hint="to watch a program, run "
                                    "Run(program, steps=N).execute(headless=False)")
    if isinstance(fps, bool) or not isinstance(fps, numbers.Real) or not fps > 0:
        raise SwarmOptionError(f"--fps must be positive, got {fps!r}")
    text("title", title)
    if recorder is not None and not callable(getattr(recorder, "add", None)):
        raise SwarmOptionError(f"recorder must have add(frame), as a VideoWriter does; "
                               f"got {type(recorder).__name__}")


def run_viewer(driver: Driver, *, fps: float = 30, title: str = "swarmdsl",
               max_px: int = 800, options: RenderOptions | None = None,
               ticks_per_frame: float = 1.0, recorder: Recorder | None = None,
               hold_at_end: bool = False) -> str:
    """Open a window and run `driver` until it is done or the user quits.

    Args:
        driver: advances the simulation (`step`, `snapshot`, `tick`, `done`).
        fps: frames drawn per second at most.
        title: window caption.
        max_px: the window's longer side in pixels (the world's aspect is kept).
        options: initial drawing options; the keys change a copy of them.
        ticks_per_frame: initial pace; `+`/`-` double and halve it.
        recorder: if given, each drawn frame showing a new tick is added to it (e.g. a
            `VideoWriter`); pausing or holding does not fill it with repeats.
        hold_at_end: keep showing the last frame after the run ends, until the user quits.

    Returns:
        "done" when the driver finished, "quit" when the user closed the window first.

    Raises:
        Whatever `driver.step()` raises, after the window is closed.
    """
    _check_arguments(driver, fps, title, recorder)
    options = replace(checked_options(options))     # the keys change a copy
    pg = require_pygame()
    state = ViewState(options, ticks_per_frame)
    snap = driver.snapshot()
    width, height = fit_size(snap.world_size, max_px)
    pg.display.init()
    try:
        screen = pg.display.set_mode((width, height))
        pg.display.set_caption(title)
        renderer = FrameRenderer(width, height)
        clock = pg.time.Clock()
        recorded_tick = None
        while True:
            for event in pg.event.get():
                action = state.handle(pg, event)
                if action == "quit":
                    return "done" if driver.done else "quit"
                if action == "step" and not driver.done:
                    driver.step()
            snap = driver.snapshot()
            state.sync_fields(snap)
            if state.click is not None:     # a click picks the agent under it, or none
                state.selected = renderer.agent_at(snap, state.click)
                state.click = None
            screen.blit(renderer.draw(snap, state.options), (0, 0))
            if recorder is not None and driver.tick != recorded_tick:
                recorder.add(renderer.array())      # one frame per tick shown, no repeats
                recorded_tick = driver.tick
            note = state.selection_note(snap)
            renderer.draw_note(screen, state.hud(driver.done) + (f"   {note}" if note else ""))
            pg.display.flip()
            if driver.done and not hold_at_end:
                return "done"
            clock.tick(fps)
            for _ in range(state.ticks_due()):
                if driver.done:
                    break
                driver.step()
    finally:
        pg.display.quit()
