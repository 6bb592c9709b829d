"""The leaves of behaviour trees: conditions, instant actions and the long actions
(`wait`, `move_to`, `retrace`, `follow`), each ticked over a whole frame at once.

A leaf notes itself as the rows' active leaf (when someone records it), does its work
for the rows in `mask` only, and returns `(succ, fail)` like every node
(`runtime/trees.py`).
"""

from __future__ import annotations

import numpy as np

from swarmdsl.errors import SwarmRuntimeError
from swarmdsl.runtime.trees import Ctx, Node, Stateful, no_result, none_of, per_row


class Leaf(Node):
    """A tick with no rows does nothing (no closure runs); otherwise the leaf notes
    itself as the active leaf of its rows, then acts for them."""

    def tick(self, c, mask):
        if not mask.any():
            return no_result(mask.size)
        if c.leaf is not None:
            c.leaf[mask] = self.leaf_id
        return self.act(c, mask)

    def act(self, c: Ctx, mask):  # pragma: no cover - abstract
        raise NotImplementedError


class Condition(Leaf):
    def __init__(self, fn, span):
        self.fn, self.span = fn, span

    def act(self, c, mask):
        v = np.asarray(self.fn(c.f), dtype=bool)
        if v.shape != mask.shape:
            v = np.broadcast_to(v, mask.shape)
        s = mask & v
        return s, mask ^ s


def run_masked(f, mask, fn) -> None:
    """Run a statement closure for the rows in `mask` only (statements obey f.active)."""
    saved = f.active
    f.active = mask       # a tree's rows are always among the body's active ones
    try:
        fn(f)
    finally:
        f.active = saved


class Action(Leaf):
    """An instant action (assignment, `deposit`, `broadcast`, ...): succeeds at once."""

    def __init__(self, fn, span):
        self.fn, self.span = fn, span

    def act(self, c, mask):
        run_masked(c.f, mask, self.fn)
        return mask.copy(), none_of(mask.size)


class Wait(Leaf, Stateful):
    """`wait(N)`: running on its first N ticks, success on the next."""

    def __init__(self, layout, tree, index, n, span):
        super().__init__(layout, tree, index, "elapsed", np.int64, 0)
        self.n, self.span = n, span

    def act(self, c, mask):
        elapsed = self.read(c) + 1
        done = elapsed > per_row(self.n(c.f), mask.size)
        self.write(c, mask & ~done, elapsed)
        return mask & done, none_of(mask.size)


def _speed(f, speed):
    """Steering speed: the given one, else the agent's finite max_speed, else 1."""
    if speed is not None:
        return np.broadcast_to(np.asarray(speed(f), dtype=np.float64), (f.n,))
    limit = np.take(f.sim.agents.cols["max_speed"], f.idx)
    return np.where(np.isfinite(limit), limit, 1.0)


def _check_velocity(f, mask, vel_rows, span, what) -> None:
    if not np.isfinite(vel_rows[mask]).all():
        raise SwarmRuntimeError(f"`{what}` produced a non-finite velocity at tick {f.tick}",
                                span, "check its target and speed for NaN")


def _steer(f, mask, vel_rows, span, what) -> None:
    _check_velocity(f, mask, vel_rows, span, what)
    cur = f.state("vel")
    f.overlay["vel"] = np.where(mask[:, None], vel_rows, cur)


class MoveTo(Leaf):
    """`move_to(TARGET, tol[, speed])`: steer straight at the target, arriving exactly;
    success (and velocity 0) once within `tol`, running before. It never fails alone.
    In a wrap-around world "straight at" is the short way round, across the edge when
    that is shorter."""

    def __init__(self, target, tol, speed, span):
        self.target, self.tol, self.speed, self.span = target, tol, speed, span

    def act(self, c, mask):
        n = mask.size
        f = c.f
        pos = np.asarray(f.state("pos"), dtype=np.float64)
        target = np.broadcast_to(np.asarray(self.target(f), dtype=np.float64), (n, 2))
        d = f.sim.world.short_way(target - pos)
        dist = np.sqrt(np.einsum("ij,ij->i", d, d))
        arrived = dist <= np.broadcast_to(np.asarray(self.tol(f), np.float64), (n,))
        step = np.minimum(_speed(f, self.speed), dist)
        with np.errstate(invalid="ignore", divide="ignore"):
            vel = np.where(arrived[:, None] | (dist[:, None] == 0), 0.0,
                           d / dist[:, None] * step[:, None])
        _steer(f, mask, vel, self.span, "move_to")
        return mask & arrived, none_of(n)


class Retrace(Leaf):
    """`retrace(MEMORY)`: running while the path memory holds points (one popped per
    tick, the agent landing exactly on it), success once it is empty."""

    def __init__(self, fn, length, span):
        self.fn, self.length, self.span = fn, length, span

    def act(self, c, mask):
        empty = self.length(c.f) == 0
        run_masked(c.f, mask, self.fn)   # pops one point; velocity 0 when empty
        return mask & empty, none_of(mask.size)


class Follow(Leaf):
    """`follow(FIELD[, speed])`: steer up the field's gradient, running while that
    climbs. A gradient of exactly 0 is rare in floating point even at a peak, so the
    peak is found the way a hill climber finds it: success (and velocity 0) once the
    step it would take lands no higher than where the agent stands, or tops out within
    its first half, which puts the agent within about half a step of a smooth peak
    instead of oscillating across it.
    Where the gradient is exactly 0 it succeeds if the value is above 0 (a plateau)
    and fails otherwise (nothing to follow)."""

    def __init__(self, field, speed, span):
        self.field, self.speed, self.span = field, speed, span

    def act(self, c, mask):
        f = c.f
        field = self.field(f)
        pos = np.asarray(f.state("pos"), dtype=np.float64)
        rep = f.sim.replicas_of(f.idx)   # a batch's: each agent on its replica's grid
        v = field.sample(pos, rep)
        g = field.gradient(pos, rep)
        norm = np.sqrt(np.einsum("ij,ij->i", g, g))
        flat = norm == 0
        with np.errstate(invalid="ignore", divide="ignore"):
            vel = np.where(flat[:, None], 0.0,
                           g / norm[:, None] * _step(f, self.speed)[:, None])
        _check_velocity(f, mask, vel, self.span, "follow")
        landing = _landing(f, pos, vel, mask)
        share = _top_along_the_step(g, norm, field.gradient(landing, rep))
        top = ~flat & ((field.sample(landing, rep) <= v) | (share <= 0.5))
        cut = ~flat & ~top & (share < 1)
        vel[top] = 0.0
        vel[cut] *= share[cut, None]
        _steer(f, mask, vel, self.span, "follow")
        done = flat | top
        up = top | (v > 0)
        return mask & done & up, mask & done & ~up


def _top_along_the_step(g, norm, g_landing):
    """How far along its step (0..1) the field tops out, where the slope along the step
    turns down before the landing (linearly between the slope here, `norm`, and the
    one at the landing); infinity where it climbs on at the landing. A step landing a
    hair higher past the top hopped across a peak for ever, each landing a hair higher
    than the last: a top within half the step ends the climb, as a hill climber's
    tolerance is its step, and a top further on is stepped to (on a ridge, the ridge's
    gradient then leads on along it)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        ahead = np.einsum("ij,ij->i", g_landing, g) / norm    # the slope there
        return np.where(ahead < 0, norm / (norm - ahead), np.inf)


def _step(f, speed):
    """The length of the step the agent will really take: the speed the leaf asks for,
    cut to the agent's max_speed as the motion step cuts it."""
    limit = np.take(f.sim.agents.cols["max_speed"], f.idx)
    return np.minimum(_speed(f, speed), limit)


def _landing(f, pos, vel, mask):
    """Where each agent in `mask` lands if it moves by `vel` this tick, with the
    world's edges applied (wrapped, or reflected off a wall); the others stay put."""
    vel = np.where(mask[:, None], vel, 0.0)
    return f.sim.world.move(pos, vel)[0]
