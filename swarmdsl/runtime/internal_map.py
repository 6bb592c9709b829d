"""Internal environment maps (the thesis' E): what each agent has perceived, as a coarse
grid of last-seen values and the tick each was seen, in the agent's own frame.

A map of ``S x S`` cells of side ``C`` is centred on the agent's origin, the point where
it was placed (its own ``(0, 0)``); a point maps to the cell ``floor((p - origin) / C +
S / 2)`` and points off the map are not kept. Three agent-store columns hold it:
``NAME:value (N, S, S)``, ``NAME:seen (N, S, S)`` (the tick, ``-inf`` for never) and
``NAME:origin (N, 2)``. Only the owner reads and writes its map, so writes go straight to
the store (as path memories do): the agent sees its own notes at once.
"""

from __future__ import annotations

import numpy as np

NEVER = -np.inf


class InternalMap:
    """The columns and kernels of one named map (``size`` cells a side, ``cell`` wide)."""

    def __init__(self, agents, name: str, cell: float, size: int):
        self.name, self.cell, self.size = name, float(cell), int(size)
        self.value, self.seen = f"{name}:value", f"{name}:seen"
        self.origin = f"{name}:origin"
        agents.add_column(self.value, (self.size, self.size), np.float64, 0.0)
        agents.add_column(self.seen, (self.size, self.size), np.float64, NEVER)
        agents.add_column(self.origin, (2,), np.float64, np.nan)

    def _origins(self, cols, rows: np.ndarray, pos: np.ndarray) -> np.ndarray:
        """``(M, 2)`` origins; an agent without one (added after placement) starts here."""
        origin = cols[self.origin][rows]
        unset = np.isnan(origin[:, 0])
        if unset.any():
            cols[self.origin][rows[unset]] = pos[unset]
            origin[unset] = pos[unset]
        return origin

    def cells(self, cols, rows, pos, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cell indices ``(iy, ix)`` of ``points (M, 2)`` and whether each is on the map."""
        local = (points - self._origins(cols, rows, pos)) / self.cell + self.size / 2
        ix, iy = np.floor(local[:, 0]), np.floor(local[:, 1])
        on = (ix >= 0) & (ix < self.size) & (iy >= 0) & (iy < self.size)
        return (np.where(on, iy, 0).astype(np.int64), np.where(on, ix, 0).astype(np.int64),
                on)

    def note(self, cols, rows, pos, points, values, tick: int) -> None:
        """Write ``values (M,)`` at ``points`` (already limited to what was sensed)."""
        iy, ix, on = self.cells(cols, rows, pos, points)
        r = rows[on]
        cols[self.value][r, iy[on], ix[on]] = values[on]
        cols[self.seen][r, iy[on], ix[on]] = float(tick)

    def recall(self, cols, rows, pos, points, tick: int) -> tuple[np.ndarray, np.ndarray]:
        """``(value (M,), age (M,))``: 0 and ``inf`` where never seen or off the map."""
        iy, ix, on = self.cells(cols, rows, pos, points)
        value = np.where(on, cols[self.value][rows, iy, ix], 0.0)
        seen = np.where(on, cols[self.seen][rows, iy, ix], NEVER)
        known = seen > NEVER
        return np.where(known, value, 0.0), np.where(known, tick - seen, np.inf)

    def best(self, cols, rows, pos) -> np.ndarray:
        """``(M, 2)`` the centre of the highest-valued cell seen (the agent's position if
        it has seen nothing), in world coordinates."""
        m = len(rows)
        seen = cols[self.seen][rows].reshape(m, -1)
        value = np.where(seen > NEVER, cols[self.value][rows].reshape(m, -1), -np.inf)
        k = value.argmax(axis=1)
        iy, ix = np.divmod(k, self.size)
        centre = (np.stack([ix, iy], axis=1) + 0.5 - self.size / 2) * self.cell
        point = self._origins(cols, rows, pos) + centre
        return np.where(np.isfinite(value.max(axis=1))[:, None], point, pos)

    def forget(self, cols, rows) -> None:
        cols[self.seen][rows] = NEVER


class MapRuntime:
    """Runtime extension: the run's internal maps; origins set where agents are placed."""

    def __init__(self, sim, spec: dict):
        sim.maps = self
        self.maps = {name: InternalMap(sim.agents, name, cell, size)
                     for name, (cell, size) in spec.items()}

    def after_placement(self, sim) -> None:
        for m in self.maps.values():
            sim.agents.cols[m.origin][...] = sim.agents.cols["pos"]

    def state_dict(self, sim) -> dict:
        return {}   # every bit of a map is in agent columns

    def load_state(self, sim, state: dict) -> None:
        pass
