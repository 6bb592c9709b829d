"""What watches a `Run` besides its recorder and metrics: observers, and the two the
viz package plugs in (the `--record` video and the viewer's window).

An observer is told when the run's outputs open (`start`), at every recorded tick
(`tick`, after the metrics and rows of that tick) and when the run ends (`close`, with
its outcome), by the run's `Driver` (`runtime/driver.py`, the one tick loop: the
batch's recorders, the tester's property monitor and the studio's plots are observers
of it too); a command or a script attaches its own with `Run.attach`. The runtime
never imports `viz/` (it sits above the runtime: it draws what the runtime computes):
`VIZ` names the viz package's plug-in module as data, imported the first time a run
asks for a video or a window, and that module registers both here (`register`).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

# The viz package's plug-in module, by name: imported on a run's first video or window.
VIZ = "swarmdsl.viz.run_observers"

_REGISTERED: dict[str, Callable] = {}


class Observer(Protocol):
    """Something that watches a run: a video, a stream, a plot."""

    def start(self, run: Any) -> None:
        """The run's outputs opened: its first tick follows."""

    def tick(self, run: Any) -> None:
        """`run.sim` is at a recorded tick."""

    def close(self, run: Any, outcome: str) -> None:
        """The run ended ("completed", "quit", "interrupted", "fault", ...)."""


def register(*, video: Callable[[Path, float, int], Observer],
             window: Callable[[Any, float, str], str]) -> None:
    """The viz package's video observer (`video(path, fps, px)`) and window (`window(run,
    fps, title)`, which drives the run and returns "done" or "quit")."""
    _REGISTERED.update(video=video, window=window)


def _viz(name: str) -> Callable:
    if name not in _REGISTERED:
        importlib.import_module(VIZ)
    return _REGISTERED[name]


def video(path: Path, fps: float, px: int) -> Observer:
    """An observer writing every recorded tick as a frame of the GIF or MP4 at `path`
    (at most `px` pixels on a side); after `close`, `complete` says whether the file
    was finished and moved into place, `error` why not."""
    return _viz("video")(path, fps, px)


def window(run, fps: float, title: str) -> str:
    """Run `run` in the viewer's window: "done" when it reached its last tick, "quit"
    when the window closed first."""
    return _viz("window")(run, fps, title)
