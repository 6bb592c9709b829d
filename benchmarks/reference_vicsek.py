"""Hand-written numpy Vicsek model with the rules, parameters and update order of
`programs/vicsek.swarm`.

Per tick, from the start-of-tick state: every particle sums the unit velocities of the
particles within `r` (the short way round the periodic box) and its own, turns to that
direction plus a uniform draw in [-eta/2, eta/2], and moves at speed `v0`. One
`cKDTree(..., boxsize=...).query_pairs` per tick; each unordered pair is visited once and
its two contributions are scattered with `bincount` (unit velocities are not
antisymmetric, so each side adds the other's).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


class ReferenceVicsek:
    def __init__(self, pos, vel, side, r=1.0, v0=0.03, eta=1.0, seed=0):
        self.pos = np.array(pos, dtype=np.float64)   # (N, 2)
        self.vel = np.array(vel, dtype=np.float64)   # (N, 2)
        self.side, self.r, self.v0, self.eta = float(side), float(r), float(v0), float(eta)
        self.rng = np.random.default_rng(seed)

    @classmethod
    def from_state(cls, start: dict, params: dict, seed: int) -> ReferenceVicsek:
        return cls(start["pos"], start["vel"], params["size"], eta=params.get("eta", 1.0),
                   seed=seed)

    def state(self) -> dict:
        return {"pos": self.pos, "vel": self.vel}

    def step(self) -> None:
        n = self.pos.shape[0]
        noise = self.rng.uniform(-self.eta / 2, self.eta / 2, n)
        speed = np.sqrt(np.einsum("ij,ij->i", self.vel, self.vel))
        unit = self.vel / np.where(speed > 0, speed, np.inf)[:, None]   # zero stays zero
        pts = np.mod(self.pos, self.side)
        pts[pts >= self.side] = 0.0
        pairs = cKDTree(pts, boxsize=self.side).query_pairs(self.r, output_type="ndarray")
        a, b = pairs[:, 0], pairs[:, 1]
        total = unit.copy()
        for c in range(2):
            total[:, c] += (np.bincount(a, unit[b, c], minlength=n)
                            + np.bincount(b, unit[a, c], minlength=n))
        angle = np.arctan2(total[:, 1], total[:, 0]) + noise
        self.vel = np.stack([np.cos(angle), np.sin(angle)], axis=1) * self.v0
        self.pos = np.mod(self.pos + self.vel, self.side)
