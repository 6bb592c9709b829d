"""Fields of a batch of replicas: one `(R, ny, nx)` grid per field, each replica's its own.

A batch (`runtime/batch.py`) places each replica with the solo code, so each replica
builds its own environment on its own store and seed: its fields' initial values (a
formula may draw, keyed by the run's seed) are its solo run's. `join_environments`
stacks them into one field of replicas per declared field and keeps replica 0's
environment (regions, obstacles, memories and label sets hold nothing of a run's own:
the regions are shapes, the rest are agent columns) as the batch's. From then on every
reader and `deposit` passes the replica of each point (`Simulation.replicas_of`), decay
and diffusion work grid by grid (`fields.Field` with `replicas`), so each replica's grid
is bit for bit its solo run's at every tick:

- deposits: a frame's points are its agents in batch row order, replica-major and in
  each replica's solo order, and `np.add.at` (or the compiled splat) adds them in
  that order, so shares landing on one node add in the solo order;
- diffusion: the neighbour sum runs over the last two axes only; a replica's border
  nodes reflect or wrap onto its own grid, never a neighbouring replica's.

Physical twins are fields too: each replica's initial sampling is its own (a static
twin's formula may draw, keyed by the run's seed), stacked like the rest. A twin sampled
anew every tick draws nothing (`batch_refusal` refuses one that would), so its formula
gives every replica the same values: it is evaluated once a tick and set on every grid.

`view_environment` gives a replica's view (`BatchedSimulation.replica`) its grids, so
recorders (`fields.npz`), snapshots, metrics and property monitors read the replica's
fields as they read a solo run's.
"""

from __future__ import annotations

import numpy as np

from swarmdsl.runtime.environment import Environment
from swarmdsl.runtime.refined_grid import RefinedField


def environment_of(extensions) -> Environment | None:
    """The run's environment among its extension objects, if it has one."""
    for ext in extensions:
        if isinstance(ext, Environment):
            return ext
    return None


def join_environments(batch, made: list[list]) -> None:
    """Make replica 0's environment the batch's, its fields holding every replica's
    grid (`made[r]`: replica r's extension objects, built on its own store)."""
    envs = [environment_of(m) for m in made]
    env = envs[0]
    if env is None:
        return
    batch.environment = env   # each replica's set itself: the batch's is replica 0's
    for name in env.fields:
        env.fields[name] = _stacked([e.fields[name] for e in envs])
    for name, v in env.vectors.items():
        v.x = _stacked([e.vectors[name].x for e in envs])
        v.y = _stacked([e.vectors[name].y for e in envs])
    if any(not t.static for t in env.twins):
        sample = env._update_twins   # every tick: once, onto every replica's grid
        env._update_twins = lambda sim, tick, static: sample(_TwinSampling(batch), tick,
                                                             static)


def _stacked(fields: list):
    """One field of replicas holding each of `fields`' grids (the replicas' own)."""
    solo = fields[0]
    joined = type(solo)(solo.name, solo.grid, decay=solo.decay, diffuse=solo.diffuse,
                        replicas=len(fields))
    joined.set_nodes(np.concatenate([f.node_values() for f in fields]))
    return joined


class _TwinSampling:
    """The run a twin's formula is sampled in for the whole batch: the batch, with a
    run's own random source for the nodes' streams (a formula sampled every tick draws
    nothing from it: `batch_refusal`)."""

    def __init__(self, batch):
        self._batch = batch
        self.rng = batch._solo_random(batch.seeds[0])
        self.rng.tick = batch.tick

    def __getattr__(self, name):
        return getattr(self._batch, name)


def view_environment(view, batch, r: int, copy: bool) -> None:
    """Give replica r's view (its environment made afresh on it) the replica's grids:
    views of the batch's (read-only, valid until the next tick), or copies (`copy`,
    for a tick rerun alone)."""
    env, mine = view.environment, batch.environment
    if env is None or mine is None:
        return
    def give(own, theirs) -> None:
        if isinstance(own, RefinedField):   # every node of a refined grid
            own.nodes = theirs.nodes[r].copy() if copy else theirs.nodes[r]
            return
        grid = theirs.values[r]
        own._values = grid.copy() if copy else grid

    for name, own in env.fields.items():
        give(own, mine.fields[name])
    for name, v in env.vectors.items():
        give(v.x, mine.vectors[name].x)
        give(v.y, mine.vectors[name].y)
