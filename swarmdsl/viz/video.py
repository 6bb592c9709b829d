"""Recording rendered frames to GIF (Pillow) or MP4 (imageio-ffmpeg).

The writer is a context manager that always finalises its file, also while an exception
is propagating, so a run stopped by a runtime fault, Ctrl+C or SIGTERM still leaves a
playable file holding every frame added so far. The file is written under a hidden
temporary name beside the target and renamed into place only once the encoder has
finished it: a video at the target path is always complete, and one that could not be
finished is removed and not claimed (`complete` is False, `error` says why). Missing
folders on the path are created, as `--out` creates its folder.

Both formats are written as frames arrive, so finishing a file takes no longer after
an hour than after a minute, and memory holds one frame. MP4 frames go to ffmpeg. GIF
frames are encoded here with Pillow's GIF encoder (`_GifStream`): imageio's Pillow
plugin, like Pillow's own animated-GIF writer, keeps every frame until the file
closes and only then quantises them all (10-30 ms a frame: stopping a run that had
recorded 5,000 frames took 110 s, with 7.7 GB of frames in memory meanwhile).
A write that fails while the run goes (a full disk, ffmpeg killed) drops the video,
not the run: later frames are ignored and `close` claims nothing, saying why.
"""

from __future__ import annotations

import numbers
import os
import struct
from pathlib import Path

import numpy as np

from swarmdsl.errors import SwarmOptionError
from swarmdsl.viz import require_imageio_ffmpeg, require_pillow

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
        from swarmdsl.runtime.arguments import required_path
        from swarmdsl.runtime.outputs import check_file

        self.path = required_path("--record", path, "give a .gif or .mp4 file")
        self.format = self.path.suffix.lower()
        if self.format not in EXTENSIONS:
            raise SwarmOptionError(
                f"--record: cannot record to '{self.path.name}': unknown extension "
                f"'{self.path.suffix}'; use one of " + ", ".join(EXTENSIONS))
        if isinstance(fps, bool) or not isinstance(fps, numbers.Real) or not fps > 0:
            raise SwarmOptionError(f"--record: frames per second must be positive, "
                                   f"got {fps!r}")
        self.fps = float(fps)
        # a path under a file, or in a folder that cannot be written: refused now, not
        # lost silently at the first frame (`Run(record=)` checks this too)
        check_file(self.path, "--record", example="run.mp4")
        # ffmpeg and Pillow pick the format from the name's extension: keep it last.
        self.tmp = self.path.with_name(f".{self.path.stem}.partial{self.path.suffix}")
        self.complete = False           # True once the file is finished and in place
        self.error: str | None = None   # why it was not, once closed
        self.frames_written = 0
        self._shape: tuple[int, ...] | None = None
        self._gif: _GifStream | None = None
        self._ffmpeg = None
        self._closed = False
        # Import now so a missing extra is reported before the run starts, not at frame 1.
        if self.format == ".gif":
            require_pillow()
        else:
            require_imageio_ffmpeg()

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()

    def add(self, frame: np.ndarray) -> None:
        """Append one frame; `(H, W, 3)` uint8, the same size as the first frame."""
        if self._closed:
            raise SwarmOptionError(f"--record {self.path}: the VideoWriter is closed; "
                                   "add frames inside its `with` block")
        frame = np.asarray(frame)
        if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype != np.uint8 \
                or not frame.size:      # an empty frame: Pillow's ValueError
            raise SwarmOptionError(f"frame must be (H, W, 3) uint8, got {frame.shape} "
                                   f"{frame.dtype}")
        if self._shape is None:
            self._shape = frame.shape
        elif frame.shape != self._shape:
            raise SwarmOptionError(f"frame size changed from {self._shape} to "
                                   f"{frame.shape}")
        if self.error is not None:      # the file is lost already: the run goes on
            return
        try:
            if self.format == ".gif":
                self._send_gif(frame)
            else:
                self._send_mp4(frame)
        except OSError as exc:
            # The disk filled up, or ffmpeg died with the job: the run and its other
            # outputs go on, and `close` claims no video, as when finishing fails.
            self.error = _reason(exc)
            return
        self.frames_written += 1

    def close(self) -> None:
        """Finalise the file. Safe to call twice, and from `finally` with no frames."""
        if self._closed:
            return
        self._closed = True
        try:
            if self.error is None:
                if self._finish():
                    os.replace(self.tmp, self.path)
                    self.complete = True
                else:
                    self.error = "no frames were recorded"
        except (OSError, RuntimeError, ValueError) as exc:
            # the encoder died (killed with the job) or the disk refused: claim nothing
            self.error = _reason(exc)
        if not self.complete:
            self._abandon()
            self.tmp.unlink(missing_ok=True)

    def _abandon(self) -> None:
        """Let go of the encoder without finishing its file (which is then removed)."""
        if self._gif is not None:
            self._gif.abandon()
        if self._ffmpeg is not None:
            try:
                self._ffmpeg.close()
            except (OSError, RuntimeError, ValueError):
                pass            # ffmpeg died already: nothing is left to stop

    def _finish(self) -> bool:
        if self.format == ".gif":
            if self._gif is None:
                return False
            self._gif.close()
            return True
        if self._ffmpeg is None:
            return False
        gen, self._ffmpeg = self._ffmpeg, None
        gen.close()          # ffmpeg flushes and writes the index; the file is playable
        return self.tmp.exists()

    def _send_gif(self, frame: np.ndarray) -> None:
        if self._gif is None:
            self.tmp.parent.mkdir(parents=True, exist_ok=True)
            # Pillow's delay, as its own writer sets it: whole hundredths, at least one
            self._gif = _GifStream(self.tmp, max(10, int(round(1000.0 / self.fps))))
        self._gif.add(frame)

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


def _reason(exc: BaseException) -> str:
    return (getattr(exc, "strerror", None) or str(exc) or type(exc).__name__).lower()


class _GifStream:
    """An animated GIF (looping, no global colour table) written frame by frame.

    Each frame after the first is the rectangle around the pixels that changed since
    the one before, with its own colour table; inside it, unchanged pixels are the
    transparent colour, so they show the previous frame as it is and cost next to
    nothing to compress (Pillow's writer lays frames out the same way). The changed
    pixels keep their exact colours when there are at most 255 (256 without a
    transparent one): rendered frames mostly have that few, flat colours and heatmap
    shades. Otherwise Pillow's median cut picks the colours, the quantiser Pillow's
    writer applies to whole frames, here spent on the changed pixels only. Every frame
    added is a frame of the file, identical ones too.
    """

    def __init__(self, path: Path, duration_ms: int):
        self._image = require_pillow()
        from PIL import GifImagePlugin

        self._frame_bytes = GifImagePlugin.getdata  # descriptor, colour table, LZW data
        self.duration_ms = duration_ms
        self.prev: np.ndarray | None = None     # the last frame, packed (`_packed`)
        self._lut: np.ndarray | None = None     # packed RGB -> palette index, reused
        self.fh = open(path, "wb")     # held open until close() or abandon()

    def add(self, frame: np.ndarray) -> None:
        h, w = frame.shape[:2]
        packed = _packed(frame)
        parts = []
        if self.prev is None:
            # GIF89a, logical screen w x h with no global colour table, loop forever
            parts.append(b"GIF89a" + struct.pack("<HHBBB", w, h, 0, 0, 0)
                         + b"!\xff\x0bNETSCAPE2.0\x03\x01\x00\x00\x00")
            box, changed = (0, 0, w, h), np.ones((h, w), bool)
        else:
            changed = packed != self.prev
            box = _box(changed) or (0, 0, 1, 1)     # an unchanged frame: one clear pixel
        x0, y0, x1, y1 = box
        changed = changed[y0:y1, x0:x1]
        new = np.ascontiguousarray(frame[y0:y1, x0:x1][changed])      # (M, 3)
        clear = not changed.all()
        index, palette = self._indices(new, packed[y0:y1, x0:x1][changed],
                                       256 - clear)
        extra: dict = {}
        if clear:           # the first index no changed pixel uses is left free for it
            extra["transparency"] = len(palette) // 3
            palette += b"\0\0\0"
        indices = np.full(changed.shape, extra.get("transparency", 0), np.uint8)
        indices[changed] = index
        image = self._image.frombytes("P", (x1 - x0, y1 - y0), indices.tobytes())
        image.putpalette(palette)
        parts += self._frame_bytes(image, offset=(x0, y0), disposal=1,
                                   duration=self.duration_ms, include_color_table=True,
                                   **extra)
        self.fh.writelines(parts)   # in one call: a stop cuts no frame in half
        self.prev = packed

    def _indices(self, rgb: np.ndarray, packed: np.ndarray, limit: int
                 ) -> tuple[np.ndarray, bytes]:
        """Palette indices of the `(M, 3)` colours `rgb` and the palette (RGB bytes, at
        most `limit` colours): exact when they have at most `limit` colours."""
        Image = self._image
        if not len(rgb):
            return np.zeros(0, np.uint8), b""
        pixels = Image.fromarray(rgb.reshape(1, -1, 3))
        colours = pixels.getcolors(limit)
        if colours is None:
            quantised = pixels.quantize(limit, method=Image.Quantize.MEDIANCUT)
            used = max(quantised.getextrema()[1] + 1, 1)
            return (np.asarray(quantised).reshape(-1),
                    bytes(quantised.getpalette()[:3 * used]))
        palette = np.array([c for _n, c in colours], np.uint32).reshape(-1, 3)
        if self._lut is None:
            self._lut = np.zeros(1 << 24, np.uint8)     # pages fill as colours appear
        self._lut[_packed(palette)] = np.arange(len(palette))
        return self._lut[packed], palette.astype(np.uint8).tobytes()

    def close(self) -> None:
        try:
            self.fh.write(b";")     # the trailer: the file is whole from here
        finally:
            self.fh.close()

    def abandon(self) -> None:
        self.fh.close()


def _packed(rgb: np.ndarray) -> np.ndarray:
    """`(..., 3)` colours as one integer each, `0xRRGGBB`."""
    c = rgb.astype(np.uint32)
    return (c[..., 0] << 16) | (c[..., 1] << 8) | c[..., 2]


def _box(mask: np.ndarray) -> tuple[int, int, int, int] | None:
    """`(x0, y0, x1, y1)`, end-exclusive, around the true pixels of `mask`; None if none."""
    rows = np.flatnonzero(mask.any(axis=1))
    if not rows.size:
        return None
    cols = np.flatnonzero(mask[rows[0]:rows[-1] + 1].any(axis=0))
    return int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1
