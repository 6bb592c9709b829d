"""Fields and regions in the language: `field` and `region`/`food`/`nest`/`obstacle`
declarations, field sensing (`sample`, `FIELD at POINT`, `gradient`, `ahead`, `cone`),
region tests (`inside`, `touching`, `touched`, `distance_to`) and the `deposit` action.

Everything registers itself in the checker, codegen and program tables; the runtime
half is `runtime/environment.py`. The declarations and `EnvInfo` are
`lang_field_decls.py` (re-exported here).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from swarmdsl.compiler import ast, checker, codegen, program, stream_places, typing_rules
from swarmdsl.compiler.actions import ActionSpec, Refused, register
from swarmdsl.compiler.batching import per_replica
from swarmdsl.compiler.builtins import BOOL, FIELD, NUM, REGION, TYPE_TEXT, VEC, declare_calls
from swarmdsl.compiler.consteval import NotConstant, const_value
from swarmdsl.compiler.lang_field_decls import (  # noqa: F401 - importers read them here
    _SHAPES,
    ERR,
    FIELD_DECL_HOOKS,
    FIELD_OPTIONS,
    LABEL,
    LABELS,
    REGION_KINDS,
    EnvInfo,
    env_info,
    periodic_grid_fits,
)
from swarmdsl.compiler.options import refuse_negative
from swarmdsl.errors import did_you_mean
from swarmdsl.limits import MAX_DEPOSIT_NODES

# The runtime modules load where a program needs them (a region, a field, a run), so
# checking a program without them does not pay for their import.
if TYPE_CHECKING:
    from swarmdsl.runtime.environment import Environment
# Add to the runtime's EnvSpec: fn(info, env, spec, gen).
ENV_SPEC_HOOKS: list = []


# ---- names ----

def _resolve(chk, e: ast.Name, scope):
    env = env_info(chk)
    n = e.id
    if n in env.fields:
        chk.facts.set_name(e, ("field", n))
        return FIELD
    if n in env.regions:
        chk.facts.set_name(e, ("region", n))
        return REGION
    if n in REGION_KINDS:
        if not any(r.kind == n for r in env.regions.values()):
            return chk.fail(f"no `{n}` region is declared", e.span,
                            f"declare one: `{n} NAME = circle(x, y, r)`")
        chk.facts.set_name(e, ("region", n))
        return REGION
    k = scope.kind
    if k is not None and n in env.memories.get(k.name, {}):
        chk.facts.set_name(e, ("memory", n))
        return "memory"
    if k is not None and n in env.label_sets.get(k.name, ()):
        chk.facts.set_name(e, ("labels", n))
        return LABELS
    return None


typing_rules.NAME_RESOLVERS.append(_resolve)


def _visible(chk, scope) -> list[str]:
    env = env_info(chk)
    names = list(env.fields) + list(env.regions)
    if scope.kind is not None:
        names += list(env.memories.get(scope.kind.name, {}))
        names += list(env.label_sets.get(scope.kind.name, ()))
    return names


checker.NAME_HINT_HOOKS.append(_visible)
codegen.NAME_CODEGEN["field"] = lambda gen, e, res: (lambda f, _n=res[1]: _n)
codegen.NAME_CODEGEN["region"] = lambda gen, e, res: (lambda f, _n=res[1]: _n)


# ---- shared argument checks (also used by lang_memory) ----

def arity(chk, call: ast.Call, scope, lo: int, hi: int, usage: str) -> bool:
    if not lo <= len(call.args) <= hi or call.each is not None or call.default is not None:
        chk.fail(f"`{call.name}` takes {_count_text(lo, hi)}: `{usage}`", call.span)
        for a in call.args:
            chk.expr(a, scope)
        return False
    return True


def _count_text(lo, hi) -> str:
    if lo == hi:
        return f"{lo} argument{'s' if lo != 1 else ''}"
    return f"{lo} to {hi} arguments"


def named_arg(chk, call, i, scope, want: str, what: str):
    """Check that argument `i` is a bare name of type `want`; return the name or None."""
    a = call.args[i]
    t = chk.expr(a, scope)
    if t == ERR:
        return None
    if t != want or not isinstance(a, ast.Name):
        chk.fail(f"`{call.name}` needs {what} here, got {TYPE_TEXT.get(t, t)}", a.span)
        return None
    return a.id


def agents_only(chk, call, scope) -> bool:
    env_info(chk).used = True
    if scope.kind is None:
        chk.fail(f"`{call.name}` reads an agent's surroundings; it is not available in a "
                 "field's initial value", call.span)
        return False
    return True


def env_of(f) -> Environment:
    return f.sim.environment


def refuse_bad_constant(chk, expr: ast.Expr, what: str) -> None:
    """A constant argument of a probe (a point, a distance, an angle, a reach) that the
    run would refuse, NaN, infinite or over the constants' limit (`cone(F, inf, 0.5)`,
    `sample(F, (inf, 0))`), reported at check time naming the argument, instead of
    "positions must be finite" at the first tick. A value known only per agent is
    the run's business; a constant that cannot be computed has its own error."""
    from swarmdsl.compiler.consteval import NotConstant, const_value
    from swarmdsl.limits import constant_problem

    try:
        value = const_value(expr, chk.params)
    except (NotConstant, ArithmeticError, ValueError, TypeError, RecursionError):
        return
    problem = constant_problem(value)
    if problem:
        chk.fail(f"{what} {problem}", expr.span,
                 "a point, distance or angle is a finite number; see docs/limits.md")


def _rule(usage: str, lo: int, hi: int, first: tuple[str, str], rest: tuple, result: str):
    """A call rule: a first argument naming a field/region, then typed values."""
    def rule(chk, call, scope):
        if not arity(chk, call, scope, lo, hi, usage) or not agents_only(chk, call, scope):
            return ERR
        named_arg(chk, call, 0, scope, *first)
        for a, (want, what) in zip(call.args[1:], rest, strict=False):
            got = chk.expect(a, want, scope, what)
            if got in (NUM, VEC):
                refuse_bad_constant(chk, a, f"{what} of `{call.name}`")
            if got == NUM and what == _REACH:
                refuse_negative(chk, a, f"the reach of `{call.name}`")
        chk.facts.set_name(call, ("env_call", call.name))
        return result
    return rule


_REACH = "the reach"   # how far from a region counts as touching it: 0 or more
_FIELD_ARG = (FIELD, "a field")
_REGION_ARG = (REGION, "a region or a region kind (food, nest, obstacle, region)")

typing_rules.CALL_RULES.update({
    "sample": _rule("sample(FIELD [, point])", 1, 2, _FIELD_ARG,
                    ((VEC, "the sampled point"),), NUM),
    "gradient": _rule("gradient(FIELD)", 1, 1, _FIELD_ARG, (), VEC),
    "ahead": _rule("ahead(FIELD, distance [, turn])", 2, 3, _FIELD_ARG,
                   ((NUM, "the look-ahead distance"), (NUM, "the turn angle")), NUM),
    "cone": _rule("cone(FIELD, distance, half_angle)", 3, 3, _FIELD_ARG,
                  ((NUM, "the look-ahead distance"), (NUM, "the half angle")), NUM),
    "inside": _rule("inside(REGION)", 1, 1, _REGION_ARG, (), BOOL),
    "touching": _rule("touching(REGION [, reach])", 1, 2, _REGION_ARG,
                      ((NUM, _REACH),), BOOL),
    "distance_to": _rule("distance_to(REGION)", 1, 1, _REGION_ARG, (), NUM),
    "centre": _rule("centre(REGION)", 1, 1, _REGION_ARG, (), VEC),
    "center": _rule("center(REGION)", 1, 1, _REGION_ARG, (), VEC),
})


def _touched_rule(chk, call, scope):
    t = _rule("touched(food [, reach])", 1, 2, _REGION_ARG, ((NUM, _REACH),), LABEL)(
        chk, call, scope)
    if t == LABEL and isinstance(call.args[0], ast.Name):
        env = env_info(chk)
        n = call.args[0].id
        r = env.regions.get(n)
        if (r is not None and r.kind != "food") or (r is None and n in REGION_KINDS
                                                    and n != "food"):
            chk.fail("`touched` tells which food source an agent touches; its argument "
                     "is `food` or a food source", call.args[0].span)
    return t


typing_rules.CALL_RULES["touched"] = _touched_rule
# fields and regions are each replica's own grid or the same shapes in every replica
declare_calls(("sample", "gradient", "ahead", "cone", "inside", "touching", "distance_to",
               "centre", "center", "touched", *_SHAPES), batch=True, kilobot=Refused(
    "a Kilobot has no fields or regions: it senses its neighbours' messages"))


# ---- codegen of the calls ----

def _args(gen, call):
    return [gen.expr(a) for a in call.args[1:]]


def _pos(f):
    return np.asarray(f.state("pos"), dtype=np.float64)


def _n(f, v):
    return np.broadcast_to(np.asarray(v, dtype=np.float64), (f.n,))


def point_reader(gen, point: ast.Expr, name: str, span):
    """closure(frame) -> (n, 2) the points where field `name` is read, refusing a NaN or
    an infinity there with an error located at the reading (not the grid's own)."""
    at = gen.expr(point)

    def points(f):
        pts = np.broadcast_to(np.asarray(at(f), np.float64), (f.n, 2))
        if not np.isfinite(pts.sum()) and not np.isfinite(pts).all():
            from swarmdsl.errors import SwarmRuntimeError

            where = f"kind `{f.kind.name}`, status `{f.status_name}`, " \
                if getattr(f, "kind", None) is not None else ""
            raise SwarmRuntimeError(f"the point where `{name}` is read is not finite "
                                    f"({where}tick {f.tick})", span)
        return pts
    return points


def replicas(f):
    """The replica of each of the frame's rows in a batch (their fields' grids: an
    agent's, or in an aggregate a pair's, whose two agents share a replica), or None in
    a run of its own: the readers' `replica=`."""
    from swarmdsl.runtime.frame import PairFrame

    return f.sim.replicas_of(f.j if isinstance(f, PairFrame) else f.idx)


def _cg_sample(gen, call):
    name = call.args[0].id
    if len(call.args) == 2:
        at = point_reader(gen, call.args[1], name, call.span)
        return lambda f: env_of(f).fields[name].sample(at(f), replicas(f))
    return lambda f: env_of(f).fields[name].sample(_pos(f), replicas(f))


def _cg_gradient(gen, call):
    name = call.args[0].id
    return lambda f: env_of(f).fields[name].gradient(_pos(f), replicas(f))


def _cg_ahead(gen, call):
    name, rest = call.args[0].id, _args(gen, call)
    dist = rest[0]
    turn = rest[1] if len(rest) > 1 else (lambda f: 0.0)
    return lambda f: env_of(f).fields[name].sample_ahead(
        _pos(f), _n(f, f.state("heading")) + _n(f, turn(f)), _n(f, dist(f)),
        replicas(f))


def _cg_cone(gen, call):
    name, (dist, half) = call.args[0].id, _args(gen, call)

    def cone(f):
        half_angle = np.asarray(half(f), dtype=np.float64)
        if half_angle.ndim:  # one cone shape per call; per-agent angles use the first
            half_angle = half_angle.flat[0] if half_angle.size else 0.0
        return env_of(f).fields[name].sense_cone(_pos(f), f.state("heading"),
                                                 _n(f, dist(f)), float(half_angle),
                                                 replica=replicas(f))
    return cone


def _cg_centre(gen, call):
    """The centre of a region; of a region kind (`food`), the centre of the one nearest
    each agent (the short way round a wrap-around world)."""
    name = call.args[0].id

    def centre(f):
        env = env_of(f)
        regions = env.select(name)
        if not regions:
            return _pos(f)
        centres = np.array([r.shape.center for r in regions], dtype=np.float64)
        if len(regions) == 1:
            return np.broadcast_to(centres[0], (f.n, 2))
        return centres[env.distances(name, _pos(f)).argmin(axis=1)]
    return centre


def _cg_touching(gen, call):
    name, rest = call.args[0].id, _args(gen, call)
    reach = rest[0] if rest else (lambda f: 0.0)
    return lambda f: env_of(f).distance_to(name, _pos(f)) <= _n(f, reach(f))


def _cg_inside(gen, call):
    name = call.args[0].id
    return lambda f: env_of(f).distance_to(name, _pos(f)) <= 0.0


def _cg_distance(gen, call):
    name = call.args[0].id
    return lambda f: env_of(f).distance_to(name, _pos(f))


def _cg_touched(gen, call):
    name, rest = call.args[0].id, _args(gen, call)
    reach = rest[0] if rest else (lambda f: 0.0)

    def touched(f):
        env = env_of(f)
        if name == "food":
            return env.touched_label(_pos(f), _n(f, reach(f)))
        region = env.regions[name]  # one food source: its label or none
        near = region.distance(_pos(f), f.sim.world.box) <= _n(f, reach(f))
        return np.where(near, env.food.index(region), -1)
    return touched


codegen.CALL_CODEGEN.update({
    "sample": _cg_sample, "gradient": _cg_gradient, "ahead": _cg_ahead, "cone": _cg_cone,
    "inside": _cg_inside, "touching": _cg_touching, "distance_to": _cg_distance,
    "touched": _cg_touched, "centre": _cg_centre, "center": _cg_centre,
})


# ---- `FIELD at POINT` ----
#
# The written form of `sample(FIELD, POINT)`: the same reading (bilinear, refined levels,
# wrapped or clamped at the world's edges, through the reader's sensing model), with
# errors that speak of `at`. Codegen hands a `sample` call built from the node to
# whatever `sample` compiles to, so the twins' vector fields and the sensing models that
# wrap `sample` apply to `at` without a second copy of either.

def _field_names(env: EnvInfo) -> list[str]:
    return [*env.fields, *env.vector_fields]


def _at_field(chk, e: ast.FieldAt, scope) -> str:
    """The type of the field on the left of `at` (or ERR, reported)."""
    f, names = e.field, _field_names(env_info(chk))
    hint = did_you_mean(f.id, names) if isinstance(f, ast.Name) else None
    if not names:
        hint = "declare one: `field heat { twin pos.x / 10 }`"
    elif hint is None:
        hint = "the fields are " + ", ".join(f"`{n}`" for n in names[:8]) + \
            (" ..." if len(names) > 8 else "")
    before = len(chk.errors)
    t = chk.expr(f, scope)
    if isinstance(f, ast.Name) and chk.facts.category(f) in ("field", "vfield"):
        return t
    if isinstance(f, ast.Name):   # not a field here (a `let` or `var` may hide one)
        del chk.errors[before:]   # an unknown name is reported below, among the fields
        if f.id in names:
            hint = f"a `let` or variable named `{f.id}` hides the field; rename it"
        if t == ERR:
            return chk.fail(f"unknown field `{f.id}`", f.span, hint)
        return chk.fail(f"`{f.id}` is {TYPE_TEXT.get(t, t)}, not a field: `at` reads a "
                        "field at a point", f.span, hint)
    if t == ERR:
        return ERR
    return chk.fail(f"`at` reads a field at a point; its left side must be a field's "
                    f"name, got {TYPE_TEXT.get(t, t)}", f.span, hint)


def _check_field_at(chk, e: ast.FieldAt, scope) -> str:
    env_info(chk).used = True
    field_type = _at_field(chk, e, scope)
    point_type = chk.expr(e.point, scope)
    if point_type not in (VEC, ERR):
        chk.fail(f"the point after `at` must be a vector (x, y), got "
                 f"{TYPE_TEXT.get(point_type, point_type)}", e.point.span,
                 "e.g. `heat at (pos + unit(heading) * 3)`")
        return ERR
    if scope.kind is None:
        return chk.fail("`at` reads an agent's surroundings; it is not available in a "
                        "field's formula or a swarm property", e.at_span)
    if ERR in (field_type, point_type):
        return ERR
    refuse_bad_constant(chk, e.point, "the point after `at`")
    _warn_out_of_range(chk, e, scope.kind)
    if chk.facts.name_of(e.point) == ("state", "pos") and isinstance(e.point, ast.Name):
        # `F at pos` is `sample(F)`: a robot reads a field where it stands without
        # knowing where that is, so this `pos` needs no `position` sense
        chk.facts.set_name(e.point, ("own_pos",))
    chk.facts.set_name(e, ("field_at", e.field.id))
    return VEC if e.field.id in env_info(chk).vector_fields else NUM


def _warn_out_of_range(chk, e: ast.FieldAt, kind) -> None:
    """A point a fixed distance away that the kind's sensing range never reaches reads 0
    every time (the sensing model's rule): almost certainly a mistake, so say so."""
    from swarmdsl.compiler.lang_robots import profile_of

    reach = _fixed_reach(chk, e.point)
    limit = profile_of(chk, kind).sense_range
    if reach is not None and reach > limit:
        chk.warn(f"this reading is {reach:g} from the agent, beyond the range {limit:g} "
                 f"of robot `{profile_of(chk, kind).name}`: it always reads 0", e.span,
                 "a field is sensed only within the robot's `range`")


def _fixed_reach(chk, point: ast.Expr) -> float | None:
    """How far `point` is from the agent when it is `pos + OFFSET` or `pos - OFFSET` and
    the offset has a constant length (a constant vector, or `unit(angle) * d`)."""
    if not (isinstance(point, ast.BinOp) and point.op in ("+", "-")
            and chk.facts.name_of(point.left) == ("state", "pos")):
        return None
    offset = point.right
    try:
        v = const_value(offset, chk.params)
        return math.hypot(*v) if isinstance(v, tuple) else None
    except (NotConstant, ArithmeticError, ValueError, TypeError):
        pass
    if isinstance(offset, ast.BinOp) and offset.op == "*":
        for unit, length in ((offset.left, offset.right), (offset.right, offset.left)):
            if isinstance(unit, ast.Call) and unit.name == "unit":
                try:
                    d = const_value(length, chk.params)
                except (NotConstant, ArithmeticError, ValueError, TypeError):
                    return None
                return abs(d) if isinstance(d, int | float) else None
    return None


def _cg_field_at(gen, e: ast.FieldAt):
    call = ast.Call(e.span, "sample", e.at_span, (e.field, e.point), None, None)
    stream_places.same_place(gen.info, call, e)   # a sensing model's noise: e's stream
    return codegen.CALL_CODEGEN["sample"](gen, call)


checker.EXPR_RULES[ast.FieldAt] = _check_field_at
codegen.EXPR_CODEGEN[ast.FieldAt] = _cg_field_at
codegen.NAME_CODEGEN["own_pos"] = lambda gen, e, res: (lambda f: f.state("pos"))


# ---- deposit ----

def _check_deposit(chk, st: ast.ActionStmt, scope, kind):
    call = ast.Call(st.span, st.name, st.name_span, st.args, None, None)
    if not arity(chk, call, scope, 2, 3, "deposit(FIELD, amount [, radius])"):
        return
    if named_arg(chk, call, 0, scope, *_FIELD_ARG) in env_info(chk).twins:
        chk.fail(f"field `{st.args[0].id}` is a physical twin: its values come from its "
                 "formula and cannot be deposited into", st.args[0].span)
    chk.expect(st.args[1], NUM, scope, "the deposited amount")
    if len(st.args) == 3:
        r = chk.expect(st.args[2], NUM, scope, "the deposit radius")
        if r != ERR:
            v = chk._const(st.args[2], "the deposit radius")  # finite, within limits
            if v is None:
                return
            if isinstance(v, bool) or v < 0:
                chk.fail(f"the deposit radius must be at least 0, got {v}", st.args[2].span)
                return
            across = v / chk.world.grid     # huge when `grid` is absurdly fine: no `** 2`
            if across > math.sqrt(MAX_DEPOSIT_NODES / math.pi):
                nodes = math.pi * across * across if across < 1e150 else math.inf
                about = f"about {nodes:,.0f}" if math.isfinite(nodes) else "more than 1e300"
                chk.fail(f"a deposit of radius {v:g} spreads over {about} grid "
                         f"nodes per agent; at most {MAX_DEPOSIT_NODES:,} are allowed",
                         st.args[2].span, "use a smaller radius or a coarser `grid`")


def _compile_deposit(gen, st: ast.ActionStmt, kind):
    name = st.args[0].id
    amount = gen.expr(st.args[1])
    radius = float(const_value(st.args[2], gen.info.params)) if len(st.args) == 3 else 0.0
    span = st.span

    def deposit(f):
        rows = f.active
        if not rows.any():
            return
        pts = np.asarray(f.state("pos"), dtype=np.float64)[rows]
        amt = _n(f, amount(f))[rows].copy()
        if not np.isfinite(amt).all():
            from swarmdsl.errors import SwarmRuntimeError

            raise SwarmRuntimeError(f"a deposit into `{name}` is not finite (kind "
                                    f"`{kind.name}`, status `{f.status_name}`, tick "
                                    f"{f.tick})", span)
        fld = env_of(f).fields[name]
        rep = replicas(f)   # in a batch: each point onto its own replica's grid
        rep = None if rep is None else rep[rows]
        f.effects.append(lambda: fld.deposit(pts, amt, radius, rep))
    return deposit


register(ActionSpec("deposit", _check_deposit, _compile_deposit,
                    "add an amount to a field at the agent's position (after the tick)",
                    batch=True, kilobot=Refused("a Kilobot has no field to deposit in")))


# ---- the runtime extension ----

def _program_hook(info, prog, gen) -> None:
    env: EnvInfo | None = info.extra.get("env")
    if env is None or not env.needed():
        return
    from swarmdsl.runtime.environment import (
        Environment,
        EnvSpec,
        FieldSpec,
        kernel_blockers,
    )

    spec = EnvSpec()
    for name, (decay, diffuse, init) in env.field_specs.items():
        init_fn = gen.expr(init) if init is not None else None
        spec.fields.append(FieldSpec(name, decay, diffuse, init_fn,
                                     env.fields[name].name_span))
    spec.regions = list(env.regions.values())
    for hook in ENV_SPEC_HOOKS:
        hook(info, env, spec, gen)
    for per_kind in env.memories.values():
        for name, k in per_kind.items():
            spec.memories[name] = max(k, spec.memories.get(name, 0))
    for per_kind in env.label_sets.values():
        for name in per_kind:
            if name not in spec.label_sets:
                spec.label_sets.append(name)
    parts = kernel_blockers(spec)
    make = per_replica(lambda sim: Environment(sim, spec),
                       f"its environment ({', '.join(parts[:3])}"
                       f"{', ...' if len(parts) > 3 else ''}) runs" if parts else None)
    if not parts:   # the whole-tick kernel holds it (`tick_plan.py`)
        make.regions = spec.regions
        make.fields = spec
    prog.extensions.append(make)


program.PROGRAM_HOOKS.append(_program_hook)
