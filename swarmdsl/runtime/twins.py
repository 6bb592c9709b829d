"""Physical twins at run time: fields whose values are a formula of position and time,
sampled onto the grid's nodes, and vector fields (a force or a flow) built from two
component fields.

A twin is evaluated once when its formula does not read `tick` (a static twin) and
otherwise once per tick, after the move, for the tick about to start: at tick `t`
every agent reads the formula at time `t`. Evaluation is one closure call over every
node at once (a `NodeFrame`), never a loop over nodes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmdsl.errors import SwarmRuntimeError


@dataclass
class TwinSpec:
    """One twin as the compiler hands it over."""

    name: str
    formula: object            # closure(NodeFrame) -> (n_nodes,) or (n_nodes, 2) values
    vector: bool
    static: bool
    span: object = None


class NodeFrame:
    """Evaluation frame over grid nodes at one tick, for a field's formula.

    Formulas may read `pos` (the node's position) and `tick`; random functions draw per
    node from the run's seeded source, keyed by node index.
    """

    def __init__(self, sim, pos: np.ndarray, tick: int | None = None):
        self.sim = sim
        self.pos = pos                                       # (n_nodes, 2)
        self.n = len(pos)
        self.idx = np.arange(self.n)
        self.rng = sim.rng.agents(np.arange(self.n), "grid nodes")  # keyed by node
        self.tick = sim.tick if tick is None else tick
        self.locals: dict = {}
        self.active = np.ones(self.n, dtype=bool)

    def state(self, col: str) -> np.ndarray:
        return self.pos  # the checker admits only `pos` in a field's formula


def evaluate(sim, twin: TwinSpec, pos: np.ndarray, tick: int) -> np.ndarray:
    """The twin's formula at every node ``pos (n, 2)``: ``(n,)`` or ``(n, 2)`` values."""
    shape = (len(pos), 2) if twin.vector else (len(pos),)
    with np.errstate(all="ignore"):   # a NaN or infinity is reported below, located
        values = np.asarray(twin.formula(NodeFrame(sim, pos, tick)), dtype=np.float64)
    try:
        values = np.broadcast_to(values, shape)
    except ValueError:
        raise SwarmRuntimeError(f"the formula of field `{twin.name}` gave values of shape "
                                f"{values.shape}, expected {shape}", twin.span) from None
    if not np.isfinite(values).all():
        bad = int(np.flatnonzero(~np.isfinite(values).reshape(len(pos), -1).all(axis=1))[0])
        x, y = pos[bad]
        raise SwarmRuntimeError(f"the formula of field `{twin.name}` is not finite at the "
                                f"node ({x:g}, {y:g}) at tick {tick}", twin.span)
    return values


class VectorField:
    """A vector quantity on the grid: two scalar fields, one per component.

    Sampling interpolates each component with the grid's own scheme, so a vector twin
    is read exactly like a scalar one (bilinear on a uniform grid, per level on a
    refined one).
    """

    def __init__(self, name: str, x_field, y_field):
        self.name = name
        self.x, self.y = x_field, y_field

    def set_nodes(self, values: np.ndarray) -> None:
        """Set both components from ``(n_nodes, 2)`` values in the grid's node order."""
        self.x.set_nodes(values[:, 0])
        self.y.set_nodes(values[:, 1])

    def sample(self, pos, replica=None) -> np.ndarray:
        """``(M, 2)`` vectors at ``pos (M, 2)`` (of replica ``replica (M,)`` in a batch)."""
        return np.stack([self.x.sample(pos, replica), self.y.sample(pos, replica)], axis=1)
