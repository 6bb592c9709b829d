"""Mesa's own boid flockers (`mesa.examples.basic.boid_flockers`), as Mesa ships them.

Mesa is only a yardstick here, never a swarmdsl dependency: `python -m benchmarks`
skips this column when it is not installed (`pip install mesa`). Its rules are Mesa's,
not `boids.swarm`'s (asynchronous updates in random order, a torus, its own weights), so
the comparison is of the cost of the same kind of work at the same size and density:
N agents on the swarmdsl world's area, vision = the program's radius (80), at the speed
of `boids.swarm` (3). The statistics printed beside it (neighbours within the radius)
show that both see as many neighbours per tick.
"""

from __future__ import annotations

import numpy as np


class MesaBoids:
    def __init__(self, start: dict, params: dict, seed: int):
        from mesa.examples.basic.boid_flockers.model import BoidFlockers

        self.model = BoidFlockers(population_size=len(start["pos"]), width=params["width"],
                                  height=params["height"], speed=3, vision=80,
                                  separation=0.4 * 80, seed=seed)

    def step(self) -> None:
        self.model.step()

    def state(self) -> dict:
        agents = list(self.model.agents)
        pos = np.array([a.position for a in agents], dtype=np.float64)
        vel = np.array([a.direction * a.speed for a in agents], dtype=np.float64)
        return {"pos": pos, "vel": vel}
