"""Hand-written numpy swarmalators with the rules, parameters and update order of
`benchmarks/models/swarmalators.swarm`.

Per tick, from the start-of-tick state, over the neighbours j within `r` (farther than
0.01, the short way round the periodic box), with d = |x_j - x_i| and m = their count
(at least 1):

    velocity_i = dt / m * sum((x_j - x_i) / d * (1 + J cos(phase_j - phase_i))
                              - (x_j - x_i) / d^2)
    phase_i   += dt * K / m * sum(sin(phase_j - phase_i) / d) + normal(0, noise)

then the speed clamp at `top_speed` and the move. Both sums are antisymmetric in the
pair, so one pass over the unordered pairs (`cKDTree.query_pairs`) and a `bincount` per
side give them: half the pair work of the compiled program's directed pairs.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


class ReferenceSwarmalators:
    def __init__(self, start: dict, params: dict, seed: int):
        self.pos = np.array(start["pos"], dtype=np.float64)     # (N, 2)
        self.vel = np.array(start["vel"], dtype=np.float64)     # (N, 2)
        self.phase = np.array(start["phase"], dtype=np.float64)  # (N,)
        p = {"r": 2.0, "j": 0.5, "k": 0.5, "dt": 0.1, "noise": 0.05, "top_speed": 0.5,
             **params}
        self.side = float(p["size"])
        self.r, self.j, self.k, self.dt = (float(p[x]) for x in ("r", "j", "k", "dt"))
        self.noise, self.top = float(p["noise"]), float(p["top_speed"])
        self.rng = np.random.default_rng(seed)

    from_state = classmethod(lambda cls, start, params, seed: cls(start, params, seed))

    def state(self) -> dict:
        return {"pos": self.pos, "vel": self.vel, "phase": self.phase}

    def step(self) -> None:
        n, side = self.pos.shape[0], self.side
        kick = self.rng.standard_normal(n) * self.noise
        pts = np.mod(self.pos, side)
        pts[pts >= side] = 0.0
        pairs = cKDTree(pts, boxsize=side).query_pairs(self.r, output_type="ndarray")
        a, b = pairs[:, 0], pairs[:, 1]
        delta = self.pos[b] - self.pos[a]                    # (H, 2), a -> b
        delta -= side * np.round(delta / side)
        d = np.sqrt(np.einsum("ij,ij->i", delta, delta))
        keep = d > 0.01
        a, b, delta, d = a[keep], b[keep], delta[keep], d[keep]
        diff = self.phase[b] - self.phase[a]
        pull = delta * ((1 + self.j * np.cos(diff)) / d - 1 / d**2)[:, None]
        sync = np.sin(diff) / d
        m = np.maximum(np.bincount(a, minlength=n) + np.bincount(b, minlength=n), 1)
        total = np.empty((n, 2))
        for c in range(2):
            total[:, c] = (np.bincount(a, pull[:, c], minlength=n)
                           - np.bincount(b, pull[:, c], minlength=n))
        turn = np.bincount(a, sync, minlength=n) - np.bincount(b, sync, minlength=n)
        vel = total * self.dt / m[:, None]
        self.phase = self.phase + self.dt * self.k * turn / m + kick
        speed = np.sqrt(np.einsum("ij,ij->i", vel, vel))
        fast = speed > self.top
        vel[fast] *= (self.top / speed[fast])[:, None]
        self.vel = vel
        self.pos = np.mod(self.pos + vel, side)
