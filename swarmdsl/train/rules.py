"""The hard-coded behaviour rules the thesis networks learn, as plain numpy functions.

Each rule uses only what the swarm language offers (+ - * /, comparisons, `if c then a
else b` as `np.where`, min, max, abs, sqrt), so a hard-coded program can state the same
rule the network was trained on and the two runs can be compared. `docs/lattice.md`
gives the formulas.
"""

from __future__ import annotations

import numpy as np

GHOST = 6000.0
"""Coordinate a missing neighbour reports, in x and y (the thesis' "ghost node")."""

GHOST_THRESHOLD = GHOST / 2
"""A neighbour whose x exceeds this is a ghost; real coordinates stay far below it."""

S0 = 40.0
"""Rest spacing of the 2D lattice, in the program's coordinate units."""

MATRIX_INPUTS = ("up.x", "up.y", "down.x", "down.y", "left.x", "left.y", "right.x", "right.y")
MATRIX_OUTPUTS = ("x", "y")
SPRING_INPUTS = ("left.x", "right.x")
SPRING_OUTPUTS = ("x",)


def spring_midpoint(nb: np.ndarray) -> np.ndarray:
    """1D spring target: the midpoint of the left and right neighbours.

    Args:
        nb: `(M, 2)` float64 rows `(left.x, right.x)`.

    Returns:
        `(M, 1)` float64 targets.
    """
    nb = np.asarray(nb, dtype=np.float64)
    return ((nb[:, 0] + nb[:, 1]) / 2)[:, None]


def bio_lattice(nb: np.ndarray, s0: float = S0, min_ratio: float = 0.25) -> np.ndarray:
    """2D "bio-lattice" target: where an agent of a soft, area-keeping sheet should be.

    Along each axis the agent sits at the midpoint of its two neighbours. When one
    neighbour on an axis is missing (a ghost), the agent keeps the *area* of its lattice
    cell at `s0**2`: its spacing to the remaining neighbour is `s0**2 / s_other`, where
    `s_other` is the spacing measured on the other axis. Spreading the rows therefore
    pulls the side columns inward, as stretched tissue narrows. A spacing that cannot be
    measured (a neighbour missing on that axis too) counts as `s0`. Measured spacings are
    floored at `min_ratio * s0` so crossed or collapsed rows never divide by ~0.

    Axis convention: `up` has the larger y, `right` the larger x.

    Args:
        nb: `(M, 8)` float64 rows `(up.x, up.y, down.x, down.y, left.x, left.y,
            right.x, right.y)`; a missing neighbour is `(GHOST, GHOST)`.
        s0: Rest spacing (the area of a cell at rest is `s0**2`).
        min_ratio: Floor of a measured spacing, as a fraction of `s0`.

    Returns:
        `(M, 2)` float64 targets `(x, y)`. With all four neighbours missing the agent has
        nothing to follow and the target is `(GHOST, GHOST)`.
    """
    nb = np.asarray(nb, dtype=np.float64)
    ux, uy, dx, dy, lx, ly, rx, ry = (nb[:, k] for k in range(8))
    has_u, has_d = ux < GHOST_THRESHOLD, dx < GHOST_THRESHOLD
    has_l, has_r = lx < GHOST_THRESHOLD, rx < GHOST_THRESHOLD
    floor = min_ratio * s0
    # Local spacings; s0 where the axis lacks a neighbour pair.
    sv = np.where(has_u & has_d, np.maximum((uy - dy) / 2, floor), s0)
    sh = np.where(has_l & has_r, np.maximum((rx - lx) / 2, floor), s0)
    area = s0 * s0

    x = np.where(
        has_l & has_r,
        (lx + rx) / 2,
        np.where(
            has_r,
            rx - area / sv,
            np.where(has_l, lx + area / sv, _fallback(has_u, has_d, ux, dx)),
        ),
    )
    y = np.where(
        has_u & has_d,
        (uy + dy) / 2,
        np.where(
            has_d,
            dy + area / sh,
            np.where(has_u, uy - area / sh, _fallback(has_l, has_r, ly, ry)),
        ),
    )
    return np.stack([x, y], axis=1)


def _fallback(has_a, has_b, a, b):
    """Both neighbours on this axis missing: follow the other axis' neighbours."""
    return np.where(
        has_a & has_b, (a + b) / 2, np.where(has_a, a, np.where(has_b, b, GHOST))
    )
