"""Recording rendered frames to GIF (imageio + Pillow) or MP4 (imageio-ffmpeg).

The writer is a context manager that always finalises its file, also while an exception
is propagating, so a run stopped by a runtime fault, Ctrl+C or SIGTERM still leaves a
playable file holding every frame added so far. The file is written under a hidden
temporary name beside the target and renamed into place only once the encoder has
finished it: a video at the target path is always complete, and one that could not be
finished is removed and not claimed (`complete` is False, `error` says why). Missing
folders on the path are created, as `--out` creates its folder. MP4 frames go to ffmpeg as
they arrive; GIF frames are kept until `close()` because Pillow writes an animated GIF
in one go, so prefer MP4 for long runs.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from swarmdsl.compiler.errors import SwarmOptionError
from swarmdsl.viz import require_imageio, require_imageio_ffmpeg

EXTENSIONS = (".gif", ".mp4")
_MACRO_BLOCK = 16


class VideoWriter:
    """Append `(H, W, 3)` uint8 frames to a `.gif` or `.mp4` file.

    Every frame must have the size of the first. MP4 needs sides that are multiples of
    16; other sizes are padded with black at the right and bottom (size frames with
    `fit_size` to avoid that).

    Args:
        path: output file; its extension picks the format.
        fps: playback frames per second.

    Raises:
        SwarmOptionError: the extension is not one of `EXTENSIONS` (names `--record`).
    """

    def __init__(self, path: str | Path, *, fps: float = 30.0):
        self.path = Path(path)
        self.format = self.path.suffix.lower()
        if self.format not in EXTENSIONS:
            raise SwarmOptionError(
                f"--record: cannot record to '{self.path.name}': unknown extension "
                f"'{self.path.suffix}'; use one of " + ", ".join(EXTENSIONS))
        if not fps > 0:
            raise SwarmOptionError(f"--record: frames per second must be positive, got {fps}")
        self.fps = float(fps)
        # ffmpeg and Pillow pick the format from the name's extension: keep it last.
        self.tmp = self.path.with_name(f".{self.path.stem}.partial{self.path.suffix}")
        self.complete = False           # True once the file is finished and in place
        self.error: str | None = None   # why it was not, once closed
        self.frames_written = 0
        self._shape: tuple[int, ...] | None = None
        self._gif_frames: list[np.ndarray] = []
        self._ffmpeg = None
        self._closed = False
        # Import now so a missing extra is reported before the run starts, not at frame 1.
        if self.format == ".gif":
            require_imageio()
        else:
            require_imageio_ffmpeg()

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()

    def add(self, frame: np.ndarray) -> None:
        """Append one frame; `(H, W, 3)` uint8, the same size as the first frame."""
        if self._closed:
            raise ValueError("VideoWriter is closed")
        frame = np.asarray(frame)
        if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype != np.uint8:
            raise ValueError(f"frame must be (H, W, 3) uint8, got {frame.shape} {frame.dtype}")
        if self._shape is None:
            self._shape = frame.shape
        elif frame.shape != self._shape:
            raise ValueError(f"frame size changed from {self._shape} to {frame.shape}")
        if self.format == ".gif":
            self._gif_frames.append(frame.copy())
        else:
            self._send_mp4(frame)
        self.frames_written += 1

    def close(self) -> None:
        """Finalise the file. Safe to call twice, and from `finally` with no frames."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._finish():
                os.replace(self.tmp, self.path)
                self.complete = True
            else:
                self.error = "no frames were recorded"
        except (OSError, RuntimeError, ValueError) as exc:
            # the encoder died (killed with the job) or the disk refused: claim nothing
            self.error = (getattr(exc, "strerror", None) or str(exc)
                          or type(exc).__name__).lower()
        if not self.complete:
            self.tmp.unlink(missing_ok=True)

    def _finish(self) -> bool:
        if self.format == ".gif":
            frames, self._gif_frames = self._gif_frames, []
            if not frames:
                return False
            iio = require_imageio()
            self.tmp.parent.mkdir(parents=True, exist_ok=True)
            duration_ms = max(10, int(round(1000.0 / self.fps)))
            with iio.imopen(self.tmp, "w", plugin="pillow", extension=".gif") as out:
                while frames:
                    out.write(frames.pop(0), duration=duration_ms, loop=0)
            return True
        if self._ffmpeg is None:
            return False
        gen, self._ffmpeg = self._ffmpeg, None
        gen.close()          # ffmpeg flushes and writes the index; the file is playable
        return self.tmp.exists()

    def _send_mp4(self, frame: np.ndarray) -> None:
        h, w = frame.shape[:2]
        ph = -h % _MACRO_BLOCK
        pw = -w % _MACRO_BLOCK
        if ph or pw:
            frame = np.pad(frame, ((0, ph), (0, pw), (0, 0)))
        if self._ffmpeg is None:
            ffmpeg = require_imageio_ffmpeg()
            self.path.parent.mkdir(parents=True, exist_ok=True)
            gen = ffmpeg.write_frames(
                str(self.tmp), (w + pw, h + ph), fps=self.fps, codec="libx264",
                pix_fmt_in="rgb24", pix_fmt_out="yuv420p", quality=7,
                macro_block_size=_MACRO_BLOCK, ffmpeg_log_level="error")
            gen.send(None)
            self._ffmpeg = gen
        self._ffmpeg.send(np.ascontiguousarray(frame))
