"""The counter-based draws' integer part as one compiled loop (the numba backend's).

`randomness.AgentRandom._unit` turns (call key, agent id, lane) into a uniform number by
two rounds of splitmix64's finaliser, a shift and a scale: a dozen whole-array passes
with their temporaries in numpy. Here it is one pass with the same unsigned 64-bit
arithmetic (wrapping, exact) and the same exact conversion, so every draw has the same
bits on both backends; the floating-point functions that follow (`log`, `cos` of a
normal draw) stay numpy's.
"""

from __future__ import annotations

import numpy as np

from swarmdsl.runtime import randomness as _r
from swarmdsl.runtime.compiled.jit import njit

_U_ID = np.uint64(_r._C_ID)
_U_GOLDEN = np.uint64(_r._GOLDEN)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_TO_UNIT = _r._TO_UNIT


@njit(cache=True, nogil=True, inline="always")
def _mix(z):
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@njit(cache=True, nogil=True)
def _units(ids, base, lanes, open_low, out):
    low = 1.0 if open_low else 0.0
    for a in range(ids.size):
        h = _mix(ids[a] * _U_ID + base)
        for k in range(lanes):
            z = _mix(h + np.uint64(k) * _U_GOLDEN)
            out[a, k] = (float(z >> _S11) + low) * _TO_UNIT


def units(ids: np.ndarray, base: int, lanes: int, open_low: bool) -> np.ndarray:
    """(n, lanes) uniform numbers of agents `ids` (uint64) for call key `base`: the bits
    of `AgentRandom._unit`."""
    out = np.empty((ids.size, lanes))
    _units(ids, np.uint64(base), lanes, open_low, out)
    return out


@njit(cache=True, nogil=True)
def _units_rows(ids, bases, lanes, open_low, out):
    low = 1.0 if open_low else 0.0
    for a in range(ids.size):
        h = _mix(ids[a] * _U_ID + bases[a])
        for k in range(lanes):
            z = _mix(h + np.uint64(k) * _U_GOLDEN)
            out[a, k] = (float(z >> _S11) + low) * _TO_UNIT


def units_rows(ids: np.ndarray, bases: np.ndarray, lanes: int, open_low: bool) -> np.ndarray:
    """`units` with a call key per agent (`bases`, uint64): a batch of replicas draws
    each row with its own replica's key, the same bits as that replica's solo run."""
    out = np.empty((ids.size, lanes))
    _units_rows(ids, np.ascontiguousarray(bases, dtype=np.uint64), lanes, open_low, out)
    return out
