"""Frames as the page receives them: one binary websocket message per frame.

Layout (little-endian): the 4 bytes `SWF1`, a uint32 header length, the header as UTF-8
JSON (tick, counts, metric samples, which arrays follow), padding to a multiple of 4,
then each array's raw bytes, each padded to a multiple of 4, so the page wraps every one
in a typed array without copying. Per-agent data is never JSON: at 10^5 agents a frame
is 1.4 MB of arrays and a few hundred bytes of header.
"""

from __future__ import annotations

import json
import struct

import numpy as np

MAGIC = b"SWF1"
_DTYPES = {"float32": np.float32, "uint8": np.uint8, "uint16": np.uint16,
           "uint32": np.uint32, "int32": np.int32}


def encode(header: dict, arrays: list[tuple[str, np.ndarray]]) -> bytes:
    """One message: `header` plus `arrays` (name, array of a dtype in `_DTYPES`)."""
    listed = []
    blobs = []
    for name, arr in arrays:
        arr = np.ascontiguousarray(arr)
        dtype = arr.dtype.name
        if dtype not in _DTYPES:
            raise ValueError(f"array {name}: dtype {dtype} is not sent")
        listed.append([name, dtype, int(arr.size)])
        blobs.append(memoryview(arr.astype(arr.dtype.newbyteorder("<"), copy=False)).cast("B"))
    head = json.dumps({**header, "arrays": listed}, separators=(",", ":"),
                      allow_nan=False).encode()
    parts = [MAGIC, struct.pack("<I", len(head)), head, _pad(8 + len(head))]
    for blob in blobs:
        parts += [blob, _pad(blob.nbytes)]
    return b"".join(parts)


def decode(message: bytes) -> tuple[dict, dict[str, np.ndarray]]:
    """The inverse of `encode` (the page's decoder in Python, for tests and tools)."""
    if message[:4] != MAGIC:
        raise ValueError("not a studio frame")
    (n,) = struct.unpack_from("<I", message, 4)
    header = json.loads(message[8:8 + n])
    offset = _up(8 + n)
    arrays = {}
    for name, dtype, size in header["arrays"]:
        dt = np.dtype(_DTYPES[dtype]).newbyteorder("<")
        arrays[name] = np.frombuffer(message, dtype=dt, count=size, offset=offset)
        offset = _up(offset + size * dt.itemsize)
    return header, arrays


def _up(n: int) -> int:
    return (n + 3) // 4 * 4


def _pad(n: int) -> bytes:
    return b"\0" * (_up(n) - n)
