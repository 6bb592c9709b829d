"""Objectives (the thesis' O) in the language: `objective NAME = TARGET` in an agent
kind, and the movement primitives that steer toward it.

`TARGET` is re-evaluated every tick, per agent: a point (a vector expression, which may
read the agent's variables), a region or region kind (its nearest point), or an agent
kind (the nearest other agent of that kind, the short way round a wrap-around world).
`target(O)`, `toward(O)`, `approach(O, speed)` and `arrived(O [, reach])` read it; the
last three go the short way round a wrap-around world, as `other.pos - pos` does.
"""

from __future__ import annotations

import numpy as np

from swarmdsl.compiler import ast, checker, codegen, typing_rules
from swarmdsl.compiler.builtins import (
    BOOL,
    KIND,
    NUM,
    REGION,
    TYPE_TEXT,
    VEC,
    Refused,
    declare_calls,
)
from swarmdsl.compiler.lang_fields import arity, env_info, env_of
from swarmdsl.compiler.options import refuse_negative
from swarmdsl.ops import portable

ERR = "error"
OBJECTIVE = "objective"
TYPE_TEXT.setdefault(OBJECTIVE, "an objective")
ARRIVED = 1e-6          # default reach of `arrived`: float rounding of an exact landing


def _objectives(chk) -> dict:
    """kind name -> {objective name: (decl, target type)}."""
    return chk.extra.setdefault("objectives", {})


def _declare(chk) -> None:
    table = _objectives(chk)
    for agent in chk.tree.decls_of(ast.AgentDecl):
        mine = table.setdefault(agent.name, {})
        for d in agent.items_of(ast.ObjectiveDecl):
            if d.name in mine:
                chk.fail(f"objective `{d.name}` is already declared in `{agent.name}`",
                         d.name_span)
                continue
            chk.name_taken(d.name, d.name_span)
            mine[d.name] = (d, ERR)
            # Targets are checked after the kind's body; the variables they read count
            # as read (no "never read" warning for `objective goal = (gx, gy)`).
            own = {v.name for v in agent.items_of(ast.VarDecl)}
            chk.used_vars.update((agent.name, n.id) for n in ast.walk(d.target)
                                 if isinstance(n, ast.Name) and n.id in own)


checker.DECL_HOOKS.append(_declare)


def _check_targets(chk, kind) -> None:
    from swarmdsl.compiler.scope import Scope

    mine = _objectives(chk).get(kind.name, {})
    for name, (d, _t) in list(mine.items()):
        if name in kind.vars:
            chk.fail(f"`{name}` names both an objective and a variable", d.name_span)
        t = chk.expr(d.target, Scope(kind))
        if t == REGION:
            env_info(chk).used = True
        if t not in (VEC, REGION, KIND, ERR):
            chk.fail(f"an objective is a point, a region or an agent kind, got "
                     f"{TYPE_TEXT.get(t, t)}", d.target.span)
            t = ERR
        mine[name] = (d, t)


checker.KIND_HOOKS.insert(0, _check_targets)


def _resolve(chk, e: ast.Name, scope):
    k = scope.kind
    if k is not None and e.id in _objectives(chk).get(k.name, {}):
        chk.facts.set_name(e, ("objective", k.name, e.id))
        return OBJECTIVE
    return None


typing_rules.NAME_RESOLVERS.append(_resolve)


def _rule(usage: str, lo: int, hi: int, extra: str | None, result: str):
    def rule(chk, call, scope):
        if not arity(chk, call, scope, lo, hi, usage):
            return ERR
        a = call.args[0]
        t = chk.expr(a, scope)
        if t != ERR and (t != OBJECTIVE or not isinstance(a, ast.Name)):
            chk.fail(f"`{call.name}` needs an objective (declare it with `objective NAME "
                     f"= TARGET`), got {TYPE_TEXT.get(t, t)}", a.span)
        if len(call.args) == 2 and chk.expect(call.args[1], NUM, scope, extra) == NUM:
            refuse_negative(chk, call.args[1], f"{extra} of `{call.name}`")
        chk.facts.set_name(call, ("objective_call", call.name))
        return result
    return rule


typing_rules.CALL_RULES.update({
    "target": _rule("target(OBJECTIVE)", 1, 1, None, VEC),
    "toward": _rule("toward(OBJECTIVE)", 1, 1, None, VEC),
    "approach": _rule("approach(OBJECTIVE, speed)", 2, 2, "the speed", VEC),
    "arrived": _rule("arrived(OBJECTIVE [, reach])", 1, 2, "the reach", BOOL),
})
# toward a point or region per agent; toward agents, searched in the replica's own rows
declare_calls(("target", "toward", "approach", "arrived"), batch=True,
              kilobot=Refused("objectives are not translated to C yet"))


# ---- run time ----

def _nearest_on(shape, pts: np.ndarray) -> np.ndarray:
    """``(M, 2)`` the nearest point of a shape (itself inside); a polygon's centre."""
    from swarmdsl.runtime.regions import Circle, Rect

    if isinstance(shape, Rect):
        return np.stack([np.clip(pts[:, 0], shape.x0, shape.x1),
                         np.clip(pts[:, 1], shape.y0, shape.y1)], axis=1)
    if isinstance(shape, Circle):
        c = np.array([shape.cx, shape.cy])
        d = pts - c
        n = portable.hypot_array(d[:, 0], d[:, 1])
        out = c + d * (shape.r / np.where(n > 0, n, 1.0))[:, None]
        return np.where((n <= shape.r)[:, None], pts, out)
    inside = shape.distance(pts) <= 0
    return np.where(inside[:, None], pts, np.asarray(shape.center, dtype=np.float64))


def _nearest_around(shape, pts: np.ndarray, box) -> np.ndarray:
    """``(M, 2)`` the nearest point of the nearest copy of a shape in a wrap-around world
    (a region near one edge is near the agents across the other), as a point of the
    world: the copy's point moved back by the offset the point was measured from."""
    q = shape.images(pts, box)                                        # (S, M, 2)
    d = shape.distance(q.reshape(-1, 2)).reshape(q.shape[:2])         # (S, M)
    qb = q[d.argmin(axis=0), np.arange(len(pts))]                     # (M, 2)
    return _into_box(pts + (_nearest_on(shape, qb) - qb), box)


def region_target(f, name: str, pos: np.ndarray) -> np.ndarray:
    env = env_of(f)
    regions = env.select(name)
    if not regions:
        return pos
    box = f.sim.world.box
    which = env.distances(name, pos).argmin(axis=1)
    out = np.empty_like(pos)
    for i, r in enumerate(regions):   # a loop over regions (a handful), not agents
        rows = np.flatnonzero(which == i)
        out[rows] = _nearest_on(r.shape, pos[rows]) if box is None else \
            _nearest_around(r.shape, pos[rows], box)
    return out


def _agent_target(f, kind_index: int, pos: np.ndarray) -> np.ndarray:
    """The nearest other agent of a kind (start-of-tick positions); itself if none.

    In a wrap-around world "nearest" is measured the short way round, as neighbour
    queries are: an agent just across the edge is nearer than one across the world.
    A batch of replicas searches each replica's agents alone, as its solo run does
    (the same points in the same order: the same tree, the same answers)."""
    cols = f.sim.agents.cols
    rows = np.flatnonzero(cols["kind"] == kind_index)
    own = f.idx
    bounds = f.sim.replica_bounds()
    if bounds.size == 2:
        return _nearest_of_kind(f.sim, rows, own, pos)
    out = np.empty_like(pos)
    replica = np.searchsorted(bounds, own, side="right") - 1
    kind_cut = np.searchsorted(rows, bounds)
    for r in np.unique(replica):   # a loop over replicas, not agents
        mine = np.flatnonzero(replica == r)
        out[mine] = _nearest_of_kind(f.sim, rows[kind_cut[r]:kind_cut[r + 1]], own[mine],
                                     pos[mine])
    return out


def _nearest_of_kind(sim, rows: np.ndarray, own: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """For agents at rows `own` (at `pos`): the position of the nearest other agent
    among `rows`, or their own position when there is none."""
    from scipy.spatial import cKDTree

    cols = sim.agents.cols
    if rows.size == 0 or (rows.size == 1 and np.isin(rows, own).all()):
        return pos
    box = sim.world.box
    if box is None:
        tree = cKDTree(cols["pos"][rows])
        query = pos
    else:
        tree = cKDTree(_into_box(cols["pos"][rows], box), boxsize=box)
        query = _into_box(pos, box)
    k = min(2, rows.size)
    _d, near = tree.query(query, k=k)
    near = near.reshape(len(pos), k)
    first = rows[near[:, 0]]
    pick = np.where(first == own, rows[near[:, -1]], first)
    alone = pick == own
    return np.where(alone[:, None], pos, cols["pos"][pick])


def _into_box(pts: np.ndarray, box) -> np.ndarray:
    """Points wrapped into ``[0, W) x [0, H)`` (a periodic KD-tree refuses a point at W:
    the modulo of a tiny negative number can round up to it)."""
    size = np.asarray(box, dtype=np.float64)
    out = np.mod(pts, size)
    return np.where(out >= size, 0.0, out)


def _target_fn(gen, res):
    _cat, kind_name, name = res
    d, t = gen.info.extra["objectives"][kind_name][name]
    value = gen.expr(d.target)

    def target(f):
        pos = np.asarray(f.state("pos"), dtype=np.float64)
        if t == VEC:
            return np.broadcast_to(np.asarray(value(f), np.float64), (f.n, 2))
        if t == REGION:
            return region_target(f, value(f), pos)
        return _agent_target(f, int(value(f)), pos)
    return target


def _cg(gen, call):
    target = _target_fn(gen, gen.facts.name_of(call.args[0]))
    extra = gen.expr(call.args[1]) if len(call.args) == 2 else (lambda f: ARRIVED)
    what = call.name

    def run(f):
        goal = target(f)
        if what == "target":
            return goal
        d = f.sim.world.short_way(goal - np.asarray(f.state("pos"), dtype=np.float64))
        n = portable.hypot_array(d[:, 0], d[:, 1])
        if what == "arrived":
            return n <= np.broadcast_to(np.asarray(extra(f), np.float64), (f.n,))
        safe = np.where(n > 0, n, 1.0)
        if what == "toward":
            return d / safe[:, None]
        speed = np.broadcast_to(np.asarray(extra(f), np.float64), (f.n,))
        return d * (np.minimum(speed, n) / safe)[:, None]
    return run


for _n in ("target", "toward", "approach", "arrived"):
    codegen.CALL_CODEGEN[_n] = _cg
codegen.NAME_CODEGEN["objective"] = lambda gen, e, res: (lambda f, _n=res[2]: _n)
