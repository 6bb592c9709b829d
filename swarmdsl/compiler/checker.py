"""Names, types, options and the status graph: every diagnostic, collected, then raised.

The checker is the only judge of meaning. It records, per expression node, its type and
what each name resolves to (`facts.py`), so codegen never has to guess. This module is
the walk over declarations (params, world, kinds, their variables and statuses); the
rules of statements and expressions are `checker_stmts.py` and `checker_exprs.py`,
mixed into `Checker` and dispatched by node class (`visit.py`).
"""

from __future__ import annotations

import re
from pathlib import Path

from swarmdsl.compiler import ast, columns
from swarmdsl.compiler.builtins import (
    BOOL,
    CONSTANTS,
    NUM,
    TYPE_TEXT,
    VEC,
)
from swarmdsl.compiler.checker_exprs import (  # noqa: F401 - the tables extensions use
    ERR,
    EXPR_RULES,
    NAME_HINT_HOOKS,
    ExprChecks,
    _declares,
    _starts_within,
)
from swarmdsl.compiler.checker_stmts import STMT_RULES, StmtChecks
from swarmdsl.compiler.consteval import NotConstant, const_value
from swarmdsl.compiler.facts import Facts
from swarmdsl.compiler.info import (
    BUILTIN_NAMES,
    KindInfo,
    ProgramInfo,
    VarInfo,
    WorldInfo,
)
from swarmdsl.compiler.options import AGENT_OPTIONS, WORLD_OPTIONS
from swarmdsl.compiler.scope import Scope
from swarmdsl.compiler.visit import Visitor
from swarmdsl.errors import (
    Span,
    SwarmCheckError,
    SwarmError,
    SwarmOptionError,
    did_you_mean,
)
from swarmdsl.limits import constant_problem

# Words of expressions and statements. The parser reads a name wherever only a name can
# stand (`param if = 3`), but a name that is one of these could not be used afterwards
# (`count if`, `on = true`, `true` is the literal), so no declaration may take one.
KEYWORDS = frozenset({"if", "then", "else", "and", "or", "not", "where", "in", "true",
                      "false", "let", "when", "tree", "on"})

# Extension hooks. DECL_HOOKS run after params and world, before agent kinds are read:
# fn(checker) (fields, regions, robot profiles). KIND_HOOKS run after each kind's body:
# fn(checker, kind). PROGRAM_CHECK_HOOKS run last: fn(checker) (invariants, analyses).
# Hooks keep what they learn in `checker.extra`, which becomes `ProgramInfo.extra`.
DECL_HOOKS: list = []
KIND_HOOKS: list = []
PROGRAM_CHECK_HOOKS: list = []
# NAME_HINT_HOOKS (fn(checker, scope) -> names an extension makes visible, for hints),
# EXPR_RULES and STMT_RULES (node classes an extension adds) live with the expressions
# and statements (`checker_exprs.py`, `checker_stmts.py`) and are the same tables here.


class Checker(StmtChecks, ExprChecks, Visitor):
    """The walk over a program's declarations; its statements and expressions are the
    mixins `StmtChecks` and `ExprChecks`, dispatched by `visit.Visitor`."""

    NODES = (ast.Expr, ast.Stmt)

    def __init__(self, tree: ast.Program, filename: str, overrides: dict[str, str],
                 program_dir: Path | None = None):
        self.tree = tree
        self.filename = filename
        # the folder files named by the program (models) are resolved against
        self.program_dir = Path(program_dir or Path(filename).resolve().parent)
        self.overrides = overrides
        self.errors: list[SwarmError] = []
        self.warnings: list[SwarmError] = []
        self.in_condition = False   # checking a `when` condition (not a value)
        self.facts = Facts()   # per node: its type, what its name resolved to
        self.params: dict[str, object] = {}
        self.param_decls: dict[str, ast.ParamDecl] = {}
        self.refused_params: set[str] = set()   # reported where declared; no type
        self.ambiguous_names: set[str] = set()  # declared twice, as two kinds of thing
        self.kinds: list[KindInfo] = []
        self.world = WorldInfo()
        self.used_vars: set[tuple[str, str]] = set()
        self.written_vars: set[tuple[str, str]] = set()   # (kind, var) some statement sets
        self.extra: dict = {}
        # names agent code can read that are declared at top level: name -> (noun, span)
        self.top_names: dict[str, tuple[str, Span]] = {}
        self.column_table = columns.ColumnTable()   # variables -> agents.parquet columns

    def extension_rule(self, node_cls: type):
        return EXPR_RULES.get(node_cls) or STMT_RULES.get(node_cls)



    # ---- reporting ----
    def fail(self, message: str, span: Span, hint: str | None = None) -> str:
        # A named tree's body is checked once per use: the same mistake is reported once.
        if self._first_time("error", message, span, hint):
            self.errors.append(SwarmError(message, span, hint))
        return ERR

    def warn(self, message: str, span: Span, hint: str | None = None) -> None:
        if self._first_time("warning", message, span, hint):
            self.warnings.append(SwarmError(message, span, hint, severity="warning"))

    def _first_time(self, *diagnostic) -> bool:
        """Whether this diagnostic (severity, message, span, hint) is new: a set, so a
        program with thousands of errors is not checked against each one."""
        reported = self.__dict__.setdefault("_reported", set())
        if diagnostic in reported:
            return False
        reported.add(diagnostic)
        return True

    # ---- entry ----
    def run(self) -> ProgramInfo:
        self._keyword_names()
        self._check_duplicates()
        self._params()
        self._world()
        for hook in DECL_HOOKS:
            hook(self)
        self._declare_kinds()
        for k in self.kinds:
            self._kind_options(k)
        for k in self.kinds:
            self._kind_body(k)
            for hook in KIND_HOOKS:
                hook(self, k)
        from swarmdsl.compiler.status_graph import check_status_graphs

        check_status_graphs(self)
        for hook in PROGRAM_CHECK_HOOKS:
            hook(self)
        self._unread_vars()
        if self.errors:
            self.errors.sort(key=lambda e: (e.span.line, e.span.col) if e.span else (0, 0))
            raise SwarmCheckError(self.errors)
        status_names: list[str] = []
        for k in self.kinds:
            for s in k.statuses:
                if s not in status_names:
                    status_names.append(s)
        return ProgramInfo(self.tree, self.filename, self.params, self.param_decls,
                           self.world, self.kinds, status_names, self.facts,
                           self.warnings, self.extra)

    def _keyword_names(self):
        """A declaration named after a keyword is refused where it is declared."""
        stack: list = [self.tree]
        while stack:
            node = stack.pop()
            if isinstance(node, ast.Expr):
                continue   # expressions declare nothing (and may be deep)
            stack.extend(node.children())
            if isinstance(node, ast.Option | ast.ActionStmt):
                continue   # their names are options and actions, not declarations
            named = [(getattr(node, "name", None), getattr(node, "name_span", None))]
            named += zip(getattr(node, "params", ()), getattr(node, "param_spans", ()),
                         strict=True)   # a named tree's parameters
            for name, span in named:
                if name in KEYWORDS and span is not None:
                    self.fail(f"`{name}` is a keyword and cannot be used as a name", span,
                              f"choose another name, e.g. `{name}_`")

    def _check_duplicates(self):
        seen: dict[str, Span] = {}
        first: dict[str, type] = {}
        for d in self.tree.decls:
            name = getattr(d, "name", None)
            if name is None:
                continue
            if name in seen:
                noun = _READABLE_DECLS.get(first[name]) if type(d) is not first[name] \
                    else None
                what = f" as {'an' if noun[0] in 'aeiou' else 'a'} {noun}" if noun else ""
                self.fail(f"`{name}` is already declared{what} (line {seen[name].line})",
                          d.name_span)
                if type(d) is not first[name]:   # a field and a kind: which is meant?
                    self.ambiguous_names.add(name)
                continue
            seen[name] = d.name_span
            first[name] = type(d)
            noun = _READABLE_DECLS.get(type(d))
            if noun is None:
                continue    # metrics, properties, robots, trees: not read by agent code
            if isinstance(d, ast.RegionDecl) and d.keyword != "region":
                noun = f"`{d.keyword}` region"
            self.top_names[name] = (noun, d.name_span)
            self.builtin_clash(name, d.name_span)
        worlds = self.tree.decls_of(ast.WorldDecl)
        for w in worlds[1:]:
            self.fail("a program has one `world` block; this is the second", w.span)

    # ---- names taken ----
    def builtin_clash(self, name: str, span: Span) -> bool:
        """Refuse a declaration named like a built-in value; True if it was."""
        if name not in BUILTIN_NAMES:
            return False
        self.fail(f"`{name}` is the name of a built-in value; choose another name", span)
        return True

    def name_taken(self, name: str, span: Span) -> bool:
        """Refuse a name a kind declares (variable, memory, map, objective) that agent
        code already reads as a built-in, param, field, region or kind; True if it was."""
        return self.builtin_clash(name, span) or self.top_level_clash(name, span)

    def top_level_clash(self, name: str, span: Span) -> bool:
        """Refuse a kind's name (variable, status) that agent code could also read as a
        param, field, region or kind declared at top level; True if it was."""
        if name not in self.top_names:
            return False
        noun, first = self.top_names[name]
        article = "an" if noun[0] in "aeiou" else "a"
        self.fail(f"`{name}` is already declared as {article} {noun} at line {first.line}",
                  span, "choose another name")
        return True

    # ---- params ----
    def _params(self):
        for p in self.tree.decls_of(ast.ParamDecl):
            if p.name in self.param_decls:
                continue
            self.param_decls[p.name] = p
            value = self._const(p.value, "a param's value")
            if value is None:
                self.params[p.name] = 0
                self.refused_params.add(p.name)
                continue
            if not isinstance(value, bool | int | float):
                self.fail(f"param `{p.name}` must be a number or a boolean", p.value.span)
                value = 0
                self.refused_params.add(p.name)
            if p.name in self.overrides:
                value = _parse_override(p.name, self.overrides[p.name], value)
                problem = constant_problem(value)
                if problem:
                    raise SwarmOptionError(f"--set {p.name}={self.overrides[p.name]}: the "
                                           f"value {problem}")
            if p.lo is not None and isinstance(value, bool):
                self.fail(f"param `{p.name}` is a boolean; only a number takes a range "
                          "`in LO..HI`", _joined(p.lo.span, p.hi.span),
                          f"drop the range: `param {p.name} = {str(value).lower()}`")
            elif p.lo is not None:
                lo = self._number(p.lo, "a range bound")
                hi = self._number(p.hi, "a range bound")
                if lo is not None and hi is not None and lo > hi:
                    self.fail(f"the range {lo}..{hi} of param `{p.name}` is empty: its low "
                              "end is above its high end", _joined(p.lo.span, p.hi.span),
                              f"write it low to high: `in {hi}..{lo}`")
                elif lo is not None and hi is not None and not lo <= value <= hi:
                    if p.name in self.overrides:
                        raise SwarmOptionError(
                            f"--set {p.name}={self.overrides[p.name]}: outside the declared "
                            f"range {lo}..{hi}")
                    self.fail(f"param `{p.name}` = {value} lies outside its range {lo}..{hi}",
                              p.value.span)
            self.params[p.name] = value
        for name in self.overrides:
            if name not in self.param_decls:
                hint = did_you_mean(name, self.param_decls)
                known = ", ".join(self.param_decls) or "none"
                raise SwarmOptionError(
                    f"--set {name}: the program has no param `{name}` (params: {known})",
                    hint=hint)

    def _number(self, expr: ast.Expr, what: str):
        """A constant that must be a number (not a boolean or a vector), or None."""
        value = self._const(expr, what)
        if value is not None and (isinstance(value, bool)
                                  or not isinstance(value, int | float)):
            self.fail(f"{what} must be a number", expr.span)
            return None
        return value

    def _const(self, expr: ast.Expr, what: str):
        if self.refused_params and any(isinstance(n, ast.Name) and n.id in
                                       self.refused_params for n in ast.walk(expr)):
            return None   # the param's own error is the mistake, not this use of it
        try:
            value = const_value(expr, self.params)
            problem = constant_problem(value)
            if problem:
                self.fail(f"{what} {problem}", expr.span,
                          "see the limits in docs/limits.md")
                return None
            return value
        except NotConstant as exc:
            self._not_constant(exc.node, what)
        except (ArithmeticError, ValueError, TypeError) as exc:
            self.fail(f"cannot compute {what}: {exc}", expr.span)
        return None

    def _not_constant(self, node: ast.Expr, what: str) -> None:
        """Say why `node` keeps a constant from being computed: a param not declared
        yet, a function that does not exist, or something known only per agent."""
        if isinstance(node, ast.Name) and node.id not in self.params:
            decl = next((d for d in self.tree.decls_of(ast.ParamDecl)
                         if d.name == node.id), None)
            if node.id in self.param_decls:
                self.fail(f"param `{node.id}` cannot use its own value", node.span)
                return
            if decl is not None:
                self.fail(f"param `{node.id}` (line {decl.span.line}) is not known yet here: "
                          f"{what} may use only the params declared before it", node.span,
                          f"declare `{node.id}` above this line")
                return
            if not self._declared_anywhere(node.id):   # `count nn`: a typo, not a rule
                self.fail(f"unknown name `{node.id}`", node.span,
                          did_you_mean(node.id, [*self.param_decls, *CONSTANTS]))
                return
        if isinstance(node, ast.Call):
            from swarmdsl.compiler.builtins import AGGREGATES, FUNCTIONS
            from swarmdsl.compiler.typing_rules import CALL_RULES

            known = {*FUNCTIONS, *AGGREGATES, *CALL_RULES, "neighbors", "neighbours"}
            if node.name not in known:
                self.fail(f"unknown function `{node.name}`", node.name_span,
                          did_you_mean(node.name, known))
                return
        self.fail(f"{what} must be a constant (numbers and params only)", node.span)

    def _declared_anywhere(self, name: str) -> bool:
        """Whether `name` means something somewhere in the program: a built-in value, a
        declaration at top level, a kind, a status, a variable, a `let`, a tree's
        parameter or a name an agent option declares (`map seen ...`). A name that
        means nothing is reported as unknown before any rule about where it stands."""
        if name in BUILTIN_NAMES or name in self.param_decls:
            return True
        stack: list = [self.tree]
        while stack:
            node = stack.pop()
            if isinstance(node, ast.Expr):
                continue    # expressions declare nothing (and may be deep)
            if isinstance(node, ast.Option):
                if _declares(node, name):
                    return True
                continue
            if getattr(node, "name", None) == name and not isinstance(node, ast.ActionStmt):
                return True
            if name in getattr(node, "params", ()):
                return True     # a named tree's parameter
            stack.extend(node.children())
        return False

    # ---- world ----
    def _world(self):
        for w in self.tree.decls_of(ast.WorldDecl)[:1]:
            seen: set[str] = set()
            for opt in w.options:
                spec = WORLD_OPTIONS.get(opt.name)
                if spec is None:
                    self.fail(f"unknown world option `{opt.name}`", opt.name_span,
                              did_you_mean(opt.name, WORLD_OPTIONS))
                    continue
                if opt.name in seen and not getattr(spec, "repeatable", False):
                    self.fail(f"option `{opt.name}` is already set for the world",
                              opt.name_span)
                    continue
                seen.add(opt.name)
                spec(self, opt, self.world)

    # ---- agent kinds ----
    def _declare_kinds(self):
        for i, decl in enumerate(self.tree.decls_of(ast.AgentDecl)):
            k = KindInfo(decl.name, i, decl)
            for s in decl.items_of(ast.StatusDecl):
                if s.name in k.status_decls:
                    self.fail(f"status `{s.name}` is already declared in `{k.name}`",
                              s.name_span)
                    continue
                # A status named like another kind (or a param, field, region) would
                # hide it. One named like its own kind (a kind with one status often
                # is) hides nothing: compared with a kind, the name is the kind.
                if not self.builtin_clash(s.name, s.name_span) and s.name != k.name:
                    self.top_level_clash(s.name, s.name_span)
                k.statuses.append(s.name)
                k.status_decls[s.name] = s
            if not k.statuses:
                self.fail(f"agent `{k.name}` declares no status", decl.name_span,
                          "add one, e.g. `status idle { }`")
            self.kinds.append(k)
        if not self.kinds:
            self.fail("the program declares no agent kind", self.tree.span,
                      "add `agent NAME { count 10; status idle { } }`")

    def _kind_options(self, k: KindInfo):
        for opt in k.decl.items_of(ast.Option):
            if opt.name in k.options:
                self.fail(f"option `{opt.name}` is already set for `{k.name}`", opt.name_span)
                continue
            spec = AGENT_OPTIONS.get(opt.name)
            if spec is None:
                self.fail(f"unknown agent option `{opt.name}`", opt.name_span,
                          did_you_mean(opt.name, AGENT_OPTIONS))
                continue
            k.options[opt.name] = opt
            spec(self, opt, k)

    def _kind_body(self, k: KindInfo):
        init_scope = Scope(k, init=True)
        for item in k.decl.items:
            if isinstance(item, ast.VarDecl | ast.AttrDecl):
                if item.name in k.vars:
                    first = k.vars[item.name].decl.name_span.line
                    self.fail(f"`{item.name}` is already declared in `{k.name}` (line "
                              f"{first})", item.name_span)
                    continue
                if item.name in k.status_decls:
                    self.fail(f"`{item.name}` is both a status and a variable of `{k.name}`",
                              item.name_span)
                    continue
                # A variable would hide the built-in or top-level name in all the
                # kind's code; it is still declared, so its uses raise nothing more.
                clash = self.name_taken(item.name, item.name_span)
                t = self.expr(item.value, init_scope)
                if t not in (NUM, BOOL, VEC, ERR):
                    self.fail(f"a variable holds a number, a boolean or a vector, "
                              f"not {TYPE_TEXT.get(t, t)}", item.value.span)
                k.vars[item.name] = VarInfo(item.name, t, item,
                                            isinstance(item, ast.VarDecl))
                if not clash:
                    self.column_table.claim(self, k, k.vars[item.name])
        # Per-agent options may read variables declared after them; check them now.
        for name, opt in k.options.items():
            late = AGENT_OPTIONS[name].late
            if late is not None and opt.args:
                late(self, opt, k, init_scope)
        for s in k.status_decls.values():
            scope = Scope(k, later={st.name: st for st in s.body
                                    if isinstance(st, ast.LetStmt)})
            self.block(s.body, scope, k)
            for name in scope.locals:
                if name not in scope.used:
                    self.warn(f"`{name}` is bound but never used", _let_span(s.body, name))
        self._sense_radius(k)

    def _unread_vars(self):
        """Warn about a `var` that nothing reads and nothing changes, once every reader
        is known: statuses of any kind (`other.NAME`), properties, metrics and the other
        extensions. Every variable is recorded in agents.parquet, so one the program
        only updates (`trips += 1`) is an output of the run, and an `attr` nobody reads
        is a per-agent label kept for the analysis: warning about those was noise. A
        `var` never read nor set is another matter: it records its initial value only,
        so an update was probably forgotten (or it is an `attr`)."""
        unread = []
        for k in self.kinds:
            for v in k.vars.values():
                key = (k.name, v.name)
                if v.assignable and key not in self.used_vars | self.written_vars:
                    unread.append(SwarmError(
                        f"variable `{v.name}` of `{k.name}` is never read nor changed",
                        v.decl.name_span, "it only records its initial value in "
                        f"agents.parquet: update it in a status, declare it `attr "
                        f"{v.name} = ...` if a per-agent constant is the point, or remove it",
                        severity="warning"))
        self.warnings.extend(unread)
        self.warnings.sort(key=lambda w: (w.span.line, w.span.col) if w.span else (0, 0))

    def _sense_radius(self, k: KindInfo):
        """Without `sense R`, a kind senses as far as its constant neighbour radii reach."""
        if k.sense is not None or not k.uses_neighbors:
            return
        for call, radius in k.neighbor_calls:
            if radius is None and call.args and self.reported_within(call.args[0].span):
                continue    # `neighbors(radus)`: the radius's own error is the mistake
            if radius is None:
                what = "a radius" if not call.args else "a constant radius"
                self.fail(f"`neighbors` without {what} needs the kind's sense radius",
                          call.span, f"add `sense R` to agent `{k.name}`")
                return
        if any(radius is None for _c, radius in k.neighbor_calls):
            return
        for call, radius in k.neighbor_calls:
            if radius <= 0:
                self.fail(f"a neighbour radius must be positive, got {radius:g}",
                          call.args[0].span)
                return
        k.sense = max(r for _c, r in k.neighbor_calls)

    def robot_names(self) -> list[str]:
        """Robot profiles declared in the program with `robot NAME { ... }`."""
        return [r.name for r in self.tree.decls_of(ast.RobotDecl)]


# Top-level declarations whose names agent code reads -> how an error names them.
_READABLE_DECLS = {ast.ParamDecl: "param", ast.FieldDecl: "field",
                   ast.RegionDecl: "region", ast.AgentDecl: "agent kind"}


def _joined(first: Span, last: Span) -> Span:
    """The span from the start of `first` to the end of `last`."""
    return Span(first.filename, first.line, first.col, last.end_line, last.end_col)


def _let_span(body, name: str) -> Span:
    for st in body:
        if isinstance(st, ast.LetStmt) and st.name == name:
            return st.name_span
    return body[0].span


_NUMBER_TEXT = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")


def _parse_override(name: str, raw: str, default):
    text = raw.strip()
    if isinstance(default, bool):
        if text.lower() in ("true", "false"):
            return text.lower() == "true"
        raise SwarmOptionError(f"--set {name}={raw}: `{name}` is a boolean; use true or false")
    # The language's own number syntax: float() would also take `1_0`, `infinity`
    # and digits of other scripts.
    if not _NUMBER_TEXT.fullmatch(text):
        raise SwarmOptionError(f"--set {name}={raw}: `{raw}` is not a number (write it as "
                               "in a program: 10, -2.5, 1e-3)")
    value = float(text)
    if isinstance(default, int) and value.is_integer():
        return int(value)
    if value != value or value in (float("inf"), float("-inf")):
        raise SwarmOptionError(f"--set {name}={raw}: the value must be finite")
    return value


def check_override(info, name: str, raw: str) -> None:
    """Refuse `--set NAME=RAW` for a checked program's param as `run` would: a value of
    the wrong type, not finite or too large, or outside the declared range. A sweep
    checks every value of its axes with it before the first run."""
    decl = info.param_decls[name]
    value = _parse_override(name, raw, info.params[name])
    problem = constant_problem(value)
    if problem:
        raise SwarmOptionError(f"--set {name}={raw}: the value {problem}")
    if decl.lo is None or isinstance(value, bool):
        return
    try:
        lo, hi = const_value(decl.lo, info.params), const_value(decl.hi, info.params)
    except (NotConstant, ArithmeticError, ValueError, TypeError):
        return
    if not lo <= value <= hi:
        raise SwarmOptionError(f"--set {name}={raw}: outside the declared range {lo}..{hi}")


def check(tree: ast.Program, filename: str, overrides: dict[str, str] | None = None,
          program_dir: Path | None = None):
    """Check a parsed program; return ProgramInfo or raise SwarmCheckError/SwarmOptionError."""
    return Checker(tree, filename, overrides or {}, program_dir).run()
