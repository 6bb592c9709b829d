"""Beliefs versus truth in the language: `believed` and `located`, the `believe` option
and action, and the `trilaterate(...)` primitive with its `.pos` / `.ok` result.

`believed` is where an agent thinks it is, in its own coordinates (a vector); `located`
says whether it has a belief yet. They are set by the `believe EXPR` agent option (the
experimenter labels a robot when placing it), by the `believe(p)` action (labelling,
trilateration) and then kept up to date by odometry (`runtime/robots.py`).
"""

from __future__ import annotations

import numpy as np

from swarmdsl.compiler import (
    actions,
    ast,
    checker,
    codegen,
    columns,
    nan_guard,
    options,
    program,
    typing_rules,
)
from swarmdsl.compiler.batching import per_replica
from swarmdsl.compiler.builtins import BOOL, NUM, SET, TYPE_TEXT, VEC, declare_calls
from swarmdsl.compiler.codegen import broadcast
from swarmdsl.compiler.info import BUILTIN_NAMES
from swarmdsl.compiler.lang_robots import profile_of
from swarmdsl.compiler.profiles import PROFILES

FIX = "fix"
TYPE_TEXT[FIX] = "a trilateration result"
codegen.RAW_LET_TYPES.add(FIX)
_BELIEF_NAMES = {"believed": (VEC, "believed"), "located": (BOOL, "located")}
BUILTIN_NAMES.update(_BELIEF_NAMES)
# Per-agent values the robot runtime keeps (and records) when the program uses them.
columns.RUNTIME_VALUES.update({
    "believed": (VEC, "the agent's believed position"),
    "located": (BOOL, "whether the agent has a believed position"),
    "led": (NUM, "the agent's LED colour"),
})


# ---- believed / located ----

def _resolve_belief(chk, e: ast.Name, scope):
    got = _BELIEF_NAMES.get(e.id)
    if got is None:
        return None
    chk.extra["beliefs"] = True
    chk.facts.set_name(e, ("belief", got[1]))
    return got[0]


def _compile_belief(gen, e, res):
    col = res[1]
    return lambda f: f.state(col)


typing_rules.NAME_RESOLVERS.append(_resolve_belief)
codegen.NAME_CODEGEN["belief"] = _compile_belief


# ---- believe EXPR (option) and believe(p) (action) ----

def _believe_option(chk, opt, kind):
    if len(opt.args) != 1:
        chk.fail("`believe` takes one vector: `believe pos - (120, 120)`", opt.span)
        return
    chk.extra["beliefs"] = True


options.AGENT_OPTIONS["believe"] = options.OptionSpec(
    _believe_option, doc="the believed coordinates an agent starts with (it is located)")


def _check_believe_option(chk, kind) -> None:
    opt = kind.options.get("believe")
    if opt is None or len(opt.args) != 1:
        return
    from swarmdsl.compiler.scope import Scope

    chk.expect(opt.args[0], VEC, Scope(kind, init=True), "the believed position")


checker.KIND_HOOKS.append(_check_believe_option)


def _check_believe(chk, st: ast.ActionStmt, scope, kind):
    if len(st.args) != 1:
        for a in st.args:
            chk.expr(a, scope)
        chk.fail("`believe` takes one vector: `believe(fix.pos)`", st.span)
        return
    chk.expect(st.args[0], VEC, scope, "the believed position")
    chk.extra["beliefs"] = True


def _compile_believe(gen, st: ast.ActionStmt, kind):
    # A belief is kept and carried by odometry: an infinite or NaN one would stay so for
    # the rest of the run, so it is a located fault where it is made, as for `believe P`.
    value = nan_guard.finite_guard(gen.expr(st.args[0]), st.args[0].span, "the belief",
                                   "guard the division, square root or log that produced it")

    def run(f):
        mask = f.active
        p = broadcast(value(f), f.n, VEC)
        f.overlay["believed"] = np.where(mask[:, None], p, f.state("believed"))
        f.overlay["located"] = mask | f.state("located")
    return run


actions.register(actions.ActionSpec(
    "believe", _check_believe, _compile_believe,
    "believe(p): take p as the agent's own coordinates (it becomes located)",
    batch=True, kilobot=True))


# ---- trilaterate ----

def _check_trilaterate(chk, e: ast.Call, scope):
    if e.default is not None:
        return chk.fail("`trilaterate` takes no `else`", e.default.span)
    if e.each is not None:
        if len(e.args) != 1:
            return chk.fail("`trilaterate(SET : POINT)` takes one neighbour set", e.span)
        t = chk.expr(e.args[0], scope)
        if t not in (SET, "error"):
            return chk.fail(f"`trilaterate(X : POINT)` needs a neighbour set as X, got "
                            f"{TYPE_TEXT.get(t, t)}", e.args[0].span)
        pair = typing_rules._pair_scope(chk, scope, e)
        chk.expect(e.each, VEC, pair, "a reference's known position")
        chk.facts.set_name(e, ("trilaterate", "set"))
        return FIX
    if len(e.args) != 6:
        for a in e.args:
            chk.expr(a, scope)
        return chk.fail("`trilaterate` takes a neighbour set and each one's known position "
                        "`trilaterate(refs : msg.at)`, or three points and distances "
                        "`trilaterate(p1, r1, p2, r2, p3, r3)`", e.span)
    for i, a in enumerate(e.args):
        chk.expect(a, VEC if i % 2 == 0 else NUM, scope,
                   "a reference point" if i % 2 == 0 else "a distance")
    chk.facts.set_name(e, ("trilaterate", "three"))
    return FIX


def _compile_trilaterate(gen, e: ast.Call):
    from swarmdsl.runtime.trilateration import solve3, solve_sets

    if e.each is not None:
        src, each = gen.expr(e.args[0]), gen.expr(e.each)

        def from_set(f):
            pairs = src(f)
            pts = broadcast(each(pairs.pair_frame()), pairs.seg.size, VEC)
            return solve_sets(pts, pairs.dist, pairs.seg, f.n)
        return from_set
    args = [gen.expr(a) for a in e.args]

    def three(f):
        p1, r1, p2, r2, p3, r3 = (a(f) for a in args)
        return np.broadcast_to(solve3(p1, r1, p2, r2, p3, r3), (f.n, 3))
    return three


def _fix_attr(chk, e: ast.Attr, scope):
    if e.name == "pos":
        chk.facts.set_name(e, ("fix_part", "pos"))
        return VEC
    if e.name == "ok":
        chk.facts.set_name(e, ("fix_part", "ok"))
        return BOOL
    return chk.fail(f"a trilateration result has `.pos` and `.ok`, not `.{e.name}`",
                    e.name_span)


def _compile_fix_part(gen, e, res):
    obj = gen.expr(e.obj)
    if res[1] == "pos":
        return lambda f: np.asarray(obj(f))[..., :2]
    return lambda f: np.asarray(obj(f))[..., 2] > 0.5


typing_rules.CALL_RULES["trilaterate"] = _check_trilaterate
declare_calls(("trilaterate",), batch=True, kilobot=True)   # over each replica's pairs
typing_rules.ATTR_RULES[FIX] = _fix_attr
codegen.CALL_CODEGEN["trilaterate"] = _compile_trilaterate
codegen.NAME_CODEGEN["fix_part"] = _compile_fix_part


# ---- runtime ----

def _robot_runtime(info, prog, gen) -> None:
    profs = [profile_of(info, k) for k in info.kinds]
    beliefs = bool(info.extra.get("beliefs"))
    led = bool(info.extra.get("led"))
    plain = all(p.speed == np.inf and p.heading_noise == 0 and p.speed_noise == 0
                for p in profs)
    if plain and not beliefs and not led:
        return
    from swarmdsl.runtime.robots import LED_OFF, RobotRuntime, RobotSpec

    if beliefs:
        prog.var_specs["believed"] = ((2,), np.float64, (0.0, 0.0))
        prog.var_types["believed"] = VEC
        prog.var_specs["located"] = ((), np.bool_, False)
        prog.var_types["located"] = BOOL
    if led:
        prog.var_specs["led"] = ((), np.float64, float(LED_OFF))
        prog.var_types["led"] = NUM
    believe = {}
    for k in info.kinds:
        opt = k.options.get("believe")
        if opt is not None:
            believe[k.index] = gen.init_value(opt.args[0], VEC, "`believe`")
    spec = RobotSpec(np.array([p.speed for p in profs], float),
                     np.array([p.heading_noise for p in profs], float),
                     np.array([p.speed_noise for p in profs], float),
                     believe, info.extra.get("origin", (0.0, 0.0)), beliefs, led)
    prog.extensions.append(per_replica(lambda sim: RobotRuntime(sim, spec),
                                       "its robots' motion and beliefs run"))


program.PROGRAM_HOOKS.append(_robot_runtime)

__all__ = ["FIX", "PROFILES"]
