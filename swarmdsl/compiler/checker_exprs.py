"""The checker's expressions: each class's type rule, and what each name resolves to.

Part of `Checker` (`checker.py`), as the mixin `ExprChecks`: one `visit_<Class>` per
expression class (`visit.Visitor` dispatches; a class an extension adds is checked by
its rule in `EXPR_RULES`). Each records the node's type (`expr`) and, for a name, call or
attribute, its resolution in `facts` (`facts.py`), which every later walker reads. The
compound rules (operators, attributes, calls, aggregates) are in `typing_rules.py`.
"""

from __future__ import annotations

import math

from swarmdsl.compiler import ast
from swarmdsl.compiler import typing_rules as rules
from swarmdsl.compiler.builtins import (
    BOOL,
    CONSTANTS,
    KIND,
    NUM,
    OTHER,
    STATUS,
    STR,
    TYPE_TEXT,
    VEC,
)
from swarmdsl.compiler.info import AGENT_STATE, GLOBAL_STATE, PAIR_NAMES, KindInfo
from swarmdsl.compiler.options import AGENT_OPTIONS
from swarmdsl.compiler.scope import Scope
from swarmdsl.errors import Span, did_you_mean
from swarmdsl.ops.operators import NEGATE

ERR = "error"  # the type of an expression that already produced a diagnostic

# NAME_HINT_HOOKS: fn(checker, scope) -> names an extension makes visible, for hints.
NAME_HINT_HOOKS: list = []
# Expression classes an extension adds: EXPR_RULES[cls](checker, expr, scope) -> type
# (behaviour trees, `F at P`).
EXPR_RULES: dict = {}


# Names users write for a vector's components (the column names of `agents.parquet`)
_COMPONENTS = {"x": "the position is `pos`: write `pos.x`",
               "y": "the position is `pos`: write `pos.y`",
               "vx": "the velocity is `velocity`: write `velocity.x`",
               "vy": "the velocity is `velocity`: write `velocity.y`"}


class ExprChecks:
    """The expression rules of `Checker` (a mixin: the checker's state is on `self`)."""

    def expect(self, e: ast.Expr, want: str, scope: Scope, what: str) -> str:
        t = self.expr(e, scope)
        if t not in (want, ERR) and want != ERR:   # want ERR: an earlier error, no type
            return self.fail(f"{what} must be {TYPE_TEXT[want]}, got {TYPE_TEXT.get(t, t)}",
                             e.span)
        return t

    def expr(self, e: ast.Expr, scope: Scope) -> str:
        t = self._expr(e, scope)
        self.facts.set_type(e, t)
        return t

    def _expr(self, e: ast.Expr, scope: Scope) -> str:
        """The type of `e` (its method by class; an extension's rule for its classes)."""
        return self.visit(e, scope)

    def visit_Num(self, e: ast.Num, scope: Scope) -> str:
        if not math.isfinite(e.value):
            self.fail("the number is too large (over 1.8e308)", e.span)
        return NUM

    def visit_BoolLit(self, e: ast.BoolLit, scope: Scope) -> str:
        return BOOL

    def visit_StrLit(self, e: ast.StrLit, scope: Scope) -> str:
        return STR

    def visit_Name(self, e: ast.Name, scope: Scope) -> str:
        return self.name(e, scope)

    def visit_Vec(self, e: ast.Vec, scope: Scope) -> str:
        self.expect(e.x, NUM, scope, "a vector's x")
        self.expect(e.y, NUM, scope, "a vector's y")
        return VEC

    def visit_Attr(self, e: ast.Attr, scope: Scope) -> str:
        return rules.attr(self, e, scope)

    def visit_BinOp(self, e: ast.BinOp, scope: Scope) -> str:
        return rules.bin_op(self, e, scope)

    def visit_Chain(self, e: ast.Chain, scope: Scope) -> str:
        return rules.chain(self, e, scope)

    def visit_Neg(self, e: ast.Neg, scope: Scope) -> str:
        t = self.expr(e.operand, scope)
        if t != ERR and (t,) not in NEGATE.types:
            return self.fail(f"cannot negate {TYPE_TEXT.get(t, t)}", e.span)
        return NEGATE.types.get((t,), t)

    def visit_Compare(self, e: ast.Compare, scope: Scope) -> str:
        return rules.compare(self, e, scope)

    def visit_AndOp(self, e: ast.AndOp, scope: Scope) -> str:
        self.expect(e.left, BOOL, scope, "each side of `and`")
        self.expect(e.right, BOOL, scope, "each side of `and`")
        return BOOL

    def visit_OrOp(self, e: ast.OrOp, scope: Scope) -> str:
        self.expect(e.left, BOOL, scope, "each side of `or`")
        self.expect(e.right, BOOL, scope, "each side of `or`")
        return BOOL

    def visit_NotOp(self, e: ast.NotOp, scope: Scope) -> str:
        self.expect(e.operand, BOOL, scope, "the operand of `not`")
        return BOOL

    def visit_Cond(self, e: ast.Cond, scope: Scope) -> str:
        self.expect(e.test, BOOL, scope, "the condition of `if`")
        a, b = self.expr(e.then, scope), self.expr(e.orelse, scope)
        if ERR in (a, b):
            return ERR
        if a != b or a not in (NUM, BOOL, VEC, STATUS):
            return self.fail(f"`if` branches must have one type, got {TYPE_TEXT[a]} and "
                             f"{TYPE_TEXT[b]}", e.span)
        return a

    def visit_Where(self, e: ast.Where, scope: Scope) -> str:
        return rules.where(self, e, scope)

    def visit_Call(self, e: ast.Call, scope: Scope) -> str:
        return rules.call(self, e, scope)

    def name(self, e: ast.Name, scope: Scope) -> str:
        n = e.id
        k = scope.kind
        if n in scope.locals:
            scope.used.add(n)
            self.facts.set_name(e, ("local", n))
            return scope.locals[n]
        if k is not None and n in k.vars:
            self.used_vars.add((k.name, n))
            self.facts.set_name(e, ("var", n))
            return k.vars[n].type
        if n in self.ambiguous_names:
            return ERR   # `field f` and `agent f`: reported at the second declaration
        if n in AGENT_STATE:
            if scope.init and n in ("status", "speed"):
                return self.fail(f"`{n}` is not known while agents are being placed", e.span)
            self.facts.set_name(e, ("state", AGENT_STATE[n][2]))
            return AGENT_STATE[n][0]
        if n in PAIR_NAMES:
            if not scope.pair:
                return self.fail(f"`{n}` is only defined inside a neighbour filter or "
                                 "aggregate", e.span,
                                 "e.g. `count(neighbors() where dist < 5)`")
            self.facts.set_name(e, ("pair", n))
            return PAIR_NAMES[n]
        if n == "other":
            if not scope.pair:
                return self.fail("`other` is only defined inside a neighbour filter or "
                                 "aggregate", e.span,
                                 "e.g. `sum(neighbors() : other.pos - pos)`")
            return OTHER
        if n in GLOBAL_STATE:
            self.facts.set_name(e, ("global", n))
            return GLOBAL_STATE[n]
        if n in self.params:
            self.facts.set_name(e, ("const", self.params[n]))
            v = self.params[n]
            if n in self.refused_params:
                return ERR   # `param g = (1, 2)`: not a number at every use too
            return BOOL if isinstance(v, bool) else NUM
        if n in CONSTANTS:
            self.facts.set_name(e, ("const", CONSTANTS[n]))
            return NUM
        for kind in self.kinds:
            if n in kind.status_decls:
                self.facts.set_name(e, ("status", n))
                return STATUS
        for kind in self.kinds:
            if n == kind.name:
                self.facts.set_name(e, ("kind", kind.index))
                return KIND
        t = rules.extra_name(self, e, scope)
        if t is not None:
            return t
        if self.refused_declaration(n, k):
            return ERR   # its declaration's error is the one mistake, not every use
        decls = [*self.tree.decls, *(k.decl.items if k is not None else ())]
        unread = _UNREAD_DECLS.get(type(next((d for d in decls
                                              if getattr(d, "name", None) == n), None)))
        if unread is not None:
            return self.fail(f"`{n}` is {unread}, which the program cannot read", e.span,
                             "metrics and properties observe the run from outside; repeat "
                             "its expression, or keep what agents need in a `var`")
        if n in scope.later and _starts_within(e.span, scope.later[n].value.span):
            return self.fail(f"`let {n}` cannot use its own value", e.span)
        if n in scope.later:
            return self.fail(f"`{n}` is bound by a `let` after this (line "
                             f"{scope.later[n].name_span.line}): a `let` is known only in "
                             "the statements after it", e.span, "move the `let` above")
        later = _declared_later(n, k) if scope.init else None
        if later is not None and _starts_within(e.span, later.value.span):  # `var e = e`
            return self.fail(f"variable `{n}` cannot use its own value", e.span,
                             "an initial value reads params, `index`, `pos` and the "
                             "variables declared above it")
        if later is not None:
            return self.fail(f"variable `{n}` (line {later.name_span.line}) is not known yet "
                             "here: an initial value may use only the variables declared "
                             "before it", e.span, f"declare `{n}` above this line")
        hint = did_you_mean(n, self.visible_names(scope))
        if hint is None and n in _COMPONENTS:   # `x > 3`: the column names of outputs
            hint = _COMPONENTS[n]
        if n.lower() == "nan":      # `x == nan` could never hold: NaN equals nothing
            hint = ("there is no `nan`: NaN is unequal to every number, itself included, "
                    "so `x == nan` would never be true; `x != x` holds exactly for NaN")
        return self.fail(f"unknown name `{n}`", e.span, hint)

    def refused_declaration(self, name: str, kind: KindInfo | None) -> bool:
        """Whether `name` is declared, as a field or region or as a map, memory or label
        set of `kind`, by a declaration already reported as wrong (`circle(50, 50, -5)`,
        `map seen 10 0`). Its uses are then no "unknown name" errors of their own."""
        decls = [d for d in self.tree.decls
                 if isinstance(d, ast.FieldDecl | ast.RegionDecl) and d.name == name]
        if kind is not None:
            decls += [o for o in kind.decl.items_of(ast.Option) if _declares(o, name)]
        return any(self.reported_within(d.span) for d in decls)

    def reported_within(self, span: Span) -> bool:
        """Whether an error has been reported inside `span`."""
        return any(e.span is not None and _starts_within(e.span, span)
                   for e in self.errors)

    def visible_names(self, scope: Scope) -> list[str]:
        names = list(scope.locals) + list(AGENT_STATE) + list(self.params) + list(CONSTANTS)
        names += list(GLOBAL_STATE) + [k.name for k in self.kinds]
        if scope.kind is not None:
            names += list(scope.kind.vars) + scope.kind.statuses
        if scope.pair:
            names += list(PAIR_NAMES) + ["other"]
        for hook in NAME_HINT_HOOKS:
            names += hook(self, scope)
        return names


# Named top-level declarations agent code, metrics and properties cannot read.
_UNREAD_DECLS = {ast.MetricDecl: "a metric", ast.InvariantDecl: "a property",
                 ast.EventuallyDecl: "a property", ast.ResponseDecl: "a property"}


def _starts_within(span: Span, outer: Span) -> bool:
    """Whether `span` starts inside `outer`."""
    return ((outer.line, outer.col) <= (span.line, span.col)
            < (outer.end_line, outer.end_col))


def _declared_later(name: str, kind: KindInfo | None):
    """The `var`/`attr` declaration of `name` in `kind` not read yet (below), or None."""
    if kind is None or name in kind.vars:
        return None
    return next((d for d in kind.decl.items_of(ast.VarDecl | ast.AttrDecl)
                 if d.name == name), None)


def _declares(opt: ast.Option, name: str) -> bool:
    """Whether agent option `opt` declares `name` (`map name 10 40`, `memory name 200`)."""
    spec = AGENT_OPTIONS.get(opt.name)
    return (spec is not None and spec.declares and bool(opt.args)
            and isinstance(opt.args[0], ast.Name) and opt.args[0].id == name)
