"""Every name of a program, where it is declared and everywhere it is used.

The walk follows the parsed AST with what the checker recorded about it: a `Name` the
checker resolved (`checker.facts.name_of`: a `let`, a variable, a status, a kind, a param's
value, a field...) is that thing; a name the checker did not reach (a named tree's
body is checked as copies, one per use; a part after an error) is looked up by the
same rules the checker applies, innermost first: the tree's parameters, the status's
`let`s above it, the kind's variables, then what the program declares at top level.

A symbol's key says what it is and where it lives: `("var", KIND, NAME)`, `("local",
KIND, STATUS, NAME)`, `("status", KIND, NAME)`, `("param", NAME)`... A built-in (a
function, an aggregate, an action, agent state such as `pos`) is keyed `("builtin",
CATEGORY, NAME)` and has no declaration in the file. One occurrence can stand for
several symbols: `other.energy` reads the variable `energy` of every kind that has one,
so renaming one renames them together (`linked`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from swarmdsl.compiler import ast
from swarmdsl.compiler.facts import Facts
from swarmdsl.compiler.visit import Visitor
from swarmdsl.lsp.ranges import Range

# How messages and hovers name each category of symbol.
CATEGORY_WORDS = {"param": "param", "var": "variable", "attr": "attribute",
                  "local": "`let` binding", "status": "status", "kind": "agent kind",
                  "field": "field", "region": "region", "robot": "robot profile",
                  "tree": "behaviour tree", "tree_param": "tree parameter",
                  "objective": "objective", "metric": "metric", "property": "property",
                  "memory": "path memory", "map": "internal map", "labels": "label set"}


@dataclass(frozen=True)
class Symbol:
    key: tuple
    name: str
    category: str        # param, var, attr, local, status, kind, field, region, ...
    range: Range         # its name where declared
    decl: object         # the declaring AST node
    container: str = ""  # the kind (and status) it belongs to, for messages


@dataclass(frozen=True)
class Occurrence:
    range: Range
    keys: tuple          # the symbols this text stands for (usually one)
    is_def: bool = False
    node: object = None  # the AST node whose type the checker recorded, if any

    @property
    def key(self) -> tuple:
        return self.keys[0]


@dataclass
class Index:
    symbols: dict[tuple, Symbol] = field(default_factory=dict)
    occurrences: list[Occurrence] = field(default_factory=list)

    def at(self, line: int, col: int) -> Occurrence | None:
        """The occurrence under (or just after) the cursor; the innermost one."""
        best = None
        for occ in self.occurrences:
            if occ.range.contains(line, col):
                if best is None or (occ.range.line, occ.range.col) >= (best.range.line,
                                                                        best.range.col):
                    best = occ
        return best

    def references(self, key: tuple) -> list[Occurrence]:
        return [o for o in self.occurrences if key in o.keys]

    def linked(self, key: tuple) -> set[tuple]:
        """`key` and every symbol an occurrence of it also stands for, transitively."""
        out, todo = {key}, [key]
        while todo:
            k = todo.pop()
            for o in self.references(k):
                for other in o.keys:
                    if other not in out and other[0] != "builtin":
                        out.add(other)
                        todo.append(other)
        return out


@dataclass
class _Ctx:
    kind: str | None = None
    status: str | None = None
    lets: dict = field(default_factory=dict)      # name -> key
    tree: str | None = None
    tree_params: dict = field(default_factory=dict)
    option_of: str = ""                           # "world", "agent", "field", "robot"


def build_index(analysis) -> Index:
    return _Builder(analysis).run()


class _Builder(Visitor):
    """The index's walk: declarations in order, then statements and expressions by
    class (`visit.Visitor`), each name met a definition or a use."""

    NODES = (ast.Expr, ast.Stmt)
    # Expressions that name nothing themselves: the names are in their children.
    WALKED = frozenset({"Num", "BoolLit", "StrLit", "Vec", "BinOp", "Chain", "Neg",
                        "Compare", "AndOp", "OrOp", "NotOp", "Cond", "Where", "FieldAt",
                        "TreeResult", "Forever"})

    def __init__(self, analysis):
        from swarmdsl.compiler.tree_ast import TreeDecl

        self.tree: ast.Program = analysis.tree
        self.chk = analysis.checker
        self.facts = self.chk.facts if self.chk is not None else Facts()
        self.index = Index()
        decls = self.tree.decls
        self.params = {d.name: d for d in decls if isinstance(d, ast.ParamDecl)}
        self.top = {}
        for d in decls:
            name = getattr(d, "name", None)
            if name is not None and not isinstance(d, ast.ParamDecl):
                self.top.setdefault(name, d)
        self.trees = {d.name: d for d in decls if isinstance(d, TreeDecl)}
        self.kinds = {d.name: d for d in decls if isinstance(d, ast.AgentDecl)}
        # per kind: variables, statuses and the names its options declare
        self.kind_vars = {k: {i.name: i for i in d.items
                              if isinstance(i, ast.VarDecl | ast.AttrDecl)}
                          for k, d in self.kinds.items()}
        self.kind_statuses = {k: {s.name: s for s in d.items_of(ast.StatusDecl)}
                              for k, d in self.kinds.items()}
        self.kind_slots = {k: self._slots(d) for k, d in self.kinds.items()}
        self.kind_objectives = {k: {o.name: o for o in d.items_of(ast.ObjectiveDecl)}
                                for k, d in self.kinds.items()}

    @staticmethod
    def _slots(decl) -> dict:
        from swarmdsl.compiler.options import AGENT_OPTIONS

        out = {}
        for opt in decl.items_of(ast.Option):
            spec = AGENT_OPTIONS.get(opt.name)
            if (spec is not None and spec.declares and opt.args
                    and isinstance(opt.args[0], ast.Name)):
                out.setdefault(opt.args[0].id, (opt, opt.args[0]))
        return out

    # ---- recording ----
    def define(self, key, name, category, span, decl, container="") -> None:
        if span is None:
            return
        rng = Range.of(span)
        self.index.symbols.setdefault(key, Symbol(key, name, category, rng, decl, container))
        self.index.occurrences.append(Occurrence(rng, (key,), True, decl))

    def use(self, keys, span, node=None) -> None:
        if keys and span is not None:
            self.index.occurrences.append(Occurrence(Range.of(span), tuple(keys), False, node))

    # ---- walk ----
    def run(self) -> Index:
        from swarmdsl.compiler.tree_ast import TreeDecl

        for d in self.tree.decls:
            if isinstance(d, ast.ParamDecl):
                self.define(("param", d.name), d.name, "param", d.name_span, d)
                for e in (d.value, d.lo, d.hi):
                    self.expr(e, _Ctx())
            elif isinstance(d, ast.WorldDecl):
                self.options(d.options, _Ctx(option_of="world"))
            elif isinstance(d, ast.FieldDecl):
                self.define(("field", d.name), d.name, "field", d.name_span, d)
                self.options(d.options, _Ctx(option_of="field"))
            elif isinstance(d, ast.RegionDecl):
                self.define(("region", d.name), d.name, "region", d.name_span, d)
                self.expr(d.shape, _Ctx())
            elif isinstance(d, ast.RobotDecl):
                self.define(("robot", d.name), d.name, "robot", d.name_span, d)
                self.options(d.options, _Ctx(option_of="robot"))
            elif isinstance(d, ast.AgentDecl):
                self.agent(d)
            elif isinstance(d, TreeDecl):
                self.define(("tree", d.name), d.name, "tree", d.name_span, d)
                ctx = _Ctx(tree=d.name)
                for p, span in zip(d.params, d.param_spans, strict=True):
                    key = ("tree_param", d.name, p)
                    self.define(key, p, "tree_param", span, d, f"tree {d.name}")
                    ctx.tree_params.setdefault(p, key)
                self.tree_node(d.root, ctx)
            else:
                self.named_decl(d, _Ctx())
        self.index.occurrences.sort(key=lambda o: (o.range.line, o.range.col))
        return self.index

    def named_decl(self, d, ctx: _Ctx, kind: str | None = None) -> None:
        """A property or metric (top level or a kind's): only its name is declared."""
        cat = "metric" if isinstance(d, ast.MetricDecl) else "property"
        name = getattr(d, "name", None)
        if name is not None and hasattr(d, "name_span"):
            key = (cat, kind, name) if kind else (cat, name)
            self.define(key, name, cat, d.name_span, d, kind or "")
        for child in d.children():
            self.any(child, ctx)

    def agent(self, d: ast.AgentDecl) -> None:
        k = d.name
        self.define(("kind", k), k, "kind", d.name_span, d)
        for item in d.items:
            if isinstance(item, ast.Option):
                self.option(item, _Ctx(kind=k, option_of="agent"))
            elif isinstance(item, ast.VarDecl | ast.AttrDecl):
                cat = "var" if isinstance(item, ast.VarDecl) else "attr"
                self.define(("var", k, item.name), item.name, cat, item.name_span, item,
                            f"agent {k}")
                self.expr(item.value, _Ctx(kind=k))
            elif isinstance(item, ast.ObjectiveDecl):
                self.define(("objective", k, item.name), item.name, "objective",
                            item.name_span, item, f"agent {k}")
                self.expr(item.target, _Ctx(kind=k))
            elif isinstance(item, ast.StatusDecl):
                self.define(("status", k, item.name), item.name, "status", item.name_span,
                            item, f"agent {k}")
                self.block(item.body, _Ctx(kind=k, status=item.name))
            else:
                self.named_decl(item, _Ctx(kind=k), kind=k)

    def options(self, options, ctx: _Ctx) -> None:
        for opt in options:
            self.option(opt, ctx)

    def option(self, opt: ast.Option, ctx: _Ctx) -> None:
        self.use([("builtin", f"{ctx.option_of}_option", opt.name)], opt.name_span, opt)
        args = list(opt.args)
        if ctx.kind and args and isinstance(args[0], ast.Name):
            slot = self.kind_slots[ctx.kind].get(args[0].id)
            if slot is not None and slot[1] is args[0]:
                self.define(("slot", ctx.kind, args[0].id), args[0].id, opt.name,
                            args[0].span, opt, f"agent {ctx.kind}")
                args = args[1:]
        for a in args:
            if isinstance(a, ast.Name) and opt.name == "robot" and a.id in self.top:
                self.use([("robot", a.id)], a.span, a)
            else:
                self.expr(a, ctx)

    def block(self, stmts, ctx: _Ctx) -> None:
        for st in stmts:
            self.stmt(st, ctx)

    def stmt(self, st, ctx: _Ctx) -> None:
        self.visit(st, ctx)

    def visit_LetStmt(self, st: ast.LetStmt, ctx: _Ctx) -> None:
        self.expr(st.value, ctx)
        key = ("local", ctx.kind, ctx.status, st.name)
        self.define(key, st.name, "local", st.name_span, st,
                    f"agent {ctx.kind}, status {ctx.status}")
        ctx.lets.setdefault(st.name, key)

    def visit_AssignStmt(self, st: ast.AssignStmt, ctx: _Ctx) -> None:
        self.expr(st.value, ctx)
        self.use(self.target_keys(st.target, ctx), st.target_span, st)

    def visit_WhenStmt(self, st: ast.WhenStmt, ctx: _Ctx) -> None:
        self.expr(st.cond, ctx)
        if ctx.kind:
            self.use([("status", ctx.kind, st.target)]
                     if st.target in self.kind_statuses[ctx.kind] else [],
                     st.target_span, st)
        self.block(st.body, ctx)

    def visit_ActionStmt(self, st: ast.ActionStmt, ctx: _Ctx) -> None:
        self.use([("builtin", "action", st.name)], st.name_span, st)
        for a in st.args:
            self.expr(a, ctx)

    def visit_TreeStmt(self, st, ctx: _Ctx) -> None:
        self.tree_node(st.root, ctx)

    def target_keys(self, name: str, ctx: _Ctx) -> list:
        from swarmdsl.compiler.info import AGENT_STATE

        if ctx.kind and name in self.kind_vars[ctx.kind]:
            return [("var", ctx.kind, name)]
        if name in AGENT_STATE:
            return [("builtin", "state", name)]
        if ctx.kind is None:      # a named tree's body: the kinds that have it
            return [("var", k, name) for k, vs in self.kind_vars.items() if name in vs]
        return []

    def tree_node(self, node, ctx: _Ctx) -> None:
        from swarmdsl.compiler.tree_ast import AssignLeaf, Composite, Decorator, Leaf

        if isinstance(node, Composite):
            self.use([("builtin", "tree_node", node.kind)], node.kw_span, node)
            self.expr(node.threshold, ctx)
            for kid in node.kids:
                self.tree_node(kid, ctx)
        elif isinstance(node, Decorator):
            word = node.kind.split()[0]
            self.use([("builtin", "tree_node", word)], node.kw_span, node)
            self.expr(node.count, ctx)
            self.tree_node(node.child, ctx)
        elif isinstance(node, Leaf):
            self.expr(node.expr, ctx)
        elif isinstance(node, AssignLeaf):
            self.stmt(node.stmt, ctx)
        elif node is not None:
            self.any(node, ctx)

    def any(self, node, ctx: _Ctx) -> None:
        if isinstance(node, ast.Expr):
            self.expr(node, ctx)
        elif isinstance(node, ast.Stmt):
            self.stmt(node, ctx)
        elif node is not None:
            for child in node.children():
                self.any(child, ctx)

    # ---- expressions ----
    def expr(self, e, ctx: _Ctx) -> None:
        if e is not None:
            self.visit(e, ctx)

    def visit_Name(self, e: ast.Name, ctx: _Ctx) -> None:
        self.use(self.name_keys(e, ctx), e.span, e)

    def visit_Attr(self, e: ast.Attr, ctx: _Ctx) -> None:
        self.expr(e.obj, ctx)
        self.use(self.attr_keys(e, ctx), e.name_span, e)

    def visit_Call(self, e: ast.Call, ctx: _Ctx) -> None:
        self.use(self.call_keys(e), e.name_span, e)
        for a in (*e.args, e.each, e.default):
            self.expr(a, ctx)

    def call_keys(self, e: ast.Call) -> list:
        from swarmdsl.compiler.actions import ACTIONS
        from swarmdsl.compiler.builtins import AGGREGATES, FUNCTIONS
        from swarmdsl.compiler.tree_ast import LONG_ACTIONS
        from swarmdsl.compiler.typing_rules import CALL_RULES

        resolved = self.facts.name_of(e)
        if e.name in self.trees:
            return [("tree", e.name)]
        if resolved and resolved[0] == "agg" or (e.name in AGGREGATES
                                                  and e.name not in FUNCTIONS):
            return [("builtin", "aggregate", e.name)]
        if e.name in FUNCTIONS:
            return [("builtin", "function", e.name)]
        if e.name in ("neighbors", "neighbours"):
            return [("builtin", "neighbors", e.name)]
        if e.name in LONG_ACTIONS:
            return [("builtin", "long_action", e.name)]
        if e.name in ACTIONS:
            return [("builtin", "action", e.name)]
        if e.name in CALL_RULES:
            return [("builtin", "call", e.name)]
        return []

    def attr_keys(self, e: ast.Attr, ctx: _Ctx) -> list:
        from swarmdsl.compiler.info import AGENT_STATE

        if isinstance(e.obj, ast.Name) and e.obj.id == "other":
            if e.name in AGENT_STATE:
                return [("builtin", "state", e.name)]
            return [("var", k, e.name) for k, vs in self.kind_vars.items() if e.name in vs]
        if e.name in ("x", "y"):
            return [("builtin", "component", e.name)]
        return []

    def name_keys(self, e: ast.Name, ctx: _Ctx) -> list:
        from swarmdsl.compiler.builtins import CONSTANTS
        from swarmdsl.compiler.info import AGENT_STATE, GLOBAL_STATE, PAIR_NAMES

        n = e.id
        resolved = self.facts.name_of(e)
        if n in ctx.tree_params:
            return [ctx.tree_params[n]]
        if n in ctx.lets:
            return [ctx.lets[n]]
        k = ctx.kind
        if k and n in self.kind_vars[k]:
            return [("var", k, n)]
        if resolved is not None:
            cat = resolved[0]
            if cat == "status":
                return self.status_keys(n, k)
            if cat == "kind" and n in self.kinds:
                return [("kind", n)]
            if cat == "const" and n in self.params:
                return [("param", n)]
            if cat in ("field", "region") and n in self.top:
                return [(cat, n)]
            if cat in ("memory", "labels", "map") and k and n in self.kind_slots[k]:
                return [("slot", k, n)]
            if cat == "objective" and n in self.kind_objectives.get(resolved[1], {}):
                return [("objective", resolved[1], n)]
            if cat == "var" and k is None:
                return [("var", kk, n) for kk, vs in self.kind_vars.items() if n in vs]
        if n in AGENT_STATE:
            return [("builtin", "state", n)]
        if n in PAIR_NAMES or n == "other":
            return [("builtin", "pair", n)]
        if n in GLOBAL_STATE:
            return [("builtin", "global", n)]
        if n in self.params:
            return [("param", n)]
        if n in CONSTANTS:
            return [("builtin", "constant", n)]
        if k and n in self.kind_slots[k]:
            return [("slot", k, n)]
        if k and n in self.kind_objectives[k]:
            return [("objective", k, n)]
        if k and n in self.kind_statuses[k]:
            return [("status", k, n)]
        decl = self.top.get(n)
        if decl is not None:
            cat = {ast.FieldDecl: "field", ast.RegionDecl: "region",
                   ast.AgentDecl: "kind", ast.RobotDecl: "robot"}.get(type(decl))
            if cat:
                return [(cat, n)]
        if k is None:   # a named tree's body or a top-level property: any kind's
            keys = [("var", kk, n) for kk, vs in self.kind_vars.items() if n in vs]
            return keys or self.status_keys(n, None)
        return []

    def status_keys(self, name: str, kind: str | None) -> list:
        """A status compared by name: the kind's own when it has one, else every kind's
        of that name (status names are compared across kinds)."""
        if kind and name in self.kind_statuses.get(kind, {}):
            return [("status", kind, name)]
        return [("status", k, name) for k, ss in self.kind_statuses.items() if name in ss]
