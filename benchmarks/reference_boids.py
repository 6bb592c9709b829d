"""Hand-written numpy boids with the rules, parameters and update order of `boids.swarm`.

The yardstick for the compiled program: what a careful numpy programmer writes for the
same model. Per tick, from the start-of-tick state:

- neighbours within `radius` R: `cKDTree.query_pairs(R, output_type="ndarray")`, each
  unordered pair once;
- separation, for d < 0.4 R: normalize(pos - other) * (0.4 R / max(d, 0.001))^2;
- cohesion, for d > R/2: (other - pos) / R;
- alignment, for d > R/3: other.vel - vel;
- steer = (0.9 sep + 0.7 coh + 0.3 ali) / max(count, 1);
- vel = rotate(normalize(vel + gain * steer) * cruise, normal(0, wander)).

Then the runtime's motion step: edge repulsion (`World.edge_push`, weight 1, range 0.4 R),
speed clamp at `cruise`, move by velocity and reflect at the walls (`World.move`). Those
two are the runtime's own functions, so both sides do exactly that work.

Every term is antisymmetric in the pair (what i gets from j, j gets with the sign
flipped), so one pass over the unordered pairs and two `bincount`s give every agent's
sum: the one liberty a hand-written version takes that a compiled one cannot.
Random draws come in a different order from the compiled program, so runs are not
bit-identical; they flock the same way (compare `polarisation`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from swarmdsl.runtime.world import World


class ReferenceBoids:
    """The boids of `programs/boids.swarm` (same defaults) as plain numpy arrays."""

    def __init__(self, n: int = 100, width: float = 600.0, height: float = 600.0,
                 radius: float = 80.0, cruise: float = 3.0, gain: float = 2.0,
                 wander: float = 0.05, seed: int = 0):
        self.n = int(n)
        self.radius = float(radius)
        self.cruise = float(cruise)
        self.gain = float(gain)
        self.wander = float(wander)
        self.rng = np.random.default_rng(seed)
        # `grid 10`, `edges repel 1.0 (0.4 * radius)`
        self.world = World(width, height, 10.0, "repel", 1.0, 0.4 * self.radius)
        self.pos = self.rng.uniform((0, 0), (width, height), (self.n, 2))  # (N, 2)
        angle = self.rng.uniform(0.0, 2 * np.pi, self.n)
        self.vel = np.stack([np.cos(angle), np.sin(angle)], axis=1) * self.cruise  # (N, 2)
        self.tick = 0

    @classmethod
    def from_state(cls, start: dict, params: dict, seed: int) -> ReferenceBoids:
        """Start from another implementation's agents (`pos`, `vel`) and params."""
        ref = cls(len(start["pos"]), params["width"], params["height"],
                  wander=params.get("wander", 0.05), seed=seed)
        ref.pos = np.array(start["pos"], dtype=np.float64)
        ref.vel = np.array(start["vel"], dtype=np.float64)
        return ref

    def state(self) -> dict:
        return {"pos": self.pos, "vel": self.vel}

    def steer(self) -> np.ndarray:
        """The weighted, neighbour-averaged steering of every agent, (N, 2)."""
        n, r = self.n, self.radius
        pos, vel = self.pos, self.vel
        pairs = cKDTree(pos).query_pairs(r, output_type="ndarray")  # (H, 2), a < b
        a, b = pairs[:, 0], pairs[:, 1]
        delta = pos[b] - pos[a]                                      # (H, 2) a -> b
        dist = np.sqrt(np.einsum("ij,ij->i", delta, delta))          # (H,)
        # What a receives from b; b receives the negative.
        # separation: normalize(pos_a - pos_b) * (0.4 R / max(d, .001))^2
        #           = -delta / d * (0.4 R / max(d, .001))^2   (zero when d == 0)
        sep = np.where(dist < 0.4 * r,
                       (0.4 * r / np.maximum(dist, 0.001)) ** 2
                       / np.where(dist > 0, dist, np.inf), 0.0)
        coh = np.where(dist > 0.5 * r, 1.0 / r, 0.0)
        along_delta = 0.7 * coh - 0.9 * sep                          # (H,)
        ali = np.where(dist > r / 3, 0.3, 0.0)[:, None] * (vel[b] - vel[a])
        force = along_delta[:, None] * delta + ali                   # (H, 2)
        total = np.empty((n, 2))
        for c in range(2):
            total[:, c] = (np.bincount(a, force[:, c], minlength=n)
                           - np.bincount(b, force[:, c], minlength=n))
        count = np.bincount(a, minlength=n) + np.bincount(b, minlength=n)
        return total / np.maximum(count, 1)[:, None]

    def step(self) -> None:
        """One synchronous tick: steer, turn a little at random, then the motion step."""
        v = self.vel + self.gain * self.steer()
        norm = np.sqrt(np.einsum("ij,ij->i", v, v))
        v = np.where(norm[:, None] > 0, v / np.where(norm > 0, norm, 1.0)[:, None], 0.0)
        v *= self.cruise
        turn = self.rng.standard_normal(self.n) * self.wander
        c, s = np.cos(turn), np.sin(turn)
        vel = np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]], axis=1)
        # the runtime's motion step: edge repulsion, speed clamp, move, reflect
        vel += self.world.edge_push(self.pos)
        speed = np.sqrt(np.einsum("ij,ij->i", vel, vel))
        fast = speed > self.cruise
        vel[fast] *= (self.cruise / speed[fast])[:, None]
        self.pos, self.vel = self.world.move(self.pos, vel)
        self.tick += 1

    def run(self, steps: int) -> None:
        for _ in range(steps):
            self.step()


def polarisation(vel: np.ndarray) -> float:
    """|mean of unit velocities|: 1 when every agent heads the same way, ~0 when random."""
    speed = np.linalg.norm(vel, axis=1)
    unit = vel[speed > 0] / speed[speed > 0, None]
    return float(np.linalg.norm(unit.mean(axis=0))) if unit.size else 0.0
