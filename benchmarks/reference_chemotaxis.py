"""Hand-written numpy chemotaxis with the rules, parameters and update order of
`benchmarks/models/chemotaxis.swarm`.

Per tick: every cell reads the chemical's gradient at its position (central differences
at the four surrounding grid nodes of the periodic grid, bilinearly interpolated), turns
to `normalize(velocity + gain * gradient) * pace` rotated by a normal draw, and lays 1
unit split bilinearly over those four nodes (`bincount`); the cells move; the chemical
decays and diffuses (`v <- (1 - decay) * ((1 - 4 D) v + D * sum of the 4 neighbours)`).
"""

from __future__ import annotations

import numpy as np


class ReferenceChemotaxis:
    def __init__(self, start: dict, params: dict, seed: int):
        self.pos = np.array(start["pos"], dtype=np.float64)   # (N, 2)
        self.vel = np.array(start["vel"], dtype=np.float64)   # (N, 2)
        p = {"spacing": 1.0, "pace": 1.0, "gain": 2.0, "turn": 0.3, "decay": 0.1,
             "diffusion": 0.2, **params}
        self.side, self.h = float(p["size"]), float(p["spacing"])
        self.pace, self.gain, self.turn = float(p["pace"]), float(p["gain"]), float(p["turn"])
        self.decay, self.diffusion = float(p["decay"]), float(p["diffusion"])
        self.nx = round(self.side / self.h)
        self.chem = np.zeros((self.nx, self.nx))              # (ny, nx)
        self.rng = np.random.default_rng(seed)

    from_state = classmethod(lambda cls, start, params, seed: cls(start, params, seed))

    def state(self) -> dict:
        return {"pos": self.pos, "vel": self.vel}

    def _corners(self):
        """Flat indices (4, N) of the surrounding nodes and their bilinear weights (4, N)."""
        nx = self.nx
        f = np.mod(self.pos, self.side) / self.h
        lo = np.floor(f)
        t = f - lo
        i0 = lo.astype(np.intp) % nx
        i1 = (i0 + 1) % nx
        x0, x1, y0, y1 = i0[:, 0], i1[:, 0], i0[:, 1], i1[:, 1]
        idx = np.stack([y0 * nx + x0, y0 * nx + x1, y1 * nx + x0, y1 * nx + x1])
        tx, ty = t[:, 0], t[:, 1]
        w = np.stack([(1 - tx) * (1 - ty), tx * (1 - ty), (1 - tx) * ty, tx * ty])
        return idx, w

    def step(self) -> None:
        n, nx, h = self.pos.shape[0], self.nx, self.h
        angle = self.rng.standard_normal(n) * self.turn
        idx, w = self._corners()
        flat = self.chem.reshape(-1)
        i, j = idx % nx, idx // nx
        gx = (flat[j * nx + (i + 1) % nx] - flat[j * nx + (i - 1) % nx]) / (2 * h)
        gy = (flat[((j + 1) % nx) * nx + i] - flat[((j - 1) % nx) * nx + i]) / (2 * h)
        v = self.vel + self.gain * np.stack([(gx * w).sum(0), (gy * w).sum(0)], axis=1)
        norm = np.sqrt(np.einsum("ij,ij->i", v, v))
        v = v / np.where(norm > 0, norm, np.inf)[:, None] * self.pace
        c, s = np.cos(angle), np.sin(angle)
        self.vel = np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]], axis=1)
        flat += np.bincount(idx.ravel(), w.ravel(), minlength=flat.size)
        self.pos = np.mod(self.pos + self.vel, self.side)
        chem = self.chem
        around = (np.roll(chem, 1, 0) + np.roll(chem, -1, 0)
                  + np.roll(chem, 1, 1) + np.roll(chem, -1, 1))
        keep = 1 - self.decay
        self.chem = keep * (1 - 4 * self.diffusion) * chem + keep * self.diffusion * around
