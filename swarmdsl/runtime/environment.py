"""The environment of a run: fields on the world grid, named regions and obstacles, and
the agents' path memories and label sets. One runtime extension object per run.

Per tick it records where agents stood (for obstacles), and after the move it keeps
agents out of obstacles, lands retracing agents exactly on their remembered points,
then decays and diffuses every field once over the whole grid.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from swarmdsl.errors import SwarmRuntimeError
from swarmdsl.ops import portable, portable_runtime
from swarmdsl.runtime.choice import (
    angles_of,
    checked,
    compiled_loops,
    direction_units,
    steps_table,
    weighted_direction_choice,
)
from swarmdsl.runtime.fields import Field, Grid
from swarmdsl.runtime.memory import LabelSet, PathMemory
from swarmdsl.runtime.refined_grid import RefinedField, RefinedGrid
from swarmdsl.runtime.regions import Region, block_moves
from swarmdsl.runtime.twins import NodeFrame, TwinSpec, VectorField, evaluate
from swarmdsl.runtime.world import short_way


@dataclass
class FieldSpec:
    name: str
    decay: float
    diffuse: float
    init: object = None          # closure(NodeFrame) -> (n_nodes,) values, or None
    span: object = None


@dataclass
class EnvSpec:
    """What the compiler hands the runtime: declared fields, regions, memories, sets."""

    fields: list[FieldSpec] = field(default_factory=list)
    regions: list[Region] = field(default_factory=list)
    memories: dict[str, int] = field(default_factory=dict)    # name -> capacity
    label_sets: list[str] = field(default_factory=list)
    twins: list[TwinSpec] = field(default_factory=list)
    refinements: list = field(default_factory=list)   # [(Shape, levels)]


# `place uniform` around obstacles: candidates per agent per round, and rounds.
PLACE_BATCH, PLACE_ROUNDS = 8, 1000


_NO_LABELS = np.zeros(0, np.int64)   # `choose`'s attraction without `unknown(...)`


def _circle_table(regions):
    """``(cx, cy, r)`` arrays when every region is a circle, else False."""
    from swarmdsl.runtime.regions import Circle

    if not regions or not all(isinstance(r.shape, Circle) for r in regions):
        return False
    return tuple(np.array([getattr(r.shape, a) for r in regions]) for a in ("cx", "cy", "r"))


def kernel_blockers(spec) -> list[str]:
    """What keeps an environment of `spec` (or a run's `Environment`) out of the
    whole-tick kernel, in words: each path memory, label set and obstacle (they change
    or act in Python every tick), a refined grid. Empty: the kernel holds it (regions,
    fields on a uniform grid, twins: the plan refuses a formula it cannot work out)."""
    refined = getattr(spec, "refinements", None)
    if refined is None:   # a run's environment: its grid says
        refined = isinstance(spec.grid, RefinedGrid)
    regions = spec.regions.values() if isinstance(spec.regions, dict) else spec.regions
    return [*(f"path memory `{m}`" for m in spec.memories),
            *(f"label set `{s}`" for s in spec.label_sets),
            *(f"obstacle `{r.name}`" for r in regions if r.kind == "obstacle"),
            *(["its refined grid"] if refined else [])]


class Environment:
    """The runtime extension for fields, regions, obstacles and per-agent memories."""

    def __init__(self, sim, spec: EnvSpec):
        sim.environment = self
        w = sim.world
        self.grid = Grid(w.width, w.height, w.grid, periodic=w.wraps)
        make = sim.backend.field_type(Field)   # numba: the field loops compiled, same bits
        if spec.refinements:   # numba: the refined grid's reading and diffusion compiled
            grid_type, make = getattr(make, "refined", (RefinedGrid, RefinedField))
            self.grid = grid_type(self.grid, spec.refinements)
        if spec.fields or spec.twins:   # what `run -v` reports
            sim.backend.fields_compiled = make not in (Field, RefinedField)
        self.fields: dict[str, Field] = {}
        for fs in spec.fields:
            f = make(fs.name, self.grid, decay=fs.decay, diffuse=fs.diffuse)
            if fs.init is not None:
                nodes = NodeFrame(sim, self.grid.node_positions())
                with np.errstate(all="ignore"):   # reported below, located
                    values = np.asarray(fs.init(nodes), dtype=np.float64)
                values = np.broadcast_to(values, (nodes.n,))
                if not np.isfinite(values).all():
                    raise SwarmRuntimeError(
                        f"the initial value of field `{fs.name}` is not finite at some node",
                        fs.span)
                f.set_nodes(values)
            self.fields[fs.name] = f
        self.twins = spec.twins
        self.vectors: dict[str, VectorField] = {
            t.name: VectorField(t.name, make(t.name + ".x", self.grid),
                                make(t.name + ".y", self.grid))
            for t in spec.twins if t.vector}
        self._update_twins(sim, sim.tick, static=True)
        self.regions: dict[str, Region] = {r.name: r for r in spec.regions}
        self.food: list[Region] = [r for r in spec.regions if r.kind == "food"]
        self.obstacles: list[Region] = [r for r in spec.regions if r.kind == "obstacle"]
        self.memories = {n: PathMemory(sim.agents, n, k) for n, k in spec.memories.items()}
        self.label_sets = {n: LabelSet(sim.agents, n) for n in spec.label_sets}
        self._circles: dict[str, object] = {}
        self._bearings: dict[str, tuple] = {}    # name -> `_bearing_table`
        self._world = w
        self._box = w.box   # (W, H) in a wrap-around world: regions repeat across edges
        self._old_pos: np.ndarray | None = None
        self._landings: list[tuple[np.ndarray, np.ndarray]] = []

    # ---- regions ----
    def select(self, name: str) -> list[Region]:
        """The regions a name stands for: one declared region, or every region of a kind."""
        if name in self.regions:
            return [self.regions[name]]
        return [r for r in self.regions.values() if r.kind == name]

    def distances(self, name: str, pts: np.ndarray) -> np.ndarray:
        """``(M, R)`` distance from each point to each region the name stands for (to
        its nearest copy in a wrap-around world, where a region repeats across edges)."""
        regions = self.select(name)
        circles = self._circle_table(name)
        if circles is not False:  # all circles: one broadcast, no loop
            cx, cy, r = circles
            dx, dy = pts[:, 0, None] - cx, pts[:, 1, None] - cy
            if self._box is not None:   # a disc's nearest copy: the centre's, short way
                w, h = self._box
                dx, dy = short_way(dx, w), short_way(dy, h)
            d = portable.hypot_array(dx, dy) - r
            return np.maximum(d, 0.0)
        if not regions:
            return np.zeros((len(pts), 0))
        return np.stack([r.distance(pts, self._box) for r in regions], axis=1)  # per region

    def _circle_table(self, name: str):
        """``(cx, cy, r)`` of the regions `name` stands for when all are circles, else
        False: made once (regions are declared, not changed by a run)."""
        circles = self._circles.get(name)
        if circles is None:
            circles = self._circles[name] = _circle_table(self.select(name))
        return circles

    def distance_to(self, name: str, pts: np.ndarray) -> np.ndarray:
        """``(M,)`` distance from each point to the nearest region named (0 inside)."""
        d = self.distances(name, pts)
        return d.min(axis=1) if d.shape[1] else np.full(len(pts), np.inf)

    def touched_label(self, pts: np.ndarray, reach) -> np.ndarray:
        """``(M,) int64``: index of the first food source within ``reach``, -1 if none."""
        near = self.distances("food", pts) <= np.asarray(reach)[..., None]  # (M, F)
        return np.where(near.any(axis=1), near.argmax(axis=1), -1).astype(np.int64)

    def place_in(self, sim, region: str, n: int, frame) -> np.ndarray:
        """``(n, 2)`` starting points uniform over a region (or a kind's regions, by area).

        In a wrap-around world the part of a region beyond an edge is the part across the
        other edge, so points drawn there start at that point of the world."""
        pts = self._place_in(region, n, frame)
        if self._box is None:
            return pts
        size = np.asarray(self._box)
        pts = np.mod(pts, size)
        return np.where(pts >= size, 0.0, pts)   # the mod of -tiny rounds up to the size

    def place_uniform(self, sim, kind, frame) -> np.ndarray | None:
        """``(n, 2)`` starting points uniform over the world outside every obstacle
        (`place uniform`, the default), or None when there is no obstacle to avoid (the
        plain uniform draw, unchanged). Each agent redraws until its point is free: a
        rejection from fixed lanes of one draw per agent, so a point depends on the seed
        and the agent's id alone, on either backend. A free area too small to hit in
        8,000 tries per agent is an error at the kind, not agents placed in walls."""
        if not self.obstacles:
            return None
        box = self._box

        def free(pts: np.ndarray) -> np.ndarray:
            blocked = np.zeros(len(pts), dtype=bool)
            for obstacle in self.obstacles:     # a loop over obstacles, not agents
                blocked |= obstacle.shape.contains_around(pts, box)
            return ~blocked

        w = sim.world
        rng = frame.rng.at("pos")
        try:
            return rng.rejection(free, (0.0, 0.0), (w.width, w.height),
                                 batch=PLACE_BATCH, rounds=PLACE_ROUNDS)
        except ValueError:
            spans = kind.option_spans
            raise SwarmRuntimeError(
                f"cannot place the agents of `{kind.name}` outside the obstacles: "
                f"{PLACE_BATCH * PLACE_ROUNDS} random points per agent all fell inside "
                "one, so the free part of the world is too small to find",
                spans.get("place") or spans.get("count"),
                "shrink the obstacles, or `place in` a region that is free") from None

    def _place_in(self, region: str, n: int, frame) -> np.ndarray:
        chosen = self.select(region)
        rng = frame.rng.at(f"place in {region}")
        if len(chosen) == 1:
            return chosen[0].sample_points_inside(rng, n)
        areas = np.array([r.shape.area() for r in chosen])
        which = rng.choice(len(chosen), size=n, p=areas / areas.sum())
        pts = np.empty((n, 2))
        for i, r in enumerate(chosen):   # every region draws, so no agent's point shifts
            rows = np.flatnonzero(which == i)
            pts[rows] = r.sample_points_inside(rng.subset(rows), rows.size)
        return pts

    # ---- direction choice ----
    def choose(self, f, k: int, persistence: float, attractors) -> np.ndarray:
        """Angles ``(M,)``: one of ``k`` compass directions per agent (see docs).

        ``attractors`` is a list of ``(gain (M,), name, is_field, known)``, ``known``
        being ``(M,)`` label bit masks of food sources to ignore, or None. A field contributes
        its value one look-ahead away in each direction; a region kind contributes
        ``max(cos(direction - bearing), 0)`` toward the nearest such region within the
        look-ahead that the agent is not already inside. Weights are multiplied by
        ``exp(sum of gain * contribution)`` (a negative gain repels).
        """
        m = f.n
        heading = np.asarray(f.state("heading"), dtype=np.float64)
        loops = compiled_loops() if attractors and m else None
        if loops is not None:
            idx = self._choose_compiled(loops, f, k, persistence, attractors, heading)
            if idx is not None:
                return angles_of(k)[idx]
        extra = None
        if attractors and m:
            pos = f.state("pos")
            angles = angles_of(k)                                          # (k,)
            look = self._look(f)                                           # (M,)
            logits = np.zeros((m, k))
            for gain, name, is_field, known in attractors:
                gain = np.asarray(gain, dtype=np.float64)
                gain = gain[:, None] if gain.ndim else gain       # (M, 1) or a number
                if is_field:
                    s = self._field_scores(f, name, pos, look, k)
                else:
                    s = self._bearing_scores(name, pos, look, angles, known)
                logits += gain * portable_runtime.log1p_array(np.maximum(s, 0.0))
            logits -= logits.max(axis=1, keepdims=True)
            extra = portable.exp_array(logits)
        idx = weighted_direction_choice(f.rng, heading, k, persistence, extra)
        return angles_of(k)[idx]

    def _choose_compiled(self, loops, f, k, persistence, attractors, heading):
        """`choose` by the numba backend's two loops (`compiled/direction_choice.py`):
        the same checks, samples, draw and bits as the array forms below, in a few calls
        instead of dozens. None (the array forms) when a region kind is not all circles
        or a heading is too large for its direction's index to be a 64-bit integer."""
        scores, pick = loops
        heading, k, persistence = checked(heading, k, persistence)
        to_index = k / (2.0 * np.pi)
        if heading.size and max(-heading.min(), heading.max()) * to_index >= 2.0 ** 62:
            return None
        if any(not is_field and self._circle_table(name) is False
               for _g, name, is_field, _known in attractors):
            return None
        m = f.n
        pos = np.ascontiguousarray(f.state("pos"), dtype=np.float64)
        look = self._look(f).astype(np.float64)
        angles = angles_of(k)
        box = np.asarray(self._box if self._box is not None else (0.0, 0.0), np.float64)
        w = self._world
        wrap = np.array([w.width, w.height] if w.wraps else [0.0, 0.0], np.float64)
        S, G = np.empty((len(attractors), m, k)), np.empty((len(attractors), m))
        for t, (gain, name, is_field, known) in enumerate(attractors):
            G[t] = gain
            if is_field:
                S[t] = self._field_scores(f, name, pos, look, k)
                continue
            cx, cy, r = (np.asarray(a, np.float64) for a in self._circle_table(name))
            bits, centers = self._bearing_table(name)
            known = _NO_LABELS if known is None else np.asarray(known).astype(np.int64)
            scores(pos, look, cx, cy, r, bits, known, centers, angles, box, wrap, S[t])
        draws = f.rng.random(m)
        out = np.empty(m, np.int64)
        if pick(S, G, steps_table(k, persistence), heading, to_index, draws, out):
            raise ValueError("weights_extra must be finite and not negative")
        return out

    def _look(self, f) -> np.ndarray:
        """``(M,)`` how far ahead each agent looks: its sense radius, else a grid step."""
        look = f.state("sense")
        return np.where(look > 0, look, self.grid.spacing)

    def _field_scores(self, f, name, pos, look, k) -> np.ndarray:
        """``(M, k)`` the field's value one look ahead in each direction."""
        pts = pos[:, None, :] + look[:, None, None] * direction_units(k)[None]  # (M, k, 2)
        rep = f.sim.replicas_of(f.idx)   # a batch's: each on its grid
        m = len(pos)
        return self.fields[name].sample(
            pts.reshape(-1, 2), None if rep is None else np.repeat(rep, k)).reshape(m, k)

    def _bearing_scores(self, name, pos, look, angles, known=None) -> np.ndarray:
        """``(M, k)`` closeness of each direction to the bearing of the nearest region
        in sight; ``known`` ``(M,)`` label bit masks hide food sources an agent knows."""
        bits, centers = self._bearing_table(name)                    # (R,), (R, 2)
        d = self.distances(name, pos)                                   # (M, R)
        seen = (d > 0) & (d <= look[:, None])
        if known is not None:
            seen &= (known[:, None] & bits[None, :]) == 0
        d = np.where(seen, d, np.inf)
        nearest = d.argmin(axis=1) if d.shape[1] else np.zeros(len(pos), np.int64)
        any_seen = seen.any(axis=1)
        c = centers[nearest] if len(centers) else np.zeros((len(pos), 2))
        toward = self._world.short_way(c - pos)   # across the edge when shorter
        bearing = portable.atan2_array(toward[:, 1], toward[:, 0])
        score = np.maximum(portable.cos_array(angles[None, :] - bearing[:, None]), 0.0)
        return np.where(any_seen[:, None], score, 0.0)

    def _bearing_table(self, name):
        """(label bits (R,), centres (R, 2)) of the regions `name` stands for: made once
        (regions are declared, not changed by a run)."""
        got = self._bearings.get(name)
        if got is None:
            regions = self.select(name)
            bits = np.array([1 << self.food.index(r) if r.kind == "food" else 0
                             for r in regions], dtype=np.int64)
            centers = np.array([r.center for r in regions], dtype=np.float64).reshape(-1, 2)
            got = self._bearings[name] = (bits, centers)
        return got

    # ---- physical twins ----
    def _update_twins(self, sim, tick: int, static: bool) -> None:
        """Sample every twin (``static``: also the static ones) onto the nodes at ``tick``."""
        pos = None
        for t in self.twins:
            if t.static and not static:
                continue
            if pos is None:
                pos = self.grid.node_positions()
            values = evaluate(sim, t, pos, tick)
            target = self.vectors[t.name] if t.vector else self.fields[t.name]
            target.set_nodes(values)

    # ---- memories ----
    def land(self, rows: np.ndarray, points: np.ndarray) -> None:
        """Agents ``rows`` retraced toward ``points`` this tick; land them exactly."""
        if rows.size:
            self._landings.append((rows, points))

    # ---- extension hooks ----
    def state_dict(self, sim) -> dict:
        """Field values; memories and label sets are agent columns, saved with them."""
        return {f"field:{name}": f.node_values().copy() for name, f in self.fields.items()}

    def load_state(self, sim, state: dict) -> None:
        for name, f in self.fields.items():
            f.set_nodes(np.array(state[f"field:{name}"], dtype=np.float64).reshape(-1))
        self._update_twins(sim, sim.tick, static=False)  # vector twins: from the formula

    def begin_tick(self, sim) -> None:
        self._old_pos = sim.agents.cols["pos"].copy() if self.obstacles else None
        self._landings = []

    def end_tick(self, sim) -> None:
        cols = sim.agents.cols
        if self._landings:
            pos = cols["pos"]
            for rows, points in self._landings:
                # the gap the short way round: in a wrap-around world an agent that
                # landed a rounding error below 0 was wrapped to just below the width
                gap = sim.world.short_way(pos[rows] - points)
                close = np.abs(gap).max(axis=1) <= 1e-9 * (1.0 + np.abs(points).max(axis=1))
                pos[rows[close]] = points[close]
        if self.obstacles and self._old_pos is not None and len(self._old_pos) == len(
                cols["pos"]):
            cols["pos"] = block_moves(self._old_pos, cols["pos"], self.obstacles,
                                      self._box)
        for f in self.fields.values():
            f.step()
        if self.twins:
            self._update_twins(sim, sim.tick + 1, static=False)

    def decorate_snapshot(self, sim, snap) -> None:
        snap.fields = {name: f.values.copy() for name, f in self.fields.items()}
        snap.vectors = {name: np.stack([v.x.values, v.y.values], axis=-1)
                        for name, v in self.vectors.items()}
        # copies, as the snapshot promises: a viewer or notebook that edits them must not
        # move the grid the fields are sampled on
        snap.grid_x, snap.grid_y = self.grid.grid_x.copy(), self.grid.grid_y.copy()
        if isinstance(self.grid, RefinedGrid):   # a uniform grid's nodes are grid_x x grid_y
            snap.grid_points = self.grid.node_positions().copy()
        snap.regions = self.regions_json(sim)

    def field_values(self, sim) -> dict[str, np.ndarray]:
        """Scalar fields by name; a vector field as its components `NAME.x`, `NAME.y`."""
        out = {name: f.values for name, f in self.fields.items()}
        for v in self.vectors.values():
            out[v.x.name], out[v.y.name] = v.x.values, v.y.values
        return out

    def grid_nodes(self, sim):
        return self.grid.grid_x, self.grid.grid_y

    def refined_nodes(self, sim) -> dict[str, np.ndarray]:
        """A refined grid's every node for `fields.npz`: positions and levels, in node
        id order (base nodes first, row by row); nothing for a uniform grid."""
        if not isinstance(self.grid, RefinedGrid):
            return {}
        pos = self.grid.node_positions()
        return {"nodes_x": pos[:, 0], "nodes_y": pos[:, 1],
                "nodes_level": self.grid.level.copy()}

    def field_node_values(self, sim) -> dict[str, np.ndarray]:
        """On a refined grid, every field's values on every node (`NAME.nodes`, in
        node id order): `field_values` holds the base nodes only."""
        if not isinstance(self.grid, RefinedGrid):
            return {}
        out = {}
        for name, values in self.field_values(sim).items():
            owner = self.fields.get(name) or self._vector_part(name)
            if owner is not None:
                out[name + ".nodes"] = owner.node_values()
        return out

    def _vector_part(self, name: str):
        for v in self.vectors.values():
            for part in (v.x, v.y):
                if part.name == name:
                    return part
        return None

    def regions_json(self, sim) -> list[dict]:
        return [r.to_json() for r in self.regions.values()]
