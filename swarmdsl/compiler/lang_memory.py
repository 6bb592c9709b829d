"""Movement and memory primitives: `choose` (weighted compass directions), `at_edge`,
per-agent path memories (`memory NAME K`, `remember`, `retrace`, `len`, `clear`) and
per-agent sets of food labels (`labels NAME`, `learn`, `knows`, `len`, `clear`).
"""

from __future__ import annotations

import numpy as np

from swarmdsl.compiler import ast, checker, codegen, stream_places, typing_rules
from swarmdsl.compiler.actions import ActionSpec, Refused, register
from swarmdsl.compiler.builtins import BOOL, FIELD, MEMORY, NUM, REGION, TYPE_TEXT, declare_calls
from swarmdsl.compiler.consteval import NotConstant, const_value
from swarmdsl.compiler.lang_fields import (
    ERR,
    LABEL,
    LABELS,
    agents_only,
    arity,
    env_info,
    env_of,
    named_arg,
)
from swarmdsl.compiler.options import AGENT_OPTIONS, OptionSpec, _positive, refuse_negative
from swarmdsl.errors import SwarmRuntimeError

DEFAULT_CAPACITY = 1000


# ---- agent options ----

def _memory_option(chk, opt: ast.Option, kind) -> None:
    if not 1 <= len(opt.args) <= 2 or not isinstance(opt.args[0], ast.Name):
        chk.fail("`memory` takes a name and a capacity: `memory trail 200`", opt.span)
        return
    cap = DEFAULT_CAPACITY
    if len(opt.args) == 2:
        cap = _positive(chk, opt.args[1], "the memory capacity", integer=True,
                        limit="memory")
        if cap is None:
            return
    chk.name_taken(opt.args[0].id, opt.args[0].span)
    env_info(chk).memories.setdefault(kind.name, {})[opt.args[0].id] = cap


def _labels_option(chk, opt: ast.Option, kind) -> None:
    if len(opt.args) != 1 or not isinstance(opt.args[0], ast.Name):
        chk.fail("`labels` takes a name: `labels known`", opt.span)
        return
    chk.name_taken(opt.args[0].id, opt.args[0].span)
    env_info(chk).label_sets.setdefault(kind.name, set()).add(opt.args[0].id)


AGENT_OPTIONS["memory"] = OptionSpec(_memory_option,
                                     doc="a bounded per-agent path memory: memory NAME K",
                                     declares=True)
AGENT_OPTIONS["labels"] = OptionSpec(_labels_option,
                                     doc="a per-agent set of food labels: labels NAME",
                                     declares=True)


def _kind_names_clash(chk, kind) -> None:
    env = env_info(chk)
    memories = env.memories.get(kind.name, {})
    for opt_name, what, names in (
            ("memory", "a path memory", memories),
            ("labels", "a label set", env.label_sets.get(kind.name, ()))):
        for n in names:
            # fields, regions and other top-level names: refused at the option
            if n in kind.vars or (opt_name == "labels" and n in memories):
                chk.fail(f"`{n}` names both {what} and another declaration",
                         kind.options[opt_name].args[0].span, "choose another name")


checker.KIND_HOOKS.append(_kind_names_clash)


# ---- choose ----

def _attractor(chk, a: ast.Expr, scope):
    """`X`, `-X`, `G * X` or `X * G` with X a field or region: returns (gain, X) or None."""
    gain, target = None, a
    if isinstance(a, ast.Neg):
        gain, target = -1.0, a.operand
    elif isinstance(a, ast.BinOp) and a.op == "*":
        left_is = _is_env_name(chk, a.left)
        gain, target = (a.right, a.left) if left_is else (a.left, a.right)
    if isinstance(target, ast.Call) and target.name == "unknown":
        t = _unknown(chk, target, scope)
    else:
        t = chk.expr(target, scope)
    if t == ERR:
        return None
    if t not in (FIELD, REGION) or not isinstance(target, ast.Name | ast.Call):
        chk.fail("each attraction in `choose` is a field or a region kind, optionally "
                 f"times a gain (`8 * pheromone`), got {TYPE_TEXT.get(t, t)}", a.span)
        return None
    if isinstance(gain, ast.Expr):
        if chk.expect(gain, NUM, scope, "an attraction's gain") == ERR:
            return None
    return gain, target


def _unknown(chk, call, scope) -> str:
    """`unknown(food, known)`: the food sources an agent's label set does not hold."""
    if not arity(chk, call, scope, 2, 2, "unknown(food, LABELS)"):
        return ERR
    named_arg(chk, call, 0, scope, REGION, "`food` or a food source")
    named_arg(chk, call, 1, scope, LABELS, "a label set (declare it with `labels NAME`)")
    return REGION


def _unknown_alone(chk, call, scope) -> str:
    """`unknown(food, S)` outside `choose`: it names directions to prefer, not a value
    (it was "unknown function `unknown`", did you mean 'known'?)."""
    for a in call.args:
        chk.expr(a, scope)
    return chk.fail("`unknown(food, LABELS)` is an attraction of `choose` only", call.span,
                    "e.g. `choose(8, 0.5, 30 * unknown(food, known))`; to test one food "
                    "source, `not knows(LABELS, alpha)`")


typing_rules.CALL_RULES["unknown"] = _unknown_alone


def _is_env_name(chk, e) -> bool:
    if isinstance(e, ast.Call) and e.name == "unknown":
        return True
    if not isinstance(e, ast.Name):
        return False
    env = env_info(chk)
    return e.id in env.fields or e.id in env.regions or e.id in ("food", "nest",
                                                                 "obstacle", "region")


def _const_in(chk, e, what: str, lo: float, hi: float, integer: bool = False):
    try:
        v = const_value(e, chk.params)
    except NotConstant:
        chk.fail(f"{what} must be a constant", e.span)
        return None
    except (ArithmeticError, ValueError, TypeError) as exc:
        chk.fail(f"cannot compute {what}: {exc}", e.span)
        return None
    if isinstance(v, bool) or not isinstance(v, int | float) or not lo <= v <= hi or (
            integer and float(v) != int(v)):
        kind = "a whole number" if integer else "a number"
        got = f"{v:g}" if isinstance(v, int | float) and not isinstance(v, bool) else v
        chk.fail(f"{what} must be {kind} from {lo:g} to {hi:g}, got {got}", e.span)
        return None
    return v


def _choose_rule(chk, call, scope):
    usage = "choose(K, persistence, attraction...)"
    if len(call.args) < 2 or call.each is not None or call.default is not None:
        chk.fail(f"`choose` takes at least 2 arguments: `{usage}`", call.span)
        return ERR
    if not agents_only(chk, call, scope):
        return ERR
    _const_in(chk, call.args[0], "the number of directions", 2, 360, integer=True)
    _const_in(chk, call.args[1], "the persistence", 0, 1)
    for a in call.args[2:]:
        _attractor(chk, a, scope)
    chk.facts.set_name(call, ("env_call", "choose"))
    return NUM


def _cg_choose(gen, call):
    k = int(const_value(call.args[0], gen.info.params))
    p = float(const_value(call.args[1], gen.info.params))
    place = stream_places.place_of(gen.info, call)
    parts = []
    for a in call.args[2:]:
        if isinstance(a, ast.Neg):
            gain, target = (lambda f: -1.0), a.operand
        elif isinstance(a, ast.BinOp):
            left_is = gen.facts.category(a.left) in ("field", "region")
            g, target = (a.right, a.left) if left_is else (a.left, a.right)
            gain = gen.expr(g)
        else:
            gain, target = (lambda f: 1.0), a
        if isinstance(target, ast.Call):  # unknown(food, known)
            parts.append((gain, target.args[0].id, False, target.args[1].id))
        else:
            is_field = gen.facts.name_of(target)[0] == "field"
            parts.append((gain, target.id, is_field, None))

    def choose(f):
        env = env_of(f)
        attractors = []
        for g, name, is_field, known in parts:
            skip = None
            if known is not None:
                skip = env.label_sets[known].bits
                skip = f.sim.agents.cols[skip][f.idx]
            attractors.append((g(f), name, is_field, skip))
        rng = f.rng   # its own stream, named by its place (after the gains drew theirs)
        f.rng = rng.at(place)
        try:
            return env.choose(f, k, p, attractors)
        finally:
            f.rng = rng
    return choose


typing_rules.CALL_RULES["choose"] = _choose_rule
codegen.CALL_CODEGEN["choose"] = _cg_choose


# ---- at_edge ----

def _at_edge_rule(chk, call, scope):
    if not arity(chk, call, scope, 0, 1, "at_edge([margin])"):
        return ERR
    if call.args and chk.expect(call.args[0], NUM, scope, "the edge margin") == NUM:
        refuse_negative(chk, call.args[0], "the margin of `at_edge`")
    chk.facts.set_name(call, ("env_call", "at_edge"))
    return BOOL


def _cg_at_edge(gen, call):
    margin = gen.expr(call.args[0]) if call.args else None

    def at_edge(f):
        w = f.sim.world
        pos = np.asarray(f.state("pos"), dtype=np.float64)
        if w.wraps:
            return np.zeros(f.n, dtype=bool)
        m = w.grid if margin is None else np.broadcast_to(np.asarray(margin(f), float),
                                                          (f.n,))
        d = np.minimum(np.minimum(pos[:, 0], w.width - pos[:, 0]),
                       np.minimum(pos[:, 1], w.height - pos[:, 1]))
        return d <= m
    return at_edge


typing_rules.CALL_RULES["at_edge"] = _at_edge_rule
codegen.CALL_CODEGEN["at_edge"] = _cg_at_edge


# ---- len, knows ----

def _len_rule(chk, call, scope):
    if not arity(chk, call, scope, 1, 1, "len(MEMORY or LABELS)"):
        return ERR
    a = call.args[0]
    t = chk.expr(a, scope)
    if t not in (MEMORY, LABELS, ERR) or (t != ERR and not isinstance(a, ast.Name)):
        chk.fail(f"`len` counts a path memory or a label set, got {TYPE_TEXT.get(t, t)}",
                 a.span)
        return ERR
    chk.facts.set_name(call, ("env_call", "len"))
    return NUM


def _cg_len(gen, call):
    cat, name = gen.facts.name_of(call.args[0])
    if cat == "memory":
        return lambda f: env_of(f).memories[name].length(f.sim.agents.cols,
                                                         f.idx).astype(np.float64)
    return lambda f: env_of(f).label_sets[name].size(f.sim.agents.cols,
                                                     f.idx).astype(np.float64)


def _label_arg(chk, a, scope) -> None:
    t = chk.expr(a, scope)
    if t in (LABEL, ERR):
        return
    res = chk.facts.name_of(a)
    if t == REGION and res is not None:
        r = env_info(chk).regions.get(res[1])
        if r is not None and r.kind == "food":
            return
    chk.fail(f"expected a food label (`touched(food)` or a food source's name), got "
             f"{TYPE_TEXT.get(t, t)}", a.span)


def _label_value(gen, a):
    res = gen.facts.name_of(a)
    if res is not None and res[0] == "region":
        name = res[1]
        return lambda f: env_of(f).food.index(env_of(f).regions[name])
    return gen.expr(a)


def _knows_rule(chk, call, scope):
    if not arity(chk, call, scope, 2, 2, "knows(LABELS, label)"):
        return ERR
    named_arg(chk, call, 0, scope, LABELS, "a label set (declare it with `labels NAME`)")
    _label_arg(chk, call.args[1], scope)
    chk.facts.set_name(call, ("env_call", "knows"))
    return BOOL


def _cg_knows(gen, call):
    name, label = call.args[0].id, _label_value(gen, call.args[1])

    def knows(f):
        labels = np.broadcast_to(np.asarray(label(f), dtype=np.int64), (f.n,))
        return env_of(f).label_sets[name].contains(f.sim.agents.cols, f.idx, labels)
    return knows


typing_rules.CALL_RULES.update({"len": _len_rule, "knows": _knows_rule})
# path memories and label sets are agent columns; `choose` draws by rows
declare_calls(("len", "knows", "unknown", "choose", "at_edge"), batch=True, kilobot=Refused(
    "path memories, label sets and direction choices are not translated to C yet"))
codegen.CALL_CODEGEN.update({"len": _cg_len, "knows": _cg_knows})


# ---- actions ----

def _as_call(st: ast.ActionStmt) -> ast.Call:
    return ast.Call(st.span, st.name, st.name_span, st.args, None, None)


def _memory_action_check(what: str):
    def check(chk, st, scope, kind):
        call = _as_call(st)
        if arity(chk, call, scope, 1, 1, f"{st.name}(MEMORY)"):
            named_arg(chk, call, 0, scope, MEMORY, what)
    return check


_MEM_WHAT = "a path memory (declare it with `memory NAME K`)"


def _rows(f):
    return f.idx[f.active]


def _compile_remember(gen, st, kind):
    name = st.args[0].id

    def remember(f):
        act = f.active
        if act.any():
            pos = np.asarray(f.state("pos"), dtype=np.float64)[act]
            env_of(f).memories[name].push(f.sim.agents.cols, f.idx[act], pos)
    return remember


def _compile_retrace(gen, st, kind):
    """`retrace(M)`: pop the newest point and set the velocity that reaches it this tick.
    In a wrap-around world that is the short way round: a path that crossed the edge is
    retraced back across it (the long way would be a step `max_speed` cuts short, and the
    agent would end its retrace far from where it started)."""
    name = st.args[0].id

    def retrace(f):
        act = f.active
        if not act.any():
            return
        env = env_of(f)
        rows = f.idx[act]
        pts, had = env.memories[name].pop(f.sim.agents.cols, rows)
        pos = np.asarray(f.state("pos"), dtype=np.float64)[act]
        vel = np.array(f.state("vel"), dtype=np.float64, copy=True)
        vel[act] = np.where(had[:, None], f.sim.world.short_way(pts - pos), 0.0)
        if not np.isfinite(vel).all():
            raise SwarmRuntimeError(f"`retrace({name})` produced a non-finite velocity",
                                    st.span)
        f.overlay["vel"] = vel
        env.land(rows[had], pts[had])
    return retrace


def _check_clear(chk, st, scope, kind):
    call = _as_call(st)
    if not arity(chk, call, scope, 1, 1, "clear(MEMORY or LABELS)"):
        return
    a = st.args[0]
    t = chk.expr(a, scope)
    if t not in (MEMORY, LABELS, ERR) or (t != ERR and not isinstance(a, ast.Name)):
        chk.fail(f"`clear` empties a path memory or a label set, got {TYPE_TEXT.get(t, t)}",
                 a.span)


def _compile_clear(gen, st, kind):
    cat, name = gen.facts.name_of(st.args[0])

    def clear(f):
        env = env_of(f)
        store = env.memories[name] if cat == "memory" else env.label_sets[name]
        store.clear(f.sim.agents.cols, _rows(f))
    return clear


def _check_learn(chk, st, scope, kind):
    call = _as_call(st)
    if arity(chk, call, scope, 2, 2, "learn(LABELS, label)"):
        named_arg(chk, call, 0, scope, LABELS, "a label set (declare it with `labels NAME`)")
        _label_arg(chk, st.args[1], scope)


def _compile_learn(gen, st, kind):
    name, label = st.args[0].id, _label_value(gen, st.args[1])

    def learn(f):
        labels = np.broadcast_to(np.asarray(label(f), dtype=np.int64), (f.n,))
        env_of(f).label_sets[name].add(f.sim.agents.cols, _rows(f), labels[f.active])
    return learn


_NO_MEMORY = Refused("path memories and label sets are not translated to C yet")
register(ActionSpec("remember", _memory_action_check(_MEM_WHAT), _compile_remember,
                    "append the agent's position to a path memory", batch=True,
                    kilobot=_NO_MEMORY))
register(ActionSpec("retrace", _memory_action_check(_MEM_WHAT), _compile_retrace,
                    "move back to the newest remembered point and forget it", batch=True,
                    kilobot=_NO_MEMORY))
register(ActionSpec("clear", _check_clear, _compile_clear,
                    "empty a path memory or a label set", batch=True, kilobot=_NO_MEMORY))
register(ActionSpec("learn", _check_learn, _compile_learn,
                    "add a food label to a label set", batch=True, kilobot=_NO_MEMORY))

__all__ = ["DEFAULT_CAPACITY", "BOOL"]
