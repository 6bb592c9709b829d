"""Physical twins in the language: `field NAME { twin FORMULA }`.

A twin is a field whose value is a formula of the node position `pos` and the time
`tick` (the thesis' PhysicalTwinBase): a number gives a scalar field (temperature), a
vector `(x, y)` a vector field (a force or a flow). A twin is read like any field
(`sample(F)`; a vector twin's `sample` is a vector, so `velocity += sample(wind)` moves
agents with the flow) but is never written: no `deposit`, `decay`, `diffuse` or
`initial`. The runtime half is `runtime/twins.py`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmdsl.compiler import ast, codegen, lang_fields, typing_rules
from swarmdsl.compiler.builtins import NUM, TYPE_TEXT, VEC

ERR = "error"
VFIELD = "vfield"
TYPE_TEXT.setdefault(VFIELD, "a vector field")
_WRITTEN = ("decay", "diffuse", "initial")


@dataclass(frozen=True)
class TwinInfo:
    formula: ast.Expr
    vector: bool
    static: bool          # the formula does not read `tick`: sampled once


def _walk(node):
    yield node
    for c in node.children():
        yield from _walk(c)


def _twin_option(chk, env, d: ast.FieldDecl, opt: ast.Option) -> None:
    from swarmdsl.compiler.info import AGENT_STATE
    from swarmdsl.compiler.scope import Scope

    if len(opt.args) != 1:
        chk.fail("`twin` takes one formula of `pos` and `tick`: "
                 "`twin 20 + sin(pos.x / 50 + tick / 10)`", opt.span)
        return
    formula = opt.args[0]
    reads_tick = False
    for node in _walk(formula):
        if isinstance(node, ast.Name):
            if node.id in AGENT_STATE and node.id != "pos":
                chk.fail(f"a twin is a formula of the node position `pos` and the time "
                         f"`tick`; `{node.id}` is not known there", node.span)
                return
            reads_tick |= node.id == "tick"
    t = chk.expr(formula, Scope(None, init=True))
    if t == ERR:
        return
    if t not in (NUM, VEC):
        chk.fail(f"a twin's formula must give a number or a vector, got "
                 f"{TYPE_TEXT.get(t, t)}", formula.span)
        return
    env.twins[d.name] = TwinInfo(formula, t == VEC, not reads_tick)
    if t == VEC:
        env.vector_fields[d.name] = d


def _after_field(chk, env, d: ast.FieldDecl, seen: set) -> None:
    if d.name not in env.twins:
        return
    for opt in d.options:
        if opt.name in _WRITTEN:
            chk.fail(f"field `{d.name}` is a physical twin: its values come from its "
                     f"formula, so it takes no `{opt.name}`", opt.name_span,
                     "declare a second field for what agents lay down")


lang_fields.FIELD_OPTIONS["twin"] = _twin_option
lang_fields.FIELD_DECL_HOOKS.append(_after_field)


# ---- names and calls ----

def _resolve(chk, e: ast.Name, scope):
    if e.id in lang_fields.env_info(chk).vector_fields:
        chk.facts.set_name(e, ("vfield", e.id))
        return VFIELD
    return None


typing_rules.NAME_RESOLVERS.insert(0, _resolve)
codegen.NAME_CODEGEN["vfield"] = lambda gen, e, res: (lambda f, _n=res[1]: _n)

_scalar_sample_rule = typing_rules.CALL_RULES["sample"]
_scalar_sample_codegen = codegen.CALL_CODEGEN["sample"]


def _is_vector(chk_or_gen, call) -> bool:
    a = call.args[0] if call.args else None
    return isinstance(a, ast.Name) and chk_or_gen.facts.category(a) == "vfield"


def _sample_rule(chk, call, scope):
    if call.args and isinstance(call.args[0], ast.Name) and \
            call.args[0].id in lang_fields.env_info(chk).vector_fields:
        if not lang_fields.arity(chk, call, scope, 1, 2, "sample(FIELD [, point])") or \
                not lang_fields.agents_only(chk, call, scope):
            return ERR
        chk.expr(call.args[0], scope)
        if len(call.args) == 2:
            chk.expect(call.args[1], VEC, scope, "the sampled point")
        chk.facts.set_name(call, ("env_call", "sample"))
        return VEC
    return _scalar_sample_rule(chk, call, scope)


def _cg_sample(gen, call):
    if not _is_vector(gen, call):
        return _scalar_sample_codegen(gen, call)
    name = call.args[0].id
    at = lang_fields.point_reader(gen, call.args[1], name, call.span) \
        if len(call.args) == 2 else None

    def sample(f):
        pts = np.broadcast_to(np.asarray(f.state("pos"), dtype=np.float64), (f.n, 2)) \
            if at is None else at(f)
        return lang_fields.env_of(f).vectors[name].sample(pts, lang_fields.replicas(f))
    return sample


typing_rules.CALL_RULES["sample"] = _sample_rule
codegen.CALL_CODEGEN["sample"] = _cg_sample


# ---- the runtime spec ----

def _spec_hook(info, env, spec, gen) -> None:
    from swarmdsl.runtime.twins import TwinSpec

    for name, t in env.twins.items():
        decl = env.vector_fields.get(name) or env.fields[name]
        spec.twins.append(TwinSpec(name, gen.expr(t.formula), t.vector, t.static,
                                   decl.name_span))


lang_fields.ENV_SPEC_HOOKS.append(_spec_hook)
