"""Field frames kept on disk while a run goes, and `fields.npz` streamed from them.

`fields.npz` holds every recorded frame of every field, `(T, ny, nx)` each; kept in
memory that is 80 kB per frame of a 100 x 100 grid, gigabytes over a long run. So each
recorded frame is appended to a raw file in a hidden folder beside the outputs
(`.fields.spool/NAME.raw`, with the recorded ticks in `ticks.raw`), and `fields.npz` is
written at the end by streaming those files into the archive one frame at a time:
memory stays one frame per field. A run killed without closing leaves the spool, from
which `--resume` rebuilds its frames.
"""

from __future__ import annotations

import shutil
import zipfile
from pathlib import Path

import numpy as np

FOLDER = ".fields.spool"
_TICKS = "ticks"


class FieldSpool:
    """Append-only frames per field, on disk."""

    def __init__(self, out: Path):
        self.folder = Path(out) / FOLDER
        self.shapes: dict[str, tuple[tuple[int, ...], np.dtype]] = {}
        self.count = 0

    def _file(self, name: str) -> Path:
        return self.folder / f"{name}.raw"

    def has_frames(self) -> bool:
        return self._file(_TICKS).exists()

    def reset(self) -> None:
        shutil.rmtree(self.folder, ignore_errors=True)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.shapes, self.count = {}, 0

    def add(self, tick: int, frames: dict[str, np.ndarray]) -> None:
        """Append one recorded tick's frames (every field, every time)."""
        if not self.count:
            self.folder.mkdir(parents=True, exist_ok=True)
        for name, values in frames.items():
            values = np.ascontiguousarray(values)
            self.shapes.setdefault(name, (values.shape, values.dtype))
            with open(self._file(name), "ab") as fh:
                fh.write(values.tobytes())
        with open(self._file(_TICKS), "ab") as fh:
            fh.write(np.int64(tick).tobytes())
        self.count += 1

    def keep_upto(self, tick: int, frames_now: dict[str, np.ndarray]) -> list[int]:
        """Keep the frames of ticks <= `tick` (resuming); returns the ticks kept.

        `frames_now` gives each field's shape and dtype (the resumed simulation's).
        """
        ticks_file = self._file(_TICKS)
        if not ticks_file.exists():
            return []
        ticks = np.fromfile(ticks_file, dtype=np.int64)
        n = int(np.searchsorted(ticks, tick, side="right"))
        for name, values in frames_now.items():
            size = values.size * values.dtype.itemsize
            path = self._file(name)
            have = path.stat().st_size // size if path.exists() else 0
            n = min(n, have)
        for name, values in frames_now.items():
            self.shapes[name] = (values.shape, values.dtype)
            with open(self._file(name), "r+b" if self._file(name).exists() else "wb") as fh:
                fh.truncate(n * values.size * values.dtype.itemsize)
        with open(ticks_file, "r+b") as fh:
            fh.truncate(n * 8)
        self.count = n
        return [int(t) for t in ticks[:n]]

    def load_npz(self, npz: Path, tick: int) -> list[int]:
        """Start the spool from a finished run's `fields.npz` (frames of ticks <= tick)."""
        self.reset()
        with np.load(npz, allow_pickle=False) as data:
            ticks = data["ticks"]
            keep = np.flatnonzero(ticks <= tick)
            names = [k for k in data.files if k not in ("ticks", "grid_x", "grid_y")]
            stacks = {name: data[name] for name in names}
        for i in keep:
            self.add(int(ticks[i]), {name: stacks[name][i] for name in names})
        return [int(ticks[i]) for i in keep]

    def write_npz(self, path: Path, grid: tuple[np.ndarray, np.ndarray]) -> None:
        """Stream the spool into the `.npz` at `path` (as `np.savez_compressed` lays it)."""
        with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, allowZip64=True) as zf:
            ticks = (np.fromfile(self._file(_TICKS), dtype=np.int64)
                     if self._file(_TICKS).exists() else np.zeros(0, dtype=np.int64))
            _put(zf, "ticks", ticks[:self.count])
            _put(zf, "grid_x", np.asarray(grid[0]))
            _put(zf, "grid_y", np.asarray(grid[1]))
            for name, (shape, dtype) in self.shapes.items():
                header = {"descr": np.lib.format.dtype_to_descr(dtype),
                          "fortran_order": False, "shape": (self.count, *shape)}
                frame_bytes = int(np.prod(shape)) * dtype.itemsize
                with zf.open(f"{name}.npy", "w", force_zip64=True) as member, \
                        open(self._file(name), "rb") as src:
                    np.lib.format.write_array_header_1_0(member, header)
                    for _ in range(self.count):
                        member.write(src.read(frame_bytes))

    def remove(self) -> None:
        shutil.rmtree(self.folder, ignore_errors=True)


def _put(zf: zipfile.ZipFile, name: str, array: np.ndarray) -> None:
    with zf.open(f"{name}.npy", "w", force_zip64=True) as member:
        np.lib.format.write_array(member, np.ascontiguousarray(array), allow_pickle=False)
