"""Training tasks: which rule a network learns and how its inputs are sampled.

A `Task` pairs a rule from `rules.py` with a sampler that covers the coordinates the
thesis experiments actually produce, plus the default hyperparameters (the thesis'
where it gives them). Samplers draw from one `numpy.random.Generator`, so the data for a
seed are always the same.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from swarmdsl.train import rules

# The nine neighbour patterns of an agent in a rectangular block (at least 2x2): inside,
# on one edge, or in a corner. Order: (up, down, left, right) present?
BLOCK_PATTERNS = (
    (True, True, True, True),
    (False, True, True, True),
    (True, False, True, True),
    (True, True, False, True),
    (True, True, True, False),
    (False, True, False, True),
    (False, True, True, False),
    (True, False, False, True),
    (True, False, True, False),
)


@dataclass(frozen=True)
class Task:
    """A learnable rule with its sampler and default training settings."""

    name: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    rule: Callable[..., np.ndarray]
    sampler: Callable[..., np.ndarray]
    description: str
    defaults: dict[str, Any] = field(default_factory=dict)
    sampling: dict[str, Any] = field(default_factory=dict)
    rule_params: dict[str, Any] = field(default_factory=dict)
    ghost_threshold: float | None = None

    @property
    def n_in(self) -> int:
        return len(self.inputs)

    @property
    def n_out(self) -> int:
        return len(self.outputs)

    def make(
        self,
        n: int,
        rng: np.random.Generator,
        sampling: dict[str, Any] | None = None,
        rule_params: dict[str, Any] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Draw `n` input rows and their rule targets: `(n, n_in)`, `(n, n_out)` float64."""
        x = self.sampler(rng, n, **{**self.sampling, **(sampling or {})})
        y = self.rule(x, **{**self.rule_params, **(rule_params or {})})
        return x, y


def sample_spring(rng: np.random.Generator, n: int, low: float = -20.0,
                  high: float = 220.0) -> np.ndarray:
    """Left and right neighbour positions, each uniform over the line's span.

    The 1D program's agents live on a line from 0 to 190; the margins cover overshoot.
    Both orders (left < right and not) are drawn: the midpoint is symmetric anyway and
    the network then never extrapolates.
    """
    return rng.uniform(low, high, size=(n, 2))


def sample_lattice(
    rng: np.random.Generator,
    n: int,
    low: float = -10.0,
    high: float = 210.0,
    spacing_low: float = 26.0,
    spacing_high: float = 60.0,
    jitter: float = 3.0,
    pattern_weights: list[float] | None = None,
) -> np.ndarray:
    """Neighbour coordinates around agents of jittered, stretched lattices.

    Each row: an agent's own (unseen) position uniform over `[low, high]^2`; each of its
    four neighbours at its own spacing drawn from `[spacing_low, spacing_high]` (so
    rows spread on one side only, as when the end row has moved but the agent has not
    caught up, are covered), each coordinate jittered by up to `jitter`. Then one of the
    nine block patterns (inside, edge, corner) replaces absent neighbours with ghosts,
    drawn with `pattern_weights` (in `BLOCK_PATTERNS` order; equal by default).

    Returns:
        `(n, 8)` float64 rows in `rules.MATRIX_INPUTS` order.
    """
    cx = rng.uniform(low, high, n)
    cy = rng.uniform(low, high, n)
    gap = rng.uniform(spacing_low, spacing_high, size=(n, 4))
    jit = rng.uniform(-jitter, jitter, size=(n, 8))
    x = np.empty((n, 8))
    x[:, 0], x[:, 1] = cx, cy + gap[:, 0]  # up
    x[:, 2], x[:, 3] = cx, cy - gap[:, 1]  # down
    x[:, 4], x[:, 5] = cx - gap[:, 2], cy  # left
    x[:, 6], x[:, 7] = cx + gap[:, 3], cy  # right
    x += jit
    k = len(BLOCK_PATTERNS)
    if pattern_weights is None:
        which = rng.integers(0, k, n)
    else:
        w = np.asarray(pattern_weights, dtype=np.float64)
        if w.shape != (k,) or (w < 0).any() or w.sum() <= 0:
            raise ValueError(f"pattern_weights must be {k} non-negative numbers, not all 0")
        which = rng.choice(k, size=n, p=w / w.sum())
    patterns = np.asarray(BLOCK_PATTERNS)[which]
    present = np.repeat(patterns, 2, axis=1)  # (n, 8): each flag covers x and y
    return np.where(present, x, rules.GHOST)


TASKS: dict[str, Task] = {
    "spring1d": Task(
        name="spring1d",
        inputs=rules.SPRING_INPUTS,
        outputs=rules.SPRING_OUTPUTS,
        rule=rules.spring_midpoint,
        sampler=sample_spring,
        description="1D spring: target = midpoint of left and right neighbours",
        defaults={
            "hidden": [4],
            "activation": "relu",
            "lr": 0.0005,
            "epochs": 20,
            "batch_size": 64,
            "samples": 20000,
        },
        sampling={"low": -20.0, "high": 220.0},
    ),
    "matrix2d": Task(
        name="matrix2d",
        inputs=rules.MATRIX_INPUTS,
        outputs=rules.MATRIX_OUTPUTS,
        rule=rules.bio_lattice,
        sampler=sample_lattice,
        description="2D matrix: bio-lattice target from up/down/left/right neighbours",
        defaults={
            "hidden": [32, 32],
            "activation": "relu",
            "lr": 0.001,
            "lr_schedule": "cosine",
            "epochs": 200,
            "batch_size": 256,
            "samples": 60000,
        },
        sampling={
            "low": -10.0,
            "high": 210.0,
            "spacing_low": 26.0,
            "spacing_high": 60.0,
            "jitter": 3.0,
            # inside and edge agents (midpoints) are the hard cases: draw them more often
            "pattern_weights": [3.0, 2.0, 2.0, 2.0, 2.0, 1.0, 1.0, 1.0, 1.0],
        },
        rule_params={"s0": rules.S0},
        ghost_threshold=rules.GHOST_THRESHOLD,
    ),
}
