"""The checker's statements: `let`, assignments, `when` and actions in a status body.

Part of `Checker` (`checker.py`), as the mixin `StmtChecks`: one `visit_<Class>` per
statement class (`visit.Visitor` dispatches, with the scope, the kind and whether the
statement is among a `when`'s actions); a class an extension adds (a behaviour tree's
`tree` statement) is checked by its rule in `STMT_RULES`. An action statement
`name(args)` is checked by its row in `actions.py`.
"""

from __future__ import annotations

from swarmdsl.compiler import ast
from swarmdsl.compiler.builtins import AGGREGATES, BOOL, FUNCTIONS, NUM, TYPE_TEXT, VEC
from swarmdsl.compiler.checker_exprs import ERR
from swarmdsl.compiler.info import AGENT_STATE, BUILTIN_NAMES, KindInfo
from swarmdsl.compiler.scope import Scope
from swarmdsl.errors import did_you_mean

# Statement classes an extension adds:
# STMT_RULES[cls](checker, stmt, scope, kind, in_when) (behaviour trees).
STMT_RULES: dict = {}


class StmtChecks:
    """The statement rules of `Checker` (a mixin: the checker's state is on `self`)."""

    def block(self, stmts, scope: Scope, k: KindInfo, in_when: bool = False):
        """Check a status body (or a `when`'s actions, `in_when`) in order."""
        for st in stmts:
            self.visit(st, scope, k, in_when)

    def visit_LetStmt(self, st: ast.LetStmt, scope: Scope, k: KindInfo, in_when: bool):
        if in_when:
            self.fail("`let` is not allowed in a transition's actions", st.span)
            return
        if st.name in scope.locals:
            self.fail(f"`{st.name}` is already bound in this status", st.name_span)
        elif st.name in k.vars:
            line = k.vars[st.name].decl.name_span.line
            self.fail(f"`let {st.name}` would hide the variable `{st.name}` (line "
                      f"{line})", st.name_span, "choose another name")
        elif st.name in BUILTIN_NAMES:
            self.fail(f"`let {st.name}` would hide the built-in value `{st.name}`",
                      st.name_span, "choose another name")
        elif st.name in self.top_names:
            noun, span = self.top_names[st.name]
            self.fail(f"`let {st.name}` would hide the {noun} `{st.name}` (line "
                      f"{span.line})", st.name_span, "choose another name")
        t = self.expr(st.value, scope)
        scope.later.pop(st.name, None)
        scope.locals[st.name] = t

    def visit_AssignStmt(self, st: ast.AssignStmt, scope: Scope, k: KindInfo,
                         in_when: bool):
        self.assign(st, scope, k)

    def visit_WhenStmt(self, st: ast.WhenStmt, scope: Scope, k: KindInfo, in_when: bool):
        if in_when:
            self.fail("`when` is not allowed in a transition's actions", st.span)
            return
        self.in_condition = True   # rules may word a message for a transition
        try:
            self.expect(st.cond, BOOL, scope, "a `when` condition")
        finally:
            self.in_condition = False
        if st.target not in k.status_decls:
            self.fail(f"unknown status `{st.target}` in agent `{k.name}`",
                      st.target_span, did_you_mean(st.target, k.statuses))
        self.block(st.body, scope, k, in_when=True)

    def visit_ActionStmt(self, st: ast.ActionStmt, scope: Scope, k: KindInfo,
                         in_when: bool):
        self.action(st, scope, k)

    def assign(self, st: ast.AssignStmt, scope: Scope, k: KindInfo):
        value_t = self.expr(st.value, scope)
        if st.target in AGENT_STATE:
            t, assignable, column = AGENT_STATE[st.target]
            if not assignable:
                hint = ("set `velocity`; the runtime moves every agent by its velocity "
                        "each tick" if st.target in ("pos", "heading", "speed") else None)
                self.fail(f"`{st.target}` is read-only", st.target_span, hint)
                return
            self.facts.set_name(st, ("state", column))
        elif st.target in k.vars:
            v = k.vars[st.target]
            if not v.assignable:
                self.fail(f"`{st.target}` is an attribute of `{k.name}` and cannot change",
                          st.target_span, "declare it with `var` to make it a variable")
                return
            t = v.type
            self.facts.set_name(st, ("var", st.target))
            self.written_vars.add((k.name, st.target))
        else:
            if st.target in scope.locals:
                msg = f"`{st.target}` is a `let` binding and cannot be assigned"
            elif st.target in self.params:
                msg = f"`{st.target}` is a param and cannot be assigned"
            elif st.target in BUILTIN_NAMES:
                msg = f"`{st.target}` is a built-in value and cannot be assigned"
            elif st.target in self.top_names:
                noun = self.top_names[st.target][0]
                msg = (f"`{st.target}` is {'an' if noun[0] in 'aeiou' else 'a'} {noun} "
                       "and cannot be assigned")
            else:
                msg = f"unknown variable `{st.target}`"
            cands = list(k.vars) + [n for n, s in AGENT_STATE.items() if s[1]]
            hint = {"believed": "an agent takes new coordinates with `believe(POINT)`"}.get(
                st.target, did_you_mean(st.target, cands))
            if self.top_names.get(st.target, ("",))[0] == "field":
                hint = f"add to it with `deposit({st.target}, AMOUNT)`"
            self.fail(msg, st.target_span, hint)
            return
        if value_t == ERR or t == ERR:
            return
        if st.op == "=":
            if value_t != t:
                self.fail(f"cannot assign {TYPE_TEXT.get(value_t, value_t)} to "
                          f"`{st.target}`, which holds {TYPE_TEXT[t]}", st.value.span)
        elif st.op in ("+=", "-="):
            if t not in (NUM, VEC) or value_t != t:
                self.fail(f"`{st.op}` needs {TYPE_TEXT[t]} on the right, got "
                          f"{TYPE_TEXT.get(value_t, value_t)}", st.value.span)
        else:
            if t not in (NUM, VEC) or value_t != NUM:
                self.fail(f"`{st.op}` needs a number on the right, got "
                          f"{TYPE_TEXT.get(value_t, value_t)}", st.value.span)

    def action(self, st: ast.ActionStmt, scope: Scope, k: KindInfo):
        from swarmdsl.compiler.actions import ACTIONS

        spec = ACTIONS.get(st.name)
        if spec is None:
            for a in st.args:
                self.expr(a, scope)
            hint = did_you_mean(st.name, ACTIONS)
            if st.name in FUNCTIONS or st.name in AGGREGATES:
                hint = f"`{st.name}(...)` computes a value; bind it with `let`"
            self.fail(f"unknown action `{st.name}`", st.name_span, hint)
            return
        spec.check(self, st, scope, k)
