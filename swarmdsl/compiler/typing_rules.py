"""Type rules for the compound expressions: operators, attributes, calls, aggregates.

Split from checker.py so the checker stays a readable walk; each rule records the
node's resolution in `checker.facts` for codegen.
"""

from __future__ import annotations

from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import (
    AGGREGATES,
    BOOL,
    FUNCTIONS,
    KIND,
    NUM,
    SET,
    STATUS,
    TYPE_TEXT,
    VEC,
)
from swarmdsl.compiler.consteval import constant_radius
from swarmdsl.compiler.info import AGENT_STATE
from swarmdsl.compiler.scope import Scope
from swarmdsl.errors import did_you_mean
from swarmdsl.ops.operators import ARITHMETIC, COMPARISONS

ERR = "error"

# Extra name resolvers registered by language extensions (fields, regions, ...):
# each is fn(checker, name_node, scope) -> type or None.
NAME_RESOLVERS: list = []
# Extra call rules: name -> fn(checker, call_node, scope) -> type
CALL_RULES: dict = {}
# Attribute rules for extension types: type -> fn(checker, attr_node, scope) -> type
ATTR_RULES: dict = {}


def extra_name(checker, e: ast.Name, scope):
    for resolve in NAME_RESOLVERS:
        t = resolve(checker, e, scope)
        if t is not None:
            return t
    return None


def attr(checker, e: ast.Attr, scope) -> str:
    if isinstance(e.obj, ast.Name) and e.obj.id == "other":
        if not scope.pair:
            checker.expr(e.obj, scope)  # reports the misuse
            return ERR
        return _other_attr(checker, e)
    t = checker.expr(e.obj, scope)
    if t == ERR:
        return ERR
    if t in ATTR_RULES:
        return ATTR_RULES[t](checker, e, scope)
    if t == VEC and e.name in ("x", "y"):
        checker.facts.set_name(e, ("component", 0 if e.name == "x" else 1))
        return NUM
    if t == VEC:
        return checker.fail(f"a vector has `.x` and `.y`, not `.{e.name}`", e.name_span,
                            did_you_mean(e.name, ["x", "y"]))
    return checker.fail(f"{TYPE_TEXT.get(t, t)} has no attribute `{e.name}`", e.name_span)


def _other_attr(checker, e: ast.Attr) -> str:
    if e.name in AGENT_STATE:
        checker.facts.set_name(e, ("other_state", AGENT_STATE[e.name][2]))
        return AGENT_STATE[e.name][0]
    for k in checker.kinds:
        if e.name in k.vars:
            checker.used_vars.update((kk.name, e.name) for kk in checker.kinds
                                     if e.name in kk.vars)
            checker.facts.set_name(e, ("other_var", e.name))
            return k.vars[e.name].type
    cands = list(AGENT_STATE) + [v for k in checker.kinds for v in k.vars]
    return checker.fail(f"neighbours have no variable `{e.name}`", e.name_span,
                        did_you_mean(e.name, cands))


def bin_op(checker, e: ast.BinOp, scope) -> str:
    a = checker.expr(e.left, scope)
    b = checker.expr(e.right, scope)
    return bin_type(checker, e.op, a, b, e.span)


def chain(checker, e: ast.Chain, scope) -> str:
    """Type a flat chain term by term, as the binary operators it stands for."""
    if e.rest[0][0] in ("and", "or"):
        for term in (e.first, *(t for _, t in e.rest)):
            checker.expect(term, BOOL, scope, f"each side of `{e.rest[0][0]}`")
        return BOOL
    t = checker.expr(e.first, scope)
    for op, term in e.rest:
        t = bin_type(checker, op, t, checker.expr(term, scope), e.span)
    return t


def bin_type(checker, op: str, a: str, b: str, span) -> str:
    """The type of `a op b` for arithmetic operators, or a located error."""
    if ERR in (a, b):
        return ERR
    result = ARITHMETIC[op].types.get((a, b))
    if result is not None:
        return result
    hint = None
    if op == "*" and a == b == VEC:
        hint = "use dot(a, b) for the dot product"
    elif a == VEC or b == VEC:
        hint = "vectors support +, -, * and / by a number"
    return checker.fail(f"cannot apply `{op}` to {TYPE_TEXT.get(a, a)} and "
                        f"{TYPE_TEXT.get(b, b)}", span, hint)


def compare(checker, e: ast.Compare, scope) -> str:
    a = checker.expr(e.left, scope)
    b = checker.expr(e.right, scope)
    if {a, b} == {KIND, STATUS} and _as_own_kind(checker, e.right if b == STATUS else e.left):
        a = b = KIND
    if ERR in (a, b):
        return BOOL
    if (a, b) in COMPARISONS[e.op].types:
        if a == b == NUM:
            from swarmdsl.compiler.comparisons import check_comparison

            check_comparison(checker, e)    # `age(M, p) == inf`: the same answer always
        return BOOL
    return checker.fail(f"cannot compare {TYPE_TEXT.get(a, a)} with {TYPE_TEXT.get(b, b)} "
                        f"using `{e.op}`", e.span)


def _as_own_kind(checker, e) -> bool:
    """Read a status name that is also its kind's name as the kind (`other.kind ==
    reference` where kind `reference` has a status `reference`); False if it is not one."""
    if not isinstance(e, ast.Name) or checker.facts.name_of(e) != ("status", e.id):
        return False
    for k in checker.kinds:
        if k.name == e.id and e.id in k.status_decls:
            checker.facts.set_name(e, ("kind", k.index))
            checker.facts.set_type(e, KIND)
            return True
    return False


def where(checker, e: ast.Where, scope) -> str:
    t = checker.expr(e.source, scope)
    if t not in (SET, ERR):
        checker.fail(f"`where` filters a neighbour set, not {TYPE_TEXT.get(t, t)}",
                     e.source.span, "e.g. `neighbors(10) where other.status == idle`")
    checker.expect(e.cond, BOOL, _pair_scope(checker, scope, e), "a `where` condition")
    return SET


def _pair_scope(checker, scope, node):
    if scope.pair:
        checker.fail("neighbour queries cannot be nested inside another one", node.span)
    inner = Scope(scope.kind, scope.locals, pair=True, init=scope.init, used=scope.used)
    return inner


def call(checker, e: ast.Call, scope) -> str:
    rule = CALL_RULES.get(e.name)
    if rule is not None:
        return rule(checker, e, scope)
    if e.name in ("neighbors", "neighbours"):
        return _neighbors(checker, e, scope)
    if e.name in AGGREGATES:
        first = checker.expr(e.args[0], scope) if e.args else None
        if first == SET or (first == ERR and e.each is not None):
            return _aggregate(checker, e, scope)
        if e.each is not None or e.default is not None:
            if first not in (SET, ERR):
                return checker.fail(f"`{e.name}(X : ...)` needs a neighbour set as X, got "
                                    f"{TYPE_TEXT.get(first, first)}", e.args[0].span
                                    if e.args else e.span)
        if e.name not in FUNCTIONS:
            if first == ERR:
                return ERR  # the argument's own error says what is wrong
            if first is None:
                return checker.fail(f"`{e.name}` needs a neighbour set", e.span,
                                    f"e.g. `{e.name}(neighbors())`")
            return checker.fail(f"`{e.name}` needs a neighbour set, got "
                                f"{TYPE_TEXT.get(first, first)}", e.args[0].span)
        return _function(checker, e, scope, first_type=first)
    if e.name in FUNCTIONS:
        if e.each is not None or e.default is not None:
            return checker.fail(f"`{e.name}` does not take `:` or `else`", e.span)
        return _function(checker, e, scope)
    for a in e.args:
        checker.expr(a, scope)
    cands = list(FUNCTIONS) + list(AGGREGATES) + list(CALL_RULES) + ["neighbors"]
    return checker.fail(f"unknown function `{e.name}`", e.name_span,
                        did_you_mean(e.name, cands))


def _function(checker, e: ast.Call, scope, first_type=None) -> str:
    b = FUNCTIONS[e.name]
    types = []
    for i, a in enumerate(e.args):
        types.append(first_type if i == 0 and first_type is not None else
                     checker.expr(a, scope))
    if len(e.args) != len(b.params):
        return checker.fail(f"`{e.name}` takes {len(b.params)} argument"
                            f"{'' if len(b.params) == 1 else 's'}, got {len(e.args)}", e.span)
    for a, t, want in zip(e.args, types, b.params, strict=True):
        if t not in (want, ERR):
            checker.fail(f"argument of `{e.name}` must be {TYPE_TEXT[want]}, got "
                         f"{TYPE_TEXT.get(t, t)}", a.span)
    checker.facts.set_name(e, ("func", e.name))
    return b.result


def _neighbors(checker, e: ast.Call, scope) -> str:
    if scope.init:
        return checker.fail("neighbour queries are not available while agents are placed",
                            e.span)
    if scope.pair:
        return checker.fail("neighbour queries cannot be nested inside another one", e.span)
    if len(e.args) > 1 or e.each is not None or e.default is not None:
        return checker.fail("`neighbors` takes at most one argument: the radius", e.span)
    if e.args:
        checker.expect(e.args[0], NUM, scope, "a neighbour radius")
    if scope.kind is not None:
        scope.kind.uses_neighbors = True
        radius = constant_radius(e.args[0], checker.params) if e.args else None
        scope.kind.neighbor_calls.append((e, radius))
    checker.facts.set_name(e, ("neighbors",))
    return SET


def _aggregate(checker, e: ast.Call, scope) -> str:
    row = AGGREGATES[e.name]
    needs_each, each_types = row.needs_each, row.each_types
    if len(e.args) != 1:
        hint = None
        if len(e.args) == 2 and needs_each and e.each is None:   # `mean(near, other.vel)`
            hint = (f"a `:` separates the set from what is aggregated: "
                    f"`{e.name}(SET : EXPR)`, e.g. `{e.name}(near : other.vel)`")
        return checker.fail(f"`{e.name}` takes one neighbour set", e.span, hint)
    pair = _pair_scope(checker, scope, e)
    result = NUM
    if e.each is None:
        if needs_each:
            return checker.fail(f"`{e.name}` needs `: EXPR` saying what to aggregate",
                                e.span, f"e.g. `{e.name}(near : other.pos)`")
    else:
        if not needs_each:
            checker.expr(e.each, pair)
            return checker.fail(f"`{e.name}` takes no `: EXPR`; filter with `where`",
                                e.each.span)
        t = checker.expr(e.each, pair)
        if t not in each_types and t != ERR:
            allowed = " or ".join(TYPE_TEXT[x] for x in each_types)
            return checker.fail(f"`{e.name}` aggregates {allowed}, got "
                                f"{TYPE_TEXT.get(t, t)}", e.each.span)
        result = t if row.result is None else row.result
    if e.default is not None:
        if not row.takes_else:
            takers = [name for name, r in AGGREGATES.items() if r.takes_else]
            checker.fail(f"`{e.name}` of no neighbours is well defined; `else` is only for "
                         f"{', '.join(takers[:-1])} and {takers[-1]}", e.default.span)
        else:
            checker.expect(e.default, result, scope, f"the `else` of `{e.name}`")
    checker.facts.set_name(e, ("agg", e.name))
    return result

