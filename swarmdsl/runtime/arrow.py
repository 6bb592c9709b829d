"""Arrow columns built straight from numpy buffers, for the recorder.

Why not `pyarrow.array`: given a numpy array (or a list of strings) it first asks
pandas whether the data is a pandas object, and that imports pandas: about 0.3 s, a
quarter of a short recorded run, for a library the recorder never uses. An Arrow column
is a handful of buffers (validity bits, values or offsets and bytes), so building it from
numpy is cheap, has no Python loop over rows, and gives the same column
(`tests/test_arrow.py` compares every kind with `pyarrow.array`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

# Arrow type name -> the numpy dtype of its values buffer (bool is packed to bits).
_DTYPES = {"float64": np.float64, "int64": np.int64, "int32": np.int32, "bool_": np.bool_}
_MAX_OFFSET = np.iinfo(np.int32).max     # `string` offsets are int32


def _validity(pa, valid: np.ndarray | None, n: int):
    """(validity bitmap buffer or None, null count) of a column whose `valid` rows hold
    a value (None: every row)."""
    if valid is None:
        return None, 0
    valid = np.asarray(valid, dtype=bool).reshape(-1)
    if valid.size != n:
        raise ValueError(f"a validity mask of {valid.size} rows for {n} values")
    nulls = n - int(np.count_nonzero(valid))
    if nulls == 0:
        return None, 0
    return pa.py_buffer(np.packbits(valid, bitorder="little")), nulls


def numbers(values: np.ndarray, type_name: str, valid: np.ndarray | None = None):
    """A `type_name` (``float64``, ``int64``, ``int32``, ``bool_``) Arrow column of
    `values`; rows where `valid` is False are null (as `pyarrow.array(mask=~valid)`)."""
    import pyarrow as pa

    if type_name not in _DTYPES:
        raise ValueError(f"no Arrow column of type {type_name!r} from numbers")
    flat = np.ascontiguousarray(np.asarray(values).reshape(-1), dtype=_DTYPES[type_name])
    n = flat.size
    bitmap, nulls = _validity(pa, valid, n)
    if type_name == "bool_":
        flat = np.packbits(flat, bitorder="little")
    return pa.Array.from_buffers(getattr(pa, type_name)(), n,
                                 [bitmap, pa.py_buffer(flat)], null_count=nulls)


def labels(names: Sequence[str | None], codes: np.ndarray):
    """A `string` Arrow column whose row i is ``names[codes[i]]`` (a None name: null),
    as for kind and status names: few distinct strings over many rows."""
    import pyarrow as pa

    codes = np.asarray(codes, dtype=np.intp).reshape(-1)
    encoded = [b"" if s is None else str(s).encode("utf-8") for s in names]
    if codes.size and (codes.min() < 0 or codes.max() >= len(encoded)):
        raise ValueError(f"a label code outside 0..{len(encoded) - 1}")
    lengths = np.array([len(b) for b in encoded], dtype=np.int64)
    row_lengths = lengths[codes]
    offsets = np.zeros(codes.size + 1, dtype=np.int64)
    np.cumsum(row_lengths, out=offsets[1:])
    if offsets[-1] > _MAX_OFFSET:       # past one `string` column's reach: let Arrow split it
        return pa.array([names[c] for c in codes], type=pa.string())
    width = int(lengths.max()) if len(encoded) else 0
    table = np.zeros((len(encoded), max(width, 1)), dtype=np.uint8)
    for row, b in enumerate(encoded):
        table[row, :len(b)] = np.frombuffer(b, dtype=np.uint8)
    rows = table[codes]
    data = rows[np.arange(rows.shape[1]) < row_lengths[:, None]]   # row by row, in order
    is_null = np.array([s is None for s in names], dtype=bool)
    bitmap, nulls = _validity(pa, ~is_null[codes], codes.size) if is_null.any() else (None, 0)
    return pa.Array.from_buffers(pa.string(), codes.size,
                                 [bitmap, pa.py_buffer(offsets.astype(np.int32)),
                                  pa.py_buffer(data)], null_count=nulls)


def values(column, type_name: str) -> np.ndarray:
    """The values of a null-free `type_name` (``float64``, ``int64``, ``int32``) column
    or chunked column as a numpy array: `to_numpy` would import pandas too."""
    if type_name not in _DTYPES or type_name == "bool_":
        raise ValueError(f"no numpy values of an Arrow {type_name!r} column")
    if hasattr(column, "combine_chunks"):
        column = column.combine_chunks()
    if column.null_count:
        raise ValueError(f"a column with {column.null_count} nulls has no plain values")
    dtype = np.dtype(_DTYPES[type_name])
    data = column.buffers()[1]
    if data is None:
        return np.zeros(0, dtype=dtype)
    return np.frombuffer(data, dtype=dtype, count=len(column),
                         offset=column.offset * dtype.itemsize)
