"""What a run records, put on disk while it goes, so a killed run keeps what it flushed.

A run may be cut by SIGKILL at any moment (the OOM killer, a batch system's hard
limit), and a long one must not hold its whole record in memory. Two forms survive a
kill and still read with the usual tools:

- `PartFolder`: a Parquet dataset, a folder of finished part files
  (`part-000000.parquet`, ...) that pyarrow and pandas read as one table. A Parquet
  file is readable only once its footer is written, so one growing file would lose
  everything; numbered parts lose only the rows not yet flushed. `agents.parquet` and
  `metrics.parquet` are both written this way.
- `FieldSpool`: field frames appended as they are recorded to one `.npy` file per key
  in `fields.npy/`, whose header (a fixed 128 bytes) is rewritten in place at each
  flush to count the frames written so far: `numpy.load` reads every flushed frame,
  and a frame half-written when the run died lies past the count, unseen. Appending
  costs one frame of memory per field and no rewrite, whatever the grid or the length
  of the run; `fields.npz` is streamed from the folder when the run closes.
"""

from __future__ import annotations

import shutil
import struct
from pathlib import Path

import numpy as np

from swarmdsl.errors import SwarmOptionError
from swarmdsl.runtime.outputs import replace_with

PART = "part-{:06d}.parquet"
FOLDER = "fields.npy"
NPZ = "fields.npz"
TICKS = "ticks"
GRID = ("grid_x", "grid_y")
# Every node of a refined grid, base nodes first (ids 0 .. ny*nx-1, row by row), then the
# finer ones; each field's values on them are the frames `NAME.nodes` (docs/outputs.md).
NODES = ("nodes_x", "nodes_y", "nodes_level")
NODE_FRAMES = ".nodes"
STATIC = GRID + NODES      # written once, not per frame
_MAGIC = b"\x93NUMPY\x01\x00"
_HEADER = 128        # bytes; a multiple of 64, as numpy aligns it


def write_part(table, path) -> None:
    """`table` as a zstd Parquet file whose whole-number and string columns (tick, id,
    kind, status, metric names) are dictionary-encoded and whose floats are not:
    positions and velocities hardly repeat, and their dictionaries made writing
    boids' 1,500 recorded ticks 4x slower (0.19 s against 0.05 s a part, and its first
    part 0.9 s) for a larger file (6.9 against 5.6 MB)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    repeating = [f.name for f in table.schema if not pa.types.is_floating(f.type)]
    pq.write_table(table, path, compression="zstd", use_dictionary=repeating)


class PartFolder:
    """A Parquet dataset written one finished part file at a time."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self.parts = 0              # part files written (the next one's number)

    def files(self) -> list[Path]:
        """The finished part files, in order."""
        if not self.folder.is_dir():
            return []
        return sorted(p for p in self.folder.glob("part-*.parquet") if p.is_file())

    def write(self, table) -> None:
        """`table` as the next part, under a hidden name renamed into place."""
        self.folder.mkdir(parents=True, exist_ok=True)
        replace_with(self.folder / PART.format(self.parts),
                     lambda tmp: write_part(table, tmp))
        self.parts += 1

    def keep_upto(self, tick: int, schema) -> set[int]:
        """Keep the rows of ticks <= `tick` (resuming): whole parts stay, a part that
        runs past it is cut, later parts go; parts are renumbered to stay consecutive.
        A single file (as runs before part files wrote it) becomes the first part.
        Returns the ticks kept. Raises ValueError for a part of other columns."""
        import pyarrow.compute as pc
        import pyarrow.parquet as pq

        if self.folder.is_file():
            table = pq.read_table(self.folder)
            self.folder.unlink()
            self.folder.mkdir()
            write_part(table, self.folder / PART.format(0))
        ticks: set[int] = set()
        parts = 0
        for path in self.files():
            table = pq.read_table(path)
            if table.schema != schema:
                raise ValueError(f"{self.folder.name} has other columns")
            kept = table.filter(pc.less_equal(table["tick"], tick))
            if kept.num_rows == 0:
                path.unlink()
                continue
            if kept.num_rows < table.num_rows:
                replace_with(path, lambda tmp, t=kept: write_part(t, tmp))
            ticks.update(pc.unique(kept["tick"]).to_pylist())
            target = self.folder / PART.format(parts)
            if path != target:
                path.rename(target)
            parts += 1
        self.parts = parts
        return ticks


def _header(dtype: np.dtype, shape: tuple[int, ...]) -> bytes:
    """A `.npy` version 1.0 header padded to `_HEADER` bytes, so it can be rewritten in
    place as the frame count grows."""
    text = repr({"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False,
                 "shape": tuple(int(s) for s in shape)}).encode("latin1")
    room = _HEADER - len(_MAGIC) - 2
    if len(text) + 1 > room:        # pragma: no cover - a 3-d shape is some 60 bytes
        raise ValueError(f"a .npy header of {len(text)} bytes does not fit")
    return _MAGIC + struct.pack("<H", room) + text + b" " * (room - len(text) - 1) + b"\n"


def _frames_on_disk(path: Path, frame_bytes: int) -> int:
    """Whole frames appended to `path` (counted or not)."""
    if not path.exists():
        return 0
    return max(path.stat().st_size - _HEADER, 0) // max(frame_bytes, 1)


class FieldSpool:
    """Recorded field frames, appended to `.npy` files in `fields.npy/` as they come."""

    def __init__(self, out: Path):
        self.folder = Path(out) / FOLDER
        self.shapes: dict[str, tuple[tuple[int, ...], np.dtype]] = {}
        self.count = 0          # frames appended
        self.counted = 0        # frames the headers count (flushed)
        self.pending: dict[str, list[bytes]] = {}   # frames added since, by file
        self.pending_bytes = 0

    def _file(self, name: str) -> Path:
        return self.folder / f"{name}.npy"

    def has_frames(self) -> bool:
        return self._file(TICKS).exists()

    def reset(self, static: dict[str, np.ndarray]) -> None:
        """An empty spool: the grid's nodes (`grid_x`, `grid_y`, and a refined grid's
        `nodes_*`), no frames."""
        shutil.rmtree(self.folder, ignore_errors=True)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.shapes, self.count, self.counted = {}, 0, 0
        self.pending, self.pending_bytes = {}, 0
        for name, values in static.items():
            replace_with(self._file(name), lambda tmp, v=np.asarray(values): _save(tmp, v))
        self._start(TICKS, (), np.dtype(np.int64))

    def _static(self) -> list[str]:
        """The grid files this spool holds (a resumed spool learns them from disk)."""
        return [name for name in STATIC if self._file(name).exists()]

    def _start(self, name: str, shape: tuple[int, ...], dtype: np.dtype) -> None:
        self.shapes[name] = (shape, dtype)
        with open(self._file(name), "wb") as fh:
            fh.write(_header(dtype, (0, *shape)))

    def add(self, tick: int, frames: dict[str, np.ndarray]) -> None:
        """Add one recorded tick's frames (every field, every time); they are appended
        to their files, and the headers count them, at the next `flush`. (Frames on
        disk but not yet counted were never read, so holding them until then loses
        nothing a kill would have kept; opening every file at every recorded tick
        cost a small swarm's run more than its ticks.)"""
        for name, values in frames.items():
            values = np.ascontiguousarray(values)
            if name not in self.shapes:
                self._start(name, values.shape, values.dtype)
            self._hold(name, values.tobytes())
        self._hold(TICKS, np.int64(tick).tobytes())
        self.count += 1

    def _hold(self, name: str, frame: bytes) -> None:
        self.pending.setdefault(name, []).append(frame)
        self.pending_bytes += len(frame)

    def flush(self) -> None:
        """Append the frames held, then rewrite each header to count every frame
        appended: the fields first, `ticks` last, so a kill between two rewrites leaves
        no field shorter than `ticks` says (readers take the first `len(ticks)`
        frames)."""
        if self.count == self.counted:
            return
        for name in [n for n in self.pending if n != TICKS] + [TICKS]:
            with open(self._file(name), "ab") as fh:
                fh.write(b"".join(self.pending.get(name, ())))
        self.pending, self.pending_bytes = {}, 0
        for name in [n for n in self.shapes if n != TICKS] + [TICKS]:
            shape, dtype = self.shapes[name]
            with open(self._file(name), "r+b") as fh:
                fh.write(_header(dtype, (self.count, *shape)))
        self.counted = self.count

    def keep_upto(self, tick: int, frames_now: dict[str, np.ndarray]) -> list[int]:
        """Keep the frames of ticks <= `tick` (resuming a killed run); returns their
        ticks. `frames_now` gives each field's shape and dtype (the resumed run's)."""
        ticks_file = self._file(TICKS)
        n_ticks = _frames_on_disk(ticks_file, 8)
        with open(ticks_file, "rb") as fh:
            fh.seek(_HEADER)
            ticks = np.frombuffer(fh.read(n_ticks * 8), dtype=np.int64)
        n = int(np.searchsorted(ticks, tick, side="right"))
        for name, values in frames_now.items():
            n = min(n, _frames_on_disk(self._file(name), values.nbytes))
        self.shapes = {TICKS: ((), np.dtype(np.int64))}
        self.pending, self.pending_bytes = {}, 0
        for name, values in frames_now.items():
            self.shapes[name] = (values.shape, values.dtype)
        for name, (shape, dtype) in self.shapes.items():
            path = self._file(name)
            if not path.exists():
                self._start(name, shape, dtype)
            with open(path, "r+b") as fh:
                fh.truncate(_HEADER + n * int(np.prod(shape)) * dtype.itemsize)
        self.count, self.counted = n, -1
        self.flush()
        return [int(t) for t in ticks[:n]]

    def load_npz(self, npz: Path, tick: int, grid) -> list[int]:
        """Start the spool from a closed run's `fields.npz` (frames of ticks <= tick),
        one frame at a time."""
        import zipfile  # here and in write_npz: only a run's end or resume needs it

        self.reset(grid)
        with zipfile.ZipFile(npz) as zf:
            with zf.open(f"{TICKS}.npy") as fh:
                ticks = np.lib.format.read_array(fh, allow_pickle=False)
            n = int(np.searchsorted(ticks, tick, side="right"))
            names = [m[:-4] for m in zf.namelist()
                     if m.endswith(".npy") and m[:-4] not in (TICKS, *STATIC)]
            for name in names:
                with zf.open(f"{name}.npy") as src:
                    shape, _fortran, dtype = _read_header(src)
                    frame = int(np.prod(shape[1:])) * dtype.itemsize
                    self._start(name, tuple(shape[1:]), dtype)
                    with open(self._file(name), "ab") as dst:
                        for _ in range(min(n, shape[0])):
                            dst.write(src.read(frame))
        with open(self._file(TICKS), "ab") as fh:
            fh.write(np.ascontiguousarray(ticks[:n], dtype=np.int64).tobytes())
        self.count, self.counted = n, -1
        self.flush()
        return [int(t) for t in ticks[:n]]

    def write_npz(self, path: Path) -> None:
        """Stream the spool into the `.npz` at `path` (as `np.savez_compressed` lays
        it), one frame at a time."""
        import zipfile

        self.flush()
        static = self._static()
        names = [TICKS, *static] + [n for n in self.shapes if n != TICKS]
        with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, allowZip64=True) as zf:
            for name in names:
                with zf.open(f"{name}.npy", "w", force_zip64=True) as member, \
                        open(self._file(name), "rb") as src:
                    # a grid file has numpy's own header; the rest have ours
                    shape, _fortran, dtype = _read_header(src)
                    if name in static:
                        rows, frame = 1, int(np.prod(shape)) * dtype.itemsize
                    else:
                        rows, frame = self.count, int(np.prod(shape[1:])) * dtype.itemsize
                    shape = shape if name in static else (self.count, *shape[1:])
                    np.lib.format.write_array_header_1_0(member, {
                        "descr": np.lib.format.dtype_to_descr(dtype),
                        "fortran_order": False, "shape": tuple(shape)})
                    for _ in range(rows):
                        member.write(src.read(frame))

    def remove(self) -> None:
        shutil.rmtree(self.folder, ignore_errors=True)


def _save(path: Path, values: np.ndarray) -> None:
    with open(path, "wb") as fh:      # a path not ending in .npy would get one added
        np.save(fh, values, allow_pickle=False)


def _read_header(fh) -> tuple[tuple[int, ...], bool, np.dtype]:
    version = np.lib.format.read_magic(fh)
    if version == (1, 0):
        return np.lib.format.read_array_header_1_0(fh)
    return np.lib.format.read_array_header_2_0(fh)


class _FieldFolder:
    """`fields.npy/` read like the `NpzFile` numpy returns for `fields.npz`."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.files = sorted(p.stem for p in folder.glob("*.npy") if p.is_file())
        self._n = len(self._load(TICKS)) if TICKS in self.files else 0

    def _load(self, name: str) -> np.ndarray:
        return np.load(self.folder / f"{name}.npy", allow_pickle=False)

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self.files:
            raise KeyError(f"{name} is not a file in {self.folder}")
        values = self._load(name)
        return values if name in STATIC else values[:self._n]

    def __contains__(self, name: str) -> bool:
        return name in self.files

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        return None

    def close(self) -> None:
        return None


class NoFields(SwarmOptionError, FileNotFoundError):
    """A folder without recorded fields: a SwarmError for the API's callers, and the
    FileNotFoundError that readers catching OSError (the analysis tools) word their
    own way."""


def open_fields(run_dir):
    """A run's recorded fields, as `np.load(RUN/fields.npz)` gives them: from
    `fields.npz` when the run closed, else from `fields.npy/` (a killed run's
    flushed frames). Use as `with open_fields(run) as data: data["ticks"]`."""
    from swarmdsl.runtime.arguments import required_path

    run_dir = required_path("run_dir", run_dir, "open_fields needs a run's out folder")
    if (run_dir / NPZ).is_file():
        return np.load(run_dir / NPZ, allow_pickle=False)
    if (run_dir / FOLDER).is_dir():
        return _FieldFolder(run_dir / FOLDER)
    raise NoFields(f"run_dir {run_dir}: no {NPZ} (or {FOLDER}/) there; give the out "
                   "folder of a run")


__all__ = ["FOLDER", "NPZ", "PART", "FieldSpool", "PartFolder", "open_fields"]
