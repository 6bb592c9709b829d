"""The ant-colony direction choice: K compass directions, persistence, weighted draw."""

from __future__ import annotations

import functools
import math

import numpy as np

from swarmdsl.ops import portable

# The numba backend's loops of a choice (`compiled/direction_choice.py`), installed by
# it and taken inside its ticks only (`portable.EVERY_SIZE`): a numpy tick keeps these
# array forms, the reference, even in a process that ran numba before.
_compiled = None


def use_compiled(loops) -> None:
    """Install `loops()` -> (scores, pick), the compiled choice (None: none)."""
    global _compiled
    _compiled = loops


def compiled_loops():
    """(scores, pick) inside a numba tick, else None."""
    if _compiled is None or not portable.at_every_size():
        return None
    return _compiled()


def direction_angles(k: int) -> np.ndarray:
    """The ``(k,)`` angles ``2 * pi * i / k`` (radians, 0 = +x, counter-clockwise)."""
    return angles_of(int(k)).copy()


@functools.lru_cache(maxsize=64)
def angles_of(k: int) -> np.ndarray:
    """`direction_angles`, made once per `k` (read-only: callers share it)."""
    out = 2.0 * np.pi * np.arange(k) / k
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=64)
def direction_units(k: int) -> np.ndarray:
    """The ``(k, 2)`` unit vectors ``(cos, sin)`` of `direction_angles` (the language's
    portable cosine and sine), made once per `k` and shared: read-only."""
    angles = angles_of(k)
    out = np.stack([portable.cos_array(angles), portable.sin_array(angles)], axis=1)
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=256)
def steps_table(k: int, persistence: float) -> np.ndarray:
    """The ``(k, k)`` base weights of `k` directions: ``[c, i]`` the weight of
    direction ``i`` for an agent heading nearest direction ``c``,
    ``persistence ** steps_away`` with the exact reverse 0; made once per (k,
    persistence) by the same power function, so each weight has the bits it had when
    computed per agent. Read-only."""
    diff = (np.arange(k)[None, :] - np.arange(k)[:, None]) % k   # (k, k)
    steps_away = np.minimum(diff, k - diff)
    weights = portable.pow_array(persistence, steps_away.astype(np.float64))  # 0 ** 0 == 1
    if k % 2 == 0:
        weights[diff == k // 2] = 0.0   # the exact reverse is never chosen
    weights.flags.writeable = False
    return weights


def heading_index(heading, k: int) -> np.ndarray:
    """Index ``(M,)`` of the compass direction nearest each heading."""
    heading = np.asarray(heading, dtype=np.float64)
    return np.rint(heading * (k / (2.0 * np.pi))).astype(np.int64) % k


def direction_weights(heading, k: int, persistence: float, weights_extra=None) -> np.ndarray:
    """Unnormalised choice weights ``(M, k)``; see ``weighted_direction_choice``."""
    return _weights(heading, k, persistence, weights_extra)[0]


def checked(heading, k, persistence) -> tuple[np.ndarray, int, float]:
    """(heading, k, persistence) as a choice takes them, or the ValueError saying which
    is wrong."""
    k = _check_k(k)
    persistence = float(persistence)
    if not 0.0 <= persistence <= 1.0:
        raise ValueError(
            f"persistence must be between 0 (always straight on) and 1 (any direction "
            f"but back), got {persistence:g}"
        )
    heading = np.asarray(heading, dtype=np.float64)
    if heading.ndim != 1:
        raise ValueError(f"heading must have shape (M,), got {heading.shape}")
    if heading.size and not -math.inf < heading.min() <= heading.max() < math.inf:
        raise ValueError("heading must be finite")    # NaN too: it compares false
    return heading, k, persistence


def _weights(heading, k, persistence, weights_extra) -> tuple[np.ndarray, np.ndarray]:
    """(`direction_weights`, the index of the direction nearest each heading)."""
    heading, k, persistence = checked(heading, k, persistence)
    m = len(heading)
    current = heading_index(heading, k)  # (M,)
    weights = steps_table(k, persistence)[current]   # (M, k): a fresh array, writable
    if weights_extra is not None:
        extra = np.asarray(weights_extra, dtype=np.float64)
        if extra.shape != (m, k):
            raise ValueError(f"weights_extra must have shape ({m}, {k}), got {extra.shape}")
        if extra.size and not 0.0 <= extra.min() <= extra.max() < math.inf:
            raise ValueError("weights_extra must be finite and not negative")
        weights *= extra
    return weights, current


def weighted_direction_choice(rng, heading, k: int, persistence: float, weights_extra=None):
    """Draw one of ``k`` directions per agent, preferring to keep going the same way.

    Direction ``i`` points at angle ``2 * pi * i / k``. Its base weight is
    ``persistence ** steps_away``, where ``steps_away`` (0 .. k // 2) counts compass
    steps between ``i`` and the direction nearest the agent's heading; the exact reverse
    (``steps_away == k / 2``, only when ``k`` is even) gets weight 0. The base weight is
    multiplied by ``weights_extra`` ``(M, k)`` (pheromone or food attraction, >= 0).

    One ``rng.random(M)`` is drawn per call whatever the weights, so the random stream,
    and hence a seeded run, does not depend on which agents fell back. An agent whose
    weights are all 0 keeps its heading's direction.

    Args:
        rng: the run's ``numpy.random.Generator``.
        heading: ``(M,)`` current headings in radians.
        k: number of directions (the seed's ant colony uses 24).
        persistence: in [0, 1]; 0 = always straight on, 1 = uniform over all but back.
        weights_extra: ``(M, k)`` non-negative multipliers, or None.

    Returns:
        ``(M,) int64`` direction indices; ``direction_angles(k)[idx]`` are the angles.
    """
    weights, current = _weights(heading, k, persistence, weights_extra)  # (M, k), (M,)
    k = weights.shape[1]
    m = len(weights)
    cum = np.cumsum(weights, axis=1)  # (M, k)
    total = cum[:, -1]  # (M,)
    u = rng.random(m) * total  # (M,) in [0, total)
    # First index whose cumulative weight exceeds u: zero-weight directions never are.
    chosen = (cum <= u[:, None]).sum(axis=1)
    # u * total can round up to total itself; the last positive weight is then the pick.
    last_positive = k - 1 - np.argmax(weights[:, ::-1] > 0, axis=1)
    chosen = np.minimum(chosen, last_positive)
    return np.where(total > 0, chosen, current).astype(np.int64)


def _check_k(k) -> int:
    if int(k) != k or k < 1:
        raise ValueError(f"number of directions must be a positive whole number, got {k}")
    return int(k)
