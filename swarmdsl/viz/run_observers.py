"""The viz package's plug-ins to a run (`runtime/observers.py`): the `--record` video as
an observer of the recorded ticks, and the viewer's window, which drives the run.

Imported by name by the runtime the first time a run asks for either, so a headless
run without `--record` never loads the viz package.
"""

from __future__ import annotations

from pathlib import Path

from swarmdsl.runtime import observers


class VideoObserver:
    """Each recorded tick as a frame of a GIF or MP4 (`VideoWriter`)."""

    def __init__(self, path: Path, fps: float, px: int):
        self.path, self.fps, self.px = path, fps, px
        self.renderer = self.writer = None
        self.complete = False       # the video was finished and moved into place
        self.error: str | None = None

    def start(self, run) -> None:
        from swarmdsl.viz import FrameRenderer, VideoWriter, fit_size

        self.renderer = FrameRenderer(*fit_size(run.sim.snapshot().world_size, self.px))
        self.writer = VideoWriter(self.path, fps=self.fps)

    def tick(self, run) -> None:
        if self.writer is not None:
            self.writer.add(self.renderer.render(run.sim.snapshot()))

    def close(self, run, outcome: str) -> None:
        if self.writer is None:
            return
        self.writer.close()
        self.complete, self.error = self.writer.complete, self.writer.error
        self.writer = None


def window(run, fps: float, title: str) -> str:
    """The viewer's window driving `run` (`viewer.run_viewer`)."""
    from swarmdsl.viz import run_viewer

    return run_viewer(run, fps=fps, title=title)


observers.register(video=VideoObserver, window=window)
