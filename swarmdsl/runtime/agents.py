"""AgentStore: every agent's state as a struct of arrays, agent axis first."""

from __future__ import annotations

import mmap

import numpy as np

BUILTIN_COLUMNS = {
    "pos": ((2,), np.float64),        # (N, 2) true position
    "vel": ((2,), np.float64),        # (N, 2) velocity, units per tick
    "heading": ((), np.float64),      # (N,) radians
    "status": ((), np.int32),         # (N,) global status code
    "kind": ((), np.int32),           # (N,) kind index
    "id": ((), np.int64),             # (N,) stable id, never reused
    "index": ((), np.float64),        # (N,) position within its kind at creation
    "sense": ((), np.float64),        # (N,) sense radius
    "max_speed": ((), np.float64),    # (N,) speed limit
}

_SPARSE_TAIL = 64            # values an agent from which a column may be mostly untouched
_SPARSE_BYTES = 4 * 2**20    # ... in a block this large


class AgentStore:
    """Columns of equal length N. Removal compacts every column at once (O(N) per call,
    not per removed agent), so ids stay stable and arrays stay dense."""

    def __init__(self, var_specs: dict[str, tuple[tuple, object, object]]):
        self.cols: dict[str, np.ndarray] = {}
        self.var_specs = var_specs            # name -> (shape tail, dtype, fill)
        for name, (tail, dtype) in BUILTIN_COLUMNS.items():
            self.cols[name] = np.zeros((0, *tail), dtype=dtype)
        for name, (tail, dtype, _fill) in var_specs.items():
            self.cols[name] = np.zeros((0, *tail), dtype=dtype)
        self.declared: dict[str, np.ndarray] = {n: np.zeros(0, bool) for n in var_specs}
        self.extra_specs: dict[str, tuple[tuple, object, object]] = {}

    def add_column(self, name: str, tail: tuple, dtype, fill=0) -> None:
        """A column a runtime extension owns (path memories, label sets): every agent gets
        `fill`, and later appends and removals keep it aligned with the other columns."""
        self.extra_specs[name] = (tail, dtype, fill)
        self.cols[name] = _block(self.n, tail, dtype, fill)

    @property
    def n(self) -> int:
        return self.cols["id"].shape[0]

    def append(self, count: int, declared_vars: set[str]) -> np.ndarray:
        """Add `count` zeroed agents; return their rows. Vars a kind lacks get their fill."""
        start = self.n
        for name, (tail, dtype) in BUILTIN_COLUMNS.items():
            self._grow(name, _block(count, tail, dtype, 0))
        for name, (tail, dtype, fill) in self.var_specs.items():
            self._grow(name, _block(count, tail, dtype, fill))
            self.declared[name] = np.concatenate(
                [self.declared[name], np.full(count, name in declared_vars)])
        for name, (tail, dtype, fill) in self.extra_specs.items():
            self._grow(name, _block(count, tail, dtype, fill))
        return np.arange(start, start + count)

    def _grow(self, name: str, block: np.ndarray) -> None:
        """Append `block` to a column; the first agents' block becomes the column
        itself, not a copy of it (a path memory of 2,000 points is 32 kB an agent)."""
        col = self.cols[name]
        self.cols[name] = block if col.shape[0] == 0 else np.concatenate([col, block])

    def remove(self, mask: np.ndarray) -> None:
        """Drop the agents where `mask` is true."""
        keep = ~np.asarray(mask, dtype=bool)
        for name in self.cols:
            self.cols[name] = self.cols[name][keep]
        for name in self.declared:
            self.declared[name] = self.declared[name][keep]

    def check_lengths(self) -> None:
        n = self.n
        bad = [k for k, v in self.cols.items() if v.shape[0] != n]
        if bad:
            raise RuntimeError(f"agent columns out of step: {bad}")


def _block(count: int, tail: tuple, dtype, fill) -> np.ndarray:
    """`count` rows of `fill`. Zero rows come from pages the system hands out zeroed
    when first touched: 10^4 ants with a 2,000-point path memory each (320 MB) are
    placed at once (it took 7.6 s to write them), and the rows an ant never fills never
    take memory. A large block of many values an agent (a path memory, an internal
    map) is its own anonymous mapping rather than `np.zeros`: numpy advises the system
    to back large arrays with 2 MB pages, and ants each touching their own 32 kB row
    then made it find and zero 320 MB of them at the first tick (0.1 s, or 2-5 s while
    it compacted memory for them)."""
    value = np.asarray(fill)
    if value.dtype.kind in "biuf" and not value.any() and not np.signbit(
            value.astype(np.float64)).any():         # -0.0 keeps its sign bit
        shape = (count, *tail)
        nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
        if int(np.prod(tail)) >= _SPARSE_TAIL and nbytes >= _SPARSE_BYTES:
            return np.frombuffer(mmap.mmap(-1, nbytes), dtype=dtype).reshape(shape)
        return np.zeros(shape, dtype=dtype)
    block = np.empty((count, *tail), dtype=dtype)
    block[...] = fill
    return block
